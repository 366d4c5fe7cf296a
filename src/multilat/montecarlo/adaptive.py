"""The adaptive procedure of JCGM 101 §7.9 (:class:`AdaptiveRule`, shared with the network Monte Carlo)
and its driver over the engine's blocks.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable

import numpy as np

from multilat.errors import MultilatError
from multilat.montecarlo.checks import _check_coverage, _check_int
from multilat.montecarlo.chunks import _ChunkSpec, _run_chunk
from multilat.montecarlo.histogram import _hist_range, _histogram_counts
from multilat.montecarlo.intervals import _exact_intervals
from multilat.montecarlo.moments import _merge_blocks
from multilat.montecarlo.result import _finish
from multilat.montecarlo.seeding import BLOCK


def numerical_tolerance(u: float, ndigits: int = 2) -> float:
    """JCGM 101 §7.9.2: delta = 10**l / 2 where u = c x 10**l and c has ``ndigits`` digits."""
    u = float(u)
    if not (math.isfinite(u) and u > 0):
        raise MultilatError(f"u must be finite and > 0 for a numerical tolerance, got {u!r}")
    l_exp = math.floor(math.log10(u)) - ndigits + 1
    if round(u / 10.0**l_exp) >= 10**ndigits:  # rounding to ndigits carried into a new decade (0.0996 -> 0.10)
        l_exp += 1
    return 0.5 * 10.0**l_exp


class AdaptiveRule:
    """The adaptive procedure of JCGM 101 §7.9: batch size, check cadence and stopping decision.

    One implementation, driven by :func:`run_mc` and by :func:`multilat.network.montecarlo.propagate.propagate`.
    A batch is ``max(100 / (1 - p), 10^4)`` trials rounded up to whole blocks of ``block`` trials
    (batch ``h`` is blocks ``h * batch_blocks .. (h + 1) * batch_blocks - 1``, so an adaptive run
    draws exactly the trials of a fixed run of the same length). The driver hands every batch's
    output samples, in batch order, to :meth:`add`; after each batch h >= 2 the rule compares twice
    the standard deviation of the batch averages (``std over batches / sqrt(h)``) of y, u(y) and
    both ends of the probabilistically symmetric interval (§7.7, the index rule of
    :func:`coverage_interval`) with the numerical tolerance δ of u(y) over all trials so far
    (:func:`numerical_tolerance`, ``ndigits`` significant digits); the run stops when all are
    ≤ δ for every output (``converged``), or after ``max_batches = max(2, max_trials // batch)``.

    Attributes
    ----------
    batch_blocks, batch_trials : int
    max_batches : int
    h : int
        Batches examined.
    converged : bool
    tolerance : ndarray (k,) or None
        δ per output at the last check.
    """

    def __init__(self, coverage: float = 0.95, ndigits: int = 2, max_trials: int = 100_000_000,
                 block: int = BLOCK):
        _check_coverage(coverage)
        self.coverage = float(coverage)
        self.ndigits = _check_int("ndigits", ndigits, 1)
        block = _check_int("block", block, 1)
        batch = max(block, int(math.ceil(100.0 / (1.0 - coverage))), 10_000)
        self.batch_blocks = -(-batch // block)
        self.batch_trials = self.batch_blocks * block
        self.max_batches = max(2, _check_int("max_trials", max_trials, 2) // self.batch_trials)
        self.h = 0
        self.converged = False
        self.tolerance = None
        self._stats = []  # per batch (k, 4): y, u, ylow, yhigh
        self._n = []

    def batch_range(self, h: int) -> tuple[int, int]:
        """Blocks ``[start, stop)`` of batch ``h``."""
        return h * self.batch_blocks, (h + 1) * self.batch_blocks

    def batches(self, evaluate_round: Callable[[int, int], Iterable], batches_per_round: int = 1):
        """Yield the results of batches 0, 1, ... in order, at most ``max_batches``.

        ``evaluate_round(h0, h1)`` returns an iterable of the results of batches ``h0 .. h1 - 1``,
        submitted together (``batches_per_round`` of them, in parallel when its map allows). The
        caller stops consuming when :meth:`add` returns True; batches computed past that one are
        discarded, so the result does not depend on the round size.
        """
        per_round = _check_int("batches_per_round", batches_per_round, 1)
        h = 0
        while h < self.max_batches:
            stop = min(h + per_round, self.max_batches)
            yield from evaluate_round(h, stop)
            h = stop

    def u(self) -> np.ndarray:
        """Standard uncertainty u(y) of all trials of the batches added (pooled from the batches)."""
        st = np.stack(self._stats)
        n = np.asarray(self._n, dtype=float)[:, None]
        total = n.sum()
        mean = (n * st[:, :, 0]).sum(axis=0) / total
        ss = ((n - 1.0) * st[:, :, 1] ** 2 + n * (st[:, :, 0] - mean) ** 2).sum(axis=0)
        return np.sqrt(ss / (total - 1.0))

    def add(self, samples, mean=None, std=None) -> bool:
        """Examine the next batch (``samples`` (n,) or (n, k), finite); True when the run stops.

        ``mean`` and ``std`` (ddof = 1) of the batch may be passed when already computed.
        """
        y2 = np.asarray(samples, dtype=float)
        y2 = y2.reshape(y2.shape[0], -1)
        n, k = y2.shape
        mean = y2.mean(axis=0) if mean is None else np.asarray(mean, dtype=float)
        std = y2.std(axis=0, ddof=1) if std is None else np.asarray(std, dtype=float)
        stats = np.empty((k, 4))
        for j in range(k):
            sym, _, _ = _exact_intervals(np.ascontiguousarray(y2[:, j]), self.coverage)
            stats[j] = mean[j], std[j], *sym
        self._stats.append(stats)
        self._n.append(n)
        self.h += 1
        if self.h >= 2:
            s = np.stack(self._stats).std(axis=0, ddof=1) / math.sqrt(self.h)  # std of the average
            delta = np.array([numerical_tolerance(x, self.ndigits) if x > 0 else 0.0 for x in self.u()])
            self.tolerance = delta
            if np.all(2.0 * s <= delta[:, None]):
                self.converged = True
                return True
        return self.h >= self.max_batches


def _run_adaptive(common, coverage, ndigits, mapper, progress, max_trials, exact_limit, quantiles, entropy,
                  batches_per_round):
    """Drive :class:`AdaptiveRule` over the engine's blocks (see :func:`run_mc`)."""
    rule = AdaptiveRule(coverage, ndigits, max_trials)
    batch = rule.batch_trials
    n, mean, m2, rejected = 0, None, None, 0
    kept, counts, edges, lo, hi = [], None, None, None, None
    bins = common["hist_bins"]
    exact = quantiles != "histogram"
    out_ndim = 1

    def evaluate_round(h0, h1):
        specs = []
        for i in range(h0, h1):
            start, stop = rule.batch_range(i)
            specs.append(_ChunkSpec(**common, block_start=start, block_stop=stop, trials=(i + 1) * batch,
                                    keep_samples=True, hist_lo=None, hist_hi=None))
        return mapper(_run_chunk, specs)

    for part in rule.batches(evaluate_round, batches_per_round):
        out_ndim = part.out_ndim
        y2 = part.samples
        k = y2.shape[1]
        n, mean, m2 = _merge_blocks(n, mean, m2, part.blocks)
        rejected += part.n_rejected
        if lo is None:  # histogram range from batch 0 (deterministic)
            lo, hi, edges_all = _hist_range(y2, bins, coverage)
        if exact:
            kept.append(y2)
            if n * k > exact_limit:  # "auto": the histogram for the rest of the run (quantile_method says so)
                if quantiles == "exact":
                    raise MultilatError(
                        f"quantiles='exact': the adaptive run has not converged at {n:,} trials x {k} output(s), "
                        f"more than exact_limit={exact_limit:,} values kept in memory (8 bytes each): raise "
                        "exact_limit, or pass quantiles='auto' (histogram intervals beyond it, stated in "
                        "quantile_method)")
                exact = False
                edges = edges_all
                counts = sum(_histogram_counts(s, lo, hi, bins) for s in kept)
                kept = []
        else:
            edges = edges_all
            c = _histogram_counts(y2, lo, hi, bins)
            counts = c if counts is None else counts + c
        if progress is not None:
            progress((rule.h + 1) * batch, max_trials)
        std_b = np.sqrt((np.diag(part.m2) if part.m2.ndim == 2 else part.m2) / (part.n - 1))
        if rule.add(y2, part.mean, std_b):
            break
    samples = np.concatenate(kept, axis=0) if exact else None
    delta = rule.tolerance
    tol = None if delta is None else (float(delta[0]) if out_ndim == 1 else delta)
    spawn_key = tuple(common["spawn_key"])
    return _finish(n, mean, m2, coverage, samples=samples, counts=counts if not exact else None,
                   edges=edges if not exact else None, out_ndim=out_ndim, converged=rule.converged,
                   tolerance=tol, seed_entropy=entropy, n_rejected=rejected, seed_spawn_key=spawn_key)
