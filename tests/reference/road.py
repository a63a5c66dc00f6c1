"""References of the road report's confidence evidence."""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def ref_spikiness(depth, inside, peak_px, spike_px):
    """The definition: peak of depth over inside / peak of its spike_px median filter over inside."""
    filt = ndimage.median_filter(depth.astype(np.float64), size=spike_px, mode="nearest")
    top = np.sort(depth[inside])[-peak_px:].mean()
    return top / np.sort(filt[inside])[-peak_px:].mean()


def ref_match_margin(left, right, disparity, region, window, pad):
    """The definition, one window at a time, for an integer disparity map: the right image
    read at ``u - d - offset`` (mirrored beyond the image, as the remap's border), the
    zero-mean NCC of each window of the box (mirrored without repeating the edge beyond the
    box, as a box filter's border), the margin NCC(d) - max(NCC(d+1), NCC(d-1)), its median
    over the region."""
    left = left.astype(np.float64)
    right = right.astype(np.float64)
    h, w = left.shape
    v, u = np.nonzero(region)
    v0, v1 = max(v.min() - pad, 0), min(v.max() + pad + 1, h)
    u0, u1 = max(u.min() - pad, 0), min(u.max() + pad + 1, w)
    r = window // 2

    def mirror(i, n):  # BORDER_REFLECT: ... 1 0 | 0 1 2 ... n-1 | n-1 n-2 ...
        i = np.mod(i, 2 * n)
        return np.where(i < n, i, 2 * n - 1 - i)

    rows, cols = np.mgrid[v0:v1, u0:u1]
    lbox = np.pad(left[v0:v1, u0:u1], r, mode="reflect")
    scores = {}
    for offset in (-1, 0, 1):
        cols_r = mirror(cols - disparity[v0:v1, u0:u1].astype(np.int64) - offset, w)
        rbox = np.pad(right[rows, cols_r], r, mode="reflect")
        ncc = np.empty(rows.shape)
        for i in range(rows.shape[0]):
            for j in range(rows.shape[1]):
                a = lbox[i:i + window, j:j + window].ravel()
                b = rbox[i:i + window, j:j + window].ravel()
                a, b = a - a.mean(), b - b.mean()
                ncc[i, j] = (a @ b) / max(np.sqrt((a @ a) * (b @ b)), 1e-6 * a.size)
        scores[offset] = ncc
    margin = scores[0] - np.maximum(scores[1], scores[-1])
    return float(np.median(margin[region[v0:v1, u0:u1]]))
