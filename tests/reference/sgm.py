"""Reference of the semi-global aggregation: every path walked pixel by pixel."""

from __future__ import annotations

import numpy as np

F32 = np.float32


def ref_sgm_paths(cost, lo, hi, p1, p2):
    """(L_left + L_down + L_right + L_up) / 4 of a dense (H, W, D) cost whose cells
    outside [lo, hi) of each pixel do not exist (inf in the path costs, 0 in the result)."""
    h, w, n = cost.shape
    p1, p2 = F32(p1), F32(p2)
    acc = np.zeros((h, w, n), F32)
    inside = (np.arange(n)[None, None, :] >= lo[:, :, None]) & (np.arange(n)[None, None, :] < hi[:, :, None])

    def walk(pixels):
        prev = np.full(n, np.inf, F32)
        for v, u in pixels:
            cur = np.full(n, np.inf, F32)
            pm = prev.min()
            for d in np.nonzero(inside[v, u])[0]:
                c = cost[v, u, d]
                if pm == np.inf:
                    el = c
                else:
                    b = min(prev[d], prev[d - 1] + p1 if d > 0 else np.inf, prev[d + 1] + p1 if d + 1 < n else np.inf,
                            pm + p2)
                    el = F32(c + F32(F32(b) - pm))
                cur[d] = el
                acc[v, u, d] = F32(acc[v, u, d] + el)
            prev = cur

    for v in range(h):
        walk([(v, u) for u in range(w)])
    for u in range(w):
        walk([(v, u) for v in range(h)])
    for v in range(h):
        walk([(v, u) for u in range(w - 1, -1, -1)])
    for u in range(w):
        walk([(v, u) for v in range(h - 1, -1, -1)])
    return acc * F32(0.25), inside
