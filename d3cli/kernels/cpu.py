"""CPU backend: the per-pixel functions of ``pixel.py`` compiled with ``njit`` and
driven by parallel (``prange``) loops over rows or over frontier pixels.

Every driver is deterministic and independent of the thread count: parallel loops only
write disjoint cells, reductions are done serially, and iterative steps are
double-buffered (Jacobi).  Arrays are C-contiguous float32 volumes (H, W, D) with the
disparity axis innermost, so inner loops run over contiguous memory.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
from numba import njit, prange


def _drop_stale_cache() -> None:
    """Pick a writable numba cache folder, and delete this module's cache there when
    pixel.py changed since it was written.

    Numba keys a cached function on its own source file only, so the drivers below
    would keep stale copies of the per-pixel functions they inline after an edit of
    pixel.py.

    When the package's ``__pycache__`` cannot be written (a read-only install, a shared
    site-packages), ``NUMBA_CACHE_DIR`` is set to ``$XDG_CACHE_HOME/d3stereo/numba``
    (default ``~/.cache/d3stereo/numba``) before anything here is compiled, so every
    process (each ``--workers`` process too) loads the kernels from one cache instead of
    compiling them again; a ``NUMBA_CACHE_DIR`` the user set is kept.
    """
    import os

    from numba import config as numba_config
    from numba.core.caching import UserProvidedCacheLocator

    here = Path(__file__).resolve().parent
    cache = here / "__pycache__"
    writable = os.access(cache if cache.is_dir() else here, os.W_OK)
    if not writable and not numba_config.CACHE_DIR:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
        os.environ["NUMBA_CACHE_DIR"] = str(base / "d3stereo" / "numba")
        numba_config.CACHE_DIR = os.environ["NUMBA_CACHE_DIR"]  # numba read the variable at import already
    if numba_config.CACHE_DIR:  # where numba will look for this module's cache
        cache = Path(numba_config.CACHE_DIR) / UserProvidedCacheLocator.get_suitable_cache_subpath(__file__)
    try:
        digest = hashlib.sha256((here / "pixel.py").read_bytes()).hexdigest()
        stamp = cache / "pixel.sha256"
        if stamp.exists() and stamp.read_text() == digest:
            return
        for f in list(cache.glob("cpu.*.nbi")) + list(cache.glob("cpu.*.nbc")):
            f.unlink()
        cache.mkdir(parents=True, exist_ok=True)
        stamp.write_text(digest)
    except OSError:  # no writable cache anywhere: numba then compiles in every process
        pass


_drop_stale_cache()

from .pixel import UNDECIDED, build_ops  # noqa: E402

ops = build_ops(njit(cache=True))
_ncc_cost = ops.ncc_cost
_cosine_cost = ops.cosine_cost
_box_sum = ops.box_sum
_rbf_weight = ops.rbf_weight
_seed_at = ops.seed_at
_diffuse_at = ops.diffuse_at
_inherit_at = ops.inherit_at
_subpixel_at = ops.subpixel_at


@njit(cache=True)
def integral_image(img, power):
    """(H+1, W+1) float64 integral image of ``img ** power`` (power 1 or 2)."""
    h, w = img.shape
    ii = np.zeros((h + 1, w + 1), np.float64)
    for y in range(h):
        row = 0.0
        for x in range(w):
            val = np.float64(img[y, x])
            row += val if power == 1 else val * val
            ii[y + 1, x + 1] = ii[y, x + 1] + row
    return ii


@njit(parallel=True, cache=True)
def ncc_cost_volume(left, right, max_disparity, window, min_variance):
    """NCC cost volume ``(1 - NCC) / 2`` with box sums (DESIGN step 2).

    The window is clipped to the part where both the left window around (u, v) and the
    right window around (u - d, v) lie inside the image.  Cells with u - d < 0 or a flat
    window cost 1.

    Parameters
    ----------
    left, right : ndarray, float32, (H, W)
        Grey images, 0-255 scale.
    max_disparity : int
        Largest disparity; the volume has ``max_disparity + 1`` slices.
    window : int
        Odd window size.
    min_variance : float
        Grey-level variance at or below which a window is flat.

    Returns
    -------
    ndarray, float32, (H, W, max_disparity + 1)
    """
    h, w = left.shape
    n_disp = max_disparity + 1
    r = window // 2
    ii_l = integral_image(left, 1)
    ii_ll = integral_image(left, 2)
    ii_r = integral_image(right, 1)
    ii_rr = integral_image(right, 2)
    cost = np.empty((h, w, n_disp), np.float32)
    # The rows are cut into blocks, one prange task each; inside a block acc is a running
    # sum along the rows (add the row entering the window, subtract the one leaving it), so
    # the work per output row no longer grows with the window (issue 10 item 2; before,
    # every output row re-summed all ``window`` rows).  float64 keeps the add/subtract
    # drift far below the 1e-5 cost tolerance (values <= 255^2 * window^2).
    block = 32
    n_blocks = (h + block - 1) // block
    for b in prange(n_blocks):
        vb0 = b * block
        vb1 = min(h, vb0 + block)
        # acc[u, d]: column sum over the window rows of L(y, u) R(y, u - d)
        acc = np.zeros((w, n_disp), np.float64)
        prefix = np.zeros((w + 1, n_disp), np.float64)
        win_l = np.zeros(w, np.float64)
        win_ll = np.zeros(w, np.float64)
        win_r = np.zeros(w, np.float64)
        win_rr = np.zeros(w, np.float64)
        for y in range(max(0, vb0 - r), min(h - 1, vb0 + r) + 1):
            _add_row_products(acc, left, right, y, 1.0)
        for v in range(vb0, vb1):
            if v > vb0:
                if v + r <= h - 1:
                    _add_row_products(acc, left, right, v + r, 1.0)
                if v - r - 1 >= 0:
                    _add_row_products(acc, left, right, v - r - 1, -1.0)
            _ncc_row(cost, v, acc, prefix, win_l, win_ll, win_r, win_rr, ii_l, ii_ll, ii_r, ii_rr,
                     h, w, n_disp, r, min_variance)
    return cost


@njit(cache=True)
def _add_row_products(acc, left, right, y, sign):
    """acc[u, d] += sign * L(y, u) R(y, u - d) for every u, d with u - d >= 0."""
    w, n_disp = acc.shape
    for u in range(w):
        lv = sign * np.float64(left[y, u])
        for d in range(min(n_disp, u + 1)):
            acc[u, d] += lv * np.float64(right[y, u - d])


@njit(cache=True)
def _ncc_row(cost, v, acc, prefix, win_l, win_ll, win_r, win_rr, ii_l, ii_ll, ii_r, ii_rr,
             h, w, n_disp, r, min_variance):
    """Costs of row v from the window-row column sums ``acc`` (buffers reused per row)."""
    v0 = max(0, v - r)
    v1 = min(h - 1, v + r)
    # prefix[u + 1, d]: running sum of acc over the columns <= u
    for u in range(w):
        for d in range(n_disp):
            prefix[u + 1, d] = prefix[u, d] + acc[u, d]
    # Window sums of an unclipped window (columns c - r .. c + r), once per column
    # instead of once per cell; the same box sums, so the same values.
    for c in range(r, w - r):
        win_l[c] = _box_sum(ii_l, v0, c - r, v1, c + r)
        win_ll[c] = _box_sum(ii_ll, v0, c - r, v1, c + r)
        win_r[c] = _box_sum(ii_r, v0, c - r, v1, c + r)
        win_rr[c] = _box_sum(ii_rr, v0, c - r, v1, c + r)
    n_full = (v1 - v0 + 1) * (2 * r + 1)
    for u in range(w):
        # d < d_fast: neither window is clipped (a branch-free loop that vectorises)
        d_fast = min(n_disp, u - r + 1) if u + r <= w - 1 else 0
        sl_u = win_l[u]
        sll_u = win_ll[u]
        for d in range(d_fast):
            slr = prefix[u + r + 1, d] - prefix[u - r, d]
            cost[v, u, d] = _ncc_cost(n_full, sl_u, sll_u, win_r[u - d], win_rr[u - d], slr, min_variance)
        for d in range(max(d_fast, 0), n_disp):
            if u - d < 0:
                cost[v, u, d] = 1.0
                continue
            c0 = max(u - r, d)
            c1 = min(u + r, w - 1)
            n = (v1 - v0 + 1) * (c1 - c0 + 1)
            sl = _box_sum(ii_l, v0, c0, v1, c1)
            sll = _box_sum(ii_ll, v0, c0, v1, c1)
            sr = _box_sum(ii_r, v0, c0 - d, v1, c1 - d)
            srr = _box_sum(ii_rr, v0, c0 - d, v1, c1 - d)
            slr = prefix[c1 + 1, d] - prefix[c0, d]
            cost[v, u, d] = _ncc_cost(n, sl, sll, sr, srr, slr, min_variance)


@njit(parallel=True, cache=True)
def cosine_cost_volume(fl, fr, nl, nr, max_disparity):
    """Deep-feature cost volume ``(1 - cos) / 2`` of one level (DESIGN step 2, features).

    Parameters
    ----------
    fl, fr : ndarray, float32, (H, W, C)
        L2-normalised feature maps of the left and right image at this level.
    nl, nr : ndarray, float32, (H, W)
        Their squared norms: 1, or 0 for a zero feature vector (cost 1).
    max_disparity : int
        The volume has ``max_disparity + 1`` slices.

    Returns
    -------
    ndarray, float32, (H, W, max_disparity + 1)
        1 where u - d < 0 or a feature vector is zero.
    """
    h, w = nl.shape
    n_disp = max_disparity + 1
    cost = np.empty((h, w, n_disp), np.float32)
    for v in prange(h):
        for u in range(w):
            for d in range(n_disp):
                cost[v, u, d] = _cosine_cost(fl, fr, nl, nr, v, u, d)
    return cost


@njit(parallel=True, cache=True)
def invalidate_out_of_view(cost):
    """Set every cell whose right pixel u - d is outside the image back to 1, in place.

    Aggregation averages such cells with valid neighbours and pulls them below 1; reset
    after it, they keep their meaning: no match, never a winner (DESIGN step 2).
    """
    h, w, n_disp = cost.shape
    for v in prange(h):
        for u in range(min(w, n_disp - 1)):
            for d in range(u + 1, n_disp):
                cost[v, u, d] = 1.0
    return cost


@njit(parallel=True, cache=True)
def rbf_weights(img, sigma_space, sigma_color):
    """Normalised 3x3 bilateral weights per pixel (paper eq. 3), computed once per level.

    Returns float32 (H, W, 9); slot k is the neighbour (dy, dx) = (k // 3 - 1, k % 3 - 1);
    neighbours outside the image get weight 0.
    """
    h, w = img.shape
    inv_ss2 = 1.0 / (sigma_space * sigma_space)
    inv_sc2 = 1.0 / (sigma_color * sigma_color)
    weights = np.zeros((h, w, 9), np.float32)
    for v in prange(h):
        for u in range(w):
            total = 0.0
            for k in range(9):
                dy = k // 3 - 1
                dx = k % 3 - 1
                y = v + dy
                x = u + dx
                if 0 <= y < h and 0 <= x < w:
                    wk = _rbf_weight(dy, dx, np.float64(img[v, u]), np.float64(img[y, x]), inv_ss2, inv_sc2)
                    weights[v, u, k] = wk
                    total += wk
            for k in range(9):
                weights[v, u, k] = weights[v, u, k] / total
    return weights


@njit(parallel=True, cache=True)
def _rbf_pass(src, dst, weights):
    """One 3x3 pass of eq. 2 from ``src`` into ``dst``.

    The nine terms are added in slot order k = 0..8 in one loop over the disparities
    (vectorised; one write per cell).  Neighbours outside the image have weight 0 and
    read a clamped, in-image cell: adding +0.0 leaves the (non-negative) sum unchanged,
    so the result is the same as skipping them.
    """
    h, w, n_disp = src.shape
    for v in prange(h):
        ym = max(v - 1, 0)
        yp = min(v + 1, h - 1)
        for u in range(w):
            xm = max(u - 1, 0)
            xp = min(u + 1, w - 1)
            w0 = weights[v, u, 0]
            w1 = weights[v, u, 1]
            w2 = weights[v, u, 2]
            w3 = weights[v, u, 3]
            w4 = weights[v, u, 4]
            w5 = weights[v, u, 5]
            w6 = weights[v, u, 6]
            w7 = weights[v, u, 7]
            w8 = weights[v, u, 8]
            for d in range(n_disp):
                acc = np.float32(0.0)
                acc += w0 * src[ym, xm, d]
                acc += w1 * src[ym, u, d]
                acc += w2 * src[ym, xp, d]
                acc += w3 * src[v, xm, d]
                acc += w4 * src[v, u, d]
                acc += w5 * src[v, xp, d]
                acc += w6 * src[yp, xm, d]
                acc += w7 * src[yp, u, d]
                acc += w8 * src[yp, xp, d]
                dst[v, u, d] = acc


def rbf_filter(cost, weights, t_max, overwrite_input=False):
    """Recursive bilateral filtering: ``t_max`` passes of the 3x3 kernel (paper eq. 2).

    Parameters
    ----------
    cost : ndarray, float32, (H, W, D)
    weights : ndarray, float32, (H, W, 9)
        From :func:`rbf_weights`.
    t_max : int
    overwrite_input : bool
        Use ``cost`` as one of the two ping-pong buffers: two volumes at the peak instead
        of three (the pipeline no longer needs the raw NCC volume).  The result is the
        same; ``cost`` then holds garbage or the result itself.

    Returns
    -------
    ndarray, float32, (H, W, D)
        A new array, or ``cost`` itself with ``overwrite_input`` and an even ``t_max``.
    """
    if t_max == 0:
        return cost if overwrite_input else cost.copy()
    # The first pass reads ``cost`` directly, so no copy of the input volume is made.
    src = np.empty_like(cost)
    _rbf_pass(cost, src, weights)
    if t_max == 1:
        return src
    dst = cost if overwrite_input else np.empty_like(cost)
    for _ in range(t_max - 1):
        _rbf_pass(src, dst, weights)
        src, dst = dst, src
    return src


@njit(parallel=True, cache=True)
def bilateral_filter(cost, img, radius, sigma_space, sigma_color):
    """One pass of a plain (2 radius + 1)^2 bilateral filter over every disparity slice.

    The ablation counterpart of RBF (paper Fig. 4): same kernel as eq. 3, larger support.
    """
    h, w, n_disp = cost.shape
    inv_ss2 = 1.0 / (sigma_space * sigma_space)
    inv_sc2 = 1.0 / (sigma_color * sigma_color)
    out = np.empty_like(cost)
    for v in prange(h):
        acc = np.empty(n_disp, np.float64)
        for u in range(w):
            acc[:] = 0.0
            total = 0.0
            for dy in range(-radius, radius + 1):
                y = v + dy
                if y < 0 or y >= h:
                    continue
                for dx in range(-radius, radius + 1):
                    x = u + dx
                    if x < 0 or x >= w:
                        continue
                    wk = _rbf_weight(dy, dx, np.float64(img[v, u]), np.float64(img[y, x]), inv_ss2, inv_sc2)
                    total += wk
                    for d in range(n_disp):
                        acc[d] += wk * cost[y, x, d]
            for d in range(n_disp):
                out[v, u, d] = acc[d] / total
    return out


@njit(parallel=True, cache=True)
def decisive_seeds(cost, pkrn_min, epsilon, lr_tolerance, exclusion):
    """Sparse seed map at the coarsest level (DESIGN step 4); int32 (H, W), -1 undecided."""
    h, w, _ = cost.shape
    out = np.empty((h, w), np.int32)
    for v in prange(h):
        for u in range(w):
            out[v, u] = _seed_at(cost, v, u, pkrn_min, epsilon, lr_tolerance, exclusion)
    return out


@njit(parallel=True, cache=True)
def _evaluate_frontier(cost, disp, min_cost, max_gap, active, n_active, new_values, tau, kappa_d, adversarial):
    w = disp.shape[1]
    for i in prange(n_active):
        p = active[i]
        new_values[i] = _diffuse_at(cost, disp, min_cost, max_gap, p // w, p % w, tau, kappa_d, adversarial)


@njit(cache=True)
def _build_frontier(changed, n_changed, stamp, sweep, active, h, w, kappa_d):
    """Pixels within ``kappa_d`` of a changed pixel (the pixel itself excluded), deduplicated."""
    n_active = 0
    for i in range(n_changed):
        p = changed[i]
        v = p // w
        u = p % w
        for dv in range(-kappa_d, kappa_d + 1):
            y = v + dv
            if y < 0 or y >= h:
                continue
            for du in range(-kappa_d, kappa_d + 1):
                x = u + du
                if x < 0 or x >= w or (dv == 0 and du == 0):
                    continue
                q = y * w + x
                if stamp[q] != sweep:
                    stamp[q] = sweep
                    active[n_active] = q
                    n_active += 1
    return n_active


@njit(cache=True)
def diffuse(cost, disp0, min_cost, max_gap, tau, kappa_d, adversarial, max_sweeps):
    """Intra-scale decisive diffusion with a frontier (paper Algorithm 1, eq. 5-6).

    Parameters
    ----------
    cost : ndarray, float32, (H, W, D)
    disp0 : ndarray, int32, (H, W)
        Sparse decisive map D_i^S (-1 undecided); not modified.
    min_cost : ndarray, float32, (H, W)
        Least cost of each pixel over all disparities (:func:`min_cost`).
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
        Sweeps run (the last one changed nothing unless the safeguard stopped it).
    """
    h, w = disp0.shape
    disp = disp0.copy()
    flat = disp.reshape(h * w)  # a view: writes go to disp
    changed = np.empty(h * w, np.int64)
    n_changed = 0
    for p in range(h * w):
        if flat[p] != UNDECIDED:
            changed[n_changed] = p
            n_changed += 1
    stamp = np.zeros(h * w, np.int64)
    active = np.empty(h * w, np.int64)
    new_values = np.empty(h * w, np.int32)
    sweeps = 0
    while n_changed > 0 and sweeps < max_sweeps:
        sweeps += 1
        n_active = _build_frontier(changed, n_changed, stamp, sweeps, active, h, w, kappa_d)
        _evaluate_frontier(cost, disp, min_cost, max_gap, active, n_active, new_values, tau, kappa_d, adversarial)
        # Jacobi: every frontier pixel read the previous map; apply all changes after.
        n_changed = 0
        for i in range(n_active):
            p = active[i]
            if new_values[i] != flat[p]:
                changed[n_changed] = p
                n_changed += 1
                new_values[n_changed - 1] = new_values[i]
        for i in range(n_changed):
            flat[changed[i]] = new_values[i]
    return disp, sweeps


@njit(parallel=True, cache=True)
def min_cost(cost):
    """Least cost of every pixel over all disparities; float32 (H, W)."""
    h, w, n_disp = cost.shape
    out = np.empty((h, w), np.float32)
    for v in prange(h):
        for u in range(w):
            best = cost[v, u, 0]
            for d in range(1, n_disp):
                if cost[v, u, d] < best:
                    best = cost[v, u, d]
            out[v, u] = best
    return out


@njit(parallel=True, cache=True)
def inherit(cost, coarse, prc, dfm_pkrn_min, epsilon):
    """Inter-scale decisive inheritance (paper Algorithm 2, eq. 7-9).

    Parameters
    ----------
    cost : ndarray, float32, (H, W, D)
        Cost volume of the finer level i.
    coarse : ndarray, int32, (>= H // 2, >= W // 2)
        Disparity map of level i + 1 (-1 undecided).

    Returns
    -------
    ndarray, int32, (H, W)
        Sparse map D_i^S.
    """
    h, w, _ = cost.shape
    out = np.empty((h, w), np.int32)
    for v in prange(h):
        for u in range(w):
            out[v, u] = _inherit_at(cost, coarse, v, u, prc, dfm_pkrn_min, epsilon)
    return out


@njit(parallel=True, cache=True)
def subpixel(cost, disp):
    """Parabola sub-pixel refinement (DESIGN step 8); float32 (H, W), inf where undecided."""
    h, w = disp.shape
    out = np.empty((h, w), np.float32)
    for v in prange(h):
        for u in range(w):
            out[v, u] = _subpixel_at(cost, disp, v, u)
    return out


# ----------------------------------------------------------------------------- array handling
# The pipeline moves data through these so that it never needs to know where arrays
# live; on the CPU they are (nearly) free.


def to_device(array):
    """C-contiguous array for the kernels (the CPU's memory is the device's)."""
    return np.ascontiguousarray(array)


def to_host(array):
    """NumPy array of a backend array (identity on the CPU)."""
    return np.asarray(array)


@njit(parallel=True, cache=True)
def merge_sparse(primary, fallback):
    """``primary`` where decided (>= 0), else ``fallback``; int32 (H, W), a new map."""
    h, w = primary.shape
    out = np.empty((h, w), np.int32)
    for v in prange(h):
        for u in range(w):
            out[v, u] = primary[v, u] if primary[v, u] >= 0 else fallback[v, u]
    return out


def count_decided(disparity) -> int:
    """Number of decided pixels (>= 0) of an integer disparity map."""
    return int(np.count_nonzero(np.asarray(disparity) >= 0))


# ----------------------------------------------------------------------------- perspective transformation
_pt_shift = ops.pt_shift
_bilinear_at = ops.bilinear_at
_pt_restore_at = ops.pt_restore_at


@njit(parallel=True, cache=True)
def pt_warp(right, a0, b1, b2, delta):
    """Right image warped by the road model (DESIGN step 6): ``R'(x, v) = R(x - s(x, v), v)``.

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
    h, w = right.shape
    out = np.empty((h, w), np.float32)
    for v in prange(h):
        for x in range(w):
            out[v, x] = _bilinear_at(right, v, x - _pt_shift(a0, b1, b2, delta, v, x))
    return out


@njit(parallel=True, cache=True)
def pt_restore(disp, a0, b1, b2, delta):
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
    h, w = disp.shape
    out = np.empty((h, w), np.float32)
    for v in prange(h):
        for u in range(w):
            out[v, u] = _pt_restore_at(disp[v, u], a0, b1, b2, delta, v, u)
    return out
