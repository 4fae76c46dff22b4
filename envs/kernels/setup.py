"""Numba set-up of the compiled kernels: the threading layer, the parallel threshold and NumPy's random streams."""

from __future__ import annotations

import ctypes
import os

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

from envs.kernels.cache import drop_stale_caches

__all__ = [
    "PARALLEL_MIN_BATCH",
    "THREADING_LAYER",
    "jit",
    "jit_inline",
    "jit_parallel",
    "random_streams",
    "uniform_batch",
]

drop_stale_caches(__file__)


def jit(fn):
    """Compile ``fn`` as every kernel is: Numba's nopython mode, cached on disk, without the GIL, NumPy's errors."""
    return numba.njit(cache=True, nogil=True, error_model="numpy")(fn)


def jit_inline(fn):
    """``jit``, inlined into its callers at Numba's IR level (per-robot helpers that take many array arguments)."""
    return numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")(fn)


def jit_parallel(fn):
    """``jit`` with its ``numba.prange`` loops run on every core (in ``THREADING_LAYER``)."""
    return numba.njit(cache=True, nogil=True, error_model="numpy", parallel=True)(fn)


def _load_tbb() -> bool:
    """Make Intel TBB (the ``tbb`` wheel) loadable by Numba; True if Numba's TBB threading layer then imports.

    The wheel puts ``libtbb.so.12`` in the environment's ``lib`` folder, which is not on the dynamic
    loader's path of a virtual environment, so Numba's ``tbbpool`` extension cannot find it by itself.
    Loading the library first, by the path the wheel records, lets the loader resolve it by its soname.
    """
    import importlib.metadata

    names = ("libtbb.so.12", "libtbb.12.dylib", "tbb12.dll")
    try:
        files = importlib.metadata.files("tbb") or []
        paths = [f.locate() for f in files if f.name in names]
        for path in paths:
            ctypes.CDLL(os.fspath(path), mode=ctypes.RTLD_GLOBAL)
        from numba.np.ufunc import parallel

        check = getattr(parallel, "_check_tbb_version_compatible", None)  # private: absent in some versions
        if check is not None:
            check()  # TBB 2021.6 or newer, as Numba requires (raises ImportError otherwise)
        from numba.np.ufunc import tbbpool  # noqa: F401  (the import is the check)
    except (importlib.metadata.PackageNotFoundError, OSError, ImportError):
        return False
    return True


#: Numba's threading layer for the parallel step: Intel TBB where the ``tbb`` wheel is installed (a
#: dependency on x86-64), else the work-queue layer. The calling thread takes part in a TBB loop and idle
#: workers steal work, so a parallel step uses both cores however the OS placed the threads; the
#: work-queue layer hands each worker a fixed share, and on an idle machine the OS often wakes both
#: workers on one core (measured: the 16384-robot step took 7.0 ms after other work in the same process,
#: as long as on one thread, against 3.7 ms with TBB). OpenMP is not used: its barriers spin, and with
#: one core busy a step ran 14× slower. TBB is also what Numba calls its "safe" layer (thread- and
#: fork-safe; the work-queue layer aborts if two threads run parallel code at once). A user's
#: ``NUMBA_THREADING_LAYER`` still wins.
THREADING_LAYER = os.environ.get("NUMBA_THREADING_LAYER") or ("tbb" if _load_tbb() else "workqueue")
numba.config.THREADING_LAYER = THREADING_LAYER

#: ``step_batch`` (the environments' hot path) runs batches at least this large on every core
#: (``numba.prange``); smaller ones stay on one thread, where waking the thread pool would cost more than
#: it saves. Measured on two cores (Reach, random actions): with TBB, N = 64 runs 1.26× faster on both
#: cores and N = 32 only 1.07×; the work-queue layer pays off later.
PARALLEL_MIN_BATCH = 64 if THREADING_LAYER == "tbb" else 512


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
