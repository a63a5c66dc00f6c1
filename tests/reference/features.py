"""Reference of the deep-feature matching cost: the cosine cost volume, pixel by pixel."""

from __future__ import annotations

import numpy as np


def ref_cosine_cost(fl, fr, max_disparity):
    h, w, _ = fl.shape
    cost = np.ones((h, w, max_disparity + 1), np.float64)
    nl = np.linalg.norm(fl, axis=2)
    nr = np.linalg.norm(fr, axis=2)
    for d in range(max_disparity + 1):
        for u in range(d, w):
            ok = (nl[:, u] > 0) & (nr[:, u - d] > 0)
            dot = np.sum(fl[:, u].astype(np.float64) * fr[:, u - d], axis=1)
            cost[ok, u, d] = 0.5 * (1 - np.clip(dot[ok], -1, 1))
    return cost
