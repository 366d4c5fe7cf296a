"""numba when installed, else stand-ins with which the kernels run as plain Python (slow, but the
same arithmetic): ``HAVE_NUMBA``, ``njit``, ``prange``, ``get_num_threads``."""

from __future__ import annotations

try:  # pragma: no cover - depends on the environment
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

__all__ = ["HAVE_NUMBA", "njit", "prange", "get_num_threads"]
