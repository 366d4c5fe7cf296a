"""Streamed moments: per-block two-pass mean and co-moment, merged in block order (Chan's formula),
so the mean, variance and covariance do not depend on chunking or workers.
"""

from __future__ import annotations

import numpy as np

#: Covariance is streamed for at most this many outputs (variances always).
COV_LIMIT = 512


def _moments(y2: np.ndarray):
    """Mean (k,) and co-moment matrix (k, k) (or sums of squared deviations (k,) for k > 512) of
    one block ``y2`` (n, k), two-pass.

    Sums use numpy's pairwise reductions over contiguous rows for k <= 8, so the bits do not depend
    on the BLAS thread count of the process (a Dask worker reproduces the driver exactly); BLAS
    (``d.T @ d``) above that.
    """
    n, k = y2.shape
    if k == 1:
        col = y2[:, 0]
        mean = col.mean()
        d = col - mean
        d *= d
        return np.array([mean]), np.array([[float(d.sum())]])
    if k <= 8:
        dt = np.array(y2.T, order="C")  # (k, n) copy: contiguous rows (axis-0 reductions are slow)
        mean = dt.mean(axis=1)
        dt -= mean[:, None]
        m2 = np.zeros((k, k))
        for s in range(0, n, 16384):  # sub-blocks keep the products in cache
            blk = dt[:, s : s + 16384]
            for j in range(k):
                m2[j, j:] += (blk[j:] * blk[j]).sum(axis=1)
        lower = np.tril_indices(k, -1)
        m2[lower] = m2.T[lower]
        return mean, m2
    mean = y2.mean(axis=0)
    d = y2 - mean
    if k <= COV_LIMIT:
        return mean, d.T @ d
    return mean, np.einsum("ij,ij->j", d, d)


def _merge_moments(na, ma, ca, nb, mb, cb):
    if na == 0:
        return nb, mb, cb
    if nb == 0:
        return na, ma, ca
    n = na + nb
    delta = mb - ma
    mean = ma + delta * (nb / n)
    f = na * nb / n
    c = ca + cb + (np.outer(delta, delta) * f if ca.ndim == 2 else delta * delta * f)
    return n, mean, c


def _merge_blocks(n, mean, m2, blocks):
    """Merge per-block moments into the running ones, in block order."""
    for nb, mb, cb in blocks:
        if mean is None:
            n, mean, m2 = nb, mb, cb
        else:
            n, mean, m2 = _merge_moments(n, mean, m2, nb, mb, cb)
    return n, mean, m2
