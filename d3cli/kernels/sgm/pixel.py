"""Per-pixel function of the semi-global smoothing: one pixel of one path over a
banded volume.  Compiled for every target by :func:`build` (composed by
:func:`d3cli.kernels.pixel.build_ops`)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ..pixel import INF, UINT


# Over 80 lines by design, as every step's factory (see d3cli.kernels.pixel.build_ops).
def build(jit, shared):
    """``sgm_step`` compiled with ``jit`` (the protocol: :func:`d3cli.kernels.pixel.build_ops`)."""

    @jit
    def sgm_step(cost, index, v, u, prev, plo, phi, cur, p1, p2, acc, mode):
        """One pixel of one semi-global path over a banded volume.

        ``L(p, d) = C(p, d) + min(L(q, d), L(q, d -+ 1) + P1, min_k L(q, k) + P2) -
        min_k L(q, k)`` over the pixel's band, with ``q`` the previous pixel of the path,
        whose band is ``[plo, phi)`` (empty at the path's start, where ``L = C``, as where
        its path costs are all inf).

        ``prev`` and ``cur`` are ``(buffer, base)``: ``L(., d)`` at ``buffer[base + d + 1]``,
        n_disp + 2 cells, inf outside the pixel's band; the two ends are sentinels, so
        ``d -+ 1`` needs no test and the loop over the band is branch-free.  The step keeps
        that so: it writes ``cur`` over its band and resets ``prev``'s band to inf (the
        cells the path writes two pixels on; start with all inf).  ``mode`` says what
        becomes of ``acc``: 0 ``acc = L`` (the first path), 1 ``acc += L``, 2 ``acc = (acc +
        L) / 4`` (the last path: the mean of four).  Float32 throughout (``p1``, ``p2``
        float32): the same operations in the same order on every backend.
        """
        pbuf, pbase = prev
        cbuf, cbase = cur
        off = index[v, u, 0]
        lo = index[v, u, 1]
        hi = index[v, u, 2]
        # Subscripts base + i made unsigned: no wraparound selects and no views (whose
        # reference counts cost more than the loops, measured), so the loops vectorise.
        seen = pbase + plo + 1
        # The least of the previous pixel's path costs in four interleaved chains: the
        # cells below wait for it, and one chain of compares over the band was a fifth of
        # the smoothing's time (KITTI, measured).  least() does the same, but called from
        # here (not inlined) it made the whole smoothing 30 % slower, measured.
        m0 = m1 = m2 = m3 = np.float32(INF)  # float32: a float64 pm would round the sums differently
        n = phi - plo
        k = 0
        while k + 4 <= n:
            at = seen + k
            x = pbuf[UINT(at)]
            m0 = x if x < m0 else m0
            x = pbuf[UINT(at + 1)]
            m1 = x if x < m1 else m1
            x = pbuf[UINT(at + 2)]
            m2 = x if x < m2 else m2
            x = pbuf[UINT(at + 3)]
            m3 = x if x < m3 else m3
            k += 4
        while k < n:
            x = pbuf[UINT(seen + k)]
            m0 = x if x < m0 else m0
            k += 1
        m0 = m1 if m1 < m0 else m0
        m2 = m3 if m3 < m2 else m2
        pm = m2 if m2 < m0 else m0
        cells = off + lo
        below = pbase + lo  # L(q, d - 1) of the band's first d
        out = cbase + lo + 1
        quarter = np.float32(0.25)
        for i in range(hi - lo):
            el = cost[UINT(cells + i)]
            if pm != INF:
                x = pbuf[UINT(below + 1 + i)]  # L(q, d)
                jump = pm + p2
                b = x if x < jump else jump
                y = pbuf[UINT(below + i)] + p1  # L(q, d - 1) + P1
                b = y if y < b else b
                y = pbuf[UINT(below + 2 + i)] + p1  # L(q, d + 1) + P1
                b = y if y < b else b
                el = el + (b - pm)
            cbuf[UINT(out + i)] = el
            if mode == 0:
                acc[UINT(cells + i)] = el
            elif mode == 1:
                acc[UINT(cells + i)] += el
            else:
                acc[UINT(cells + i)] = (acc[UINT(cells + i)] + el) * quarter
        for i in range(phi - plo):
            pbuf[UINT(seen + i)] = INF

    return SimpleNamespace(
        sgm_step=sgm_step,
    )
