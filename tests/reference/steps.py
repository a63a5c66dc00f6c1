"""Slow, obviously-correct NumPy/Python references for the D3Stereo kernels.

Written from the specification (the docstrings of the steps' ``pixel*.py`` and of
``d3cli/kernels/backend.py``, and docs/design.md, 'Cost volumes'), not from the Numba code: every
window, neighbour and candidate set is built explicitly, costs are computed in float64
and nothing is vectorised cleverly.  Only for tiny inputs (a few thousand cells).

Conventions shared with the kernels
-----------------------------------
* cost volumes are (H, W, D), disparity innermost, lower is better;
* disparity maps are int32 with -1 for undecided pixels;
* ``C(p, d)`` of a cell that does not exist (pixel outside the image, disparity outside
  [0, D-1]) is +inf, so that ``c < C(missing)`` is always true;
* the right-view cost is the left volume re-indexed: ``C_R(x, v, d) = C_L(x + d, v, d)``;
* ties in an arg-min go to the smaller disparity.
"""

from __future__ import annotations

import math

import numpy as np

UNDECIDED = -1
INF = math.inf


# ----------------------------------------------------------------------------- helpers
def cell(cost, v, u, d):
    """Left-view cost C(u, v, d), inf where the cell does not exist."""
    h, w, n_disp = cost.shape
    if not (0 <= v < h and 0 <= u < w and 0 <= d < n_disp):
        return INF
    return float(cost[v, u, d])


def right_cell(cost, v, x, d):
    """Right-view cost C_R(x, v, d) = C_L(x + d, v, d), inf where that cell does not exist."""
    return cell(cost, v, x + d, d)


def argmin_smallest(pairs):
    """(d, c) of least c among (d, c) pairs, smaller d on ties; (-1, inf) for none."""
    best = (UNDECIDED, INF)
    for d, c in sorted(pairs):
        if c < best[1]:
            best = (d, c)
    return best


# ----------------------------------------------------------------------------- pyramid
def ref_downsample(img):
    """2x2 area average; an odd last row/column is dropped."""
    img = np.asarray(img, dtype=np.float64)
    h, w = img.shape[0] // 2, img.shape[1] // 2
    out = np.empty((h, w), np.float64)
    for y in range(h):
        for x in range(w):
            out[y, x] = img[2 * y:2 * y + 2, 2 * x:2 * x + 2].mean()
    return out.astype(np.float32)


# ----------------------------------------------------------------------------- cost
def ref_ncc_cost(left_window, right_window, min_variance):
    """(1 - NCC) / 2 of two equally shaped windows; 1 when either is flat."""
    a = np.asarray(left_window, dtype=np.float64).ravel()
    b = np.asarray(right_window, dtype=np.float64).ravel()
    if a.size == 0:
        return 1.0
    da = a - a.mean()
    db = b - b.mean()
    var_a = (da * da).mean()
    var_b = (db * db).mean()
    if var_a <= min_variance or var_b <= min_variance:
        return 1.0
    ncc = (da * db).mean() / math.sqrt(var_a * var_b)
    return 0.5 * (1.0 - min(1.0, max(-1.0, ncc)))


def ref_ncc_cost_volume(left, right, max_disparity, window, min_variance):
    """NCC cost volume by direct per-window computation (docs/design.md, step 2).

    The window around (u, v) is clipped to the rows inside the image and to the columns
    [max(u - r, d), min(u + r, W - 1)], where both the left window around u and the right
    window around u - d lie inside the image.  Cells with u - d < 0 cost 1.

    Returns float32 (H, W, max_disparity + 1).
    """
    left = np.asarray(left, dtype=np.float64)
    right = np.asarray(right, dtype=np.float64)
    h, w = left.shape
    r = window // 2
    out = np.ones((h, w, max_disparity + 1), np.float64)
    for v in range(h):
        y0, y1 = max(0, v - r), min(h - 1, v + r)
        for u in range(w):
            for d in range(max_disparity + 1):
                if u - d < 0:
                    continue
                c0, c1 = max(u - r, d), min(u + r, w - 1)
                lw = left[y0:y1 + 1, c0:c1 + 1]
                rw = right[y0:y1 + 1, c0 - d:c1 - d + 1]
                out[v, u, d] = ref_ncc_cost(lw, rw, min_variance)
    return out.astype(np.float32)


# ----------------------------------------------------------------------------- aggregation
def kernel_weight(dy, dx, i_p, i_q, sigma_space, sigma_color):
    """K(p, q) of paper eq. 3, unnormalised."""
    return math.exp(-(dy * dy + dx * dx) / sigma_space**2 - (i_p - i_q) ** 2 / sigma_color**2)


def ref_rbf_weights(img, sigma_space, sigma_color):
    """Normalised 3x3 weights (H, W, 9); slot k is (dy, dx) = (k // 3 - 1, k % 3 - 1)."""
    img = np.asarray(img, dtype=np.float64)
    h, w = img.shape
    out = np.zeros((h, w, 9), np.float64)
    for v in range(h):
        for u in range(w):
            for k in range(9):
                dy, dx = k // 3 - 1, k % 3 - 1
                if 0 <= v + dy < h and 0 <= u + dx < w:
                    out[v, u, k] = kernel_weight(dy, dx, img[v, u], img[v + dy, u + dx], sigma_space, sigma_color)
            out[v, u] /= out[v, u].sum()
    return out.astype(np.float32)


def ref_rbf_filter(cost, weights, t_max):
    """t_max passes of C_t(p, d) = sum_q w(p, q) C_{t-1}(q, d) (paper eq. 2)."""
    cur = np.asarray(cost, dtype=np.float64).copy()
    weights = np.asarray(weights, dtype=np.float64)
    h, w, _ = cur.shape
    for _ in range(t_max):
        nxt = np.zeros_like(cur)
        for v in range(h):
            for u in range(w):
                for k in range(9):
                    y, x = v + k // 3 - 1, u + k % 3 - 1
                    if 0 <= y < h and 0 <= x < w:
                        nxt[v, u] += weights[v, u, k] * cur[y, x]
        cur = nxt
    return cur.astype(np.float32)


def ref_bilateral_filter(cost, img, radius, sigma_space, sigma_color):
    """One normalised bilateral pass over a (2 radius + 1)^2 window clipped to the image."""
    cost = np.asarray(cost, dtype=np.float64)
    img = np.asarray(img, dtype=np.float64)
    h, w, _ = cost.shape
    out = np.empty_like(cost)
    for v in range(h):
        for u in range(w):
            acc = np.zeros(cost.shape[2])
            total = 0.0
            for y in range(max(0, v - radius), min(h, v + radius + 1)):
                for x in range(max(0, u - radius), min(w, u + radius + 1)):
                    k = kernel_weight(y - v, x - u, img[v, u], img[y, x], sigma_space, sigma_color)
                    acc += k * cost[y, x]
                    total += k
            out[v, u] = acc / total
    return out.astype(np.float32)


# ----------------------------------------------------------------------------- seeds
def ref_seed(cost, v, u, pkrn_min, epsilon, lr_tolerance, exclusion):
    """Decisive seed of one pixel (docs/design.md, step 4) or -1."""
    n_disp = cost.shape[2]
    d1, c1 = argmin_smallest([(d, float(cost[v, u, d])) for d in range(n_disp)])
    if c1 >= 1.0:
        return UNDECIDED
    others = [float(cost[v, u, d]) for d in range(n_disp) if abs(d - d1) > exclusion]
    if not others:
        return UNDECIDED
    c2 = min(others)
    if (c2 + epsilon) / (c1 + epsilon) < pkrn_min:
        return UNDECIDED
    # Left-right check: WTA of the right view at x = u - d1 over the cells that exist.
    # A match whose right pixel is outside the image is no match (docs/design.md, step 2: such
    # cells never win), even when aggregation has pulled its cost below 1.
    x = u - d1
    if x < 0:
        return UNDECIDED
    right_curve = [(d, right_cell(cost, v, x, d)) for d in range(n_disp)]
    dr, cr = argmin_smallest([(d, c) for d, c in right_curve if c < INF])
    if dr < 0 or abs(dr - d1) > lr_tolerance:
        return UNDECIDED
    return d1


def ref_decisive_seeds(cost, pkrn_min, epsilon, lr_tolerance, exclusion):
    """Sparse seed map, int32 (H, W), -1 undecided."""
    h, w, _ = cost.shape
    out = np.full((h, w), UNDECIDED, np.int32)
    for v in range(h):
        for u in range(w):
            out[v, u] = ref_seed(cost, v, u, pkrn_min, epsilon, lr_tolerance, exclusion)
    return out


def ref_min_cost(cost):
    """Least cost per pixel, float32 (H, W)."""
    return np.asarray(cost).min(axis=2).astype(np.float32)


# ----------------------------------------------------------------------------- diffusion
def ref_accepts(cost, v, u, s, c):
    """Hypotheses (2) local minimum and (3) right-view consistency for state s of cost c."""
    if c >= 1.0:
        return False
    local_min = c < cell(cost, v, u, s - 1) and c < cell(cost, v, u, s + 1)
    right_consistent = c < cell(cost, v, u - 1, s - 1) and c < cell(cost, v, u + 1, s + 1)
    return local_min and right_consistent


def ref_diffuse_pixel(cost, disp, least, max_gap, v, u, tau, kappa_d, adversarial):
    """New state of (u, v) from the previous map ``disp`` (paper eq. 4-5)."""
    h, w = disp.shape
    n_disp = cost.shape[2]
    candidates = set()
    for y in range(v - kappa_d, v + kappa_d + 1):
        for x in range(u - kappa_d, u + kappa_d + 1):
            if (y, x) == (v, u) or not (0 <= y < h and 0 <= x < w) or disp[y, x] < 0:
                continue
            for r in range(-tau, tau + 1):
                if 0 <= disp[y, x] + r < n_disp:
                    candidates.add(int(disp[y, x]) + r)
    cur = int(disp[v, u])
    s, c = argmin_smallest([(s, float(cost[v, u, s])) for s in candidates])
    if s < 0 or s == cur or not ref_accepts(cost, v, u, s, c):
        return cur
    if max_gap >= 0 and c > float(least[v, u]) + max_gap:
        return cur
    if cur < 0:
        return s
    if adversarial and c < float(cost[v, u, cur]):
        return s
    return cur


def ref_diffuse(cost, disp0, max_gap, tau, kappa_d, adversarial, max_sweeps=10**6):
    """Jacobi diffusion over the WHOLE image until a sweep changes nothing.

    Every sweep evaluates every pixel against the previous map.  Sweeps are counted like
    the frontier implementation: every sweep run, including the last one that changed
    nothing; 0 when the initial map has no decided pixel (the frontier is then empty).

    Returns (int32 (H, W), sweeps).
    """
    least = ref_min_cost(cost)
    disp = np.asarray(disp0, dtype=np.int32).copy()
    if not (disp >= 0).any():
        return disp, 0
    h, w = disp.shape
    sweeps = 0
    while sweeps < max_sweeps:
        sweeps += 1
        new = disp.copy()
        for v in range(h):
            for u in range(w):
                new[v, u] = ref_diffuse_pixel(cost, disp, least, max_gap, v, u, tau, kappa_d, adversarial)
        changed = bool((new != disp).any())
        disp = new
        if not changed:
            break
    return disp, sweeps


# ----------------------------------------------------------------------------- inheritance
def view_cost(cost, v, x, d, right_view):
    return right_cell(cost, v, x, d) if right_view else cell(cost, v, x, d)


def ref_candidates(x, d, right_view, candidates):
    """(in-patch, outside) candidate disparities of the patch pixel in column x.

    symmetric: {d-1, d, d+1} and {d-2, d+2}.  paper (eq. 6-7 read literally): the
    partners of a pixel are the co-row pixels of the other view's patch, the outside
    pixels those just beside it.  Left patch columns u0, u0 + 1 (u0 even), right patch
    columns x0 = u0 - d, x0 + 1; the left pixel u0 + a meets right columns x0 + {0, 1}
    (disparities d + a - {0, 1}) and x0 - 1, x0 + 2 (d + a + 1, d + a - 2); the right
    pixel x0 + b meets left columns u0 + {0, 1} (d - b + {0, 1}) and u0 - 1, u0 + 2
    (d - b - 1, d - b + 2).
    """
    if candidates == "symmetric":
        return (d - 1, d, d + 1), (d - 2, d + 2)
    if right_view:
        b = (x - d) % 2  # the right patch starts at an even column (u0 and d even)
        return (d - b, d - b + 1), (d - b - 1, d - b + 2)
    a = x % 2
    return (d + a - 1, d + a), (d + a - 2, d + a + 1)


def ref_patch_least_outside(cost, rows, cols, d, right_view, candidates="symmetric"):
    """PRC of one view's 2x2 patch: least outside cost, or None when unreliable.

    In-patch cost of a pixel: least of its costs at its in-patch candidates; outside
    cost: least of its costs at its outside candidates (:func:`ref_candidates`).
    Reliable when mean(in-patch) < min(outside).
    """
    inside, outside = [], []
    for y in rows:
        for x in cols:
            ins, outs = ref_candidates(x, d, right_view, candidates)
            inside.append(min(view_cost(cost, y, x, s, right_view) for s in ins))
            outside.append(min(view_cost(cost, y, x, s, right_view) for s in outs))
    if sum(inside) / 4.0 < min(outside):
        return min(outside)
    return None


def ref_pixel_decisive(cost, v, x, d, right_view, prc, least_out, dfm_pkrn_min, epsilon, candidates="symmetric"):
    """Best in-patch disparity of one pixel in one view if it passes its test, else -1."""
    ins = ref_candidates(x, d, right_view, candidates)[0]
    curve = {s: view_cost(cost, v, x, s, right_view) for s in range(d - 3, d + 4)}
    best_d, best_c = argmin_smallest([(s, curve[s]) for s in ins if curve[s] < INF])
    if best_d < 0 or best_c >= 1.0:
        return UNDECIDED
    if prc:
        ok = best_c < curve[best_d - 1] and best_c < curve[best_d + 1] and best_c < least_out
        return best_d if ok else UNDECIDED
    second = min([curve[s] for s in ins if s != best_d])
    return best_d if (second + epsilon) / (best_c + epsilon) >= dfm_pkrn_min else UNDECIDED


def ref_inherit_pixel(cost, coarse, v, u, prc, dfm_pkrn_min, epsilon, candidates="symmetric"):
    """Inherited disparity of fine pixel (u, v), or -1 (paper Algorithm 2, eq. 6-8).

    Coarse pixel (u // 2, v // 2) with disparity dc; d = 2 dc; left patch rows
    2(v // 2) + {0, 1}, columns u0 = 2(u // 2) + {0, 1}; right patch columns u0 - d + {0, 1}.
    PRC in the left view over the left patch and in the right view over the right patch.
    """
    pv, pu = v // 2, u // 2
    if pv >= coarse.shape[0] or pu >= coarse.shape[1] or coarse[pv, pu] < 0:
        return UNDECIDED
    d = 2 * int(coarse[pv, pu])
    rows = (2 * pv, 2 * pv + 1)
    left_cols = (2 * pu, 2 * pu + 1)
    right_cols = (2 * pu - d, 2 * pu - d + 1)
    least_l = least_r = INF
    if prc:
        least_l = ref_patch_least_outside(cost, rows, left_cols, d, False, candidates)
        least_r = ref_patch_least_outside(cost, rows, right_cols, d, True, candidates)
        if least_l is None or least_r is None:
            return UNDECIDED
    dl = ref_pixel_decisive(cost, v, u, d, False, prc, least_l, dfm_pkrn_min, epsilon, candidates)
    if dl < 0:
        return UNDECIDED
    dr = ref_pixel_decisive(cost, v, u - dl, d, True, prc, least_r, dfm_pkrn_min, epsilon, candidates)
    return dl if dr == dl else UNDECIDED


def ref_inherit(cost, coarse, prc, dfm_pkrn_min, epsilon, candidates="symmetric"):
    """Sparse inherited map, int32 (H, W), -1 undecided; ``candidates`` symmetric | paper."""
    h, w, _ = cost.shape
    out = np.full((h, w), UNDECIDED, np.int32)
    for v in range(h):
        for u in range(w):
            out[v, u] = ref_inherit_pixel(cost, coarse, v, u, prc, dfm_pkrn_min, epsilon, candidates)
    return out


# ----------------------------------------------------------------------------- finish
def ref_subpixel(cost, disp, equiangular=False):
    """Parabola vertex through C(d-1), C(d), C(d+1), offset clamped to +-0.5; with
    ``equiangular`` the crossing of two lines of equal and opposite slope through them.

    Integer d at the ends of the range and on flat or concave curves; inf where undecided.
    """
    h, w = disp.shape
    n_disp = cost.shape[2]
    out = np.full((h, w), np.inf, np.float64)
    for v in range(h):
        for u in range(w):
            d = int(disp[v, u])
            if d < 0:
                continue
            out[v, u] = d
            if d == 0 or d == n_disp - 1:
                continue
            c0, c1, c2 = (float(cost[v, u, s]) for s in (d - 1, d, d + 1))
            # the parabola's curvature, or the lines' rise over one disparity
            curvature = max(c0, c2) - c1 if equiangular else c0 + c2 - 2.0 * c1
            if curvature <= 0.0:
                continue
            out[v, u] = d + min(0.5, max(-0.5, 0.5 * (c0 - c2) / curvature))
    return out.astype(np.float32)


# ----------------------------------------------------------------------------- perspective transformation
def ref_pt_warp(right, a0, b1, b2, delta):
    """``R'(x, v) = R(x - s(x, v), v)``, ``s = a0 + b1 v + b2 x - delta``; bilinear, border replicated."""
    right = np.asarray(right, dtype=np.float64)
    h, w = right.shape
    out = np.empty((h, w), np.float64)
    for v in range(h):
        for x in range(w):
            src = x - (a0 + b1 * v + b2 * x - delta)
            if src <= 0:
                out[v, x] = right[v, 0]
            elif src >= w - 1:
                out[v, x] = right[v, w - 1]
            else:
                x0 = int(np.floor(src))
                t = src - x0
                out[v, x] = (1 - t) * right[v, x0] + t * right[v, x0 + 1]
    return out.astype(np.float32)


def ref_pt_restore(disp, a0, b1, b2, delta):
    """``d = d' + s(u - d', v)`` written out literally (inf stays inf)."""
    disp = np.asarray(disp, dtype=np.float64)
    h, w = disp.shape
    out = np.full((h, w), np.inf)
    for v in range(h):
        for u in range(w):
            d = disp[v, u]
            if np.isfinite(d):
                x = u - d
                out[v, u] = d + (a0 + b1 * v + b2 * x - delta)
    return out.astype(np.float32)
