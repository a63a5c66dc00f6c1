"""Perspective transformation (PT) for road scenes (docs/design.md, 'Perspective transformation').

A planar road seen by a rectified rig has the disparity

    d(u, v) = a0 + a1 (v cos(theta) - u sin(theta))                      (road model)

(theta = camera roll; theta = 0 gives the v-disparity line).  It is linear in
disguise: ``d = a0 + b1 v + b2 u`` with ``b1 = a1 cos(theta)``, ``b2 = -a1 sin(theta)``.
:func:`fit_road_model` fits it robustly to a coarse disparity map (RANSAC start, then
iteratively re-weighted least squares with Tukey's biweight), so that cars, kerbs and
potholes do not bend it.  The right image is then warped by the per-pixel shift
``s(u, v) = a0 + b1 v + b2 u - delta`` (``kernels.*.pt_warp``), the pair is matched over
the narrow range [0, 2 delta + slack], and the disparity is restored exactly with
``d = d' (1 - b2) + s(u, v)`` (``kernels.*.pt_restore``).

:meth:`RoadModel.off_band` rejects the model after the narrow-range match when too many
pixels lie off the band (:func:`band_end_share`): the scene is not a road.

The road model's rules are written once, per pixel, in :mod:`d3cli.kernels.road_model`
(the shift, the restore, the right-image rule, the validity after the restore), compiled
into the warp and restore of both backends and into the host kernels this module reaches
through :mod:`d3cli.kernels.host`: :func:`restored_validity` (PT-D3Stereo and PT-SGM),
:func:`match_in_right_image` (the road report too) and ``host.shift_plane_f32`` (the
road plane of the smoothing in step 8).
"""

from __future__ import annotations

import logging
import math
from dataclasses import asdict, dataclass, replace

import numpy as np

from ..kernels import host

log = logging.getLogger(__name__)

# Fewer decided coarse pixels than this cannot tell a road from noise.
MIN_POINTS = 50
_RANSAC_HYPOTHESES = 200
_RANSAC_SAMPLE = 5000  # points scored per hypothesis (a seeded subsample)
TUKEY_C = 4.685  # Tukey biweight constant (95 % efficiency for Gaussian residuals)


@dataclass(frozen=True)
class RoadModel:
    """A fitted road disparity model, full-resolution pixels.

    Attributes
    ----------
    a0, b1, b2 : float
        ``d(u, v) = a0 + b1 v + b2 u``.
    a1 : float
        Signed gradient along the road: ``b1 = a1 cos(theta)``, ``b2 = -a1 sin(theta)``,
        with theta in (-90, 90) degrees (so ``a1`` has the sign of ``b1``).
    theta : float
        Roll angle, radians.
    inlier_share : float
        Share of the fitted points within the inlier threshold, in [0, 1].
    n_points : int
        Decided coarse pixels the fit used.
    road_like : bool
        True when the model may be used (enough points and inliers, ``a1 > 0``).
    reason : str
        Why the scene is not road-like ("" when it is).
    """

    a0: float
    b1: float
    b2: float
    a1: float
    theta: float
    inlier_share: float
    n_points: int
    road_like: bool = True
    reason: str = ""

    def predict(self, u, v):
        """Model disparity at full-resolution pixel coordinates (arrays broadcast)."""
        return self.a0 + self.b1 * np.asarray(v, dtype=np.float64) + self.b2 * np.asarray(u, dtype=np.float64)

    def to_info(self, *, narrow_range: int) -> dict:
        """JSON-ready summary for ``DisparityResult.info['pt']``.

        ``narrow_range`` is the range searched after the transformation; it is recorded as
        None, with ``fallback`` True, when the model is not road-like.
        """
        out = asdict(self)
        out["theta_deg"] = math.degrees(out.pop("theta"))
        out = {k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in out.items()}
        return out | {"narrow_range": narrow_range if self.road_like else None, "fallback": not self.road_like}

    def fallback_warning(self, max_disparity: int, *, settings: str = "") -> str:
        """The warning of a pair that is matched over the full range instead.

        Parameters
        ----------
        max_disparity : int
        settings : str, keyword-only
            The bundled config whose settings match the pair instead (``pt.fallback_config``);
            "" when the run's own.
        """
        with_ = f" with the settings of {settings}.yaml" if settings else ""
        return f"perspective transformation skipped: {self.reason}; searched the full range 0-{max_disparity}{with_}"

    def off_band(self, share: float, *, limit: float, margin: int) -> "RoadModel":
        """This model rejected when too much of the image lies off the road band.

        The coarsest-level fit cannot tell an indoor scene from a road: at 1/8 resolution,
        with an inlier band of one coarse pixel (8 px), the Motorcycle sample's disparities
        fit a plane as well as a road's do (89 % inliers; its implied camera height and
        pitch, about 1.7 m and 37 deg, are those of a road camera).  The narrow-range match at
        full resolution can: a pixel matched at an end of the band (``d' = 0`` or
        ``2 margin + slack``) has its true disparity more than ``margin`` off the plane.

        Parameters
        ----------
        share : float
            Share of all pixels matched at an end of the narrow range.
        limit : float, keyword-only
            Largest share of a road surface (``pt.max_band_end_share``).
        margin : int, keyword-only
            ``pt.margin``, for the reason's text.

        Returns
        -------
        RoadModel
            ``self`` when ``share <= limit``; otherwise a copy with ``road_like`` False and
            the reason.
        """
        if share <= limit:
            return self
        reason = (f"{100 * share:.1f}% of the pixels lie more than {margin} px of disparity off the "
                  f"fitted plane (> {100 * limit:.1f}%)")
        return replace(self, road_like=False, reason=reason)


def band_end_share(narrow: np.ndarray, *, narrow_range: int) -> float:
    """Share of all pixels of a narrow-range map matched at an end of the range.

    The ``range_end_share`` of :func:`restored_validity` (decided pixels at ``d' <= 0``
    or ``d' >= narrow_range``), before the map is refined and restored.

    Parameters
    ----------
    narrow : ndarray, int, (H, W)
        Full-resolution narrow-range disparities d', ``-1`` undecided.
    narrow_range : int, keyword-only
        Largest narrow-range disparity ``2 margin + slack``.

    Returns
    -------
    float
        In [0, 1].
    """
    narrow = np.asarray(narrow)
    return float(np.count_nonzero((narrow == 0) | (narrow >= narrow_range))) / max(narrow.size, 1)


def coarse_points(disparity: np.ndarray, *, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Decided pixels of a coarse disparity map in full-resolution units.

    Parameters
    ----------
    disparity : ndarray, (h, w)
        Coarse-level disparity: int (``-1`` undecided) or float (non-finite or < 0
        undecided).
    scale : float, keyword-only
        Level scale ``2^(k-1)``: the coarse pixel (u_c, v_c) covers full-resolution
        pixels ``u = (u_c + 0.5) scale - 0.5`` (area averaging), ``d = d_c scale``.

    Returns
    -------
    u, v, d : ndarray, float64, (N,)
    """
    disp = np.asarray(disparity)
    good = disp >= 0
    if disp.dtype.kind == "f":
        good &= np.isfinite(disp)
    vc, uc = np.nonzero(good)
    u = (uc + 0.5) * scale - 0.5
    v = (vc + 0.5) * scale - 0.5
    return u, v, disp[vc, uc].astype(np.float64) * scale


#: Relative size below which the centred normal matrix of :func:`solve_road_model` counts as singular
#: (collinear points: its determinant is 0 up to rounding).
SINGULAR = 1e-12


def solve_road_model(u, v, d, w=None):
    """Weighted least squares of d = a0 + b1 v + b2 u; None when singular.

    Solved by the normal equations in coordinates centred on the weighted means: there the
    constant's column is orthogonal to the others, so (b1, b2) come from a 2x2 system whose
    condition is that of the points' spread (about 1-10 on a road image; uncentred, the
    columns 1, v, u of a 720p image give about 1e7).  Compiled, one pass per sum
    (:func:`d3cli.kernels.perspective.road_fit.solve_weighted`, which the IRLS rounds call
    too: one solver for the whole fit) instead of LAPACK's SVD least squares
    (``np.linalg.lstsq``: 1.2 ms per call on the 14,000 coarse points of a 720p road pair);
    the solutions agree with it to about 1e-12 relative (tests/method/test_perspective.py),
    not bit for bit.
    """
    from ..kernels.host import solve_weighted

    u, v, d = (np.ascontiguousarray(x, np.float64) for x in (u, v, d))
    w = np.ones_like(u) if w is None else np.ascontiguousarray(w, np.float64)
    ok, a0, b1, b2 = solve_weighted(u, v, d, w, SINGULAR)
    return np.array([a0, b1, b2]) if ok else None


def draw_triples(rng, n, count):
    """``count`` rows of three distinct indices below ``n`` (>= 3), each row uniform over
    the ordered triples: integer triples drawn at once, the rows that repeat an index
    drawn again.

    One call instead of ``count`` calls of ``Generator.choice(n, 3, replace=False)``,
    which take 4.4 ms a road pair (200 calls of Python and small-array overhead; 3 % of
    the pair's time on 2 cores); the same distribution, another stream of the same seed
    (the road check of docs/road.md runs with it).
    """
    picks = rng.integers(0, n, size=(count, 3))
    while True:
        again = (picks[:, 0] == picks[:, 1]) | (picks[:, 0] == picks[:, 2]) | (picks[:, 1] == picks[:, 2])
        k = int(np.count_nonzero(again))
        if k == 0:
            return picks
        picks[again] = rng.integers(0, n, size=(k, 3))


def _ransac(u, v, d, threshold, rng):
    """Best 3-point hypothesis by inlier count on a subsample; None if all degenerate.

    The hypotheses are drawn at once (:func:`draw_triples`), then solved and scored all
    at once: NumPy's stacked ``det``/``solve`` run the same LAPACK routine per matrix and
    the scores are the same element-wise float64 expressions, so the result is bit for
    bit that of a loop over the hypotheses (the first of the best counts wins), without
    200 rounds of Python and small-array overhead.
    """
    n = u.size
    idx = rng.choice(n, size=min(n, _RANSAC_SAMPLE), replace=False)
    us, vs, ds = u[idx], v[idx], d[idx]
    picks = draw_triples(rng, us.size, _RANSAC_HYPOTHESES)
    a = np.stack([np.ones(picks.shape, np.float64), vs[picks], us[picks]], axis=2)  # (hypotheses, 3, 3)
    usable = np.abs(np.linalg.det(a)) >= 1e-6  # not a collinear sample
    if not usable.any():
        return None
    sols = np.linalg.solve(a[usable], ds[picks[usable]][:, :, None])[:, :, 0]
    # numba loaded here, not at import: the PT-SGM baseline imports this module too
    from ..kernels.host import ransac_inlier_counts

    counts = ransac_inlier_counts(np.ascontiguousarray(sols), np.ascontiguousarray(us), np.ascontiguousarray(vs),
                                  np.ascontiguousarray(ds), float(threshold))
    best = sols[int(np.argmax(counts))]
    # Refit on the hypothesis' inliers: a 3-point model is noisy.
    inl = np.abs(d - (best[0] + best[1] * v + best[2] * u)) <= threshold
    refit = solve_road_model(u[inl], v[inl], d[inl]) if inl.sum() >= 3 else None
    return refit if refit is not None else best


def reweighted_refit(u, v, d, sol, threshold, iterations):
    """Tukey-biweight IRLS from ``sol``; the scale never drops below the threshold.

    Compiled (:func:`d3cli.kernels.perspective.road_fit.irls`): as a NumPy loop the rounds
    take 2.9 ms of a 720p road pair's 3.9 ms fit; the same rounds, sums in another order
    (the models agree to about 1e-12: tests/method/test_perspective.py holds the two).
    """
    from ..kernels.host import irls

    return irls(np.ascontiguousarray(u, np.float64), np.ascontiguousarray(v, np.float64),
                np.ascontiguousarray(d, np.float64), np.asarray(sol, np.float64), float(threshold), int(iterations),
                TUKEY_C, SINGULAR)


def fit_road_model(
    disparity: np.ndarray,
    *,
    scale: float,
    inlier_threshold: float = 1.0,
    iterations: int = 10,
    min_inlier_share: float = 0.5,
    seed: int = 0,
) -> RoadModel:
    """Robust fit of the road disparity model to a coarse disparity map (docs/design.md, 'Perspective transformation').

    RANSAC (seeded, 3-point hypotheses scored on a subsample) gives the start, IRLS with
    Tukey's biweight refines it on all points.  Obstacles, kerbs and potholes are
    outliers and get zero weight.

    Parameters
    ----------
    disparity : ndarray, (h, w)
        Coarse-level disparity (int, ``-1`` undecided; or float, non-finite undecided),
        in coarse pixels.
    scale : float, keyword-only
        Level scale ``2^(k-1)``; the fit is in full-resolution units.
    inlier_threshold : float, keyword-only
        |residual| counted as inlier, in coarse pixels (``scale`` full-resolution px).
    iterations : int, keyword-only
        IRLS rounds.
    min_inlier_share : float, keyword-only
        Below this inlier share the scene is not road-like.
    seed : int, keyword-only
        Seed of the RANSAC generator (the fit is deterministic).

    Returns
    -------
    RoadModel
        ``road_like`` False (with ``reason``) when there are fewer than 50 decided
        pixels, the inlier share is below ``min_inlier_share`` or ``a1 <= 0``
        (disparity not growing towards the bottom of the image).
    """
    u, v, d = coarse_points(disparity, scale=scale)
    n = int(u.size)
    threshold = float(inlier_threshold) * float(scale)
    if n < MIN_POINTS:
        return RoadModel(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, n, False, f"only {n} decided coarse pixels (< {MIN_POINTS})")
    rng = np.random.default_rng(seed)
    sol = _ransac(u, v, d, threshold, rng)
    if sol is None:
        return RoadModel(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, n, False, "all decided coarse pixels are collinear")
    sol = reweighted_refit(u, v, d, sol, threshold, int(iterations))
    a0, b1, b2 = (float(x) for x in sol)
    share = float(np.mean(np.abs(d - (a0 + b1 * v + b2 * u)) <= threshold))
    theta = math.atan(-b2 / b1) if b1 != 0.0 else math.copysign(math.pi / 2, -b2)
    a1 = math.copysign(math.hypot(b1, b2), b1) if b1 != 0.0 else 0.0
    reason = ""
    if share < min_inlier_share:
        reason = f"only {100 * share:.0f}% of the coarse disparities fit a plane (< {100 * min_inlier_share:.0f}%)"
    elif a1 <= 0.0:
        reason = f"the disparity does not grow towards the image bottom (a1 = {a1:.4f})"
    return RoadModel(a0, b1, b2, a1, theta, share, n, not reason, reason)


#: The plane is fitted again to the band (:func:`refit_on_band`) when more than this share of
#: ``pt.max_band_end_share`` of the pixels were matched at the band's ends: a road whose
#: plane is right puts fewer there (below 0.9 % on 95 % of 189 synthetic 720p road pairs,
#: 1.0 % on sid-campus), and a plane several pixels off at the far rows puts the floors of
#: potholes there before it puts the road (a pair with 3.0 % lost half of a 61 mm pothole).
REFIT_SHARE = 0.5

#: Inlier threshold of :func:`refit_on_band`, full-resolution pixels: the restored
#: disparities of a narrow match scatter by a fraction of a pixel about a planar road, so
#: a pothole floor or a kerb a few pixels off the plane is an outlier there (the coarse
#: fit's threshold, one coarse pixel, counts up to 8 px as the road).
REFIT_THRESHOLD_PX = 1.0


def refit_on_band(narrow: np.ndarray, model: RoadModel, *, margin: float, narrow_range: int, scale: int,
                  iterations: int = 10, min_inlier_share: float = 0.5) -> RoadModel:
    """The road model fitted again to the full-resolution match against the road band.

    The coarse fit of :func:`fit_road_model` reads disparities in steps of ``scale``
    pixels: on a dark pair it can tilt the plane by several pixels at the far rows, and on
    a pair whose nearest potholes lie several pixels below the plane they pull it (within
    the coarse fit's inlier band).  The narrow match then puts the road near an end of
    its band, and :meth:`RoadModel.off_band` would take a road for another scene.  Its
    estimates inside the band are full-resolution disparities of the road, so the plane
    fitted to them is the road's, whatever the coarse fit's error was.

    The estimates away from the band's ends (``0 < d' < narrow_range``), restored to the
    full range (``d' (1 - b2) + s(u, v)``, :mod:`d3cli.kernels.road_model`), are averaged
    over blocks of ``scale`` x ``scale`` pixels (a block with fewer than half of its pixels
    estimated is left out) and fitted as a coarse map (:func:`fit_road_model`) with an
    inlier threshold of :data:`REFIT_THRESHOLD_PX`.

    Parameters
    ----------
    narrow : ndarray, int, (H, W)
        Narrow-range disparities d' of a match against the right image warped by ``model``
        (``-1`` undecided).
    model : RoadModel
        The model the right image was warped with.
    margin : float, keyword-only
        ``pt.margin``.
    narrow_range : int, keyword-only
        ``pt.narrow_range``.
    scale : int, keyword-only
        Block side, pixels (the coarse fit's level scale).
    iterations, min_inlier_share : keyword-only
        As :func:`fit_road_model`.

    Returns
    -------
    RoadModel
    """
    narrow = np.asarray(narrow)
    h, w = (narrow.shape[0] // scale) * scale, (narrow.shape[1] // scale) * scale
    d_prime = narrow[:h, :w].astype(np.float64)
    inside = (d_prime > 0) & (d_prime < narrow_range)
    v, u = np.mgrid[0:h, 0:w]
    restored = d_prime * (1.0 - model.b2) + (model.a0 + model.b1 * v + model.b2 * u - margin)
    blocks = (h // scale, scale, w // scale, scale)
    count = inside.reshape(blocks).sum(axis=(1, 3))
    total = np.where(inside, restored, 0.0).reshape(blocks).sum(axis=(1, 3))
    coarse = np.where(count >= scale * scale / 2, total / np.maximum(count, 1) / scale, np.nan)
    return fit_road_model(coarse, scale=scale, inlier_threshold=REFIT_THRESHOLD_PX / scale, iterations=iterations,
                          min_inlier_share=min_inlier_share)


def restored_validity(valid: np.ndarray, narrow: np.ndarray, restored: np.ndarray, *,
                      narrow_range: float) -> tuple[np.ndarray, dict]:
    """Which estimates survive the restore of step 6 (PT-D3Stereo and PT-SGM alike).

    The road model's validity rule (:mod:`d3cli.kernels.road_model`, ``restore_drops``),
    computed by :func:`restored_validity_counts`.  Dropped (holes for the filling):

    * estimates at either end of the narrow range (``narrow <= 0`` or ``>= narrow_range``):
      the true disparity most likely lies outside the band (obstacle, kerb, deep
      pothole); a clipped value would be wrong (measured: EPE 0.317 vs 0.340 kept, see
      configs/road.yaml);
    * restored disparities whose match ``u - d`` is not in the right image
      (:func:`match_in_right_image`);
    * negative restored disparities: disparities are >= 0 by contract, and a negative one
      comes from a wrong narrow match where the shift ``s(u, v)`` is below zero (far road,
      sky).

    Parameters
    ----------
    valid : ndarray, bool, (H, W)
    narrow : ndarray, (H, W)
        Narrow-range disparities d' (integer or float).
    restored : ndarray, float32, (H, W)
        Full-range disparities ``d' (1 - b2) + s(u, v)``, as the restore gives them
        (another dtype is rounded to float32 first).
    narrow_range : float, keyword-only
        Largest narrow-range disparity ``2 margin + slack``.

    Returns
    -------
    valid : ndarray, bool, (H, W)
    shares : dict
        ``range_end_share``, ``outside_share``, ``negative_share`` of all pixels.
    """
    valid, counts, _ = restored_validity_counts(valid, narrow, restored, narrow_range=narrow_range)
    return valid, restored_shares(counts, valid.size)


def restored_validity_counts(valid: np.ndarray, narrow: np.ndarray, restored: np.ndarray, *,
                             narrow_range: float, masked: bool = False):
    """:func:`restored_validity` in one pass over the map, with counts instead of shares.

    The kernel :func:`d3cli.kernels.finishing.restored_validity` (the road model's rule at
    every pixel), the pipeline's masking of the map included.

    Parameters
    ----------
    valid, narrow : ndarray, (H, W)
        As :func:`restored_validity`.
    restored : ndarray, float32, (H, W)
    narrow_range : float, keyword-only
    masked : bool, keyword-only
        Also return ``np.where(kept, restored, inf)`` (float32), from the same pass.

    Returns
    -------
    kept : ndarray, bool, (H, W)
    counts : ndarray, int64, (3,)
        Pixels at the range ends, outside, negative (of the others), for :func:`restored_shares`.
    masked : ndarray, float32, (H, W), or None
    """
    restored = np.ascontiguousarray(restored, dtype=np.float32)
    narrow = np.asarray(narrow)
    # the type NumPy compares ``narrow >= narrow_range`` in (NEP 50: float32 stays float32)
    hi = np.result_type(narrow, narrow_range).type(narrow_range)
    narrow = np.ascontiguousarray(np.broadcast_to(narrow, restored.shape))
    valid = np.ascontiguousarray(np.broadcast_to(np.asarray(valid, dtype=bool), restored.shape))
    out = np.empty(restored.shape, np.float32) if masked else None
    kept, counts = host.restored_validity(valid, narrow, restored, hi, out)
    return kept, counts, out


def restored_shares(counts, size: int) -> dict:
    """The shares of :func:`restored_validity` from :func:`restored_validity_counts`'s counts
    (``bool.mean()`` bit for bit: an exact float64 sum divided by the size; 0 for an empty map)."""
    size = max(int(size), 1)
    return {"range_end_share": float(counts[0]) / size, "outside_share": float(counts[1]) / size,
            "negative_share": float(counts[2]) / size}


def match_in_right_image(disparity: np.ndarray, *, finite: bool = False) -> np.ndarray:
    """True where the match ``u - d`` of a disparity lies in the right image, bool (H, W).

    The road model's rule (:mod:`d3cli.kernels.road_model`, ``in_right_image``: half a
    pixel of slack, the area of the first pixel) over a map.  NaN and +inf give False; with
    ``finite`` -inf too.  After the transformation a narrow-range estimate can restore to
    a match left of the right image (:func:`restored_validity`); the road report treats a
    disparity whose match the right camera does not see as no estimate
    (:func:`d3cli.road.plane.seen_by_both`).

    Parameters
    ----------
    disparity : ndarray, (H, W)
        Float32 or float64 (another dtype is converted to float64).
    finite : bool, keyword-only
    """
    d = np.asarray(disparity)
    d = np.ascontiguousarray(d if d.dtype in (np.float32, np.float64) else d.astype(np.float64))
    return host.right_image_mask(d, bool(finite))
