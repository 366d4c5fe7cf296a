"""numba when installed, else stand-ins with which the kernels run as plain Python (slow, but the
same arithmetic): ``HAVE_NUMBA``, ``njit``, ``prange``, ``get_num_threads``; and the boundary of
every compiled entry point (:func:`boundary`, :func:`writable`).

``MULTILAT_PURE_PYTHON=1`` in the environment (read at import) runs every kernel as plain Python
even with numba installed: the fallback the tests exercise (``tests/test_kernel_fallback.py``).
"""

from __future__ import annotations

import functools
import os

import numpy as np

try:  # pragma: no cover - depends on the environment
    if os.environ.get("MULTILAT_PURE_PYTHON", "") not in ("", "0"):
        raise ImportError("MULTILAT_PURE_PYTHON is set: kernels run as plain Python")
    import numba as _numba
    from numba import get_num_threads, prange
    HAVE_NUMBA = True

    def njit(*args, **kwargs):
        """``numba.njit`` with IEEE division by default (``error_model="numpy"``): a zero divisor gives
        inf or nan, as in the numpy paths the kernels are tested against, never an exception. numba
        cannot carry an exception out of a ``prange`` region: a singular 3x3 target block in the
        sparse assembly left a ZeroDivisionError pending, and the process's next compiled call failed
        with "SystemError: ... returned a result with an exception set". Results with non-zero
        divisors are the same bits (only the zero test is dropped)."""
        kwargs.setdefault("error_model", "numpy")
        return _numba.njit(*args, **kwargs)
except Exception:  # pragma: no cover
    HAVE_NUMBA = False

    def njit(*args, **kwargs):
        if args and callable(args[0]):
            return args[0]
        return lambda f: f

    prange = range

    def get_num_threads():
        return 1



def writable(x, dtype=None):
    """``x`` as a C-contiguous, writeable array (of ``dtype`` when given; a copy only when it is not
    one already). numba compiles one variant of a kernel per array type, and a read-only array (a
    file's buffer, an array a reader froze) is another type: the first ``adjust`` of a CSV read from
    disk compiled every kernel again after the install's warm-up (33 s against 6 s)."""
    return np.require(x, dtype, ("C", "W"))


def boundary(kernel):
    """The Python entry point of a compiled ``kernel``: read-only array arguments are passed as
    writeable copies (:func:`writable`; the kernel never writes to them: numba refuses to compile
    a write to a read-only array), so one compiled variant serves arrays from memory and from files.
    Other arguments pass unchanged (a writeable output is written in place). ``.dispatcher`` is
    the compiled function (its ``signatures``: the variants compiled in this process)."""

    def call(*args):
        return kernel(*[writable(a) if isinstance(a, np.ndarray) and not a.flags.writeable else a
                        for a in args])

    functools.update_wrapper(call, kernel, assigned=("__module__", "__name__", "__qualname__", "__doc__"),
                             updated=())
    call.dispatcher = kernel
    call.py_func = getattr(kernel, "py_func", kernel)
    return call


__all__ = ["HAVE_NUMBA", "njit", "prange", "get_num_threads", "writable", "boundary"]
