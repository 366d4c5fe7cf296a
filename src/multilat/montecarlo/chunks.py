"""The chunk worker: evaluates whole blocks of trials and returns their streamed moments and samples or
histogram counts (the unit of work handed to ``map``; picklable for process pools and Dask).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from multilat.errors import MultilatError
from multilat.montecarlo.histogram import _histogram_counts
from multilat.montecarlo.intervals import _tail_thresholds
from multilat.montecarlo.moments import _merge_moments, _moments
from multilat.montecarlo.seeding import BLOCK, block_generator, block_trials


@dataclass(frozen=True, eq=False)
class _ChunkSpec:
    model: Callable
    inputs: tuple
    entropy: Any
    spawn_key: tuple
    block_start: int
    block_stop: int
    trials: int  # total trials of the run (the last block may be partial)
    keep_samples: bool
    hist_lo: np.ndarray | None
    hist_hi: np.ndarray | None
    hist_bins: int
    nonfinite: str
    out: Any = None  # in-process only: a _Store the samples are written straight into


class _Store:
    """In-process sample store: chunks write their blocks straight into ``data`` and, for a scalar
    output, also pick out tail candidates while each block is still in cache (thresholds from block
    0, which the in-process map evaluates first), so the final intervals need not scan ``data``."""

    def __init__(self, data: np.ndarray, coverage: float, tails: bool):
        self.data = data
        self.coverage = coverage
        self.tails = tails and data.ndim == 1
        self.t_lo = self.t_hi = None
        self.low: list = []
        self.high: list = []

    def put(self, b: int, y: np.ndarray) -> None:
        self.data[b * BLOCK : b * BLOCK + y.shape[0]] = y
        if not self.tails:
            return
        if self.t_lo is None:
            if b != 0:  # blocks out of order: no candidates, the final step scans the data
                self.tails = False
                return
            self.t_lo, self.t_hi = _tail_thresholds(y, self.coverage, y.size)
        self.low.append(y[y <= self.t_lo])
        self.high.append(y[y >= self.t_hi])

    def candidates(self):
        if not self.tails or not self.low:
            return None
        return np.concatenate(self.low), np.concatenate(self.high)


@dataclass
class _Partial:
    n: int
    mean: np.ndarray  # (k,)
    m2: np.ndarray  # (k, k) co-moment or (k,) sums of squared deviations
    samples: np.ndarray | None  # (n, k)
    counts: np.ndarray | None  # (k, bins + 2)
    n_rejected: int
    offset: int  # trial index of the first sample (before rejection)
    out_ndim: int
    blocks: list  # per-block (n, mean, m2), merged by the driver in block order (chunking-invariant)


def _eval_block(spec: _ChunkSpec, b: int) -> np.ndarray:
    n = block_trials(b, spec.trials)
    gen = block_generator(spec.entropy, spec.spawn_key, b)
    kw = {name: dist.sample(gen, n) for name, dist in spec.inputs}
    y = np.asarray(spec.model(**kw), dtype=float)
    if y.ndim not in (1, 2) or y.shape[0] != n:
        raise MultilatError(f"model must return shape (n,) or (n, k) with n = {n}, got {y.shape}")
    return y


def _run_chunk(spec: _ChunkSpec) -> _Partial:
    """Evaluate blocks ``[block_start, block_stop)``; return streamed moments and samples/counts."""
    n_tot, mean, m2 = 0, None, None
    samples, counts, rejected, out_ndim, blocks = [], None, 0, 1, []
    for b in range(spec.block_start, spec.block_stop):
        y = _eval_block(spec, b)
        out_ndim = y.ndim
        y2 = y.reshape(y.shape[0], -1)
        ok = np.isfinite(y2).all(axis=1)
        if not ok.all():
            bad = int((~ok).sum())
            if spec.nonfinite == "raise":
                first = b * BLOCK + int(np.flatnonzero(~ok)[0])
                raise MultilatError(f"model returned {bad} non-finite value(s) in block {b} (first at trial {first})")
            rejected += bad
            y2 = y2[ok]
        if y2.shape[0] == 0:
            continue
        mb, cb = _moments(y2)
        blocks.append((y2.shape[0], mb, cb))
        if mean is None:
            n_tot, mean, m2 = y2.shape[0], mb, cb
        else:
            n_tot, mean, m2 = _merge_moments(n_tot, mean, m2, y2.shape[0], mb, cb)
        if spec.keep_samples:
            if spec.out is not None:  # no rejection possible here (nonfinite="raise")
                spec.out.put(b, y)
            else:
                samples.append(y2)
        if spec.hist_lo is not None:
            c = _histogram_counts(y2, spec.hist_lo, spec.hist_hi, spec.hist_bins)
            counts = c if counts is None else counts + c
    if mean is None:
        raise MultilatError(f"model returned no finite value in blocks {spec.block_start}..{spec.block_stop - 1}")
    s = None
    if spec.keep_samples and spec.out is None:
        s = samples[0] if len(samples) == 1 else np.concatenate(samples, axis=0)
    return _Partial(n_tot, mean, m2, s, counts, rejected, spec.block_start * BLOCK, out_ndim, blocks)
