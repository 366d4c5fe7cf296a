"""Propagation of distributions by Monte Carlo (JCGM 101:2008, GUM Supplement 1).

One function runs a Monte Carlo: :func:`run_mc` draws every input from its distribution, evaluates a
vectorised model over blocks of trials, and returns an :class:`MCResult` (estimate, standard
uncertainty, probabilistically symmetric and shortest coverage intervals, histogram). Alongside:
:func:`summarize` (the same summary for samples you drew yourself), :func:`coverage_interval`,
:func:`gum_linear` (first-order GUM propagation with numerical sensitivities),
:func:`validate_gum` (the JCGM 101 §8 comparison) and :func:`budget` (each source's contribution).

Example
-------
>>> import numpy as np
>>> from multilat.distributions import Arcsine, Normal, Uniform
>>> from multilat.montecarlo import run_mc
>>> def telemetric_error_m(rf, crosstalk, ampm, noise, distance_m=20.0):   # seed eq. (3), Rm - Rt
...     return distance_m * rf + crosstalk + ampm + noise
>>> inputs = {"rf": Normal(0.0, 1.5e-9), "crosstalk": Arcsine.from_amplitude(2.7e-6),
...           "ampm": Uniform.from_std(0.2e-6), "noise": Normal(0.0, 0.8e-6)}
>>> res = run_mc(telemetric_error_m, inputs, trials=200_000, rng=1)
>>> round(res.std * 1e6, 1)                       # um, k = 1 (the seed's 2.1 um)
2.1
>>> res.trials
200000

Conventions
-----------
* ``model(**{name: ndarray (n,)}) -> ndarray (n,)`` or ``(n, k)`` (k output quantities). It must be
  vectorised over the first axis; it is called with ``n`` up to :data:`BLOCK` trials at a time. An
  input may be any object with ``sample(rng, size)`` (see :mod:`multilat.distributions`); a custom
  one may return ``(n, ...)`` arrays, handed to the model as they are.
* Reproducibility: trials are drawn in fixed blocks of :data:`BLOCK` trials; block ``b`` draws from
  its own generator seeded by ``SeedSequence(entropy, spawn_key=root.spawn_key + (b,))`` (the
  ``b``-th ``spawn`` child of the root). Chunks (the unit of work handed to ``map``) are whole
  blocks, so the numbers depend only on the seed and the number of trials, never on ``chunk_size``
  or on how many processes ran the chunks (bit for bit; for more than 8 outputs the covariance
  uses BLAS, whose last bits may depend on its thread count).
* Memory is bounded whatever the number of trials. Mean, variance (and covariance for k <= 512
  outputs) are streamed (per-block two-pass moments merged with Chan's formula). Coverage intervals
  are computed *exactly* from the sorted samples (JCGM 101 §7.7) when ``trials * k`` does not exceed
  ``exact_limit`` (default 2e7 values, 160 MB); beyond that from a fixed fine histogram per output
  (``hist_bins`` bins, default 16384, plus under/overflow counts) over the range between block 0's
  0.1 % and 99.9 % quantiles widened by half their distance on each side, with linear
  interpolation of the cumulative distribution inside a bin. The histogram quantile error is below
  one bin width, ``MCResult.quantile_resolution`` (for a normal output about 7.5e-4 standard
  deviations: a seventh of the Monte Carlo standard error of a 95 % end point at 10^6 trials,
  comparable to it at 10^8); ``MCResult.quantile_method`` says which was used.
* Shortest coverage interval, tie rule: among the candidate intervals ``[y_(r), y_(r+q)]`` whose
  length is within ``1e-9`` (relative) of the minimum, the one with the lowest lower end is
  reported. When the output distribution is symmetric and bimodal (an arcsine-dominated error such as
  the seed's eq. 3), the shortest interval of the *distribution* is not unique: two mirror-image
  intervals have the same length and the sample picks whichever Monte Carlo noise makes shorter.
  ``MCResult.shortest_ambiguous`` is True when an interval whose lower end lies more than
  ``(1 - p)/2`` in probability away from the reported one is within ``5/sqrt(M)`` (relative) of its
  length; report the probabilistically symmetric interval in that case.
"""

from __future__ import annotations

from multilat.montecarlo.adaptive import AdaptiveRule, numerical_tolerance
from multilat.montecarlo.engine import EXACT_LIMIT, run_mc
from multilat.montecarlo.gum import GUMResult, GUMValidation, gum_linear, validate_gum
from multilat.montecarlo.intervals import coverage_interval
from multilat.montecarlo.moments import COV_LIMIT
from multilat.montecarlo.result import MCResult, summarize
from multilat.montecarlo.seeding import BLOCK, block_generator, block_trials, chunk_ranges, resolve_map, resolve_seed
from multilat.montecarlo.uncertainty_budget import BudgetComponent, UncertaintyBudget, budget

__all__ = [
    "BLOCK",
    "EXACT_LIMIT",
    "COV_LIMIT",
    "MCResult",
    "run_mc",
    "summarize",
    "coverage_interval",
    "GUMResult",
    "gum_linear",
    "GUMValidation",
    "validate_gum",
    "BudgetComponent",
    "UncertaintyBudget",
    "budget",
    "numerical_tolerance",
    "resolve_seed",
    "block_generator",
    "block_trials",
    "chunk_ranges",
    "AdaptiveRule",
    "resolve_map",
]
