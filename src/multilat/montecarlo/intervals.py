"""Coverage intervals from samples (JCGM 101 §7.7): probabilistically symmetric and shortest,
exactly from the tails of the sorted samples (only the (1 - p) tails are sorted).
"""

from __future__ import annotations

import math

import numpy as np

from multilat.errors import MultilatError
from multilat.montecarlo.checks import _check_coverage

_TIE_RTOL = 1e-9


def _q_index(m: int, coverage: float) -> int:
    """JCGM 101 §7.7.1: q = pM if integer, else the integer part of pM + 1/2."""
    q = int(math.floor(coverage * m + 0.5))
    return min(max(q, 1), m - 1) if m > 1 else 0


def _shortest_from_lengths(lengths: np.ndarray, alpha: np.ndarray, coverage: float, m: int):
    """Index of the shortest candidate (tie rule) and the ambiguity flag."""
    lmin = float(lengths.min())
    cand = np.flatnonzero(lengths <= lmin * (1.0 + _TIE_RTOL) + 0.0)
    r = int(cand[0]) if cand.size else int(np.argmin(lengths))
    far = np.abs(alpha - alpha[r]) > 0.5 * (1.0 - coverage)
    ambiguous = bool(np.any(lengths[far] <= lmin * (1.0 + 5.0 / math.sqrt(max(m, 1))))) if far.any() else False
    return r, ambiguous


def _tails(y: np.ndarray, n_cand: int, q: int):
    """The ``n_cand`` smallest (sorted) and the ``m - q`` largest (sorted) values of ``y``, exactly.

    For large samples, thresholds safely beyond the tails are estimated from a strided subsample
    (6 binomial standard errors of margin), the values beyond them are selected with a mask and
    only those are sorted; if a selection comes out too small the full partition is used.
    """
    m = y.size
    if m >= 200_000 and q > n_cand:
        sub = y[:: m // 65536]
        t_lo, t_hi = _tail_thresholds(sub, 1.0 - n_cand / m, sub.size)
        if math.isfinite(t_lo):
            low = y[y <= t_lo]
            high = y[y >= t_hi]
            if low.size >= n_cand and high.size >= m - q:
                low.sort()
                high.sort()
                return low[:n_cand], high[high.size - (m - q):]
    if q > n_cand - 1:
        part = np.partition(y, [n_cand - 1, q])
        return np.sort(part[:n_cand]), np.sort(part[q:])
    ys = np.sort(y)
    return ys[:n_cand], ys[q:]


def _exact_intervals(y: np.ndarray, coverage: float, candidates=None):
    """Symmetric and shortest intervals of 1-D samples ``y`` (JCGM 101 §7.7), ambiguity flag.

    Only the lower and upper (1 - p) tails are sorted. ``candidates`` (low, high): values of ``y``
    at or below / at or above thresholds picked while the samples were produced; used when they
    hold enough values (then they contain the tails exactly), else ``y`` is scanned.
    """
    m = y.size
    if m < 2:
        raise MultilatError(f"need at least 2 samples for a coverage interval, got {m}")
    q = _q_index(m, coverage)
    n_cand = m - q  # candidates r = 0 .. m - q - 1 ; interval [y(r), y(r+q)]
    lower = upper = None
    if candidates is not None and q > n_cand:
        low, high = candidates
        if low.size >= n_cand and high.size >= m - q:
            low = np.sort(low)
            high = np.sort(high)
            lower, upper = low[:n_cand], high[high.size - (m - q):]
    if lower is None:
        lower, upper = _tails(y, n_cand, q)
    lengths = upper - lower
    # probabilistically symmetric (JCGM 101 §7.7.2, 1-based): r = (M - q)/2 if integer, else the integer
    # part of (M - q + 1)/2; 0-based index r - 1
    rs = max((m - q + 1) // 2 - 1, 0)
    sym = (float(lower[rs]), float(upper[rs]))
    alpha = np.arange(n_cand) / m
    r, amb = _shortest_from_lengths(lengths, alpha, coverage, m)
    return sym, (float(lower[r]), float(upper[r])), amb


def coverage_interval(samples, coverage: float = 0.95, kind: str = "symmetric") -> np.ndarray:
    """Coverage interval of ``samples`` (JCGM 101 §7.7).

    Parameters
    ----------
    samples : array_like, shape (M,) or (M, k)
    coverage : float
        Coverage probability p in (0, 1).
    kind : {"symmetric", "shortest"}
        Probabilistically symmetric, or shortest (tie rule: see module docstring).

    Returns
    -------
    ndarray, shape (2,) or (k, 2)
        ``[low, high]`` in the unit of the samples.
    """
    if kind not in ("symmetric", "shortest"):
        raise MultilatError(f"kind must be 'symmetric' or 'shortest', got {kind!r}")
    _check_coverage(coverage)
    y = np.asarray(samples, dtype=float)
    if y.ndim not in (1, 2):
        raise MultilatError(f"samples must have shape (M,) or (M, k), got {y.shape}")
    cols = y[:, None] if y.ndim == 1 else y
    if not np.all(np.isfinite(cols)):
        raise MultilatError("samples must be finite")
    out = np.empty((cols.shape[1], 2))
    for j in range(cols.shape[1]):
        sym, short, _ = _exact_intervals(np.ascontiguousarray(cols[:, j]), coverage)
        out[j] = sym if kind == "symmetric" else short
    return out[0] if y.ndim == 1 else out


def _tail_thresholds(sub: np.ndarray, coverage: float, s: int):
    """Thresholds beyond the (1 - p) tails, from a sample ``sub`` of size ``s`` (6-sigma margin).

    Returns (t_lo, t_hi) with, with overwhelming probability, at least a fraction (1 - p) of the
    population below t_lo and above t_hi; (-inf, inf) when the margin would reach the median.
    """
    f = 1.0 - coverage
    margin = 6.0 * math.sqrt(f * (1.0 - f) / s) + 4.0 / s
    if f + margin >= 0.5:
        return -math.inf, math.inf
    i_lo = min(int(math.ceil((f + margin) * s)), s - 1)
    i_hi = max(int(math.floor((1.0 - f - margin) * s)), 0)
    part = np.partition(sub, [i_lo, i_hi])
    return part[i_lo], part[i_hi]
