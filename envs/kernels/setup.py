"""Numba set-up of the compiled kernels: their threads, the parallel threshold and NumPy's random streams."""

from __future__ import annotations

import ctypes
import os
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

from envs.kernels.cache import drop_stale_caches

__all__ = [
    "ONE_THREAD",
    "PARALLEL_MIN_BATCH",
    "THREADS",
    "borrow",
    "claim",
    "jit",
    "jit_inline",
    "keep_alive",
    "on_every_core",
    "on_every_thread",
    "random_streams",
    "uniform_batch",
    "uses_every_core",
]

drop_stale_caches(__file__)


def jit(fn):
    """Compile ``fn`` as every kernel is: Numba's nopython mode, cached on disk, without the GIL, NumPy's errors."""
    return numba.njit(cache=True, nogil=True, error_model="numpy")(fn)


def jit_inline(fn):
    """``jit``, inlined into its callers at Numba's IR level (per-robot helpers that take many array arguments)."""
    return numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")(fn)


#: Threads a large batch runs on (``on_every_core``): ``NUMBA_NUM_THREADS``, the machine's cores unless set.
THREADS = max(1, int(numba.config.NUMBA_NUM_THREADS))

#: ``step_batch`` (the environments' hot path) runs batches at least this large on every core
#: (``on_every_core``); smaller ones stay on one thread, where waking the others (about 40 µs) would cost more
#: than it saves. Measured on two cores, 3-RPR Reach, random actions: N = 128 took 101 µs on both cores and 81 µs
#: on one, N = 256 141 and 159 µs, N = 512 223 and 317 µs.
PARALLEL_MIN_BATCH = 256


def uses_every_core(n: int) -> bool:
    """Whether an env of n robots steps on the multi-core kernel (from ``PARALLEL_MIN_BATCH`` robots on).

    Everything such an env computes with the step's kernel (``envs.kernels.modes``) runs on that kernel too: a
    process that used both would compile the whole step twice.
    """
    return n >= PARALLEL_MIN_BATCH


_pool: tuple[int, ThreadPoolExecutor] | None = None


def _executor() -> ThreadPoolExecutor:
    """The process's ``THREADS - 1`` worker threads (made again in a forked child, whose threads are gone)."""
    global _pool
    pid = os.getpid()
    if _pool is None or _pool[0] != pid:
        _pool = (pid, ThreadPoolExecutor(max_workers=THREADS - 1, thread_name_prefix="envs-kernels"))
    return _pool[1]


#: The counter of a one-thread call of a kernel that shares its work out by ``claim``: none to claim, the calling
#: thread does it all (an empty int64 array; ``on_every_core`` gives the threads a one-element one).
ONE_THREAD = np.zeros(0, dtype=np.int64)


def on_every_thread(kernel, *args) -> list:
    """Run ``kernel(*args)`` on ``THREADS`` threads at once (this one and the pool's); their results.

    The kernel (compiled with ``jit``, so it runs without the GIL) shares the work out itself, from a counter its
    arguments hold (``claim``).
    """
    if THREADS == 1:
        return [kernel(*args)]
    futures = [_executor().submit(kernel, *args) for _ in range(THREADS - 1)]
    results = [kernel(*args)]
    results.extend(future.result() for future in futures)
    return results


def on_every_core(kernel, *args) -> list:
    """Run ``kernel(*args, counter)`` on ``THREADS`` threads at once (``on_every_thread``); their results.

    Each thread takes the next chunk of the work with ``claim(counter)`` until none is left, so a thread that runs
    ahead does more of them, as with work stealing. ``counter`` is a fresh int64 array holding one zero.
    """
    return on_every_thread(kernel, *args, np.zeros(1, dtype=np.int64))


@intrinsic
def claim(typingctx, counter):
    """Atomically add one to ``counter[0]`` (an int64 array) and return the value before: the next chunk to do."""
    sig = types.int64(counter)

    def codegen(context, builder, signature, args):
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        return builder.atomic_rmw("add", data, ir.Constant(ir.IntType(64), 1), "monotonic")

    return sig, codegen


@intrinsic
def _next_double(typingctx, fn, state):
    """``fn(state)``: a bit generator's ``next_double`` at address fn on its state at address ``state``.

    This is what ``Generator.random()`` computes (a uniform double in [0, 1)), called through the
    bit generator's documented ctypes interface (NumPy's "extending with Numba" example), so a
    generator's stream is the same whether NumPy or a kernel draws from it.
    """
    sig = types.float64(fn, state)

    def codegen(context, builder, signature, args):
        pointer = ir.IntType(8).as_pointer()
        function = builder.inttoptr(args[0], ir.FunctionType(ir.DoubleType(), [pointer]).as_pointer())
        return builder.call(function, [builder.inttoptr(args[1], pointer)])

    return sig, codegen


def random_streams(generators) -> np.ndarray:
    """The kernels' handle on NumPy generators: (address of ``next_double``, address of the state) of each.

    Kernels given these draw exactly the numbers ``Generator.random()`` would, and advance the
    generators' states. The generators must stay alive while a kernel uses the addresses (the caller
    holds them); like Numba's own generator support, the kernels do not take the bit generators' locks.

    Args:
        generators: A sequence of ``np.random.Generator``.

    Returns:
        uint64 array of shape (len(generators), 2).

    Raises:
        TypeError: If an element is not a ``np.random.Generator``.
    """
    out = np.empty((len(generators), 2), dtype=np.uint64)
    for i, generator in enumerate(generators):
        if not isinstance(generator, np.random.Generator):
            raise TypeError(f"expected a numpy.random.Generator, got {type(generator).__name__} {generator!r}")
        bit_generator = generator.bit_generator
        interface = bit_generator.ctypes
        function = _NEXT_DOUBLE.get(type(bit_generator))
        if function is None:
            function = ctypes.cast(interface.next_double, ctypes.c_void_p).value
        out[i, 0] = function
        out[i, 1] = interface.state_address
    return out


#: ``next_double`` addresses of NumPy's bit generators: one C function per class, looked up once.
_NEXT_DOUBLE = {
    kind: ctypes.cast(kind().ctypes.next_double, ctypes.c_void_p).value
    for kind in (np.random.PCG64, np.random.PCG64DXSM, np.random.MT19937, np.random.Philox, np.random.SFC64)
}


@jit
def _uniform_loop(streams, out):
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[i, j] = _next_double(streams[i, 0], streams[i, 1])


def uniform_batch(streams, m):
    """Uniform draws in [0, 1), m from each stream, shape (S, m) (the kernels' ``Generator.random(m)``).

    Args:
        streams: ``random_streams(generators)``, shape (S, 2).
        m: Draws per stream.

    Returns:
        float64 array of shape (S, m).
    """
    out = np.empty((streams.shape[0], m))
    _uniform_loop(streams, out)
    return out


def _borrowed(context, builder, typ, value):
    """``value`` of Numba type ``typ`` with its arrays borrowed (``borrow``), as a new reference."""
    if isinstance(typ, types.Array):
        source = context.make_array(typ)(context, builder, value)
        out = context.make_array(typ)(context, builder)
        for field in ("nitems", "itemsize", "data", "shape", "strides"):
            setattr(out, field, getattr(source, field))
        out.meminfo = context.get_constant_null(types.MemInfoPointer(types.voidptr))
        out.parent = context.get_constant_null(types.pyobject)
        return out._getvalue()
    if isinstance(typ, types.BaseTuple):
        members = [
            _borrowed(context, builder, member, builder.extract_value(value, i)) for i, member in enumerate(typ.types)
        ]
        return context.make_tuple(builder, typ, members)
    context.nrt.incref(builder, typ, value)
    return value


@intrinsic
def borrow(typingctx, value):
    """``value`` with its arrays borrowed: the same data, shape and strides, without a meminfo (nor parent).

    Numba counts the references to an array each time it passes it on or takes a view of it (an atomic add and
    subtract on its meminfo, most of a per-robot loop's time); views of a borrowed array have no meminfo, so the
    counts are skipped. ``value``: an array, or a tuple or record of them (other members are returned as they
    are). Only for arrays that outlive what borrows them: an entry kernel's arguments (its caller holds them), or
    arrays held to the end of the loop by ``keep_alive``. A borrowed array must not be returned or stored.
    """
    sig = value(value)

    def codegen(context, builder, signature, args):
        return _borrowed(context, builder, signature.args[0], args[0])

    return sig, codegen


@intrinsic
def keep_alive(typingctx, value):
    """A use of ``value`` that compiles to nothing: its owner's reference lives (at least) until here."""
    sig = types.none(value)

    def codegen(context, builder, signature, args):
        return context.get_dummy_value()

    return sig, codegen
