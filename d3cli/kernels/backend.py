"""The backend contract: every function both kernel backends provide, written once.

:mod:`d3cli.kernels.cpu` and :mod:`d3cli.kernels.cuda` are modules (``get_backend``
returns one), each providing every method of :class:`Backend` under the same name, with
the same arguments, shapes, dtypes and results; their own docstrings say only what is
specific to their target.  The pipeline (:mod:`d3cli.method`, and the baselines that
use kernels) calls nothing else of a backend: its functions take ``backend: Backend``,
and the host-only kernels come from the facade :mod:`d3cli.kernels.host`
(``tests/test_architecture.py`` holds both rules).

Conventions
-----------
* Arrays are *backend arrays*: NumPy arrays on the CPU; on CUDA device arrays, and every
  CUDA function also accepts host arrays, uploaded on the way in.  Results stay on the
  backend; :meth:`Backend.to_host` brings any array back.
* A cost volume is a :class:`d3cli.kernels.volume.Volume` (banded) or, for convenience
  (tests, the ablation), a plain float32 (H, W, D) array; a function gives back the kind
  it was given.  Cost is ``(1 - NCC) / 2`` (or the cosine counterpart) in [0, 1], lower is
  better; a missing or flat match costs 1 and never wins.
* Disparity maps are int32 (H, W) with -1 for undecided pixels; sub-pixel maps float32
  with inf for undecided.
* Integer results are equal on both backends; float results agree to rounding (CUDA may
  contract a multiply-add into one FMA and its ``exp`` is not libm's).

May import: nothing at run time (typing only).
"""

from __future__ import annotations

from typing import Any, Protocol


class Backend(Protocol):
    """What :func:`d3cli.kernels.get_backend` returns: a module with these functions."""

    def to_device(self, array) -> Any:
        """C-contiguous array for the kernels (the CPU's memory is the device's).

        The CPU returns a C-contiguous NumPy array; CUDA a device array (uploaded once).
        """
        ...

    def to_host(self, array) -> Any:
        """NumPy array of a backend array (identity on the CPU).

        The CPU returns the array itself; CUDA downloads it.
        """
        ...

    def pyramid(self, image, levels) -> list:
        """Grey pyramid of an image (docs/design.md, 'Pyramid and bands'), finest first.

        Parameters
        ----------
        image : ndarray, uint8 or float32, (H, W)
            Grey image on the 0-255 scale (a host or backend array).
        levels : int
            Number of levels; level i + 1 is the 2x2 area average of level i, an odd last
            row or column dropped (``kernels/pyramid/halve.py``: float32 ``0.25 (((a00 +
            a10) + a01) + a11)``).

        Returns
        -------
        list of ndarray, float32, (H >> i, W >> i)
            Backend arrays.  CUDA uploads a host image once in its own dtype (uint8: a
            quarter of the float32 bytes) and converts and halves it on the device.
        """
        ...

    def dense_index(self, height, width, n_disp) -> Any:
        """Index of the full-range volume (:func:`d3cli.kernels.volume.dense_index`), int32
        (H, W, 3), a backend array (CUDA builds it on the device).
        """
        ...

    def band_indexes(self, coarse, shape, *, n_disp, margin, tile, halo) -> Any:
        """Indexes of the stored and of the visible volume of a finer level
        (:func:`d3cli.kernels.cost.band.band_indexes`, which says what the bands are).

        Parameters
        ----------
        coarse : ndarray, int32, (Hc, Wc)
            Integer map of the coarser level (-1 undecided), a backend array.
        shape, n_disp, margin, tile, halo
            As :func:`d3cli.kernels.cost.band.band_indexes`.

        Returns
        -------
        store, visible : ndarray, int32, (H, W, 3)
            Backend arrays, equal on both backends.
        n_cells : int
            Cells of the stored volume; on CUDA a count left on the device (as
            :meth:`count_decided`'s), the volume allocated at the level's full-range size
            instead (``kernels/cost/band_cuda.py``).
        """
        ...

    def ncc_cost_volume(self, left, right, max_disparity, window, min_variance, index=None) -> Any:
        """NCC cost volume ``(1 - NCC) / 2`` with box sums (docs/design.md, step 2).

        The window is clipped to the part where both the left window around (u, v) and the
        right window around (u - d, v) lie inside the image.  Cells with u - d < 0 or a flat
        window cost 1.

        Parameters
        ----------
        left, right : ndarray, float32, (H, W)
            Grey images, 0-255 scale.
        max_disparity : int
            Largest disparity of the level (``n_disp = max_disparity + 1``).
        window : int
            Odd window size.
        min_variance : float
            Grey-level variance at or below which a window is flat.
        index : ndarray, int32, (H, W, 3), optional
            Bands to compute (:mod:`d3cli.kernels.volume`); default the full range.

        Returns
        -------
        ndarray, float32, (H, W, max_disparity + 1)
            Without ``index``; with it a :class:`Volume` of those bands.  A cell holds the
            same value whatever band it is computed in.
        """
        ...

    def cosine_cost_volume(self, fl, fr, nl, nr, max_disparity, index=None) -> Any:
        """Deep-feature cost volume ``(1 - cos) / 2`` of one level (docs/design.md, step 2, features).

        Parameters
        ----------
        fl, fr : ndarray, float32, (H, W, C)
            L2-normalised feature maps of the left and right image at this level.
        nl, nr : ndarray, float32, (H, W)
            Their squared norms: 1, or 0 for a zero feature vector (cost 1).
        max_disparity : int
            The level's range is ``max_disparity + 1`` disparities.
        index : ndarray, int32, (H, W, 3), optional
            Bands to compute; default the full range.

        Returns
        -------
        ndarray, float32, (H, W, max_disparity + 1), or a :class:`Volume` with ``index``
            1 where u - d < 0 or a feature vector is zero.
        """
        ...

    def invalidate_out_of_view(self, cost) -> Any:
        """Set every cell whose right pixel u - d is outside the image back to 1, in place.

        Aggregation averages such cells with valid neighbours and pulls them below 1; reset
        after it, they keep their meaning: no match, never a winner (docs/design.md, step 2).
        Returns ``cost`` (a Volume or an (H, W, D) array).
        """
        ...

    def rbf_weights(self, img, sigma_space, sigma_color) -> Any:
        """Normalised 3x3 bilateral weights per pixel (paper eq. 3), computed once per level.

        Returns float32 (H, W, 9); slot k is the neighbour (dy, dx) = (k // 3 - 1, k % 3 - 1);
        neighbours outside the image get weight 0.
        """
        ...

    def rbf_filter(self, cost, weights, t_max, overwrite_input=False) -> Any:
        """Recursive bilateral filtering: ``t_max`` passes of the 3x3 kernel (paper eq. 2).

        Parameters
        ----------
        cost : Volume or ndarray, float32, (H, W, D)
        weights : ndarray, float32, (H, W, 9)
            From :func:`rbf_weights`.
        t_max : int
        overwrite_input : bool
            The pipeline no longer needs the raw volume: the backend may use ``cost``'s
            memory (one volume fewer at the peak).  The result is the same.

        Returns
        -------
        Volume or ndarray, float32, (H, W, D)
            The same kind as ``cost``; ``cost``'s own array with ``overwrite_input``.
        """
        ...

    def bilateral_filter(self, cost, img, radius, sigma_space, sigma_color) -> Any:
        """One pass of a plain (2 radius + 1)^2 bilateral filter over every disparity slice.

        The ablation counterpart of RBF (paper Fig. 4): same kernel as eq. 3, larger support.
        A neighbour whose band lacks the disparity contributes the pixel's own cell (as in
        :func:`rbf_filter`; never for a cell the later steps read).
        """
        ...

    def sgm_smooth(self, cost, p1, p2) -> Any:
        """Mean of four semi-global path costs (left, down, right, up) of a volume.

        Parameters
        ----------
        cost : Volume or ndarray, float32, (H, W, D)
        p1, p2 : float
            Penalties of a one-disparity step and of a larger jump, in cost units.

        Returns
        -------
        Volume or ndarray
            Same kind and band layout; each cell ``(L_left + L_down + L_right + L_up) / 4``
            with ``L(p, d) = C(p, d) + min(L(q, d), L(q, d -+ 1) + P1, min_k L(q, k) + P2) -
            min_k L(q, k)`` along each path (``q`` the previous pixel; ``L = C`` at its
            start), in float32, the paths summed in that order.  The one place per target
            where the per-cell math is not a shared per-pixel function: the CPU driver runs
            it in LLVM vectors of 8 disparities, the CUDA driver across a block's threads,
            the same float32 operations in the same order (tests/kernels/sgm/ hold both to
            a NumPy reference and to each other).
        """
        ...

    def decisive_seeds(self, cost, pkrn_min, epsilon, lr_tolerance, exclusion, skip=None) -> Any:
        """Sparse seed map (docs/design.md, step 4); int32 (H, W), -1 undecided.

        ``skip`` (int32 (H, W), optional): pixels decided there (>= 0) are not examined and
        stay -1 (the pipeline merges fresh seeds only where inheritance left a hole).
        """
        ...

    def diffuse(self, cost, disp0, min_cost, max_gap, tau, kappa_d, adversarial, max_sweeps) -> Any:
        """Intra-scale decisive diffusion with a frontier (paper Algorithm 1, eq. 4-5).

        Parameters
        ----------
        cost : Volume or ndarray, float32, (H, W, D)
        disp0 : ndarray, int32, (H, W)
            Sparse decisive map D_i^S (-1 undecided); not modified.
        min_cost : ndarray, float32, (H, W), or None
            Least cost of each pixel over its band (:func:`min_cost`); not read when
            ``max_gap < 0``; None: found by the backend where the gap test needs it.
        max_gap : float
            Accepted states cost at most min_cost + max_gap; < 0: off.
        tau, kappa_d : int
            Disparity tolerance and neighbourhood radius.
        adversarial : bool
            Allow decided pixels to switch to a strictly cheaper accepted candidate.
        max_sweeps : int
            Safeguard on the number of sweeps.

        Returns
        -------
        disp : ndarray, int32, (H, W)
        sweeps : int
            Sweeps run (the last one changed nothing unless the safeguard stopped it); on
            CUDA a count left on the device, as :meth:`count_decided`'s.
        """
        ...

    def inherit(self, cost, coarse, prc, dfm_pkrn_min, epsilon, candidates=0) -> Any:
        """Inter-scale decisive inheritance (paper Algorithm 2, eq. 6-8).

        The patch tests (eq. 6-7) run once per coarse pixel and serve the four fine pixels
        of its 2x2 patch; the pixel test (eq. 8) per fine pixel.

        Parameters
        ----------
        cost : Volume or ndarray, float32, (H, W, D)
            Cost volume of the finer level i.
        coarse : ndarray, int32, (>= H // 2, >= W // 2)
            Disparity map of level i + 1 (-1 undecided).
        candidates : int
            0: symmetric candidate sets; 1: the per-pixel sets of the paper
            (``pixel.candidate_range``).

        Returns
        -------
        ndarray, int32, (H, W)
            Sparse map D_i^S.
        """
        ...

    def min_cost(self, cost) -> Any:
        """Least cost of every pixel over its band; float32 (H, W) (1 for an empty band).
        """
        ...

    def subpixel(self, cost, disp, equiangular: bool = False) -> Any:
        """Sub-pixel refinement (docs/design.md, step 8): the parabola through C(d-1), C(d),
        C(d+1), or with ``equiangular`` the equiangular line fit; float32 (H, W), inf where
        undecided.
        """
        ...

    def merge_sparse(self, primary, fallback) -> Any:
        """``primary`` where decided (>= 0), else ``fallback``; int32 (H, W), a new map.
        """
        ...

    def decided_mask(self, disparity) -> Any:
        """``disparity >= 0`` of an integer map: bool (H, W), a new backend map.
        """
        ...

    def count_decided(self, disparity) -> Any:
        """Number of decided pixels (>= 0) of an integer disparity map.

        An ``int`` on the CPU; on CUDA a count left on the device (``int()`` reads it), so
        that a pipeline level makes no copy to the host: :meth:`counts_to_host` reads many.
        """
        ...

    def counts_to_host(self, values) -> list[int]:
        """Plain ints of counts from :meth:`count_decided`, :meth:`diffuse` (its sweeps) and
        :meth:`band_indexes` (its cells),
        read from the device in one copy (per pool of counts) on CUDA.
        """
        ...

    def outputs_to_host(self, disparity, valid, counts=()) -> tuple:
        """The finished map, its validity and counts on the host.

        Parameters
        ----------
        disparity : ndarray, float32, (H, W)
        valid : ndarray, bool, (H, W)
            Backend arrays.
        counts : sequence
            Counts as :meth:`counts_to_host` takes them.

        Returns
        -------
        disparity, valid : ndarray
            Host arrays: the CPU returns the arrays themselves; CUDA packs both with the
            counts' pools into one device buffer and downloads it in one copy (the arrays
            are views of it, and the pools are read: :meth:`counts_to_host` of any of their
            counts makes no copy).
        values : list of int
            ``counts`` as ints.
        """
        ...

    def small_ints_to_host(self, disparity, max_value) -> Any:
        """An integer map with values in ``[-1, max_value]`` on the host, the same values.

        The CPU returns the array itself; CUDA downloads it as int8 (``max_value`` up to
        127) or int16 (up to 32767), a quarter or half of the int32 bytes (the road fit's
        coarse map).
        """
        ...

    def pt_warp(self, right, a0, b1, b2, delta) -> Any:
        """Right image warped by the road model (docs/design.md, step 6): ``R'(x, v) = R(x - s(x, v), v)``.

        Parameters
        ----------
        right : ndarray, float32, (H, W)
            Full-resolution grey right image.
        a0, b1, b2, delta : float
            Road model ``d = a0 + b1 v + b2 u`` and margin, full-resolution pixels.

        Returns
        -------
        ndarray, float32, (H, W)
            Bilinear samples; columns beyond the image replicate the border.
        """
        ...

    def count_range_ends(self, narrow, narrow_range) -> Any:
        """Pixels of a narrow-range integer map (docs/design.md, step 6) matched at an end of
        the range: ``d' == 0`` or ``d' >= narrow_range``.

        An ``int`` on the CPU; on CUDA a count left on the device (as :meth:`count_decided`'s).
        """
        ...

    def pt_validity(self, narrow, restored, narrow_range) -> Any:
        """The estimates that survive the restore of the perspective transformation: the road
        model's rule (``restore_drops`` of :mod:`d3cli.kernels.road_model`) at every pixel
        (:func:`d3cli.kernels.finishing.restored_validity`).

        Parameters
        ----------
        narrow : ndarray, int32, (H, W)
            Narrow-range integer map, decided where ``>= 0``.
        restored : ndarray, float32, (H, W)
            Its sub-pixel map restored to the full range (:meth:`pt_restore`).
        narrow_range : int
            Largest narrow-range disparity.

        Returns
        -------
        kept : ndarray, bool, (H, W)
        masked : ndarray, float32, (H, W)
            ``restored`` where kept, else inf.
        counts : list of 3 counts
            Decided pixels dropped at the range ends, outside the right image, and negative
            (but neither of the others); ints on the CPU, counts left on the device on CUDA.
        """
        ...

    def drop_occluded(self, disparity, valid, tolerance, start, out) -> Any:
        """Both occlusion tests of the finishing, their holes and the masked map, a row at a
        time (:func:`d3cli.kernels.finishing.drop_occluded`, which says what the tests are;
        the row bodies: ``kernels/finishing/pixel_occlusion.py``).

        Parameters
        ----------
        disparity : ndarray, float32, (H, W)
        valid : ndarray, bool, (H, W)
            Updated in place: ``valid &= ~occluded``.
        tolerance : float
            The uniqueness test's tolerance.
        start : int
            First column the left-border test searches (0 <= start < W).
        out : ndarray, float32, (H, W)
            Receives ``np.where(valid, disparity, inf)``; may be ``disparity``.

        Returns
        -------
        occluded : ndarray, bool, (H, W)
        count : occluded pixels; an ``int`` on the CPU, on CUDA a count left on the device
            (as :meth:`count_decided`'s).
        """
        ...

    def drop_speckles(self, disparity, valid, max_size, max_diff, out) -> Any:
        """The speckle filter of the finishing, its holes and the masked map
        (:func:`d3cli.method.refinement.speckles` says what a speckle is): the regions of
        ``cv2.filterSpeckles`` on the 1/16 px fixed point of the usable pixels (valid and
        finite; the others in no region), 4-connected, neighbours within ``max_diff``; the
        usable pixels of every region of at most ``max_size`` pixels become holes.

        Parameters
        ----------
        disparity : ndarray, float32, (H, W)
        valid : ndarray, bool, (H, W)
            Updated in place: ``valid &= ~speck``.
        max_size : int
            Largest speckle, pixels (0: none).
        max_diff : float
            Largest disparity step inside a region, pixels (1/16 px:
            :func:`d3cli.kernels.finishing.pixel_speckle.fixed_step`).
        out : ndarray, float32, (H, W)
            Receives ``np.where(valid, disparity, inf)``; may be ``disparity``.

        Returns
        -------
        count : speckle pixels; an ``int`` on the CPU, on CUDA a count left on the device
            (as :meth:`count_decided`'s).  The CPU labels the regions with a union-find in
            one thread (``finishing/speckle.py``), CUDA with a union-find over the
            device's threads in four launches (``finishing/cuda_speckle.py``).
        """
        ...

    def fill_inside(self, disparity, valid, occluded) -> Any:
        """The filling inside surfaces (``refine.fill_inside``, docs/design.md,
        'Finishing'): a hole that is not occluded and has a usable pixel in one of the four
        directions takes the median of the nearest usable values (left, right, up, down;
        the float32 mean of the middle two of an even count), any other hole the smaller of
        its nearest row neighbours; a row without a usable pixel a copy of the nearest row
        that has one (the upper on a tie); all inf when nothing is usable
        (``kernels/finishing/pixel_fill_inside.py``, the values of
        ``refinement.fill_holes`` with ``occluded``, without its median).

        Returns
        -------
        filled : ndarray, float32, (H, W)
        use : ndarray, bool, (H, W)
            The usable pixels, ``valid & isfinite(disparity)``: those filled from.
        """
        ...

    def fill_rows(self, disparity, valid) -> Any:
        """The row-wise hole filling (docs/design.md, 'Finishing'): each hole the smaller of
        the nearest usable values left and right in its row, a row without one a copy of the
        nearest row that has one (the upper on a tie); all inf when nothing is usable
        (``kernels/finishing/pixel_fill.py``, the values of ``refinement.fill_holes``
        without its median).

        Returns
        -------
        filled : ndarray, float32, (H, W)
        use : ndarray, bool, (H, W)
            The usable pixels, ``valid & isfinite(disparity)``: those filled from.
        """
        ...

    def median_of_holes(self, filled, use) -> Any:
        """``filled`` where ``use``, else the median of its 5x5 window, borders replicated:
        the values of ``cv2.medianBlur(filled, 5)`` at the holes, for a map without NaN
        (what :meth:`fill_rows` gives); float32 (H, W), a new map.
        """
        ...

    def smooth_map(self, disparity, radius, sigma, kernel, plane, non_negative) -> Any:
        """The finishing's edge-preserving smoothing of a finished map, every finite pixel
        used (:func:`d3cli.method.refinement.smooth_disparity` with ``valid=None``, which says
        what it computes; the per-pixel bodies: ``kernels/finishing/pixel_smoothing.py``).

        Parameters
        ----------
        disparity : ndarray, float32, (H, W)
            Non-finite = no estimate (stays as it is).
        radius : int
            Box radius in pixels; 0 returns a copy.
        sigma : float
            Range sigma (Gaussian) or threshold (box) in disparity pixels.
        kernel : {"box", "gaussian"}
        plane : tuple (a0, b1, b2) or None
            The road plane ``s(u, v) = a0 + b1 v + b2 u`` (float64, rounded once to float32
            per pixel: :func:`d3cli.kernels.finishing.shift_plane_f32` with a zero margin)
            whose residual is smoothed; None: the disparity itself.
        non_negative : bool
            Negative results become 0.

        Returns
        -------
        ndarray, float32, (H, W)
            A new map.  CUDA computes the plane per pixel from its coefficients.
        """
        ...

    def pt_restore(self, disp, a0, b1, b2, delta) -> Any:
        """Full-range disparity from the disparity against the warped right image.

        ``d = d' (1 - b2) + s(u, v)`` (exact inverse of :func:`pt_warp`); inf stays inf.

        Parameters
        ----------
        disp : ndarray, float32, (H, W)
            Disparity ``d'`` of the left image against ``pt_warp(right, ...)``.

        Returns
        -------
        ndarray, float32, (H, W)
        """
        ...
