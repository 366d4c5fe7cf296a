"""Standard normal draws bit-identical to ``numpy.random.Generator.standard_normal``, through numba's
implementation of the same ziggurat when numba is installed (about three times faster for large draws).

Used by :mod:`multilat.distributions` for normal and multivariate-normal samples; the switch-over state
(:data:`NUMBA_AFTER`, whether the kernel compiled) is per process.
"""

from __future__ import annotations

import os

import numpy as np


def _std_normal_kernel(g, n):  # compiled by numba in _fast_std_normal (same algorithm as numpy)
    return g.standard_normal(n)


_NUMBA_NORMAL = None  # None: not tried yet; False: unavailable; else the compiled kernel
_NUMPY_NORMALS = 0  # normals drawn by numpy so far in this process
#: numba is imported (about 0.5 s with its on-disk cache) only once a process has drawn this many
#: normals through numpy (or straight away if numba is already imported), so small runs never pay it.
NUMBA_AFTER = 2_000_000


def _fast_std_normal(g: np.random.Generator, size) -> np.ndarray:
    """Standard normal draws, bit-identical to ``g.standard_normal(size)``.

    numba's implementation of ``Generator.standard_normal`` (the same ziggurat on the same bit
    stream: the same numbers and the same generator state afterwards) runs about three times faster
    than numpy's for large sizes; it is used for calls of at least 4096 draws once the process has
    drawn :data:`NUMBA_AFTER` normals (numba's import then pays for itself). ``MULTILAT_NO_NUMBA=1``
    keeps the plain-numpy path; the tests check that both give identical draws.
    """
    global _NUMBA_NORMAL, _NUMPY_NORMALS
    n = int(np.prod(size)) if np.ndim(size) else int(size)
    if n < 4096 or _NUMBA_NORMAL is False:
        return g.standard_normal(size)
    if _NUMBA_NORMAL is None:
        import sys

        if _NUMPY_NORMALS < NUMBA_AFTER and "numba" not in sys.modules:
            _NUMPY_NORMALS += n
            return g.standard_normal(size)
        _NUMBA_NORMAL = False
        if not os.environ.get("MULTILAT_NO_NUMBA"):
            try:
                import numba

                _NUMBA_NORMAL = numba.njit(cache=True)(_std_normal_kernel)
            except Exception:  # noqa: BLE001 - any numba problem: use numpy
                _NUMBA_NORMAL = False
        if _NUMBA_NORMAL is False:
            return g.standard_normal(size)
    out = _NUMBA_NORMAL(g, n)
    return out if np.ndim(size) == 0 else out.reshape(size)
