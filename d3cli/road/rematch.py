"""Re-measure the disparity inside road defects with a small matching window.

Where the bias comes from: the road configuration matches with a 25 x 25 NCC window and
smooths the restored map over a box of radius 15 (configs/road.yaml): both average a
pothole's bottom with its shallower walls.  A pothole 190 mm across at 640x360 (30 px)
comes out 15.4 mm deep instead of 30.2 on that map (synth --seed 3 pair 0); on the exact
disparity the detector itself measures 33.5 mm (the floor relief included), so the loss
is the map's, not the detector's.  Matching again in the defect only, with a small window and a narrow
search around the stored disparity, keeps the method's result everywhere else (the
stored disp.pfm is not changed) and gives the detector the floor's own depth.
"""

from __future__ import annotations

import numpy as np

from .compiled import best_offsets, shifted_rows, zncc_scores
from .morphology import grown_box
from .threads import halves, map_on_threads

#: Window side (pixels), search reach either side of the stored disparity (pixels) and
#: the step of the search (pixels; parabola interpolation between steps).  Two pixels
#: hold what the re-match is there for: on the 12 pairs of ``synth --seed 0`` 99 % of
#: every zone's re-measured pixels moved by at most 1.6 px; what a reach of 3 px adds is
#: specular matches on wet floors (reliable by score, up to 2.75 px off), which read wet
#: potholes too deep.  Against a reach of 3 px on the 315 stored maps of fifteen spent
#: check seeds (docs/road.md): only wet pairs change, 3 more of the 433 potholes
#: flagged, 2 fewer false ``ok`` defects, as many ``ok`` ones more than 20 % off (6),
#: the wet ``ok`` potholes' median depth error 5.3 -> 4.3 %, and 9 offsets to match
#: instead of 13.
WINDOW, REACH, STEP = 9, 2.0, 0.5
#: Windows tried, smallest first: a noisy (dark) pair needs a larger one.  The first whose
#: heights on the road around the defect scatter (1.4826 MAD of the high-pass residual) by
#: at most :func:`noise_limit` of the defect's depth is used; none: the stored map is kept.
WINDOWS, NOISE_M, REL_NOISE = (9, 13, 17, 25), 1.5e-3, 0.05


def noise_limit(depth: float) -> float:
    """The largest scatter (metres) of the re-matched road around a defect of ``depth``
    metres (as the stored map reads it) for which the re-match is used: ``NOISE_M``, or
    ``REL_NOISE`` of the depth where that is more.

    A scatter that does not fall with the window is the road's own relief, not matching
    noise: the synthetic wet asphalt scatters by 1.9-2.1 mm at every window, and its
    potholes, 40-60 mm deep, kept the stored map, which reads cones and narrow potholes
    20-35 % shallow (the averaging the re-match is there to undo).  Against a depth 20
    times larger that scatter moves the depth little: on the 252 stored maps of twelve spent
    check seeds (docs/road.md), 2 fewer potholes reported ``ok`` are more than 20 % off and
    those re-matched read closer to the truth.
    """
    return max(NOISE_M, REL_NOISE * float(depth))


#: A re-matched pixel whose best ZNCC score is below this, or whose best offset is an end
#: of the search, keeps the stored disparity: on wet and dark pairs such pixels (specular
#: highlights, untextured floors) are 0.5-4 px off the true disparity (median), and their
#: few deepest values would become the reported maximum depth.
MIN_SCORE = 0.9
#: A window is used only where at least this share of the defect's zone matched reliably
#: (:data:`MIN_SCORE`): a few reliable pixels among stored ones are the noisiest matches
#: (a dark pair at window 9 read a 34 mm pothole 14 % too deep from them).
MIN_RELIABLE = 0.5
#: The most the reliable share of a zone is taken to grow from one window of
#: :data:`WINDOWS` to the next: the larger windows are not tried once the share is below
#: ``MIN_RELIABLE / SHARE_GROWTH ** (windows left)``.  On the 500 re-matched zones of the
#: 315 stored maps of docs/road.md the share grew by at most 1.41 a window (median 1.03);
#: most zones of a dark pair match no pixel reliably at any window, and the three larger
#: windows cost three times the first.
SHARE_GROWTH = 1.5


def hopeless(share: float, windows_left: int) -> bool:
    """Whether a zone whose reliable share is ``share`` at one window cannot reach
    :data:`MIN_RELIABLE` at any of the ``windows_left`` larger ones (:data:`SHARE_GROWTH`)."""
    return share * SHARE_GROWTH ** windows_left < MIN_RELIABLE


def grey_image(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image, np.float32)
    return img.mean(axis=2) if img.ndim == 3 else img


def _holes_at_median(disparity: np.ndarray, finite: np.ndarray) -> np.ndarray:
    """float32 copy of a box of ``disparity`` whose pixels without an estimate (not
    ``finite``; at least one is) hold the median of the others: a box's warps need a
    disparity at every pixel.  The median only where a pixel lacks one."""
    if finite.all():
        return np.array(disparity, np.float32)
    return np.where(finite, disparity, np.float32(np.median(disparity[finite]))).astype(np.float32)


def warped_right(right_grey: np.ndarray, v0: int, u0: int, disparity: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """float32 (K, h, w): the grey right image warped onto the left's box at row ``v0``,
    column ``u0`` by ``disparity`` (h, w) plus each of the K ``offsets``, interpolated as
    OpenCV's bicubic remap (:func:`~d3cli.road.compiled.shifted_rows`); the offsets split
    between the report's two threads."""
    image = np.ascontiguousarray(right_grey, np.float32)
    disparity = np.ascontiguousarray(disparity, np.float32)
    offsets = np.ascontiguousarray(offsets, np.float32)
    parts = map_on_threads(lambda part: shifted_rows(image, v0, u0, disparity, offsets[part]), halves(len(offsets)))
    return np.concatenate(parts)


def _zncc(left: np.ndarray, warps: np.ndarray, rows: tuple, cols: tuple, window: int) -> np.ndarray:
    """float32 (K, rows, columns): the zero-mean NCC of every ``window`` x ``window`` window
    of ``left`` with the same window of each of ``warps`` (K, h, w), centred on the pixels
    of ``rows`` and ``cols`` ((start, stop) each; the windows mirrored at the arrays' edges),
    compiled (:func:`~d3cli.road.compiled.zncc_scores`); the offsets split between the
    report's two threads."""
    left = np.ascontiguousarray(left, np.float32)
    warps = np.ascontiguousarray(warps, np.float32)
    parts = map_on_threads(lambda part: zncc_scores(left, warps[part], *rows, *cols, window), halves(len(warps)))
    return np.concatenate(parts)


def rematch(left: np.ndarray, right: np.ndarray, disparity: np.ndarray, mask: np.ndarray, *,
            window: int = WINDOW, reach: float = REACH, step: float = STEP,
            min_score: float = MIN_SCORE, shared: dict | None = None,
            origin: tuple[int, int] = (0, 0)) -> tuple[np.ndarray, np.ndarray]:
    """Disparity re-measured at the pixels of ``mask`` by zero-mean NCC.

    Parameters
    ----------
    left, right : ndarray, (H, W[, C])
        The rectified images.
    disparity : ndarray, float32, (H, W)
        The stored disparity (inf: no estimate); the search is centred on it.
    mask : ndarray, bool, (H, W)
        Pixels to re-measure (a defect grown by its surrounding ring).
    window, reach, step : keyword-only
        Odd window side; the search covers ``d +- reach`` in ``step`` increments, with a
        parabola through the best score and its neighbours.
    min_score : float, keyword-only
        A pixel whose best score is lower, or whose best offset is an end of the search
        (the true disparity may lie beyond it), keeps its stored disparity.
    shared : dict, optional, keyword-only
        What calls for one ``mask`` with several windows share (the caller passes the same
        dict to each): the grey images and the right image warped by every offset,
        computed once on the box of the first call's window, or of ``"pad_window"`` where
        the dict gives one; a call whose box that holds reads its own box out of it, one
        with a larger window warps its own, so the results are those of separate calls.
        Used only where the box's disparities are all finite (else a pixel without one is
        searched around the box's own median).
    origin : (int, int), keyword-only
        (row, column) in the images of the first pixel of ``disparity`` and ``mask``, when
        they are a window of the images (the results are those of the whole images where
        the window holds the mask grown by ``window + ceil(reach) + 1`` pixels, or reaches
        the images' edge).

    Returns
    -------
    disparity : ndarray, float32, (H, W)
        A copy of ``disparity`` with the finite pixels of ``mask`` re-measured where the
        match is reliable.
    reliable : ndarray, bool, (H, W)
        The pixels re-measured.
    """
    out = np.array(disparity, np.float32, copy=True)
    done = np.zeros(out.shape, bool)
    # The pixels to re-measure, found on the mask's bounding box (not a pass over the image
    # per call: a zone is tried with several windows).
    within = grown_box(mask, 0, 0)
    if within is None:
        return out, done
    todo, (m0, n0) = mask[within] & np.isfinite(out[within]), (within[0].start, within[1].start)
    rows, cols = np.flatnonzero(todo.any(axis=1)), np.flatnonzero(todo.any(axis=0))
    if rows.size == 0:
        return out, done
    shared = {} if shared is None else shared
    if "grey" not in shared:
        shared["grey"] = (grey_image(left), grey_image(right))
    lg, rg = shared["grey"]
    first_v, last_v, first_u, last_u = m0 + int(rows[0]), m0 + int(rows[-1]), n0 + int(cols[0]), n0 + int(cols[-1])
    oy, ox = int(origin[0]), int(origin[1])

    def box_of(pad):  # in the window's pixels, cut at the images' edge (and the window's)
        return (max(first_v - pad, -oy, 0), min(last_v + pad + 1, lg.shape[0] - oy, out.shape[0]),
                max(first_u - pad, -ox, 0), min(last_u + pad + 1, lg.shape[1] - ox, out.shape[1]))

    pad = window + int(np.ceil(reach)) + 1
    v0, v1, u0, u1 = box_of(pad)
    sub = out[v0:v1, u0:u1]
    finite = np.isfinite(sub)
    # Pixels of the box without an estimate are searched around the median, never kept.
    centre = _holes_at_median(sub, finite)
    lsub = lg[oy + v0:oy + v1, ox + u0:ox + u1]
    offsets = np.arange(-reach, reach + 1e-9, step, dtype=np.float32)
    warps = None
    if finite.all():  # the warps of the largest box, made once: a remap is per pixel
        key = (float(reach), float(step))
        if shared.get("warps_key") != key:
            big = max(pad, int(shared.get("pad_window", window)) + int(np.ceil(reach)) + 1)
            b0, b1, c0, c1 = box_of(big)
            disp_big = np.asarray(disparity[b0:b1, c0:c1], np.float32)
            stored = None
            if np.isfinite(disp_big).all():
                stored = ((b0, c0), warped_right(rg, oy + b0, ox + c0, disp_big, offsets))
            shared["warps_key"], shared["warps"] = key, stored
        if shared["warps"] is not None:
            (b0, c0), stack = shared["warps"]
            if v0 >= b0 and u0 >= c0 and v1 - b0 <= stack.shape[1] and u1 - c0 <= stack.shape[2]:
                warps = stack[:, v0 - b0:v1 - b0, u0 - c0:u1 - c0]
    if warps is None:
        warps = warped_right(rg, oy + v0, ox + u0, centre, offsets)
    # The scores of the pixels that may be re-measured (the mask's bounding box), their
    # windows read from the box around it
    rows, cols = (first_v - v0, last_v + 1 - v0), (first_u - u0, last_u + 1 - u0)
    scores = _zncc(lsub, warps, rows, cols, window)
    # the best offset, a parabola through its neighbours, reliable or not: compiled
    new, reliable = best_offsets(scores, centre[rows[0]:rows[1], cols[0]:cols[1]], offsets, float(step),
                                 float(min_score))
    inside = todo[first_v - m0:last_v + 1 - m0, first_u - n0:last_u + 1 - n0] & reliable
    sub[rows[0]:rows[1], cols[0]:cols[1]][inside] = new[inside]
    done[first_v:last_v + 1, first_u:last_u + 1] = inside
    return out, done


#: Window side (pixels) of the match margin (:func:`match_margin`): the road
#: configuration's own matching window, so the margin says how decisively the map's
#: matching could tell the disparity from its neighbours.
MARGIN_WINDOW = 25
#: Pixels around a defect's bounding box that the margin's windows read.
MARGIN_PAD = 20


def match_margin(left_grey: np.ndarray, right_grey: np.ndarray, disparity: np.ndarray, region: np.ndarray, *,
                 window: int = MARGIN_WINDOW, pad: int = MARGIN_PAD) -> float:
    """How decisively the images support ``disparity`` over ``region``: the median over the
    region of the zero-mean NCC at the disparity minus the better of the NCCs one pixel to
    either side.

    A textured surface matched at its true disparity scores clearly better there than one
    pixel off; on a dark, smooth or wet floor the NCC curve is flat, every disparity within
    a pixel scores about the same, and the depth the map reports there is one of many that
    fit.  This margin is what separates badly measured defects from good ones on synthetic
    pairs with exact ground truth (docs/road.md, "Confidence"), far better than the height
    noise or the spikiness of the floor.

    Parameters
    ----------
    left_grey, right_grey : ndarray, float32, (H, W)
        The grey images (:func:`grey_image`).
    disparity : ndarray, float32, (H, W)
        The disparity the defect was measured on (inf: no estimate; those pixels of the box
        are warped by the box's median disparity).
    region : ndarray, bool, (H, W)
        The defect's pixels.
    window, pad : int, keyword-only
        Odd NCC window side; pixels read around the region's bounding box.

    Returns
    -------
    float
        The margin (NCC units; nan for an empty region or a box without any disparity).
    """
    box = grown_box(region, pad, pad)
    if box is None:
        return float("nan")
    (v0, v1), (u0, u1) = (box[0].start, box[0].stop), (box[1].start, box[1].stop)
    d = np.asarray(disparity[v0:v1, u0:u1], np.float32)
    finite = np.isfinite(d)
    if not finite.any():
        return float("nan")
    d = _holes_at_median(d, finite)
    lsub = np.ascontiguousarray(left_grey[v0:v1, u0:u1], np.float32)
    inner = grown_box(region[v0:v1, u0:u1], 0, 0)  # the region's own box: its pixels' windows
    rows, cols = (inner[0].start, inner[0].stop), (inner[1].start, inner[1].stop)
    at, right_of, left_of = _zncc(lsub, warped_right(right_grey, v0, u0, d, np.array([0.0, 1.0, -1.0], np.float32)),
                                  rows, cols, window)
    margin = at - np.maximum(right_of, left_of)
    return float(np.median(margin[region[v0:v1, u0:u1][inner]]))
