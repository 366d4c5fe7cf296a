"""numba when installed, else stand-ins with which the kernels run as plain Python (slow, but the
same arithmetic): ``HAVE_NUMBA``, ``njit``, ``prange``, ``get_num_threads``."""

from __future__ import annotations

try:  # pragma: no cover - depends on the environment
    from numba import get_num_threads, njit, prange
    HAVE_NUMBA = True
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
