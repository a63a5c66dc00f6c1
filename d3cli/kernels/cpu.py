"""CPU backend: the per-pixel functions of ``pixel.py`` compiled with ``njit`` and
driven by parallel (``prange``) loops over rows or over frontier pixels.

Every driver is deterministic and independent of the thread count: parallel loops only
write disjoint cells, reductions are done serially, and iterative steps are
double-buffered (Jacobi).  Arrays are C-contiguous float32 volumes (H, W, D) with the
disparity axis innermost, so inner loops run over contiguous memory.
"""

from __future__ import annotations

import hashlib
import platform
from pathlib import Path

import numba
import numpy as np
from llvmlite import ir
from numba import njit, prange, types
from numba.core import cgutils, errors
from numba.extending import intrinsic
from numba.cpython.unsafe.numbers import trailing_zeros


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

from .pixel import UINT, UNDECIDED, build_ops  # noqa: E402
from .volume import Volume, dense_index  # noqa: E402

# error_model="numpy" (here and on every driver): a float division by zero gives inf/nan
# instead of raising, so numba emits no zero test per division and a loop with a
# division can vectorise (the NCC formula: 0.161 -> 0.143 s CPU at level 1 of the 720p
# road pair).  Every division the kernels do has a non-zero divisor (a zero one would
# have raised before), so the results are the same (issue 10; checked with the md5 that
# scripts/bench_speed.py prints per case, before and after).
ops = build_ops(njit(cache=True, error_model="numpy"))
_cosine_cost = ops.cosine_cost
_box_sum = ops.box_sum
_rbf_weight = ops.rbf_weight
_seed_candidate = ops.seed_candidate
_right_wta = ops.right_wta
_diffuse_at = ops.diffuse_at
_holds_own_disparity = ops.holds_own_disparity
_band_min = ops.band_min
_inherit_patch_into = ops.inherit_patch_into
_subpixel_at = ops.subpixel_at
# compiled again to be inlined into the drivers (numba IR inlining: its mode folds to a
# constant per call site; the semi-global smoothing of a KITTI volume 43 -> 37 ms)
_sgm_step = njit(cache=True, error_model="numpy", inline="always")(ops.sgm_step.py_func)

#: Rows per parallel task of the NCC driver (one running window sum per task).
NCC_BLOCK_ROWS = 32
#: Tasks per thread of the NCC driver when its sums are exact (:func:`_ncc_banded`).
NCC_EXACT_TASKS = 4
#: Fractional bits of the grey levels that :func:`_integral_pair_into` tests for.
GRID_BITS = (6, 20)
#: Bands of at most this many unclipped cells take the NCC row's one-loop slide (below a
#: vector's few steps, one loop over the cells beats two).
NCC_NARROW = 8


# ----------------------------------------------------------------------------- volumes
def _unpack(cost):
    """``(flat cost, index, n_disp, dense shape or None)`` of a Volume or an (H, W, D) array."""
    if isinstance(cost, Volume):
        return cost.cost, cost.index, int(cost.n_disp), None
    cost = np.ascontiguousarray(cost)
    h, w, n_disp = cost.shape
    return cost.reshape(-1), dense_index(h, w, n_disp), n_disp, cost.shape


def _pack(flat, index, n_disp, dense_shape):
    """The result in the caller's kind: a Volume, or an (H, W, D) array."""
    if dense_shape is not None:
        return flat.reshape(dense_shape)
    return Volume(flat, index, n_disp)


@intrinsic
def _store_nt(typingctx, arr, i, val):
    """``arr.flat[i] = val`` (a C-contiguous array; val cast to its dtype) as a
    non-temporal store: LLVM's ``!nontemporal`` hint, the line written around the caches
    without being read first."""

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        ptr = builder.gep(ary.data, [context.cast(builder, args[1], signature.args[1], types.intp)])
        val = context.cast(builder, args[2], signature.args[2], signature.args[0].dtype)
        store = builder.store(val, ptr)
        store.set_metadata("nontemporal", builder.module.add_metadata([ir.Constant(ir.IntType(32), 1)]))
        return context.get_dummy_value()

    return types.void(arr, i, val), codegen


#: Whether this machine is x86 (its non-temporal stores need an sfence).
_X86 = platform.machine().lower() in ("x86_64", "amd64", "i386", "i686")


@intrinsic
def _store_fence(typingctx):
    """Order the non-temporal stores before (:func:`_store_nt`) before every later store:
    x86's ``sfence``, where such stores are weakly ordered (nothing elsewhere)."""

    def codegen(context, builder, signature, args):
        if _X86:
            fn = builder.module.declare_intrinsic("llvm.x86.sse.sfence", (), ir.FunctionType(ir.VoidType(), ()))
            builder.call(fn, ())
        return context.get_dummy_value()

    return types.void(), codegen


@njit(cache=True, error_model="numpy")
def integral_image(img, power):
    """(H+1, W+1) float64 integral image of ``img ** power`` (power 1 or 2)."""
    h, w = img.shape
    ii = np.empty((h + 1, w + 1), np.float64)
    _integral_into(img, power, ii)
    return ii


@njit(cache=True, error_model="numpy")
def _integral_into(img, power, ii):
    """Write :func:`integral_image` of ``img ** power`` into ``ii`` (H+1, W+1)."""
    h, w = img.shape
    for x in range(w + 1):
        ii[0, x] = 0.0
    for y in range(h):
        ii[y + 1, 0] = 0.0
        row = 0.0
        for x in range(w):
            val = np.float64(img[y, x])
            row += val if power == 1 else val * val
            ii[y + 1, x + 1] = ii[y, x + 1] + row


@njit(cache=True, error_model="numpy")
def _integral_pair_into(img, ii, ii2):
    """:func:`_integral_into` of ``img`` (into ``ii``) and of ``img ** 2`` (into ``ii2``)
    in one scan: two independent chains of adds, so each waits less on the other's
    latency (the same operations per image)."""
    h, w = img.shape
    for x in range(w + 1):
        ii[0, x] = 0.0
        ii2[0, x] = 0.0
    for y in range(h):
        ii[y + 1, 0] = 0.0
        ii2[y + 1, 0] = 0.0
        row = 0.0
        row2 = 0.0
        for x in range(w):
            val = np.float64(img[y, x])
            row += val
            row2 += val * val
            ii[y + 1, x + 1] = ii[y, x + 1] + row
            ii2[y + 1, x + 1] = ii2[y, x + 1] + row2


@njit(cache=True, error_model="numpy")
def _grid_bits(img):
    """The least k in :data:`GRID_BITS` such that every value of ``img`` is a multiple of
    2^-k of magnitude <= 255 (6: the first four pyramid levels of an 8-bit image; 20: a
    warped one), else 64 (:func:`_on_grid`)."""
    for k in GRID_BITS:
        if _on_grid(img, 2.0 ** k, -255):
            return k
    return 64


@njit(parallel=True, cache=True, error_model="numpy")
def _integral_images(left, right):
    """The four integral images of the NCC (L, L^2, R, R^2), two at a time: each is a
    serial scan, and four in a row were 4 ms of one thread at 1280x720.  Each is written
    in place into its slice of one array (issue 10: a zeroed temporary per image and a
    copy of it were 6.4 -> 3.9 ms of one thread at 1280x720, 2.7 -> 1.5 ms on KITTI),
    an image's two in one scan (2.6 -> 1.7 ms CPU at 1280x720, 1.3 -> 0.7 ms on KITTI)."""
    h, w = left.shape
    out = np.empty((4, h + 1, w + 1), np.float64)
    bits = np.empty(2, np.int64)
    for k in prange(2):
        img = left if k == 0 else right
        _integral_pair_into(img, out[2 * k], out[2 * k + 1])
        bits[k] = _grid_bits(img)
    return out[0], out[1], out[2], out[3], bits[0] + bits[1]


# ----------------------------------------------------------------------------- band search (issue 10)
@njit(parallel=True, cache=True, error_model="numpy")
def band_indexes(coarse, h, w, n_disp, margin, tile, halo):
    """Stored and visible indexes of a finer level's banded volume (host side, any backend).

    The rules are those of :mod:`d3cli.method.band` (its docstring explains them; its
    tests hold a NumPy reference): per tile ``[2 min dc - margin, 2 max dc + margin]``
    over the decided coarse pixels under it (the full range when none is); visible per
    pixel the hull of that over its tile and the eight around it; stored per pixel the
    hull of the visible bands of the tiles within ``halo``.

    Returns
    -------
    store, visible : ndarray, int32, (h, w, 3)
    n_cells : int
    """
    ch, cw = coarse.shape
    nty = (h + tile - 1) // tile
    ntx = (w + tile - 1) // tile
    # Per column, once (issue 10: no integer divisions per pixel): the coarse column, the
    # tile column and the tile columns within the halo.
    col_cu = np.empty(w, np.int64)
    col_tx = np.empty(w, np.int64)
    col_tx0 = np.empty(w, np.int64)
    col_tx1 = np.empty(w, np.int64)
    for u in range(w):
        col_cu[u] = min(u // 2, cw - 1)
        col_tx[u] = u // tile
        col_tx0[u] = min(max((u - halo) // tile, 0), ntx - 1)
        col_tx1[u] = min(max((u + halo) // tile, 0), ntx - 1)
    own_lo = np.zeros((nty, ntx), np.int64)
    own_hi = np.full((nty, ntx), n_disp, np.int64)
    for ty in prange(nty):  # one tile row per task: no two tasks touch a tile
        t_min = np.full(ntx, np.iinfo(np.int64).max, np.int64)
        t_max = np.full(ntx, -1, np.int64)
        last_cv = -1
        for v in range(ty * tile, min(h, ty * tile + tile)):
            cv = min(v // 2, ch - 1)
            if cv == last_cv:
                continue  # the row before read the same coarse row into the same tiles
            last_cv = cv
            last_cu = -1
            last_tx = -1
            for u in range(w):
                cu = col_cu[u]
                tx = col_tx[u]
                if cu == last_cu and tx == last_tx:
                    continue  # the same coarse pixel into the same tile: min/max unchanged
                last_cu = cu
                last_tx = tx
                dc = np.int64(coarse[cv, cu])
                if dc >= 0:
                    t_min[tx] = min(t_min[tx], dc)
                    t_max[tx] = max(t_max[tx], dc)
        for tx in range(ntx):
            if t_max[tx] >= 0:
                lo = min(max(2 * t_min[tx] - margin, 0), n_disp - 1)
                hi = min(max(2 * t_max[tx] + margin + 1, 1), n_disp)
                own_lo[ty, tx] = lo
                own_hi[ty, tx] = max(hi, lo + 1)
    # each tile's band: the hull over itself and the eight tiles around it
    t_lo = own_lo.copy()
    t_hi = own_hi.copy()
    for ty in range(nty):
        for tx in range(ntx):
            for yy in range(max(ty - 1, 0), min(ty + 1, nty - 1) + 1):
                for xx in range(max(tx - 1, 0), min(tx + 1, ntx - 1) + 1):
                    t_lo[ty, tx] = min(t_lo[ty, tx], own_lo[yy, xx])
                    t_hi[ty, tx] = max(t_hi[ty, tx], own_hi[yy, xx])
    # Runs of columns with the same tiles (own and within the halo) have the same bands
    # in a row: per row the stored band of each run and the row's cells first, then the
    # bands and offsets written once per pixel, instead of a second pass over the
    # stored bands for the offsets (issue 10: 2 threads, A/B on the pipeline's inputs,
    # finest level: 720p road pair 3.16 -> 2.50 ms CPU, KITTI 1.83 -> 1.49 ms).
    seg = np.empty(w + 1, np.int64)  # run k: columns seg[k] .. seg[k + 1] - 1
    n_seg = 0
    for u in range(w):
        if u == 0 or col_tx0[u] != col_tx0[u - 1] or col_tx1[u] != col_tx1[u - 1] or col_tx[u] != col_tx[u - 1]:
            seg[n_seg] = u
            n_seg += 1
    seg[n_seg] = w
    seg_lo = np.empty((h, n_seg), np.int64)
    seg_hi = np.empty((h, n_seg), np.int64)
    row_cells = np.zeros(h + 1, np.int64)
    for v in prange(h):
        ty0 = min(max((v - halo) // tile, 0), nty - 1)
        ty1 = min(max((v + halo) // tile, 0), nty - 1)
        ty = v // tile
        total = 0
        for k in range(n_seg):
            u = seg[k]
            tx = col_tx[u]
            s_lo = t_lo[ty, tx]
            s_hi = t_hi[ty, tx]
            for yy in range(ty0, ty1 + 1):
                for xx in range(col_tx0[u], col_tx1[u] + 1):
                    s_lo = min(s_lo, t_lo[yy, xx])
                    s_hi = max(s_hi, t_hi[yy, xx])
            seg_lo[v, k] = s_lo
            seg_hi[v, k] = s_hi
            total += (s_hi - s_lo) * (seg[k + 1] - u)
        row_cells[v + 1] = total
    for v in range(h):
        row_cells[v + 1] += row_cells[v]
    store = np.empty((h, w, 3), np.int32)
    visible = np.empty((h, w, 3), np.int32)
    # The visible bands with streaming stores (_store_nt): they are read only after the
    # level's cost and aggregation, which evict them anyway (issue 10: finest level, 2
    # threads, A/B on the pipeline's inputs: 720p road pair 2.22 -> 2.02 ms CPU, KITTI
    # 1.21 -> 1.11 ms); the stored ones go to the NCC next, from the caches.
    for v in prange(h):  # the cells are packed pixel after pixel
        ty = v // tile
        base = row_cells[v]
        sv = store[v]
        vf = visible[v].reshape(-1)
        for k in range(n_seg):
            u0 = seg[k]
            u1 = seg[k + 1]
            s_lo = seg_lo[v, k]
            s_hi = seg_hi[v, k]
            tx = col_tx[u0]
            v_lo = t_lo[ty, tx]
            v_hi = t_hi[ty, tx]
            size = s_hi - s_lo
            off = base - s_lo - u0 * size  # pixel u's offset: off + u size
            for u in range(u0, u1):
                o = off + u * size
                sv[u, 0] = o
                sv[u, 1] = s_lo
                sv[u, 2] = s_hi
                _store_nt(vf, UINT(3 * u), o)
                _store_nt(vf, UINT(3 * u + 1), v_lo)
                _store_nt(vf, UINT(3 * u + 2), v_hi)
            base += size * (u1 - u0)
        _store_fence()
    return store, visible, row_cells[h]


# ----------------------------------------------------------------------------- matching cost (step 2)
def ncc_cost_volume(left, right, max_disparity, window, min_variance, index=None):
    """NCC cost volume ``(1 - NCC) / 2`` with box sums (DESIGN step 2).

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
    h, w = left.shape
    n_disp = int(max_disparity) + 1
    dense = index is None
    if dense:
        index = dense_index(h, w, n_disp)
    n_cells = int(index[-1, -1, 0]) + int(index[-1, -1, 2])
    flat = _ncc_banded(left, right, index, n_disp, n_cells, int(window), float(min_variance), numba.get_num_threads())
    return _pack(flat, index, n_disp, (h, w, n_disp) if dense else None)


@njit(parallel=True, cache=True, error_model="numpy")
def _ncc_banded(left, right, index, n_disp, n_cells, window, min_variance, n_threads):
    h, w = left.shape
    r = window // 2
    ii_l, ii_ll, ii_r, ii_rr, bits = _integral_images(left, right)
    max_row = _row_layout(index)[1]  # the most cells of a row
    cost = np.empty(n_cells, np.float32)
    # The rows are cut into blocks, one prange task each; inside a block acc is a running
    # sum along the rows (add the row entering the window, subtract the one leaving it),
    # and along a row the window sum over columns slides too, so the work per cell does
    # not grow with the window (issue 10 item 2).  acc holds, per column, only the
    # disparities some pixel within the window radius needs (the hull of their bands).
    # float64 keeps the add/subtract drift far below the 1e-5 cost tolerance (values
    # <= 255^2 * window^2; float32 sums drift by more than that: measured, see tests).
    block = NCC_BLOCK_ROWS
    if bits <= 36 and (2 * r + 2) ** 2 <= 2 ** (36 - bits):
        # Grey levels up to 255 that are multiples of 2^-kl (left) and 2^-kr (right) have
        # products that are multiples of 2^-(kl + kr) below 2^16; every sum here (acc,
        # the window sums, their slides) holds fewer than (2r + 2)^2 of them, so below
        # 2^53 units of 2^-(kl + kr) all are exact in float64: they do not depend on
        # where the blocks start, and fewer, taller blocks fill fewer window rows anew
        # (issue 10: the 720p road pair, window 25, left 8-bit and right PT-warped, 2
        # threads, A/B on the pipeline's inputs: level 0 32.6 -> 31.0 ms CPU, level 1
        # 7.4 -> 6.6 ms; KITTI's grey levels from colour fail the test in the first row).
        block = max(block, h // (NCC_EXACT_TASKS * n_threads))  # (numba's get_num_threads here: no caching)
    n_blocks = (h + block - 1) // block
    for b in prange(n_blocks):
        vb0 = b * block
        vb1 = min(h, vb0 + block)
        acc_lo, acc_hi = _block_hull(index, vb0, vb1, n_disp, r)
        # acc[u, d]: column sum over the window rows of L(y, u) R(y, u - d)
        acc = np.zeros((w, n_disp), np.float64)
        win = np.zeros(n_disp, np.float64)
        ml = np.zeros(w, np.float64)  # window means and variances per column (left, right)
        vl = np.zeros(w, np.float64)
        mr = np.zeros(w, np.float64)
        vr = np.zeros(w, np.float64)
        num = np.zeros(max_row, np.float64)  # per cell of a row: NCC numerator, denominator^2
        den = np.zeros(max_row, np.float64)
        r_in = np.empty(w, np.float64)  # a right row reversed, float64 (_add_row_products)
        r_out = np.empty(w, np.float64)
        for y in range(max(0, vb0 - r), min(h - 1, vb0 + r) + 1):
            _add_row_products(acc, acc_lo, acc_hi, left, right, y, -1, r_in, r_out)
        for v in range(vb0, vb1):
            if v > vb0:
                y_in = v + r if v + r <= h - 1 else -1
                y_out = v - r - 1 if v - r - 1 >= 0 else -1
                if y_in >= 0 or y_out >= 0:
                    _add_row_products(acc, acc_lo, acc_hi, left, right, y_in, y_out, r_in, r_out)
            _ncc_row(cost, index, v, acc, win, ml, vl, mr, vr, num, den, ii_l, ii_ll, ii_r, ii_rr, h, w, r,
                     min_variance)
    return cost


@njit(cache=True, error_model="numpy")
def _block_hull(index, vb0, vb1, n_disp, r):
    """``(acc_lo, acc_hi)``, int64 (W,): per column u the hull of the bands of rows
    vb0 .. vb1 - 1 over the columns within r of u (every disparity some window over u
    needs), cut at u + 1 (d > u: the right pixel is outside the image).

    Branch-free over the bands, then one pass per column offset over contiguous columns
    (vectorised) instead of a 2r + 1 loop per column; min and max are exact, so the
    hull is the same.  Issue 10: all blocks of level 0, one thread, A/B on the
    pipeline's inputs: 720p road pair 2.70 -> 2.29 ms, KITTI 0.41 -> 0.33 ms.
    """
    w = index.shape[1]
    col_lo = np.full(w, n_disp, np.int64)
    col_hi = np.zeros(w, np.int64)
    for v in range(vb0, vb1):  # row by row, index in memory order
        for u in range(w):
            lo = np.int64(index[v, u, 1])
            hi = np.int64(index[v, u, 2])
            empty = hi <= lo
            col_lo[u] = min(col_lo[u], n_disp if empty else lo)
            col_hi[u] = max(col_hi[u], 0 if empty else hi)
    acc_lo = np.full(w, n_disp, np.int64)
    acc_hi = np.zeros(w, np.int64)
    for k in range(-r, r + 1):  # column u + k, for the u that have it
        for u in range(max(0, -k), min(w, w - k)):
            acc_lo[UINT(u)] = min(acc_lo[UINT(u)], col_lo[UINT(u + k)])
            acc_hi[UINT(u)] = max(acc_hi[UINT(u)], col_hi[UINT(u + k)])
    for u in range(w):
        acc_hi[u] = min(acc_hi[u], u + 1)
    return acc_lo, acc_hi


@njit(cache=True, error_model="numpy")
def _reversed_row(img, y, out):
    """``out[k] = img[y, w - 1 - k]`` as float64."""
    w = out.shape[0]
    src = img[y]
    for k in range(w):
        out[k] = np.float64(src[w - 1 - k])


@njit(cache=True, error_model="numpy")
def _add_row_products(acc, acc_lo, acc_hi, left, right, y_in, y_out, r_in, r_out):
    """acc[u, d] += L(y_in, u) R(y_in, u - d), then acc[u, d] -= L(y_out, u) R(y_out, u - d),
    for every u and acc_lo[u] <= d < acc_hi[u]; a row < 0 is left out.

    One pass over acc for the row entering the window and the row leaving it, each cell
    rounded after each of the two terms as two passes would (``(a + x) + (-y)``, no
    fused multiply-add), so the sums are the same bits.  The right rows are read
    reversed (``R(y, u - d)`` with d rising), so they are first copied reversed into
    ``r_in``, ``r_out`` and both operands run forward (vectorises).  Issue 10: with the
    in-place integral images, NCC CPU time (2 threads, captured inputs) at level 0 of
    KITTI 74 -> 59 ms, Middlebury-Q 51 -> 41 ms, the 720p road pair 64 -> 52 ms.
    """
    w = acc.shape[0]
    if y_in >= 0:
        _reversed_row(right, y_in, r_in)
    if y_out >= 0:
        _reversed_row(right, y_out, r_out)
    acc_w = acc.shape[1]
    accf = acc.reshape(-1)  # flat, unsigned subscripts: as in _ncc_row
    for u in range(w):
        lo = acc_lo[u]
        n = acc_hi[u] - lo
        if n <= 0:
            continue
        o = u * acc_w + lo  # acc[u, lo] in accf
        k = w - 1 - u + lo  # R(y, u - lo - i) = r_in[k + i]
        if y_out < 0:
            a = np.float64(left[y_in, u])
            for i in range(n):
                accf[UINT(o + i)] += a * r_in[UINT(k + i)]
        elif y_in < 0:
            b = -np.float64(left[y_out, u])
            for i in range(n):
                accf[UINT(o + i)] += b * r_out[UINT(k + i)]
        else:
            a = np.float64(left[y_in, u])
            b = -np.float64(left[y_out, u])
            for i in range(n):
                accf[UINT(o + i)] = (accf[UINT(o + i)] + a * r_in[UINT(k + i)]) + b * r_out[UINT(k + i)]


@njit(cache=True, error_model="numpy")
def _window_stats(ii, ii2, v0, v1, r, inv, mean, var):
    """Mean and variance of the unclipped windows (columns c - r .. c + r, rows v0 .. v1)
    of one image, for every column c with such a window: ``mean[c], var[c]``.

    The box sums are :func:`_box_sum`'s expression ``ii[r1+1, c1+1] - ii[r0, c1+1] -
    ii[r1+1, c0] + ii[r0, c0]`` and the moments :func:`pixel.ncc_cost`'s (``s inv``,
    ``ss inv - m m``), so the values are bit for bit those the formula computed per
    cell; written over slices (non-negative subscripts) the loop vectorises (issue 10:
    the per-column box sums took a third of the NCC time at level 1 of Middlebury-Q).
    """
    m = ii.shape[1] - 1 - 2 * r  # columns with an unclipped window
    if m <= 0:
        return
    a1 = ii[v1 + 1, 2 * r + 1:2 * r + 1 + m]
    b1 = ii[v0, 2 * r + 1:2 * r + 1 + m]
    c1 = ii[v1 + 1, 0:m]
    d1 = ii[v0, 0:m]
    a2 = ii2[v1 + 1, 2 * r + 1:2 * r + 1 + m]
    b2 = ii2[v0, 2 * r + 1:2 * r + 1 + m]
    c2 = ii2[v1 + 1, 0:m]
    d2 = ii2[v0, 0:m]
    mean_c = mean[r:r + m]
    var_c = var[r:r + m]
    for i in range(m):
        s = a1[i] - b1[i] - c1[i] + d1[i]
        ss = a2[i] - b2[i] - c2[i] + d2[i]
        mu = s * inv
        mean_c[i] = mu
        var_c[i] = ss * inv - mu * mu


@njit(cache=True, error_model="numpy")
def _unclipped_end(u, lo, hi, r, w):
    """``d_fast``: the band's disparities ``lo <= d < d_fast`` of pixel u have neither
    window clipped (left window inside the image, right window at u - d too)."""
    d_fast = min(hi, u - r + 1) if u + r <= w - 1 else lo
    return max(d_fast, lo)


@njit(cache=True, error_model="numpy")
def _ncc_row(cost, index, v, acc, win, ml, vl, mr, vr, num, den, ii_l, ii_ll, ii_r, ii_rr, h, w, r, min_variance):
    """Costs of the bands of row v from the window-row column sums ``acc``.

    ``win[d]`` is the window sum of ``acc`` over the columns u - r .. u + r; it slides
    from column to column while the band stays the same and the window is not clipped,
    and is summed afresh otherwise.  The window means and variances of unclipped windows
    are computed once per column (:func:`_window_stats`), not once per cell.  The cells
    of unclipped windows are done in two passes over the row: the first leaves each
    cell's numerator ``slr / n - m_l m_r`` and ``v_l v_r`` (-1: a flat window) in the
    row buffers ``num``, ``den``; the second, one loop over the row's contiguous cells,
    takes the square root and the division (a band of 5-7 cells is shorter than a
    vector; a row of cells is not: NCC at level 1 of the 720p road pair 0.071 -> 0.062 s
    CPU).  Operation for operation this is :func:`pixel.ncc_cost`, so the values are the
    same bits.  Cells of clipped windows (the image borders) get their ``num``, ``den``
    from their own box sums (:func:`_clipped_terms`) before that second pass.
    """
    v0 = max(0, v - r)
    v1 = min(h - 1, v + r)
    n_full = (v1 - v0 + 1) * (2 * r + 1)
    inv = 1.0 / n_full
    _window_stats(ii_l, ii_ll, v0, v1, r, inv, ml, vl)
    _window_stats(ii_r, ii_rr, v0, v1, r, inv, mr, vr)
    start = index[v, 0, 0] + index[v, 0, 1]  # the row's cells: cost[start:start + n_row]
    n_row = 0
    clipped = False
    run_lo = 0
    run_hi = -1  # no running window sum yet
    acc_w = acc.shape[1]
    accf = acc.reshape(-1)
    for u in range(w):
        off = index[v, u, 0]
        lo = index[v, u, 1]
        hi = index[v, u, 2]
        n_row += max(hi - lo, 0)
        d_fast = _unclipped_end(u, lo, hi, r, w)
        if d_fast < hi:
            clipped = True
        if d_fast > lo:
            # flat subscripts cast to unsigned (known >= 0): no negative-index wraparound,
            # so the loops vectorise, and no slice objects per pixel, whose set-up cost
            # more than the 5-40 cells of a band (issue 10: NCC at level 0 of the road
            # pair 52.0 -> 47.7 ms of one thread, KITTI 59.0 -> 57.3 ms)
            n = d_fast - lo
            ea = (u + r) * acc_w + lo  # acc[u + r, lo] in accf
            la = (u - r - 1) * acc_w + lo
            o = off + lo - start
            if run_lo == lo and run_hi == d_fast and u > r and n <= NCC_NARROW:
                # a narrow band: slide and the cell's terms in one loop, the same operations
                # (issue 10: two loops over 5-8 cells barely vectorise, and one costs less;
                # NCC at level 0 of the road pair 51.9 -> 46.9 ms of one thread; on wide
                # bands one loop is slower, KITTI's 37 cells 56.7 -> 60.0 ms)
                ml_u = ml[u]
                vl_u = vl[u]
                for i in range(n):  # slide by one column
                    t = win[UINT(lo + i)] + (accf[UINT(ea + i)] - accf[UINT(la + i)])
                    win[UINT(lo + i)] = t
                    x = UINT(u - lo - i)  # the right window of d = lo + i sits at column u - d
                    vr_x = vr[x]
                    num[UINT(o + i)] = t * inv - ml_u * mr[x]
                    den[UINT(o + i)] = vl_u * vr_x if (vl_u > min_variance and vr_x > min_variance) else -1.0
                continue
            if run_lo == lo and run_hi == d_fast and u > r:
                for i in range(n):  # slide by one column
                    win[UINT(lo + i)] += accf[UINT(ea + i)] - accf[UINT(la + i)]
            else:
                for i in range(n):
                    win[UINT(lo + i)] = 0.0
                for c in range(u - r, u + r + 1):
                    ca = c * acc_w + lo
                    for i in range(n):
                        win[UINT(lo + i)] += accf[UINT(ca + i)]
            run_lo = lo
            run_hi = d_fast
            ml_u = ml[u]
            vl_u = vl[u]
            for i in range(n):
                x = UINT(u - lo - i)  # the right window of d = lo + i sits at column u - d
                vr_x = vr[x]
                num[UINT(o + i)] = win[UINT(lo + i)] * inv - ml_u * mr[x]
                den[UINT(o + i)] = vl_u * vr_x if (vl_u > min_variance and vr_x > min_variance) else -1.0
        else:
            run_hi = -1
    if clipped:
        _clipped_terms(index, v, acc, num, den, start, ii_l, ii_ll, ii_r, ii_rr, v0, v1, w, r, min_variance)
    out = cost[start:start + n_row]
    for j in range(n_row):
        den_j = den[j]
        ncc = num[j] / np.sqrt(den_j)
        if ncc > 1.0:
            ncc = 1.0
        elif ncc < -1.0:
            ncc = -1.0
        out[j] = 0.5 * (1.0 - ncc) if den_j >= 0.0 else 1.0  # a flat window: NCC undefined


@njit(cache=True, error_model="numpy")
def _clipped_terms(index, v, acc, num, den, start, ii_l, ii_ll, ii_r, ii_rr, v0, v1, w, r, min_variance):
    """``num``, ``den`` of row v's cells of clipped windows (the image borders), for
    :func:`_ncc_row`'s pass over the row: den -1 where u - d < 0 or a window is flat.

    Operation for operation :func:`pixel.ncc_window_cost` up to the square root and the
    division, which the row's pass does for them too (issue 10: done per cell, serially,
    after that pass, these cells took 7.3 ms of one thread at level 0 of the road pair,
    window 25; now 4.8 ms).  Each window sum of L*R is summed up from 0 over its columns
    as before: summing column by column over a pixel's cells (one vector loop per
    column) measured slower on these 5-20 cell bands.
    """
    n_disp = acc.shape[1]
    # Where the window starts at column d (c0 = d: clipped by the right image's edge),
    # the sum over columns d .. c1 is the one over d .. c1' < c1 of a pixel before it
    # (c1 grows with u) continued: the same additions in the same order, so it is kept
    # per disparity and continued instead of summed afresh (issue 10: with _block_hull,
    # NCC at level 0 of the 720p road pair, window 25, 2 threads, A/B on the pipeline's
    # inputs: 33.4 -> 32.0 ms CPU; KITTI's window 5 gains within noise).
    run_c1 = np.full(n_disp, -1, np.int64)  # the last column summed into run_slr[d], -1: none
    run_slr = np.empty(n_disp, np.float64)
    for u in range(w):
        off = index[v, u, 0] - start
        lo = index[v, u, 1]
        hi = index[v, u, 2]
        c1 = min(u + r, w - 1)
        for d in range(_unclipped_end(u, lo, hi, r, w), hi):
            if u - d < 0:
                den[off + d] = -1.0
                continue
            c0 = max(u - r, d)
            if c0 == d:
                c = run_c1[d] + 1
                slr = run_slr[d]
                if c == 0:
                    c = d
                    slr = 0.0
                for c in range(c, c1 + 1):
                    slr += acc[c, d]
                run_c1[d] = c1
                run_slr[d] = slr
            else:
                slr = 0.0
                for c in range(c0, c1 + 1):
                    slr += acc[c, d]
            inv = 1.0 / ((v1 - v0 + 1) * (c1 - c0 + 1))
            ml = _box_sum(ii_l, v0, c0, v1, c1) * inv
            mr = _box_sum(ii_r, v0, c0 - d, v1, c1 - d) * inv
            vl = _box_sum(ii_ll, v0, c0, v1, c1) * inv - ml * ml
            vr = _box_sum(ii_rr, v0, c0 - d, v1, c1 - d) * inv - mr * mr
            num[off + d] = slr * inv - ml * mr
            den[off + d] = vl * vr if (vl > min_variance and vr > min_variance) else -1.0


def cosine_cost_volume(fl, fr, nl, nr, max_disparity, index=None):
    """Deep-feature cost volume ``(1 - cos) / 2`` of one level (DESIGN step 2, features).

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
    h, w = nl.shape
    n_disp = int(max_disparity) + 1
    dense = index is None
    if dense:
        index = dense_index(h, w, n_disp)
    n_cells = int(index[-1, -1, 0]) + int(index[-1, -1, 2])
    flat = _cosine_banded(fl, fr, nl, nr, index, n_cells)
    return _pack(flat, index, n_disp, (h, w, n_disp) if dense else None)


@njit(parallel=True, cache=True, error_model="numpy")
def _cosine_banded(fl, fr, nl, nr, index, n_cells):
    h, w = nl.shape
    cost = np.empty(n_cells, np.float32)
    for v in prange(h):
        for u in range(w):
            off = index[v, u, 0]
            for d in range(index[v, u, 1], index[v, u, 2]):
                cost[off + d] = _cosine_cost(fl, fr, nl, nr, v, u, d)
    return cost


def invalidate_out_of_view(cost):
    """Set every cell whose right pixel u - d is outside the image back to 1, in place.

    Aggregation averages such cells with valid neighbours and pulls them below 1; reset
    after it, they keep their meaning: no match, never a winner (DESIGN step 2).
    Returns ``cost`` (a Volume or an (H, W, D) array).
    """
    flat, index, n_disp, _ = _unpack(cost)
    _invalidate(flat, index, int(n_disp))
    return cost


@njit(parallel=True, cache=True, error_model="numpy")
def _invalidate(cost, index, n_disp):
    h, w, _ = index.shape
    for v in prange(h):
        for u in range(min(w, n_disp)):  # d > u only where u < n_disp - 1
            off = index[v, u, 0]
            for d in range(max(index[v, u, 1], u + 1), index[v, u, 2]):
                cost[UINT(off + d)] = 1.0  # unsigned: no wraparound test, the loop vectorises


# ----------------------------------------------------------------------------- aggregation (step 3)
#: Grey-level steps 4^-k, k < this, that rbf_weights recognises (the first four pyramid
#: levels of an 8-bit image: 2x2 means of 2x2 means of integers).
GREY_STEPS = 4


@njit(cache=True, error_model="numpy")
def _grey_scale(img):
    """``s`` in {1, 4, 16, 64} when every grey level is in [0, 255] and a multiple of
    1 / s (the smallest such s), else 0.

    Level k of the pyramid of an 8-bit image holds exact multiples of 4^-(k-1) (2x2
    means, exact in float32), so a pixel and its neighbour differ by one of 255 s + 1
    values.
    """
    scale = 1
    for k in range(GREY_STEPS):
        if _on_grid(img, scale, 0):
            return scale
        scale *= 4
    return 0


@njit(cache=True, error_model="numpy")
def _on_grid(img, scale, least):
    """Whether every value of ``img`` lies in [least, 255] and is a multiple of 1 / scale.

    Row by row, branch-free within a row (vectorised; issue 10: 0.95 -> 0.25 ms for the
    720p road image), stopping after the first row that fails.
    """
    for v in range(img.shape[0]):
        row = img[v]
        bad = 0
        for u in range(img.shape[1]):
            g = np.float64(row[u]) * scale
            bad += not ((g >= least * scale) & (g <= 255 * scale) & (g == np.floor(g)))
        if bad:
            return False
    return True


@njit(parallel=True, cache=True, error_model="numpy")
def rbf_weights(img, sigma_space, sigma_color):
    """Normalised 3x3 bilateral weights per pixel (paper eq. 3), computed once per level.

    Returns float32 (H, W, 9); slot k is the neighbour (dy, dx) = (k // 3 - 1, k % 3 - 1);
    neighbours outside the image get weight 0.
    """
    h, w = img.shape
    inv_ss2 = 1.0 / (sigma_space * sigma_space)
    inv_sc2 = 1.0 / (sigma_color * sigma_color)
    # K(p, q) = K(q, p): the kernel towards the four "forward" neighbours (slots 5..8:
    # right, below-left, below, below-right) is computed once and read back from the
    # neighbour for the mirrored slot (8 - k): half the exp calls, the same values.
    # Row by row within a block of rows, the forward kernels of a row and of the row
    # above in a two-row ring (nothing zero-filled: the kernels towards neighbours
    # outside the image are never read).  Issue 10: a row's sum, its quotients (through
    # the reciprocal, checked exact) and its float32 staging in one vectorised pass
    # instead of copies of the kernels, nine exact divisions per pixel and a staging
    # pass per slot, and the table index from float32 differences: level 0, 2 threads,
    # 720p road 7.7 -> 5.0 ms, KITTI 6.9 -> 5.6 ms, Middlebury-Q 5.6 -> 4.5 ms; the same
    # bits.
    centre = _rbf_weight(0, 0, 0.0, 0.0, inv_ss2, inv_sc2)
    # Grey levels that are all multiples of 1/s in 0..255 (an 8-bit image: s = 1 at full
    # resolution, 4, 16, 64 at the next levels) have only 255 s + 1 differences
    # |i_p - i_q|: the kernel is read from a table made with the same expression (the
    # difference and the table's argument are the same float64), so the values are the
    # same, without an exp per neighbour.  The table is built when it needs fewer exp
    # calls than the image (level 2 of a 720p pair: 2042 instead of 921,600); other
    # images compute the kernel.
    scale = _grey_scale(img)
    n_lut = 255 * scale + 1
    grey8 = scale > 0 and 2 * n_lut < 4 * h * w
    lut = np.empty((2, n_lut if grey8 else 1), np.float64)  # row 0: axis neighbours, row 1: diagonal ones
    if grey8:
        for i in range(n_lut):
            lut[0, i] = _rbf_weight(0, 1, np.float64(i) / scale, 0.0, inv_ss2, inv_sc2)
            lut[1, i] = _rbf_weight(1, 1, np.float64(i) / scale, 0.0, inv_ss2, inv_sc2)
    weights = np.empty((h, w, 9), np.float32)
    block = 32
    n_blocks = (h + block - 1) // block
    for b in prange(n_blocks):
        vb0 = b * block
        vb1 = min(h, vb0 + block)
        # forward kernels of two rows (slot-major: a row of one slot is contiguous), the
        # row above the block first (its slots towards the block only)
        ring = np.empty((2, 4, w), np.float64)
        stage = np.empty((9, w), np.float32)
        if vb0 > 0:
            _rbf_forward_row(ring[(vb0 - 1) & 1], img, vb0 - 1, 1, 4, lut, scale if grey8 else 0, inv_ss2, inv_sc2)
        for v in range(vb0, vb1):
            cur = ring[v & 1]
            _rbf_forward_row(cur, img, v, 0, 4 if v + 1 < h else 1, lut, scale if grey8 else 0, inv_ss2, inv_sc2)
            _rbf_normalise_row(weights[v], ring[(v - 1) & 1], cur, centre, v > 0, v + 1 < h, stage)
        _store_fence()  # the block's streaming stores done before the task ends
    return weights


@njit(cache=True, error_model="numpy")
def _rbf_forward_row(fwd, img, v, j0, j1, lut, scale, inv_ss2, inv_sc2):
    """``fwd[j, u]``, j0 <= j < j1: the kernel from pixel (u, v) towards its forward
    neighbour (slot 5 + j: right, below-left, below, below-right), for the u whose
    neighbour is in the image (the others are never read).  From the table ``lut`` when
    ``scale`` > 0 (grey levels multiples of 1 / scale), else from the exp."""
    w = img.shape[1]
    ip = img[v]
    for j in range(j0, j1):
        k = 5 + j
        dy = k // 3 - 1
        dx = k % 3 - 1
        iq = img[v + dy]
        dst = fwd[j]
        lo = max(0, -dx)
        hi = min(w, w - dx)
        if scale > 0:
            table = lut[dy * dx * dx]
            # float32 is exact here too (multiples of 1 / scale up to 255: 14 bits), the
            # same index as the float64 difference, on twice the lanes
            sc = np.float32(scale)
            for u in range(lo, hi):
                diff = abs(ip[UINT(u)] - iq[UINT(u + dx)]) * sc
                dst[UINT(u)] = table[UINT(np.int32(diff))]
        else:
            for u in range(lo, hi):
                dst[UINT(u)] = _rbf_weight(dy, dx, np.float64(ip[UINT(u)]), np.float64(iq[UINT(u + dx)]),
                                           inv_ss2, inv_sc2)


@njit(cache=True, error_model="numpy")
def _rbf_pixel(stage, up, cur, centre, has_up, has_down, u):
    """``stage[k, u]``, k < 9: pixel u's normalised weights, the exact expressions (for
    the border pixels and the rare rows that :func:`_rbf_interior` leaves)."""
    w = stage.shape[1]
    left = u >= 1
    right = u + 1 < w
    r0 = up[3, u - 1] if has_up and left else 0.0
    r1 = up[2, u] if has_up else 0.0
    r2 = up[1, u + 1] if has_up and right else 0.0
    r3 = cur[0, u - 1] if left else 0.0
    r5 = cur[0, u] if right else 0.0
    r6 = cur[1, u] if has_down and left else 0.0
    r7 = cur[2, u] if has_down else 0.0
    r8 = cur[3, u] if has_down and right else 0.0
    t = 0.0
    t += r0
    t += r1
    t += r2
    t += r3
    t += centre
    t += r5
    t += r6
    t += r7
    t += r8
    stage[0, u] = np.float32(r0) / t
    stage[1, u] = np.float32(r1) / t
    stage[2, u] = np.float32(r2) / t
    stage[3, u] = np.float32(r3) / t
    stage[4, u] = np.float32(centre) / t
    stage[5, u] = np.float32(r5) / t
    stage[6, u] = np.float32(r6) / t
    stage[7, u] = np.float32(r7) / t
    stage[8, u] = np.float32(r8) / t


@njit(cache=True, error_model="numpy", inline="always")
def _rbf_quotient(dst, u, r, rc):
    """``dst[u] = float32(float32(r) / t)`` from ``rc = 1 / t``; True where that is not
    certain (then ``dst[u]`` may differ by one float32 step).

    ``q = a rc`` is within 3 2^-53 q of the float64 quotient ``a / t`` (three roundings
    of 2^-53), so ``q (1 - 2^-50)`` and ``q (1 + 2^-50)`` (rounded) bracket it; float32
    rounding is monotonic, so when both round to the same float32, ``a / t`` rounds to
    it too.  The others (about 2^-26 of the weights: q within 2^-50 q of a float32
    rounding boundary) are reported.
    """
    q = np.float64(np.float32(r)) * rc
    lo = np.float32(q * (1.0 - 2.0 ** -50))
    hi = np.float32(q * (1.0 + 2.0 ** -50))
    dst[u] = hi
    return lo != hi


@njit(cache=True, error_model="numpy")
def _rbf_interior(stage, up, cur, centre, w):
    """The weights of pixels 1..W-2 of a row with rows above and below, into ``stage``;
    the number of uncertain quotients (:func:`_rbf_quotient`): the row must then be
    redone exactly.  One division per pixel (the reciprocal of the sum) instead of nine:
    the divider was the bottleneck (two cycles per float64 lane)."""
    a0 = up[3]
    a1 = up[2]
    a2 = up[1]
    c0 = cur[0]
    b6 = cur[1]
    b7 = cur[2]
    b8 = cur[3]
    bad = 0
    for u in range(1, w - 1):
        uu = UINT(u)
        r0 = a0[uu - 1]
        r1 = a1[uu]
        r2 = a2[uu + 1]
        r3 = c0[uu - 1]
        r5 = c0[uu]
        r6 = b6[uu]
        r7 = b7[uu]
        r8 = b8[uu]
        t = r0  # 0.0 + r0: the same (r0 >= 0)
        t += r1
        t += r2
        t += r3
        t += centre
        t += r5
        t += r6
        t += r7
        t += r8
        rc = 1.0 / t
        bad += _rbf_quotient(stage[0], uu, r0, rc)
        bad += _rbf_quotient(stage[1], uu, r1, rc)
        bad += _rbf_quotient(stage[2], uu, r2, rc)
        bad += _rbf_quotient(stage[3], uu, r3, rc)
        bad += _rbf_quotient(stage[4], uu, centre, rc)
        bad += _rbf_quotient(stage[5], uu, r5, rc)
        bad += _rbf_quotient(stage[6], uu, r6, rc)
        bad += _rbf_quotient(stage[7], uu, r7, rc)
        bad += _rbf_quotient(stage[8], uu, r8, rc)
    return bad


@njit(cache=True, error_model="numpy")
def _rbf_normalise_row(out, up, cur, centre, has_up, has_down, stage):
    """Row ``out`` (W, 9) of the normalised weights from the forward kernels of its own
    row (``cur``) and of the row above (``up``; ``has_up`` / ``has_down``: whether the
    rows above / below are in the image), through the slot-major ``stage`` (9, W)."""
    w = out.shape[0]
    if has_up and has_down and _rbf_interior(stage, up, cur, centre, w) == 0:
        _rbf_pixel(stage, up, cur, centre, has_up, has_down, 0)
        _rbf_pixel(stage, up, cur, centre, has_up, has_down, w - 1)
    else:
        for u in range(w):
            _rbf_pixel(stage, up, cur, centre, has_up, has_down, u)
    # Streaming stores: the weights (36 bytes a pixel, 33 MB at 720p) are read back by
    # the filter only after the rest of the level's weights, so caching them only
    # evicts the cost volume and costs a read of each line first (issue 10: 2 threads,
    # A/B on the pipeline's inputs, level 0: 720p road pair 7.40 -> 6.25 ms CPU, KITTI
    # 9.01 -> 8.33 ms; these weights and then rbf_filter on the level's NCC volume:
    # 45.7 -> 44.5 ms and 61.7 -> 60.7 ms).
    outf = out.reshape(-1)
    for u in range(w):
        for k in range(9):
            _store_nt(outf, UINT(9 * u + k), stage[k, u])


@njit(parallel=True, cache=True, error_model="numpy")
def _row_layout(index):
    """``(row_start, max_row)`` of a volume for the filter passes: the first cell of
    every row (int64 (H + 1,), cells packed row after row) and the most cells of a row
    (at least 1).  One parallel pass over the index instead of NumPy passes in the
    calling thread (issue 10)."""
    h, w, _ = index.shape
    row_start = np.zeros(h + 1, np.int64)
    for v in prange(h):
        total = 0
        for u in range(w):
            total += np.int64(index[v, u, 2]) - np.int64(index[v, u, 1])
        row_start[v + 1] = total
    max_row = 1
    for v in range(h):
        max_row = max(max_row, row_start[v + 1])
        row_start[v + 1] += row_start[v]
    return row_start, max_row


@njit(parallel=True, cache=True, error_model="numpy")
def _covered_bands(index):
    """uint8 (H, W) for the filter passes: 2 where the 3x3 neighbours (clamped at the
    border) all have the pixel's band, 1 where their bands contain it (every cell a pass
    reads exists), 0 elsewhere."""
    h, w, _ = index.shape
    out = np.empty((h, w), np.uint8)
    # Most pixels have the band of all eight neighbours.  Whether a pixel has the band of
    # both row neighbours is found once per pixel and reused by the rows above and below
    # (3.8 -> 1.5 ms at level 1 of the 720p road pair, 2 threads; the same map).  The
    # band (lo, hi) as one int64 key, so that both tests are branch-free loops over
    # contiguous rows (vectorised); only the pixels that fail them (the border columns,
    # and about 2 % at level 0) take the test of every neighbour (issue 10: 1.58 -> 0.92 ms
    # at level 0 of the 720p road pair, 2 threads; the same map).
    key = np.empty((h, w), np.int64)
    same_row = np.empty((h, w), np.bool_)
    for y in prange(h):
        ky = key[y]
        sy = same_row[y]
        for u in range(w):
            ky[u] = (np.int64(index[y, u, 2]) << 32) | (np.int64(index[y, u, 1]) & 0xFFFFFFFF)
        if w > 0:
            sy[0] = False
            sy[w - 1] = False
        for u in range(1, w - 1):
            sy[u] = (ky[u - 1] == ky[u]) & (ky[u + 1] == ky[u])
    for v in prange(h):
        ym = max(v - 1, 0)
        yp = min(v + 1, h - 1)
        k0 = key[v]
        km = key[ym]
        kp = key[yp]
        s0 = same_row[v]
        sm = same_row[ym]
        sp = same_row[yp]
        ov = out[v]
        for u in range(w):
            ov[u] = np.uint8(2) * (s0[u] & sm[u] & sp[u] & (km[u] == k0[u]) & (kp[u] == k0[u]))
        for u in range(w):
            if ov[u] == 2:
                continue
            lo = index[v, u, 1]
            hi = index[v, u, 2]
            covered = 1
            same = 2
            for y in range(ym, yp + 1):
                for x in range(max(u - 1, 0), min(u + 1, w - 1) + 1):
                    if index[y, x, 1] > lo or index[y, x, 2] < hi:
                        covered = 0
                    if index[y, x, 1] != lo or index[y, x, 2] != hi:
                        same = 1
            ov[u] = covered * same
    return out


@njit(cache=True, error_model="numpy", inline="always")
def _rbf_cells(dst, b, count, q0, q1, q2, q3, q4, q5, q6, q7, q8, wp):
    """``dst[b + i]``, i < count: the nine sources at ``b + i`` weighted by ``wp[0..8]``
    and added in slot order.  ``b`` is unsigned, so the indexes need no negative-index
    wraparound and the loop vectorises."""
    w0 = wp[0]
    w1 = wp[1]
    w2 = wp[2]
    w3 = wp[3]
    w4 = wp[4]
    w5 = wp[5]
    w6 = wp[6]
    w7 = wp[7]
    w8 = wp[8]
    for i in range(count):
        j = b + np.uint64(i)
        a = np.float32(0.0)
        a += w0 * q0[j]
        a += w1 * q1[j]
        a += w2 * q2[j]
        a += w3 * q3[j]
        a += w4 * q4[j]
        a += w5 * q5[j]
        a += w6 * q6[j]
        a += w7 * q7[j]
        a += w8 * q8[j]
        dst[j] = a


#: The widest block of :func:`_rbf_run` (six vectors of 16); the rings of
#: :func:`_rbf_passes` have this many cells more, so that a block reading past the last
#: row stays in its ring.
RBF_MAX_LANES = 96


def _splat16(builder, x, ty):
    """LLVM IR: a vector of 16 ``ty`` lanes, each ``x`` (for the vector intrinsics below)."""
    undef = ir.Constant(ir.VectorType(ty, 16), ir.Undefined)
    first = builder.insert_element(undef, x, ir.IntType(32)(0))
    return builder.shuffle_vector(first, undef, ir.Constant(ir.VectorType(ir.IntType(32), 16), [0] * 16))


@intrinsic
def _rbf_cells_vec(typingctx, dst, b, band, q0, q1, q2, q3, q4, q5, q6, q7, q8, wx, wy, wz, vectors):
    """:func:`_rbf_cells` over the ``16 vectors`` cells from ``b`` (``vectors`` a
    literal) of up to three pixels of ``band`` cells each: cell ``b + i`` with i < band
    takes the weights ``wx``, i < 2 band ``wy``, the others ``wz`` (one pixel's
    weights repeated for fewer pixels).  Same terms in the same order per cell (float32
    multiply, then add: no fused multiply-add), written as vectors of 16: LLVM's
    vectoriser leaves the loop that picks a weight per cell scalar."""
    if not isinstance(vectors, types.IntegerLiteral):
        raise errors.RequireLiteralValue("vectors")
    sources = (q0, q1, q2, q3, q4, q5, q6, q7, q8)
    n_vec = vectors.literal_value

    def codegen(context, builder, signature, args):
        f32 = ir.FloatType()
        i64 = ir.IntType(64)
        vec = ir.VectorType(f32, 16)

        def at(k, i):  # a pointer to cell i of (1D) array argument k
            ary = context.make_array(signature.args[k])(context, builder, args[k])
            return cgutils.get_item_pointer(context, builder, signature.args[k], ary, [i])

        start = context.cast(builder, args[1], signature.args[1], types.intp)
        width = context.cast(builder, args[2], signature.args[2], types.int64)
        ends = (_splat16(builder, width, i64), _splat16(builder, builder.mul(width, i64(2)), i64))
        weights = [[_splat16(builder, builder.load(at(12 + g, i64(k))), f32) for k in range(9)] for g in range(3)]
        for v in range(n_vec):
            lanes = ir.Constant(ir.VectorType(i64, 16), list(range(16 * v, 16 * v + 16)))
            first = builder.icmp_signed("<", lanes, ends[0])
            second = builder.icmp_signed("<", lanes, ends[1])
            j = builder.add(start, i64(16 * v))
            a = ir.Constant(vec, [0.0] * 16)
            for k in range(9):
                w = builder.select(first, weights[0][k], builder.select(second, weights[1][k], weights[2][k]))
                q = builder.load(builder.bitcast(at(3 + k, j), vec.as_pointer()), align=4)
                a = builder.fadd(a, builder.fmul(w, q))
            builder.store(a, builder.bitcast(at(0, j), vec.as_pointer()), align=4)
        return context.get_dummy_value()

    return types.void(dst, b, band, *sources, wx, wy, wz, vectors), codegen


@intrinsic
def _rbf_cells_borrowing(typingctx, out, d0, ring, own, nbr, weights, v, u, c0, band):
    """Cells ``c0 .. c0 + 15`` (those below ``band``) of a pixel whose neighbours lack
    some of its disparities: ``out[d0 + c]`` from the 3x3 neighbours' cells, neighbour k
    at ``ring[nbr[3k] + c]`` for ``nbr[3k + 1] <= c < nbr[3k + 2]``, the pixel's own
    cell ``ring[own + c]`` elsewhere, weighted by ``weights[v, u, k]`` and added in slot
    order (float32 multiply, then add).  Masked loads and a masked store: no cell
    outside the bands is read, none past the pixel written."""

    def codegen(context, builder, signature, args):
        f32 = ir.FloatType()
        i64 = ir.IntType(64)
        vec = ir.VectorType(f32, 16)
        ivec = ir.VectorType(i64, 16)
        bits = ir.VectorType(ir.IntType(1), 16)
        ring_t, out_t, nbr_t, weights_t = signature.args[2], signature.args[0], signature.args[4], signature.args[5]
        ring_ary = context.make_array(ring_t)(context, builder, args[2])
        out_ary = context.make_array(out_t)(context, builder, args[0])
        nbr_ary = context.make_array(nbr_t)(context, builder, args[4])
        weights_ary = context.make_array(weights_t)(context, builder, args[5])

        def as_i64(k):
            return context.cast(builder, args[k], signature.args[k], types.int64)

        ptr_t = ring_ary.data.type
        load = cgutils.get_or_insert_function(builder.module, ir.FunctionType(vec, [ptr_t, ir.IntType(32), bits, vec]),
                                              "llvm.masked.load.v16f32.p0")
        store = cgutils.get_or_insert_function(builder.module,
                                               ir.FunctionType(ir.VoidType(), [vec, ptr_t, ir.IntType(32), bits]),
                                               "llvm.masked.store.v16f32.p0")
        c0 = as_i64(8)
        lanes = builder.add(_splat16(builder, c0, i64), ir.Constant(ivec, list(range(16))))
        inside = builder.icmp_signed("<", lanes, _splat16(builder, as_i64(9), i64))
        zero = ir.Constant(vec, [0.0] * 16)
        own_cells = builder.call(load, [builder.gep(ring_ary.data, [builder.add(as_i64(3), c0)]), ir.IntType(32)(4),
                                        inside, zero])
        a = zero
        for k in range(9):
            at, lo_k, hi_k = (builder.load(cgutils.get_item_pointer(context, builder, nbr_t, nbr_ary, [i64(3 * k + j)]))
                              for j in range(3))
            theirs = builder.and_(builder.icmp_signed(">=", lanes, _splat16(builder, lo_k, i64)),
                                  builder.icmp_signed("<", lanes, _splat16(builder, hi_k, i64)))
            cells = builder.call(load, [builder.gep(ring_ary.data, [builder.add(at, c0)]), ir.IntType(32)(4),
                                        builder.and_(theirs, inside), own_cells])
            wk = builder.load(cgutils.get_item_pointer(context, builder, weights_t, weights_ary,
                                                       [as_i64(6), as_i64(7), i64(k)]))
            a = builder.fadd(a, builder.fmul(_splat16(builder, wk, f32), cells))
        builder.call(store, [a, builder.gep(out_ary.data, [builder.add(as_i64(1), c0)]), ir.IntType(32)(4), inside])
        return context.get_dummy_value()

    return types.void(out, d0, ring, own, nbr, weights, v, u, c0, band), codegen


@njit(cache=True, error_model="numpy", inline="always")
def _rbf_groups(dst, q0, q1, q2, q3, q4, q5, q6, q7, q8, wr, band, room, group, vectors):
    """:func:`_rbf_run` with blocks of ``16 vectors`` cells that hold ``group`` pixels
    (literals; ``group band <= 16 vectors``)."""
    m = wr.shape[0]
    lanes = 16 * vectors
    step = group * band
    n_fast = min(m // group, (room - lanes) // step + 1) if room >= lanes else 0
    b = np.uint64(0)
    for g in range(n_fast):
        p = g * group
        _rbf_cells_vec(dst, b, band, q0, q1, q2, q3, q4, q5, q6, q7, q8, wr[p], wr[p + (group > 1)],
                       wr[p + group - 1], vectors)
        b += np.uint64(step)
    p_fast = min(m, (room - lanes) // band + 1) if room >= lanes else 0
    for p in range(n_fast * group, p_fast):
        _rbf_cells_vec(dst, b, band, q0, q1, q2, q3, q4, q5, q6, q7, q8, wr[p], wr[p], wr[p], vectors)
        b += np.uint64(band)
    for p in range(max(n_fast * group, p_fast), m):
        _rbf_cells(dst, b, band, q0, q1, q2, q3, q4, q5, q6, q7, q8, wr[p])
        b += np.uint64(band)


@njit(cache=True, error_model="numpy")
def _rbf_run(out, d0, ring, o0, o1, o2, o3, o4, o5, o6, o7, o8, weights, v, u0, u1, band, room):
    """New values of a run of pixels u0 .. u1 - 1 of row v with one band B: cell (p, i)
    is ``out[d0 + p B + i]``, from the sources ``ring[ok + p B + i]`` (k = 0 .. 8)
    weighted by ``weights[v, u0 + p, k]``; ``room`` cells of ``out`` from ``d0`` (to the
    end of the row) may be written.  It takes the arrays and offsets, not slices of
    them: a slice passed to a function costs reference counting, and the covered pixels
    outside the runs call it for one pixel each (KITTI's finest level, 1 thread, CPU
    time of the passes: 39.6 ms before they did; 49.8 ms with slices, 35.5 ms with
    offsets).

    A loop over the B cells of a pixel vectorises only where it is long, and the bands
    are 4-130 wide (PT bands: 4-16).  The cells are computed in blocks of one to six
    vectors of 16 (:func:`_rbf_cells_vec`, 16 .. 96 cells) instead: a block holds one
    pixel, or two or three pixels of a narrow band (each cell with its own pixel's
    weights), so that a band of 5 fills 15 lanes of a vector instead of 5.  The cells of
    a block past its pixels are the next pixels' of the row: they are computed
    afterwards and overwrite them (the sources' cells past the run are read, and
    dropped).  The pixels at the end of the row, whose block would leave it, and bands
    over 96 take the plain loop.  Same terms in the same order per cell, so the same
    values.  Measured (issue 10; the passes, 1 thread, level 0 .. coarsest): road 63 ->
    50, 27 -> 16, 6.8 -> 4.3 ms; KITTI 88 -> 78, 19 -> 17, 4.8 -> 3.2 ms (blocks of one
    pixel, LLVM's vectoriser); on the finest level's volume, A/B in one process, CPU
    time: road 30.1 -> 20.6 ms, KITTI 46.4 -> 39.6 ms (these vectors and groups).
    Each (pixels, vectors) pair below is compiled on its own: a cold first call
    compiles the passes in 14 s without them, 41 s with nine, 35 s with these eight
    (bands of 9 and 10, rare, go one pixel a vector).
    """
    dst = out[d0:d0 + room]
    q0 = ring[o0:o0 + room]
    q1 = ring[o1:o1 + room]
    q2 = ring[o2:o2 + room]
    q3 = ring[o3:o3 + room]
    q4 = ring[o4:o4 + room]
    q5 = ring[o5:o5 + room]
    q6 = ring[o6:o6 + room]
    q7 = ring[o7:o7 + room]
    q8 = ring[o8:o8 + room]
    wr = weights[v, u0:u1]
    if band <= 5:
        _rbf_groups(dst, q0, q1, q2, q3, q4, q5, q6, q7, q8, wr, band, room, 3, 1)
    elif band <= 8:
        _rbf_groups(dst, q0, q1, q2, q3, q4, q5, q6, q7, q8, wr, band, room, 2, 1)
    elif band <= 16:
        _rbf_groups(dst, q0, q1, q2, q3, q4, q5, q6, q7, q8, wr, band, room, 1, 1)
    elif band <= 24:
        _rbf_groups(dst, q0, q1, q2, q3, q4, q5, q6, q7, q8, wr, band, room, 2, 3)
    elif band <= 32:
        _rbf_groups(dst, q0, q1, q2, q3, q4, q5, q6, q7, q8, wr, band, room, 1, 2)
    elif band <= 48:
        _rbf_groups(dst, q0, q1, q2, q3, q4, q5, q6, q7, q8, wr, band, room, 1, 3)
    elif band <= 64:
        _rbf_groups(dst, q0, q1, q2, q3, q4, q5, q6, q7, q8, wr, band, room, 1, 4)
    elif band <= 96:
        _rbf_groups(dst, q0, q1, q2, q3, q4, q5, q6, q7, q8, wr, band, room, 1, 6)
    else:
        b = np.uint64(0)
        for p in range(wr.shape[0]):
            _rbf_cells(dst, b, band, q0, q1, q2, q3, q4, q5, q6, q7, q8, wr[p])
            b += np.uint64(band)


@njit(cache=True, error_model="numpy")
def _rbf_row(out, shift, v, ring, ra, rh, rb, row_start, index, covered, run_end, weights):
    """New values of row v, written into ``out`` (cell ``(v, u, d)`` at ``out[shift +
    off + d]``: the volume itself with ``shift`` 0, or a ring row), from the old rows
    v - 1, v, v + 1 (clamped at the image border) held in ``ring`` rows ``ra``, ``rh``,
    ``rb``.

    ``ring`` is flat (one source array of layout C: the loops vectorise) and ``ra``,
    ``rh``, ``rb`` are the starts of the rows in it: cell (y, x, d) of an old row is
    ``ring[r + index[y, x, 0] + d - row_start[y]]``.  The
    nine terms are added in slot order k = 0..8 in float32.  Neighbours outside the image
    have weight 0 and read a clamped, in-image cell: adding +0.0 leaves the
    (non-negative) sum unchanged, so the result is the same as skipping them.  Where
    every neighbour's band contains the pixel's (``covered``: all but thin lines along
    the tile borders) :func:`_rbf_run` does it, for a run of pixels at once where their
    neighbours all have their band (``run_end``, :func:`_run_ends`: the end of each
    run), else for the pixel alone.  Elsewhere, where a
    neighbour's band lacks a disparity of the pixel's band, the pixel's own cell stands
    in (:func:`_rbf_cells_borrowing`, vectors of 16 cells; KITTI's finest level, 1
    thread, CPU time of the passes: 35.5 -> 30.5 ms against a scalar loop per slot and
    part of the band, road 20.4 -> 18.0 ms): the bands are built (:mod:`d3cli.method.band`) so that
    this never happens for a cell the later steps read, it only keeps the halo cells
    finite.
    """
    h, w, _ = index.shape
    ym = max(v - 1, 0)
    yp = min(v + 1, h - 1)
    sh_a = row_start[ym]
    sh_h = row_start[v]
    sh_b = row_start[yp]
    nbr = np.empty(27, np.int64)
    u = 0
    while u < w:
        off = index[v, u, 0]
        lo = index[v, u, 1]
        hi = index[v, u, 2]
        if hi <= lo:
            u += 1
            continue
        band = hi - lo
        if covered[v, u] == 2 and 0 < u < w - 1:
            # a run of interior pixels whose neighbours all hold this band: their cells,
            # and each neighbour row's, follow one another B apart, so each of the nine
            # sources is one (m, B) view and the per-pixel work is nine weights
            # (_rbf_run)
            u1 = run_end[v, u]
            m = u1 - u
            room = row_start[v + 1] - off - lo  # the cells to the row's end
            ba = ra + index[ym, u - 1, 0] - sh_a + lo
            bh = rh + index[v, u - 1, 0] - sh_h + lo
            bb = rb + index[yp, u - 1, 0] - sh_b + lo
            _rbf_run(out, shift + off + lo, ring, ba, ba + band, ba + 2 * band, bh, bh + band, bh + 2 * band, bb,
                     bb + band, bb + 2 * band, weights, v, u, u1, band, room)
            u = u1
            continue
        o4 = off - sh_h
        if covered[v, u]:
            # one pixel, its neighbours' cells anywhere: a run of one
            xm = max(u - 1, 0)
            xp = min(u + 1, w - 1)
            o0 = ra + index[ym, xm, 0] - sh_a + lo
            o1 = ra + index[ym, u, 0] - sh_a + lo
            o2 = ra + index[ym, xp, 0] - sh_a + lo
            o3 = rh + index[v, xm, 0] - sh_h + lo
            o5 = rh + index[v, xp, 0] - sh_h + lo
            o6 = rb + index[yp, xm, 0] - sh_b + lo
            o7 = rb + index[yp, u, 0] - sh_b + lo
            o8 = rb + index[yp, xp, 0] - sh_b + lo
            room = row_start[v + 1] - off - lo
            _rbf_run(out, shift + off + lo, ring, o0, o1, o2, o3, rh + o4 + lo, o5, o6, o7, o8, weights, v, u, u + 1,
                     band, room)
            u += 1
            continue
        for k in range(9):
            y = min(max(v + k // 3 - 1, 0), h - 1)
            x = min(max(u + k % 3 - 1, 0), w - 1)
            r = ra if k < 3 else (rh if k < 6 else rb)
            # [a0, a1): the disparities the neighbour holds; its cells at disparities
            # lo .. hi - 1 would lie from nbr[3k] on
            a0 = min(max(lo, index[y, x, 1]), hi)
            a1 = max(min(hi, index[y, x, 2]), a0)
            nbr[3 * k] = r + index[y, x, 0] - row_start[y] + lo
            nbr[3 * k + 1] = a0 - lo
            nbr[3 * k + 2] = a1 - lo
        for c0 in range(0, band, 16):
            _rbf_cells_borrowing(out, shift + off + lo, ring, rh + o4 + lo, nbr, weights, v, u, c0, band)
        u += 1


@njit(cache=True, error_model="numpy")
def _run_ends(run_end, covered, index):
    """For the pixels of a row that start a run in :func:`_rbf_row` (interior,
    ``covered`` 2), the end of the run: the first pixel past it that is not interior,
    not ``covered`` 2 or has another band.  Found once per call, not once per pass and
    halo row (the passes at road level 0: 49.9 -> 43.8 ms, 1 thread)."""
    w = covered.shape[0]
    for u in range(w - 2, 0, -1):
        if covered[u] == 2:
            if (u + 1 < w - 1 and covered[u + 1] == 2 and index[u + 1, 1] == index[u, 1]
                    and index[u + 1, 2] == index[u, 2]):
                run_end[u] = run_end[u + 1]
            else:
                run_end[u] = u + 1


@njit(parallel=True, cache=True, error_model="numpy")
def _rbf_passes(cost, index, covered, weights, row_start, n_tasks, max_row, t_max):
    """``t_max`` 3x3 passes of eq. 2, in place, temporally blocked (issue 10 item 4).

    The rows are cut into ``n_tasks`` strips, one task each.  A task runs all passes
    over its strip as a wavefront: at step t it reads input row t + 1 and computes row
    t of pass 1, row t - 1 of pass 2, ..., row t - t_max + 1 of the last pass, which goes
    straight into the volume.  Each pass keeps its last three rows in a ring (the rows
    the next pass reads), so a row of the volume and of the weights is read from memory
    once for all passes instead of once per pass, and the rings stay in cache.  Pass p
    also computes the ``t_max - p`` rows beyond each end of the strip that the later
    passes need (``t_max (t_max - 1)`` extra rows per strip: few strips keep that small);
    the input rows there belong to the neighbouring tasks, which overwrite them, so
    their originals are copied before any task starts.  Every row of every pass is
    computed by :func:`_rbf_row` from the same three rows as pass-by-pass filtering
    would, so the result is the same, bit for bit (``tests/kernels``: against the NumPy
    reference and one pass at a time).  Measured on the level-1 volumes of
    ``scripts/bench_speed.py``'s cases, 2 threads, A/B in one process: road full range
    0.065 -> 0.054 s, road.yaml 0.061 -> 0.053 s, Middlebury-Q 0.033 -> 0.028 s.
    """
    h = index.shape[0]
    t = max(1, t_max)
    strip = (h + n_tasks - 1) // n_tasks
    n_strips = (h + strip - 1) // strip
    edges = np.empty((n_strips, 2 * t, max_row), np.float32)  # t rows above, t below
    run_end = np.empty(covered.shape, np.int32)
    for s in prange(n_strips):
        s0 = s * strip
        s1 = min(h, s0 + strip)
        for v in range(s0, s1):
            _run_ends(run_end[v], covered[v], index[v])
        for k in range(t):
            y = s0 - t + k
            if y >= 0:
                edges[s, k, :row_start[y + 1] - row_start[y]] = cost[row_start[y]:row_start[y + 1]]
            y = s1 + k
            if y < h:
                edges[s, t + k, :row_start[y + 1] - row_start[y]] = cost[row_start[y]:row_start[y + 1]]
    for s in prange(n_strips):
        s0 = s * strip
        s1 = min(h, s0 + strip)
        # level 0: input rows; level p: rows of pass p; row y of a level at slot y % 3;
        # zeros after the last slot for the blocks of _rbf_run that read past it
        ring = np.zeros(t * 3 * max_row + RBF_MAX_LANES, np.float32)
        y_first = max(0, s0 - t)
        y_last = min(h, s1 + t)
        for step in range(y_first - 1, s1 + t - 1):
            y = step + 1
            if y_first <= y < y_last:
                n = row_start[y + 1] - row_start[y]
                base = y % 3 * max_row
                if y < s0:
                    ring[base:base + n] = edges[s, y - (s0 - t), :n]
                elif y >= s1:
                    ring[base:base + n] = edges[s, t + y - s1, :n]
                else:  # not overwritten yet: the last pass writes row y at a later step
                    ring[base:base + n] = cost[row_start[y]:row_start[y + 1]]
            for p in range(1, t + 1):
                y = step - (p - 1)
                if y < max(0, s0 - (t - p)) or y >= min(h, s1 + (t - p)):
                    continue
                src = (p - 1) * 3 * max_row
                ra = src + max(y - 1, 0) % 3 * max_row
                rh = src + y % 3 * max_row
                rb = src + min(y + 1, h - 1) % 3 * max_row
                if p == t:
                    _rbf_row(cost, 0, y, ring, ra, rh, rb, row_start, index, covered, run_end, weights)
                else:
                    dst = p * 3 * max_row + y % 3 * max_row
                    _rbf_row(ring, dst - row_start[y], y, ring, ra, rh, rb, row_start, index, covered, run_end, weights)


#: Strips (tasks) per thread of the blocked RBF: two balance the threads, more repeat
#: the halo rows of the passes (2 per thread: 0.054 s, 8: 0.058 s on the road-full volume).
RBF_TASKS_PER_THREAD = 2


def rbf_filter(cost, weights, t_max, overwrite_input=False):
    """Recursive bilateral filtering: ``t_max`` passes of the 3x3 kernel (paper eq. 2).

    The passes run in place, row by row and all passes at once (:func:`_rbf_passes`),
    so the filter needs one volume and a few row buffers.

    Parameters
    ----------
    cost : Volume or ndarray, float32, (H, W, D)
    weights : ndarray, float32, (H, W, 9)
        From :func:`rbf_weights`.
    t_max : int
    overwrite_input : bool
        Filter ``cost`` itself (the pipeline no longer needs the raw NCC volume): one
        volume at the peak instead of two.  The result is the same.

    Returns
    -------
    Volume or ndarray, float32, (H, W, D)
        The same kind as ``cost``; ``cost``'s own array with ``overwrite_input``.
    """
    flat, index, n_disp, dense_shape = _unpack(cost)
    work = flat if overwrite_input else flat.copy()
    if t_max == 0 or work.size == 0:
        return _pack(work, index, n_disp, dense_shape)
    row_start, max_row = _row_layout(index)
    covered = _covered_bands(index)
    n_tasks = RBF_TASKS_PER_THREAD * numba.get_num_threads()
    _rbf_passes(work, index, covered, weights, row_start, n_tasks, max_row, int(t_max))
    return _pack(work, index, n_disp, dense_shape)


def bilateral_filter(cost, img, radius, sigma_space, sigma_color):
    """One pass of a plain (2 radius + 1)^2 bilateral filter over every disparity slice.

    The ablation counterpart of RBF (paper Fig. 4): same kernel as eq. 3, larger support.
    A neighbour whose band lacks the disparity contributes the pixel's own cell (as in
    :func:`rbf_filter`; never for a cell the later steps read).
    """
    flat, index, n_disp, dense_shape = _unpack(cost)
    max_band = max(1, int((index[:, :, 2] - index[:, :, 1]).max()))
    out = _bilateral(flat, index, img, int(radius), float(sigma_space), float(sigma_color), max_band)
    return _pack(out, index, n_disp, dense_shape)


@njit(parallel=True, cache=True, error_model="numpy")
def _bilateral(cost, index, img, radius, sigma_space, sigma_color, max_band):
    h, w, _ = index.shape
    inv_ss2 = 1.0 / (sigma_space * sigma_space)
    inv_sc2 = 1.0 / (sigma_color * sigma_color)
    out = np.empty_like(cost)
    for v in prange(h):
        acc = np.empty(max_band, np.float64)
        for u in range(w):
            off = index[v, u, 0]
            lo = index[v, u, 1]
            hi = index[v, u, 2]
            for i in range(hi - lo):
                acc[i] = 0.0
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
                    q_off = index[y, x, 0]
                    q_lo = index[y, x, 1]
                    q_hi = index[y, x, 2]
                    for d in range(lo, hi):
                        if q_lo <= d < q_hi:
                            acc[d - lo] += wk * cost[q_off + d]
                        else:
                            acc[d - lo] += wk * cost[off + d]
            for d in range(lo, hi):
                out[off + d] = acc[d - lo] / total
    return out


# ----------------------------------------------------------------------------- seeds (step 4)
def decisive_seeds(cost, pkrn_min, epsilon, lr_tolerance, exclusion, skip=None):
    """Sparse seed map (DESIGN step 4); int32 (H, W), -1 undecided.

    ``skip`` (int32 (H, W), optional): pixels decided there (>= 0) are not examined and
    stay -1 (the pipeline merges fresh seeds only where inheritance left a hole).
    """
    flat, index, n_disp, _ = _unpack(cost)
    has_skip = skip is not None
    if not has_skip:
        skip = np.empty((1, 1), np.int32)
    return _seeds(flat, index, n_disp, float(pkrn_min), float(epsilon), int(lr_tolerance), int(exclusion),
                  skip, has_skip)


#: :func:`_seeds` prefetches the band of the examined pixel this many ahead, and its
#: index entry twice as far ahead (the band's address is read from it).
SEED_PREFETCH = 16


@njit(parallel=True, cache=True, error_model="numpy")
def _seeds(cost, index, n_disp, pkrn_min, epsilon, lr_tolerance, exclusion, skip, has_skip):
    """:func:`pixel.seed_at` for every pixel, row by row: first test (a) (the PKRN of the
    pixel's own band) for the row's pixels that ``skip`` leaves, then test (b), the right
    view's WTA at u - d1, for the candidates.  Where the candidates are many, (b) reads
    the row's right-view WTA from a table made in one pass over the row's cells
    (:func:`_right_wta_row`) instead of scanning ``n_disp`` pixels per candidate; the
    same winners, so the same seeds.

    Test (a) runs over a list of the row's examined pixels and prefetches the band of the
    one :data:`SEED_PREFETCH` further: where inheritance decided many pixels, the bands
    left lie scattered and each waited its own cache misses.  Issue 10: finest levels,
    1 thread (CPU time), A/B on the pipeline's inputs: KITTI 12.3 -> 7.7 ms, road
    3.2 -> 2.7 ms, road-full 15.6 -> 9.7 ms.
    """
    h, w, _ = index.shape
    out = np.empty((h, w), np.int32)
    for v in prange(h):
        row = out[v]
        todo = np.empty(w, np.int32)  # the row's pixels to examine, in increasing u
        n = 0
        for u in range(w):
            row[u] = UNDECIDED
            todo[n] = u
            n += not (has_skip and skip[v, u] >= 0)
        n_cand = 0
        sparse = n < w  # a full row's bands are one stream: the hardware prefetches it
        for i in range(n):
            if sparse:
                if i + 2 * SEED_PREFETCH < n:
                    _prefetch(index, 3 * (v * w + todo[i + 2 * SEED_PREFETCH]))
                if i + SEED_PREFETCH < n:
                    _prefetch_band(cost, index, v, todo[i + SEED_PREFETCH])
            u = todo[i]
            d1 = _seed_candidate(cost, index, v, u, pkrn_min, epsilon, exclusion)
            row[u] = d1
            n_cand += d1 != UNDECIDED
        if n_cand == 0:
            continue
        # the row's cells are packed (kernels.volume): its first and last pixel bound them
        n_cells = index[v, w - 1, 0] + index[v, w - 1, 2] - index[v, 0, 0] - index[v, 0, 1]
        if n_cand * n_disp > n_cells:  # the table reads each cell once: cheaper
            wta = _right_wta_row(cost, index, v)
            for u in range(w):
                d1 = row[u]
                if d1 != UNDECIDED and abs(wta[u - d1] - d1) > lr_tolerance:
                    row[u] = UNDECIDED
        else:
            for u in range(w):
                d1 = row[u]
                if d1 != UNDECIDED and abs(_right_wta(cost, index, n_disp, v, u - d1) - d1) > lr_tolerance:
                    row[u] = UNDECIDED
    return out


@njit(cache=True, error_model="numpy")
def _prefetch_band(cost, index, v, u):
    """Prefetch the cells of pixel (u, v)'s band."""
    off = index[v, u, 0]
    _prefetch_cells(cost, off + index[v, u, 1], off + index[v, u, 2] - 1)


@njit(cache=True, error_model="numpy", inline="always")
def _prefetch_cells(cost, c0, c1):
    """Prefetch the cells ``c0 .. c1`` of ``cost`` (c1 included): one per 64-byte line
    from c0, and c1's."""
    for c in range(c0, c1, 16):  # 16 cells: a 64-byte line
        _prefetch(cost, c)
    _prefetch(cost, c1)


@njit(cache=True, error_model="numpy")
def _right_wta_row(cost, index, v):
    """:func:`pixel.right_wta` of every column x of row v: int32 (W,).

    One pass over the row's cells: cell (u, d) is a candidate of the right pixel x = u - d.
    Pixels are taken in increasing u, so each x sees its candidates in increasing d, and
    a strict ``<`` keeps the smallest d on ties, as ``right_wta``'s scan does; x without
    a cell gets 0, as there.  Issue 10: the scan read up to ``n_disp`` pixels' index and
    cost per candidate seed.
    """
    w = index.shape[1]
    best = np.full(w, np.inf, np.float32)
    wta = np.zeros(w, np.int32)
    for u in range(w):
        off = index[v, u, 0]
        lo = index[v, u, 1]
        end = min(index[v, u, 2], u + 1)  # x = u - d >= 0
        n = end - lo
        if n <= 0:
            continue
        # x = u - d runs backwards: reversed slices (non-negative indices: the loop vectorises)
        cells = cost[off + lo:off + end]
        best_x = best[u - end + 1:u - lo + 1]
        wta_x = wta[u - end + 1:u - lo + 1]
        for i in range(n):
            j = n - 1 - i
            c = cells[i]
            better = c < best_x[j]
            best_x[j] = c if better else best_x[j]
            wta_x[j] = lo + i if better else wta_x[j]
    return wta


# ----------------------------------------------------------------------------- diffusion (step 5)
@intrinsic
def _prefetch(typingctx, arr, i):
    """Hint that ``arr.flat[i]`` (a C-contiguous array) will be read soon: LLVM's
    prefetch intrinsic, a no-op where the target has none.  A prefetch never faults: i
    may lie past the end."""

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        ptr = builder.gep(ary.data, [context.cast(builder, args[1], signature.args[1], types.intp)])
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fn = builder.module.declare_intrinsic("llvm.prefetch", [i8p],
                                              ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]))
        # read, high temporal locality, data cache
        builder.call(fn, [builder.bitcast(ptr, i8p), i32(0), i32(3), i32(1)])
        return context.get_dummy_value()

    return types.void(arr, i), codegen


#: :func:`_evaluate_pixels` prefetches the cells of the next this many frontier pixels
#: before it evaluates this many.
PREFETCH_BLOCK = 8


@njit(cache=True, error_model="numpy")
def _evaluate_pixels(cost, index, flat_index, disp, min_cost, max_gap, active, i0, i1, new_values, tau, kappa_d,
                     adversarial):
    """``new_values[i]`` for the frontier pixels ``active[i0:i1]``; ``flat_index`` is
    ``index`` flat.

    Block by block, the next block's cells are prefetched first (issue 10: the frontier
    is sparse, its cells are not in the cache and the hardware prefetcher cannot guess
    them; KITTI finest level, 41 sweeps, 2 threads: 69 -> 63 ms).  A prefetch per pixel inside the
    loop cost 30 ns a pixel: the loop compiled worse (road, coarsest level 2.7 -> 4.1 ms).
    """
    w = UINT(disp.shape[1])
    for b in range(i0, i1, PREFETCH_BLOCK):
        e = min(b + PREFETCH_BLOCK, i1)
        _prefetch_pixels(cost, flat_index, active, e, min(e + PREFETCH_BLOCK, i1))
        if tau == 1 and kappa_d == 1:  # the defaults as constants: unrolled neighbour loops
            for i in range(b, e):
                p = UINT(active[i])  # unsigned: a plain division, no sign fix-up
                new_values[i] = _diffuse_at(cost, index, disp, min_cost, max_gap, p // w, p % w, 1, 1, adversarial)
        else:
            for i in range(b, e):
                p = UINT(active[i])
                new_values[i] = _diffuse_at(cost, index, disp, min_cost, max_gap, p // w, p % w, tau, kappa_d,
                                            adversarial)


@njit(cache=True, error_model="numpy")
def _prefetch_pixels(cost, flat_index, active, i0, i1):
    """Prefetch the bands of the frontier pixels ``active[i0:i1]`` (and the first cells
    of their right neighbours, which :func:`pixel.accept_state` reads)."""
    for i in range(i0, i1):
        k = 3 * active[i]
        off = flat_index[k]
        # to the band's end: the line of the right neighbour's first cells too
        _prefetch_cells(cost, off + flat_index[k + 1], off + flat_index[k + 2])


@njit(parallel=True, cache=True, error_model="numpy")
def _evaluate_frontier(cost, index, flat_index, disp, min_cost, max_gap, active, n_active, new_values, tau, kappa_d,
                       adversarial):
    n_chunks = (n_active + FRONTIER_CHUNK - 1) // FRONTIER_CHUNK
    for c in prange(n_chunks):
        _evaluate_pixels(cost, index, flat_index, disp, min_cost, max_gap, active, c * FRONTIER_CHUNK,
                         min(n_active, (c + 1) * FRONTIER_CHUNK), new_values, tau, kappa_d, adversarial)


@njit(cache=True, error_model="numpy")
def _evaluate_frontier_serial(cost, index, flat_index, disp, min_cost, max_gap, active, n_active, new_values, tau,
                              kappa_d, adversarial):
    _evaluate_pixels(cost, index, flat_index, disp, min_cost, max_gap, active, 0, n_active, new_values, tau, kappa_d,
                     adversarial)


#: Frontier pixels per parallel task.
FRONTIER_CHUNK = 1024

#: Frontiers smaller than this are evaluated in the calling thread: waking the worker
#: threads costs more than the work (late sweeps touch a few hundred pixels).
SERIAL_FRONTIER = 4096


#: :func:`_plain_neighbourhoods` codes: nothing known; no neighbour decided; the pixel
#: decided and its decided neighbours all at its disparity.
MIXED = 0
NONE_DECIDED = 1
UNIFORM = 2


@njit(cache=True, error_model="numpy")
def _plain_neighbourhoods(disp0, v, plain):
    """``plain[u]`` for the inner pixels of row v (0 < v < H - 1) of ``disp0``:
    NONE_DECIDED, UNIFORM (the pixel decided, its decided neighbours at its disparity)
    or MIXED.  Branch-free, one pass over three rows: the compiler vectorises it."""
    up = disp0[v - 1]
    row = disp0[v]
    down = disp0[v + 1]
    for u in range(1, disp0.shape[1] - 1):
        d = row[u]
        a = up[u - 1]
        b = up[u]
        c = up[u + 1]
        e = row[u - 1]
        f = row[u + 1]
        g = down[u - 1]
        i = down[u]
        j = down[u + 1]
        top = max(max(max(a, b), max(c, e)), max(max(f, g), max(i, j)))
        # an undecided neighbour adds no candidate
        same = (((a == d) | (a < 0)) & ((b == d) | (b < 0)) & ((c == d) | (c < 0)) & ((e == d) | (e < 0))
                & ((f == d) | (f < 0)) & ((g == d) | (g < 0)) & ((i == d) | (i < 0)) & ((j == d) | (j < 0)) & (d >= 0))
        plain[u] = NONE_DECIDED if top < 0 else (UNIFORM if same else MIXED)


@njit(parallel=True, cache=True, error_model="numpy")
def _evaluate_all(cost, index, disp0, min_cost, max_gap, disp, tau, kappa_d, adversarial, row_changes):
    """First sweep: the new state of every pixel of ``disp0`` into ``disp``;
    ``row_changes[v + 1]``: how many pixels of row v changed.

    With tau = kappa_d = 1 (the defaults), the plain pixels are settled without
    :func:`pixel.diffuse_at`: a pixel without a decided neighbour has no candidate, and a
    decided pixel whose decided neighbours all hold its disparity d keeps it when d wins
    its one candidate set (:func:`pixel.holds_own_disparity`); :func:`_plain_neighbourhoods`
    finds them a row at a time.  Issue 10: most pixels of a first sweep are plain (road
    pair, finest level: 97 %, KITTI 65 %), and the candidate loop's branches are what a
    pixel costs; first sweep, 2 threads, A/B on the pipeline's inputs: road finest level
    7.8 -> 2.6 ms, KITTI finest level 10.4 -> about 8.5 ms (0.81x on a loaded machine);
    the whole diffusion of those levels 0.45x and 0.91x.
    """
    h, w = disp0.shape
    for v in prange(h):
        n = 0
        # tau = kappa_d = 1 (the defaults) as constants: the compiler unrolls the
        # neighbour loops (issue 10: 26 -> 22 ms CPU, road pair level 1)
        if tau == 1 and kappa_d == 1:
            plain = np.zeros(w, np.uint8)  # border pixels stay MIXED
            if 0 < v < h - 1:
                _plain_neighbourhoods(disp0, v, plain)
            for u in range(w):
                cur = disp0[v, u]
                kind = plain[u]
                if kind == NONE_DECIDED or (kind == UNIFORM and _holds_own_disparity(cost, index, v, u, cur)):
                    s = cur
                else:
                    s = _diffuse_at(cost, index, disp0, min_cost, max_gap, v, u, 1, 1, adversarial)
                disp[v, u] = s
                n += s != cur
        else:
            for u in range(w):
                s = _diffuse_at(cost, index, disp0, min_cost, max_gap, v, u, tau, kappa_d, adversarial)
                disp[v, u] = s
                n += s != disp0[v, u]
        row_changes[v + 1] = n


@njit(parallel=True, cache=True, error_model="numpy")
def _list_changes(disp0, disp, row_changes, changed):
    """Flat indices of the pixels where ``disp`` differs from ``disp0``, in row-major
    order; row v's start at ``row_changes[v]`` (cumulative counts)."""
    h, w = disp0.shape
    for v in prange(h):
        j = row_changes[v]
        for u in range(w):
            if disp[v, u] != disp0[v, u]:
                changed[j] = v * w + u
                j += 1


@njit(cache=True, error_model="numpy")
def _build_frontier(changed, n_changed, listed, row_listed, active, h, w, kappa_d):
    """Pixels within ``kappa_d`` of a changed pixel (the pixel itself excluded), deduplicated,
    in row-major order.

    ``listed`` is a bitmap of the map, ``(w + 63) // 64`` uint64 words per row, and
    ``row_listed`` a flag per row; both are all zero on entry and on return.  The pixels
    are marked, then collected row by row (issue 10: in row-major order the evaluation
    reads the cost volume nearly sequentially; KITTI level 1, 41 sweeps: 57 -> 43 ms
    CPU against the order of the changed pixels' neighbourhoods).
    """
    words = (w + 63) // 64
    one = np.uint64(1)
    for i in range(n_changed):
        p = changed[i]
        v = p // w
        u = p % w
        for dv in range(-kappa_d, kappa_d + 1):
            y = v + dv
            if y < 0 or y >= h:
                continue
            row_listed[y] = 1
            for du in range(-kappa_d, kappa_d + 1):
                x = u + du
                if x < 0 or x >= w or (dv == 0 and du == 0):
                    continue
                listed[y * words + (x >> 6)] |= one << np.uint64(x & 63)
    n_active = 0
    for y in range(h):
        if row_listed[y] == 0:
            continue
        row_listed[y] = 0
        for k in range(words):
            word = listed[y * words + k]
            if word == 0:
                continue
            listed[y * words + k] = 0
            base = y * w + 64 * k
            while word != 0:
                active[n_active] = base + trailing_zeros(word)
                n_active += 1
                word &= word - one  # clear the lowest set bit
    return n_active


def diffuse(cost, disp0, min_cost, max_gap, tau, kappa_d, adversarial, max_sweeps):
    """Intra-scale decisive diffusion with a frontier (paper Algorithm 1, eq. 5-6).

    Parameters
    ----------
    cost : Volume or ndarray, float32, (H, W, D)
    disp0 : ndarray, int32, (H, W)
        Sparse decisive map D_i^S (-1 undecided); not modified.
    min_cost : ndarray, float32, (H, W), or None
        Least cost of each pixel over its band (:func:`min_cost`); None: found by
        ``pixel.diffuse_at`` for the few pixels whose candidate gets as far as the gap
        test (issue 10: KITTI finest level, 13 % of the first sweep's pixels; no
        :func:`min_cost` pass over the whole volume).
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
    flat, index, _, _ = _unpack(cost)
    if min_cost is None:
        min_cost = np.empty((0, 0), np.float32)  # empty: diffuse_at finds the least cost itself
    return _diffuse(flat, index, disp0, min_cost, float(max_gap), int(tau), int(kappa_d), bool(adversarial),
                    int(max_sweeps))


@njit(cache=True, error_model="numpy")
def _diffuse(cost, index, disp0, min_cost, max_gap, tau, kappa_d, adversarial, max_sweeps):
    h, w = disp0.shape
    any_decided = False
    for p in range(h * w):
        if disp0.flat[p] != UNDECIDED:
            any_decided = True
            break
    if not any_decided or max_sweeps <= 0:
        return disp0.copy(), 0
    # The first frontier is nearly the whole image: evaluate every pixel in parallel,
    # reading disp0 and writing the new map, instead of listing the pixels serially.  The
    # same result: a pixel without a decided neighbour has no candidate and keeps its
    # state.  Issue 10: no copy of disp0, no full-size zeroed stamp: every full-size
    # array written here costs its page faults (road pair, level 1: 4 ms of 31).
    disp = np.empty((h, w), np.int32)
    row_changes = np.zeros(h + 1, np.int64)
    _evaluate_all(cost, index, disp0, min_cost, max_gap, disp, tau, kappa_d, adversarial, row_changes)
    for v in range(h):
        row_changes[v + 1] += row_changes[v]
    n_changed = row_changes[h]
    # pixel lists in int32: 12 bytes a pixel less than int64 (a 1280x720 level: 11 MB);
    # only their used part is ever touched
    changed = np.empty(h * w, np.int32)
    _list_changes(disp0, disp, row_changes, changed)
    flat = disp.reshape(h * w)  # a view: writes go to disp
    flat_index = index.reshape(-1)
    listed = np.zeros(h * ((w + 63) // 64), np.uint64)
    row_listed = np.zeros(h, np.uint8)
    active = np.empty(h * w, np.int32)
    new_values = np.empty(h * w, np.int32)
    sweeps = 1
    while n_changed > 0 and sweeps < max_sweeps:
        sweeps += 1
        n_active = _build_frontier(changed, n_changed, listed, row_listed, active, h, w, kappa_d)
        if n_active < SERIAL_FRONTIER:
            _evaluate_frontier_serial(cost, index, flat_index, disp, min_cost, max_gap, active, n_active, new_values,
                                      tau, kappa_d, adversarial)
        else:
            _evaluate_frontier(cost, index, flat_index, disp, min_cost, max_gap, active, n_active, new_values, tau,
                               kappa_d, adversarial)
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


def min_cost(cost):
    """Least cost of every pixel over its band; float32 (H, W) (1 for an empty band)."""
    flat, index, _, _ = _unpack(cost)
    return _min_cost(flat, index)


@njit(parallel=True, cache=True, error_model="numpy")
def _min_cost(cost, index):
    h, w, _ = index.shape
    out = np.empty((h, w), np.float32)
    for v in prange(h):
        for u in range(w):
            # pixel.band_min, as the diffusion finds it for itself (CPU) and CUDA's min_cost
            out[v, u] = _band_min(cost, index, v, u) if index[v, u, 2] > index[v, u, 1] else np.float32(1.0)
    return out


# ----------------------------------------------------------------------------- inheritance (step 7)
def inherit(cost, coarse, prc, dfm_pkrn_min, epsilon, candidates=0):
    """Inter-scale decisive inheritance (paper Algorithm 2, eq. 7-9).

    The patch tests (eq. 7-8) run once per coarse pixel and serve the four fine pixels
    of its 2x2 patch; the pixel test (eq. 9) per fine pixel.

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
    flat, index, _, _ = _unpack(cost)
    return _inherit(flat, index, coarse, bool(prc), float(dfm_pkrn_min), float(epsilon), int(candidates))


@njit(parallel=True, cache=True, error_model="numpy")
def _inherit(cost, index, coarse, prc, dfm_pkrn_min, epsilon, candidates):
    h, w, _ = index.shape
    out = np.empty((h, w), np.int32)
    for pv in prange((h + 1) // 2):
        # The test variant as constants in each branch: the compiler specialises the
        # inlined tests (road pair, level 1: 63 -> 49 ms CPU against one generic call).
        if prc and candidates == 0:
            _inherit_row_prc(cost, index, coarse, pv, out, 0)
        elif prc:
            _inherit_row_prc(cost, index, coarse, pv, out, 1)
        elif candidates == 0:
            _inherit_row(cost, index, coarse, pv, out, False, dfm_pkrn_min, epsilon, 0)
        else:
            _inherit_row(cost, index, coarse, pv, out, False, dfm_pkrn_min, epsilon, 1)
    return out


@njit(cache=True, error_model="numpy")
def _inherit_row(cost, index, coarse, pv, out, prc, dfm_pkrn_min, epsilon, candidates):
    """The fine rows 2 pv, 2 pv + 1 of :func:`_inherit` (one patch row)."""
    for pu in range((out.shape[1] + 1) // 2):
        _inherit_patch_into(out, cost, index, coarse, pv, pu, prc, dfm_pkrn_min, epsilon, candidates)


_window5 = ops.window5
_right_window5 = ops.right_window5
_window_summary = ops.window_summary
_patch_reliable4 = ops.patch_reliable4
_pixel_decisive5 = ops.pixel_decisive5


@njit(cache=True, error_model="numpy", inline="always")
def _right_decision(s, d, least_out):
    """:func:`pixel.pixel_decisive5` with ``prc`` of a right-view window from its
    :func:`pixel.window_summary` ``s`` alone (the PRC test needs no more of the window)."""
    if s[0] < 0 or s[1] >= 1.0:
        return UNDECIDED
    if s[3] and s[1] < least_out:
        return d - 2 + s[0]
    return UNDECIDED


@njit(cache=True, error_model="numpy", inline="always")
def _pick4(j, a, b, c, e):
    """The j-th (0..3) of four ints, as selects (j is data: no branch to mispredict)."""
    lo = a if j == 0 else b
    hi = c if j == 2 else e
    return lo if j < 2 else hi


@njit(cache=True, error_model="numpy", inline="always")
def _inherit_pixel_prc(left, left_s, u, d, x0, least_out_l, rd0, rd1, rd2, rd3, candidates):
    """:func:`pixel.inherit_pixel5` with ``prc``: the matched right pixel x = u - dl is
    one of x0 - 1 .. x0 + 2, whose right-view decisions are ``rd0 .. rd3``."""
    dl = _pixel_decisive5(left, left_s, u, d, False, True, least_out_l, 1.0, 0.0, candidates)
    dr = _pick4(u - dl - x0 + 1, rd0, rd1, rd2, rd3)
    return dl if dl >= 0 and dr == dl else UNDECIDED


@njit(cache=True, error_model="numpy")
def _inherit_row_prc(cost, index, coarse, pv, out, candidates):
    """:func:`_inherit_row` with ``prc`` (the configured test): the same decisions, with the
    right-view windows of a patch row shared along it.

    A left pixel of the patch at u0 matches a right pixel x0 - 1 .. x0 + 2 (x0 = u0 - d):
    the patch's own two and, for about a quarter of the decided pixels, one beside them,
    which :func:`pixel.inherit_quad` reads on demand (a branch on data).  Here each
    patch summarises the right windows x0 + 1 and x0 + 2 of both rows and takes x0 - 1
    and x0 from the patch before it, whose x0 + 1 and x0 + 2 they are when its coarse
    disparity is the same (84-99 % of the decided patches); otherwise it reads all four.
    The pixel then picks its right pixel's decision by a select.  Issue 10, A/B on the
    pipeline's inputs, 2 threads, finest level: road 18.8 -> 12.2 ms, Middlebury
    7.0 -> 4.7 ms, KITTI 8.1 -> 5.6 ms (the levels above: about -33 % too).
    """
    h = out.shape[0]
    w = out.shape[1]
    y0 = 2 * pv
    y1 = y0 + 1
    n_pu = (w + 1) // 2
    if pv >= coarse.shape[0]:
        for pu in range(n_pu):
            _write_patch(out, y0, 2 * pu, UNDECIDED, UNDECIDED, UNDECIDED, UNDECIDED)
        return
    prev_d = -1  # d of the patch before whose x0 + 1, x0 + 2 summaries are held (-1: none)
    q02 = q03 = q12 = q13 = (0, 0.0, 0.0, False)  # those summaries (row b: q_b2, q_b3)
    for pu in range(n_pu):
        u0 = 2 * pu
        dc = coarse[pv, pu] if pu < coarse.shape[1] else UNDECIDED
        if dc < 0:
            _write_patch(out, y0, u0, UNDECIDED, UNDECIDED, UNDECIDED, UNDECIDED)
            prev_d = -1
            continue
        d = 2 * dc
        x0 = u0 - d
        l00 = _window5(cost, index, y0, u0, d)
        l01 = _window5(cost, index, y0, u0 + 1, d)
        l10 = _window5(cost, index, y1, u0, d)
        l11 = _window5(cost, index, y1, u0 + 1, d)
        sl00 = _window_summary(l00, u0, d, False, candidates)
        sl01 = _window_summary(l01, u0 + 1, d, False, candidates)
        sl10 = _window_summary(l10, u0, d, False, candidates)
        sl11 = _window_summary(l11, u0 + 1, d, False, candidates)
        least_out_l = _patch_reliable4(sl00, sl01, sl10, sl11)
        if least_out_l < 0.0:
            _write_patch(out, y0, u0, UNDECIDED, UNDECIDED, UNDECIDED, UNDECIDED)
            prev_d = -1
            continue
        if prev_d == d:
            s00, s01, s10, s11 = q02, q03, q12, q13
        else:
            s00 = _window_summary(_right_window5(cost, index, y0, x0 - 1, d), x0 - 1, d, True, candidates)
            s01 = _window_summary(_right_window5(cost, index, y0, x0, d), x0, d, True, candidates)
            s10 = _window_summary(_right_window5(cost, index, y1, x0 - 1, d), x0 - 1, d, True, candidates)
            s11 = _window_summary(_right_window5(cost, index, y1, x0, d), x0, d, True, candidates)
        s02 = _window_summary(_right_window5(cost, index, y0, x0 + 1, d), x0 + 1, d, True, candidates)
        s03 = _window_summary(_right_window5(cost, index, y0, x0 + 2, d), x0 + 2, d, True, candidates)
        s12 = _window_summary(_right_window5(cost, index, y1, x0 + 1, d), x0 + 1, d, True, candidates)
        s13 = _window_summary(_right_window5(cost, index, y1, x0 + 2, d), x0 + 2, d, True, candidates)
        prev_d = d
        q02, q03, q12, q13 = s02, s03, s12, s13
        least_out_r = _patch_reliable4(s01, s02, s11, s12)
        if least_out_r < 0.0:
            _write_patch(out, y0, u0, UNDECIDED, UNDECIDED, UNDECIDED, UNDECIDED)
            continue
        r00 = _right_decision(s00, d, least_out_r)
        r01 = _right_decision(s01, d, least_out_r)
        r02 = _right_decision(s02, d, least_out_r)
        r03 = _right_decision(s03, d, least_out_r)
        r10 = _right_decision(s10, d, least_out_r)
        r11 = _right_decision(s11, d, least_out_r)
        r12 = _right_decision(s12, d, least_out_r)
        r13 = _right_decision(s13, d, least_out_r)
        _write_patch(out, y0, u0,
                     _inherit_pixel_prc(l00, sl00, u0, d, x0, least_out_l, r00, r01, r02, r03,
                                        candidates),
                     _inherit_pixel_prc(l01, sl01, u0 + 1, d, x0, least_out_l, r00, r01, r02, r03,
                                        candidates),
                     _inherit_pixel_prc(l10, sl10, u0, d, x0, least_out_l, r10, r11, r12, r13,
                                        candidates),
                     _inherit_pixel_prc(l11, sl11, u0 + 1, d, x0, least_out_l, r10, r11, r12, r13,
                                        candidates))


@njit(cache=True, error_model="numpy", inline="always")
def _write_patch(out, v, u, o00, o01, o10, o11):
    """The (up to four) fine pixels of the patch at (u, v) (a patch of the last row or
    column may be cut by the border), as :func:`pixel.inherit_patch_into`."""
    out[v, u] = o00
    if u + 1 < out.shape[1]:
        out[v, u + 1] = o01
    if v + 1 < out.shape[0]:
        out[v + 1, u] = o10
        if u + 1 < out.shape[1]:
            out[v + 1, u + 1] = o11


# ----------------------------------------------------------------------------- semi-global smoothing (issue 16)
def sgm_smooth(cost, p1, p2):
    """Mean of four semi-global path costs (left, right, down, up) of a volume.

    Parameters
    ----------
    cost : Volume or ndarray, float32, (H, W, D)
    p1, p2 : float
        Penalties of a one-disparity step and of a larger jump, in cost units.

    Returns
    -------
    Volume or ndarray
        Same kind and band layout; each cell ``(L_left + L_right + L_down + L_up) / 4``
        (:func:`pixel.sgm_step`), summed in that order.
    """
    flat, index, n_disp, dense = _unpack(cost)
    acc = np.zeros_like(flat)  # zeros: cells outside every visible band stay defined (0)
    p1, p2 = np.float32(p1), np.float32(p2)
    _sgm_rows(flat, index, n_disp, p1, p2, acc)
    _sgm_columns(flat, index, n_disp, p1, p2, acc)
    return _pack(acc, index, n_disp, dense)


#: Columns per task of the column paths: each task walks its columns down (then up) row
#: by row, so the cells it reads lie side by side (8, 16 and 64 measured the same on
#: KITTI; the first kernel walked one column at a time, a cache line per pixel).
SGM_COLUMNS = 32
#: The column paths prefetch the cells of the pixel this many rows ahead: each task's
#: rows lie apart in the volume, where the hardware's prefetcher does not follow (both
#: column paths of a KITTI volume 20.1 -> 13.2 ms; 1 row ahead 15.1, 4 rows 13.5).
SGM_PREFETCH_ROWS = 2


@njit(parallel=True, cache=True)
def _sgm_rows(cost, index, n_disp, p1, p2, acc):
    for v in prange(index.shape[0]):
        # two path buffers, inf outside the band (pixel.sgm_step's layout)
        a = np.full(n_disp + 2, np.inf, np.float32)
        b = np.full(n_disp + 2, np.inf, np.float32)
        _sgm_row_pass(cost, index, v, a, b, p1, p2, acc, 1, 0)  # left to right: the first path stores
        a[:] = np.inf
        b[:] = np.inf
        _sgm_row_pass(cost, index, v, a, b, p1, p2, acc, -1, 1)  # right to left


@njit(cache=True, inline="always")
def _sgm_row_pass(cost, index, v, a, b, p1, p2, acc, step, mode):
    """One row path (``step`` 1 rightwards, -1 leftwards) along row v; ``a``, ``b`` the
    path buffers (all inf on entry)."""
    w = index.shape[1]
    plo, phi = 0, 0
    for i in range(w):
        u = i if step > 0 else w - 1 - i
        _sgm_step(cost, index, v, u, (a, 0), plo, phi, (b, 0), p1, p2, acc, mode)
        plo, phi = index[v, u, 1], index[v, u, 2]
        a, b = b, a


@njit(parallel=True, cache=True)
def _sgm_columns(cost, index, n_disp, p1, p2, acc):
    w = index.shape[1]
    n_tasks = (w + SGM_COLUMNS - 1) // SGM_COLUMNS
    size = n_disp + 2
    for task in prange(n_tasks):
        u0 = task * SGM_COLUMNS
        u1 = min(w, u0 + SGM_COLUMNS)
        # per column two path buffers, column k's at k size of two arrays
        a = np.full(size * (u1 - u0), np.inf, np.float32)
        b = np.full(size * (u1 - u0), np.inf, np.float32)
        _sgm_column_pass(cost, index, u0, u1, a, b, size, p1, p2, acc, 1, 1)  # down
        a[:] = np.inf
        b[:] = np.inf
        _sgm_column_pass(cost, index, u0, u1, a, b, size, p1, p2, acc, -1, 2)  # up: the last path scales


@njit(cache=True, inline="always")
def _sgm_column_pass(cost, index, u0, u1, a, b, size, p1, p2, acc, step, mode):
    """One column path (``step`` 1 down, -1 up) over columns u0..u1, row by row; column
    k's two path buffers at ``k size`` of ``a`` and ``b`` (all inf on entry)."""
    h = index.shape[0]
    for i in range(h):
        v = i if step > 0 else h - 1 - i
        ahead = v + step * SGM_PREFETCH_ROWS
        for u in range(u0, u1):
            if 0 <= ahead < h:
                _prefetch_pixel(cost, acc, index, ahead, u)
            plo, phi = (index[v - step, u, 1], index[v - step, u, 2]) if i > 0 else (0, 0)
            k = (u - u0) * size
            _sgm_step(cost, index, v, u, (a, k), plo, phi, (b, k), p1, p2, acc, mode)
        a, b = b, a


@njit(cache=True, inline="always")
def _prefetch_pixel(cost, acc, index, v, u):
    """Prefetch the band of pixel (v, u) in the volume and in the sums."""
    c0 = index[v, u, 0] + index[v, u, 1]
    c1 = index[v, u, 0] + index[v, u, 2] - 1
    _prefetch_cells(cost, c0, c1)
    _prefetch_cells(acc, c0, c1)


# ----------------------------------------------------------------------------- sub-pixel (step 8)
def subpixel(cost, disp):
    """Parabola sub-pixel refinement (DESIGN step 8); float32 (H, W), inf where undecided."""
    flat, index, _, _ = _unpack(cost)
    return _subpixel(flat, index, disp)


#: :func:`_subpixel` prefetches the cells of the pixel this many columns ahead.
SUBPIXEL_PREFETCH = 32


@njit(parallel=True, cache=True, error_model="numpy")
def _subpixel(cost, index, disp):
    """:func:`pixel.subpixel_at` for every pixel, row by row.

    Each pixel reads the three cells around its disparity, one line of its band: with
    wide bands the lines a row needs lie apart and each waited its own cache miss, so the
    line of the pixel :data:`SUBPIXEL_PREFETCH` columns ahead is prefetched (an undecided
    or out-of-band disparity prefetches a line that is not needed; a prefetch never
    faults).  Issue 10: finest levels, 1 thread (CPU time), A/B on the pipeline's inputs:
    KITTI 5.3 -> 2.7 ms, Middlebury 4.5 -> 2.6 ms, road-full 5.1 -> 3.9 ms, road (narrow
    bands) 3.4 -> 2.8 ms.
    """
    h, w = disp.shape
    out = np.empty((h, w), np.float32)
    for v in prange(h):
        for u in range(w):
            if u + SUBPIXEL_PREFETCH < w:
                q = u + SUBPIXEL_PREFETCH
                _prefetch(cost, index[v, q, 0] + disp[v, q])
            out[v, u] = _subpixel_at(cost, index, disp, v, u)
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


@njit(parallel=True, cache=True, error_model="numpy")
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


@njit(parallel=True, cache=True, error_model="numpy")
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


@njit(parallel=True, cache=True, error_model="numpy")
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
