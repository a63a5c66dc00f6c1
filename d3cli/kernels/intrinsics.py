"""LLVM intrinsics and inlined prefetch helpers shared by the CPU drivers:
non-temporal stores and their fence, prefetch hints, the 16-lane splat of the vector
intrinsics of :mod:`d3cli.kernels.aggregation.cpu_vector`, and the atomic loads, stores
and pause by which threads of one sweep hand work to each other (the smoothing's)."""

from __future__ import annotations

import platform
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from . import compile_cache as _compile_cache  # noqa: F401  (chooses the numba cache folder first)


@intrinsic
def store_nt(typingctx, arr, i, val):
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
def store_fence(typingctx):
    """Order the non-temporal stores before (:func:`store_nt`) before every later store:
    x86's ``sfence``, where such stores are weakly ordered (nothing elsewhere)."""

    def codegen(context, builder, signature, args):
        if _X86:
            fn = builder.module.declare_intrinsic("llvm.x86.sse.sfence", (), ir.FunctionType(ir.VoidType(), ()))
            builder.call(fn, ())
        return context.get_dummy_value()

    return types.void(), codegen


def splat16(builder, x, ty):
    """LLVM IR: a vector of 16 ``ty`` lanes, each ``x`` (for the vector intrinsics below)."""
    undef = ir.Constant(ir.VectorType(ty, 16), ir.Undefined)
    first = builder.insert_element(undef, x, ir.IntType(32)(0))
    return builder.shuffle_vector(first, undef, ir.Constant(ir.VectorType(ir.IntType(32), 16), [0] * 16))


@njit(cache=True, error_model="numpy")
def prefetch_band(cost, index, v, u):
    """Prefetch the cells of pixel (u, v)'s band."""
    off = index[v, u, 0]
    prefetch_cells(cost, off + index[v, u, 1], off + index[v, u, 2] - 1)


@njit(cache=True, error_model="numpy", inline="always")
def prefetch_cells(cost, c0, c1):
    """Prefetch the cells ``c0 .. c1`` of ``cost`` (c1 included): one per 64-byte line
    from c0, and c1's."""
    for c in range(c0, c1, 16):  # 16 cells: a 64-byte line
        prefetch_cell(cost, c)
    prefetch_cell(cost, c1)


# ----------------------------------------------------------------------------- diffusion (step 5)
@intrinsic
def prefetch_cell(typingctx, arr, i):
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


# ----------------------------------------------------------------------------- threads handing work over
@intrinsic
def load_acquire(typingctx, arr, i):
    """``arr[i]`` of an int64 array as an atomic load with acquire order: what the thread
    that stored it (:func:`store_release`) wrote before is visible after, and the load is
    never hoisted out of a waiting loop."""

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        ptr = builder.gep(ary.data, [context.cast(builder, args[1], signature.args[1], types.intp)])
        return builder.load_atomic(ptr, "acquire", 8)

    return types.int64(arr, i), codegen


@intrinsic
def store_release(typingctx, arr, i, val):
    """``arr[i] = val`` of an int64 array as an atomic store with release order (every
    store before it is visible to a thread that loads it with :func:`load_acquire`)."""

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        ptr = builder.gep(ary.data, [context.cast(builder, args[1], signature.args[1], types.intp)])
        builder.store_atomic(context.cast(builder, args[2], signature.args[2], types.int64), ptr, "release", 8)
        return context.get_dummy_value()

    return types.void(arr, i, val), codegen


#: Whether the C library has ``sched_yield`` (POSIX; not on Windows).
_POSIX = platform.system() != "Windows"


@intrinsic
def spin_pause(typingctx, give_up_cpu):
    """One round of a waiting loop: x86's ``pause`` (a spinning core leaves the pipeline to
    its sibling), and with ``give_up_cpu`` true ``sched_yield`` too, so that on a machine
    with more busy threads than cores the thread being waited for gets the core."""

    def codegen(context, builder, signature, args):
        if _X86:
            fn = builder.module.declare_intrinsic("llvm.x86.sse2.pause", (), ir.FunctionType(ir.VoidType(), ()))
            builder.call(fn, ())
        if _POSIX:
            with builder.if_then(args[0]):
                fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.IntType(32), ()), "sched_yield")
                builder.call(fn, ())
        return context.get_dummy_value()

    return types.void(give_up_cpu), codegen
