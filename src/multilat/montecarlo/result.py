"""The summary of a Monte Carlo run (:class:`MCResult`) and how it is made from streamed moments and
samples or histogram counts (:func:`summarize` for samples drawn by the caller).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from multilat.errors import MultilatError
from multilat.montecarlo.checks import _check_coverage
from multilat.montecarlo.histogram import _hist_intervals
from multilat.montecarlo.intervals import _exact_intervals
from multilat.montecarlo.moments import _moments


@dataclass(frozen=True, eq=False)
class MCResult:
    """Summary of a Monte Carlo propagation (or of user-drawn samples).

    Attributes
    ----------
    estimate : float or ndarray (k,)
        Mean of the output samples (JCGM 101 §7.6), in the unit of the model output.
    std : float or ndarray (k,)
        Standard deviation of the output samples (standard uncertainty, ddof = 1).
    interval_symmetric : ndarray (2,) or (k, 2)
        Probabilistically symmetric coverage interval ``[low, high]``.
    interval_shortest : ndarray (2,) or (k, 2)
        Shortest coverage interval (tie rule in the module docstring).
    coverage : float
        Coverage probability of the intervals.
    trials : int
        Number of Monte Carlo trials used (for adaptive runs: what the stopping rule needed).
    cov : ndarray (k, k) or None
        Covariance matrix of vector outputs (None for a scalar output or k > 512).
    shortest_ambiguous : bool or ndarray (k,) of bool
        True where a far-away interval is as short within Monte Carlo noise (bimodal outputs).
    quantile_method : str
        ``"exact"`` (sorted samples) or ``"histogram"`` (fine histogram, see module docstring).
    samples : ndarray (M,) or (M, k) or None
        The output samples when they were kept (exact mode), else None.
    converged : bool or None
        Adaptive runs: whether the JCGM 101 §7.9 tolerance was met within ``max_trials``;
        None for a fixed number of trials.
    tolerance : float or ndarray (k,) or None
        Adaptive runs: the numerical tolerance delta of u(y) (JCGM 101 §7.9.2).
    seed_entropy : int or None
        Entropy of the root SeedSequence (pass it back as ``rng`` to reproduce the run; with a
        ``seed_spawn_key``, as ``SeedSequence(seed_entropy, spawn_key=seed_spawn_key)``).
    seed_spawn_key : tuple of int
        Spawn key of the root SeedSequence: empty for a run seeded by an int, None or a Generator;
        a run on a spawned branch (a budget's component, a child of another seed) reports its key,
        without which its entropy alone would seed a different run.
    n_rejected : int
        Trials whose output was not finite and were dropped (``nonfinite="drop"``).
    """

    estimate: Any
    std: Any
    interval_symmetric: np.ndarray
    interval_shortest: np.ndarray
    coverage: float
    trials: int
    cov: np.ndarray | None = None
    shortest_ambiguous: Any = False
    quantile_method: str = "exact"
    samples: np.ndarray | None = field(default=None, repr=False)
    converged: bool | None = None
    tolerance: Any = None
    seed_entropy: int | None = None
    n_rejected: int = 0
    seed_spawn_key: tuple = ()
    _hist_counts: np.ndarray | None = field(default=None, repr=False)
    _hist_edges: np.ndarray | None = field(default=None, repr=False)

    @property
    def expanded_uncertainty(self):
        """Half-width of the probabilistically symmetric interval (not assuming symmetry of y)."""
        iv = np.asarray(self.interval_symmetric)
        return 0.5 * (iv[..., 1] - iv[..., 0])

    @property
    def quantile_resolution(self):
        """Histogram bin width (per output) bounding the interval error in histogram mode; 0 if exact."""
        if self._hist_edges is None:
            return 0.0 if np.ndim(self.estimate) == 0 else np.zeros(np.size(self.estimate))
        w = self._hist_edges[:, 1] - self._hist_edges[:, 0]
        return float(w[0]) if np.ndim(self.estimate) == 0 else w

    def as_dict(self) -> dict:
        """Plain-JSON summary (no samples, no fine histogram): for ``--json`` output and reports."""

        def conv(v):
            if v is None or isinstance(v, (bool, int, float, str)):
                return v
            a = np.asarray(v)
            return a.tolist() if a.ndim else a.item()

        return {
            "estimate": conv(self.estimate),
            "std": conv(self.std),
            "interval_symmetric": conv(self.interval_symmetric),
            "interval_shortest": conv(self.interval_shortest),
            "coverage": self.coverage,
            "trials": self.trials,
            "cov": conv(self.cov),
            "shortest_ambiguous": conv(self.shortest_ambiguous),
            "quantile_method": self.quantile_method,
            "quantile_resolution": conv(self.quantile_resolution),
            "converged": self.converged,
            "tolerance": conv(self.tolerance),
            "seed": self.seed_entropy,
            **({"seed_spawn_key": [int(x) for x in self.seed_spawn_key]} if self.seed_spawn_key else {}),
            "n_rejected": self.n_rejected,
        }

    def histogram(self, bins: int = 100, component: int | None = None):
        """Histogram of the output distribution.

        Parameters
        ----------
        bins : int
            Number of bins over the sample range (exact mode) or over the populated part of the
            fine histogram (histogram mode; bins are merged groups of fine bins, so their number
            may be slightly smaller than asked).
        component : int, optional
            Which output for vector outputs (required when k > 1).

        Returns
        -------
        counts : ndarray (bins,) of int
        edges : ndarray (bins + 1,)
        """
        if not isinstance(bins, (int, np.integer)) or bins < 1:
            raise MultilatError(f"bins must be a positive integer, got {bins!r}")
        vector = np.ndim(self.estimate) > 0
        if vector and component is None:
            raise MultilatError("component is required for a vector output")
        j = 0 if component is None else int(component)
        k = np.size(self.estimate)
        if not 0 <= j < k:
            raise MultilatError(f"component must lie in [0, {k}), got {component!r}")
        if self.samples is not None:
            y = self.samples if self.samples.ndim == 1 else self.samples[:, j]
            return np.histogram(y, bins=int(bins))
        counts = self._hist_counts[j, 1:-1]
        edges = self._hist_edges[j]
        step = edges[1] - edges[0]
        nz = np.flatnonzero(counts)
        lo, hi = int(nz[0]), int(nz[-1]) + 1
        group = max(1, int(math.ceil((hi - lo) / bins)))
        ngroups = int(math.ceil((hi - lo) / group))
        c = np.zeros(ngroups * group, dtype=np.int64)
        c[: hi - lo] = counts[lo:hi]
        merged = c.reshape(ngroups, group).sum(axis=1)
        fine = edges[lo] + step * group * np.arange(ngroups + 1)
        return merged, fine


def _finish(n, mean, m2, coverage, *, samples, counts, edges, out_ndim, tail_candidates=None, **extra) -> MCResult:
    k = mean.size
    if n < 2:
        raise MultilatError(f"need at least 2 trials, got {n}")
    var = (np.diag(m2) if m2.ndim == 2 else m2) / (n - 1)
    std = np.sqrt(np.maximum(var, 0.0))
    cov = m2 / (n - 1) if (m2.ndim == 2 and out_ndim == 2) else None
    if samples is not None:
        sym = np.empty((k, 2))
        short = np.empty((k, 2))
        amb = np.zeros(k, dtype=bool)
        for j in range(k):
            col = samples[:, j] if samples.ndim == 2 else samples
            sym[j], short[j], amb[j] = _exact_intervals(np.ascontiguousarray(col), coverage,
                                                        candidates=tail_candidates if k == 1 else None)
        method = "exact"
    else:
        sym, short, amb = _hist_intervals(counts, edges, coverage, n)
        method = "histogram"
    if out_ndim == 1:
        est, sd, sym, short, amb = float(mean[0]), float(std[0]), sym[0], short[0], bool(amb[0])
        if samples is not None and samples.ndim == 2:
            samples = samples[:, 0]
    else:
        est, sd = mean.copy(), std
    return MCResult(
        estimate=est,
        std=sd,
        interval_symmetric=sym,
        interval_shortest=short,
        coverage=float(coverage),
        trials=int(n),
        cov=cov,
        shortest_ambiguous=amb,
        quantile_method=method,
        samples=samples,
        _hist_counts=counts,
        _hist_edges=edges,
        **extra,
    )


def summarize(samples, coverage: float = 0.95) -> MCResult:
    """Summarise output samples you drew yourself (exact quantiles).

    Parameters
    ----------
    samples : array_like, shape (M,) or (M, k)
        Monte Carlo output values (finite), one row per trial.
    coverage : float
        Coverage probability of the intervals.

    Returns
    -------
    MCResult
        With ``samples`` kept and ``quantile_method == "exact"``.
    """
    _check_coverage(coverage)
    y = np.asarray(samples, dtype=float)
    if y.ndim not in (1, 2) or y.shape[0] < 2:
        raise MultilatError(f"samples must have shape (M,) or (M, k) with M >= 2, got {y.shape}")
    if not np.all(np.isfinite(y)):
        raise MultilatError(f"samples contain {int((~np.isfinite(y)).sum())} non-finite value(s)")
    y2 = y.reshape(y.shape[0], -1)
    mean, m2 = _moments(y2)
    return _finish(y.shape[0], mean, m2, coverage, samples=y, counts=None, edges=None, out_ndim=y.ndim)
