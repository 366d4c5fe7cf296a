"""The histogram path: coverage intervals from a fixed fine histogram per output when the samples
are too many to keep (range from block 0, under/overflow counts, linear interpolation of the cdf).
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.montecarlo.intervals import _shortest_from_lengths


def _histogram_counts(y2, lo, hi, bins):
    """Counts per output of ``y2`` (n, k) on [lo, hi) in ``bins`` bins plus under/overflow."""
    n, k = y2.shape
    scale = bins / (hi - lo)
    # slot = floor((y - lo) * scale) + 1, clipped to [0, bins + 1] (0: underflow, bins + 1: overflow);
    # truncation equals floor once the value is clipped to be non-negative
    t = y2 - lo
    t *= scale
    t += 1.0
    np.clip(t, 0.0, bins + 1.0, out=t)
    idx = t.astype(np.intp)
    if k > 1:
        idx += np.arange(k, dtype=np.intp) * (bins + 2)
    return np.bincount(idx.ravel(), minlength=k * (bins + 2)).reshape(k, bins + 2)


def _hist_range(y2, bins, coverage):
    """Histogram range per output from a pilot ``y2`` (n, k).

    The pilot's quantiles at ``a`` and ``1 - a`` (``a = min(1e-3, (1 - p)/20)``, at least 20 pilot
    values deep) widened by half their distance on each side: robust to heavy tails (the range is not
    set by a pilot's extreme values), and wide enough that the ``p`` coverage ends and the shortest
    interval search stay inside for all but extremely heavy tails (which then raise). Values outside
    go to the under/overflow counts and still enter the mean and standard deviation.
    """
    n = y2.shape[0]
    a = max(min(1e-3, (1.0 - coverage) / 20.0), min(20.0 / n, 0.25))
    qlo, qhi = np.quantile(y2, [a, 1.0 - a], axis=0)
    span = qhi - qlo
    span = np.where(span > 0, span, np.maximum(np.abs(qhi), 1.0) * 1e-12)
    lo, hi = qlo - 0.5 * span, qhi + 0.5 * span
    edges = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, bins + 1)[None, :]
    return lo, hi, edges


def _hist_intervals(counts, edges, coverage, m):
    """Symmetric and shortest intervals from fine-histogram counts (k, bins+2) and edges (k, bins+1)."""
    k = counts.shape[0]
    sym = np.empty((k, 2))
    short = np.empty((k, 2))
    amb = np.zeros(k, dtype=bool)
    for j in range(k):
        c = counts[j].astype(float)
        total = c.sum()
        under, over = c[0] / total, c[-1] / total
        cdf = np.concatenate([[under], under + np.cumsum(c[1:-1]) / total])  # at edges
        e = edges[j]
        # strictly increasing abscissa for interpolation of the inverse cdf
        keep = np.concatenate([[True], np.diff(cdf) > 0])
        cx, ex = cdf[keep], e[keep]

        def qf(a, cx=cx, ex=ex):
            return np.interp(a, cx, ex)

        lo_a, hi_a = 0.5 * (1 - coverage), 0.5 * (1 + coverage)
        if lo_a < under or hi_a > 1 - over:
            raise MultilatError(
                "coverage quantile outside the histogram range (very heavy tails): "
                "use quantiles='exact' (fewer trials) or a wider hist range"
            )
        sym[j] = qf(lo_a), qf(hi_a)
        a0, a1 = under, 1.0 - coverage - over
        if a1 <= a0:
            short[j] = sym[j]
            continue
        alpha = np.linspace(a0, a1, 8193)
        lengths = qf(alpha + coverage) - qf(alpha)
        r, amb[j] = _shortest_from_lengths(lengths, alpha, coverage, m)
        short[j] = qf(alpha[r]), qf(alpha[r] + coverage)
    return sym, short, amb
