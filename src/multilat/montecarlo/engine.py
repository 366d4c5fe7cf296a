"""The engine: :func:`run_mc` draws every input, evaluates the model over blocks of trials (through
``map``) and summarises; fixed runs here, adaptive runs in :mod:`multilat.montecarlo.adaptive`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from multilat.errors import MultilatError
from multilat.montecarlo.adaptive import _run_adaptive
from multilat.montecarlo.checks import _check_coverage, _check_int, _validate_inputs
from multilat.montecarlo.chunks import _ChunkSpec, _eval_block, _run_chunk, _Store
from multilat.montecarlo.histogram import _hist_range
from multilat.montecarlo.moments import _merge_blocks
from multilat.montecarlo.result import MCResult, _finish
from multilat.montecarlo.seeding import BLOCK, chunk_ranges, resolve_map, resolve_seed

#: Largest number of output values (trials x outputs) kept in memory for exact quantiles.
EXACT_LIMIT = 20_000_000
_PROBE_KEY = 0xFFFFFFFF


def run_mc(
    model: Callable[..., np.ndarray],
    inputs: Mapping[str, Any],
    *,
    trials: int | None = None,
    adaptive: bool = False,
    ndigits: int = 2,
    coverage: float = 0.95,
    rng=None,
    chunk_size: int = 16 * BLOCK,
    map=None,
    progress: Callable[[int, int], None] | None = None,
    quantiles: str = "auto",
    exact_limit: int = EXACT_LIMIT,
    hist_bins: int = 1 << 14,
    max_trials: int = 100_000_000,
    nonfinite: str = "raise",
    batches_per_round: int | None = None,
) -> MCResult:
    """Propagate the input distributions through ``model`` by Monte Carlo (JCGM 101).

    Parameters
    ----------
    model : callable
        ``model(**{name: ndarray (n, ...)}) -> ndarray (n,) or (n, k)``, vectorised over trials.
        Must be picklable (a module-level function or a ``functools.partial`` of one) to run on
        processes or a Dask cluster.
    inputs : mapping str -> distribution
        One entry per model argument: anything with ``sample(rng, size)``.
    trials : int, optional
        Fixed number of trials M (default 10^6 when not adaptive). Ignored when ``adaptive``.
    adaptive : bool
        Adaptive procedure of JCGM 101 §7.9: batches of ``max(BLOCK, 100/(1-p), 10^4)`` trials,
        rounded up to whole blocks, until twice the standard deviation of the batch estimates of
        y, u(y) and both ends of the probabilistically symmetric interval is below the numerical
        tolerance of u(y) (``ndigits`` significant digits), for every output.
    ndigits : int
        Significant decimal digits of u(y) for the adaptive tolerance.
    coverage : float
        Coverage probability p of the intervals.
    rng : numpy Generator, int, SeedSequence or None
        Seed of the run (see the module docstring for how blocks are seeded).
    chunk_size : int
        Trials per unit of work handed to ``map`` (rounded up to whole blocks). Does not change the
        numbers, only the granularity of parallel work and of progress updates.
    map : callable or object with ``.map``, optional
        ``map(func, iterable)`` used to evaluate the chunks (builtin ``map`` by default; e.g.
        :func:`multilat.parallel.dask_map` or a ``multiprocessing.Pool``). Results must come back
        in order.
    progress : callable(done, total), optional
        Called after every chunk with trials done and trials planned.
    quantiles : {"auto", "exact", "histogram"}
        Interval method; "auto" is exact when ``trials * k <= exact_limit`` (adaptive: up to that many
        values, then histogram intervals; ``MCResult.quantile_method`` says which). "exact" is always
        exact: an adaptive run that would keep more than ``exact_limit`` values raises
        :class:`MultilatError` naming the option instead of changing the method.
    exact_limit : int
        Largest number of output values kept in memory for exact quantiles ("auto"; an adaptive
        "exact" run's memory bound).
    hist_bins : int
        Bins of the fine histogram per output (histogram mode).
    max_trials : int
        Adaptive runs stop here with ``converged=False``.
    batches_per_round : int, optional
        Adaptive runs: batches submitted to ``map`` together (default 1 in-process, 4 with a
        ``map``); they are examined in order and any computed past the stopping batch are
        discarded, so the result is the same for every value.
    nonfinite : {"raise", "drop"}
        A non-finite model output raises :class:`MultilatError`, or the trial is dropped and counted
        in ``MCResult.n_rejected``.

    Returns
    -------
    MCResult
    """
    inp = _validate_inputs(inputs)
    if not callable(model):
        raise MultilatError("model must be callable")
    _check_coverage(coverage)
    ndigits = _check_int("ndigits", ndigits, 1)
    chunk_size = _check_int("chunk_size", chunk_size, 1)
    hist_bins = _check_int("hist_bins", hist_bins, 16)
    exact_limit = _check_int("exact_limit", exact_limit, 0)
    if quantiles not in ("auto", "exact", "histogram"):
        raise MultilatError(f"quantiles must be 'auto', 'exact' or 'histogram', got {quantiles!r}")
    if nonfinite not in ("raise", "drop"):
        raise MultilatError(f"nonfinite must be 'raise' or 'drop', got {nonfinite!r}")
    root = resolve_seed(rng)
    mapper = resolve_map(map)
    common = dict(
        model=model,
        inputs=inp,
        entropy=root.entropy,
        spawn_key=tuple(root.spawn_key),
        hist_bins=hist_bins,
        nonfinite=nonfinite,
    )
    entropy = root.entropy if isinstance(root.entropy, int) else None
    if adaptive:
        max_trials = _check_int("max_trials", max_trials, 2)
        if batches_per_round is None:
            batches_per_round = 1 if map is None else 4
        batches_per_round = _check_int("batches_per_round", batches_per_round, 1)
        return _run_adaptive(common, coverage, ndigits, mapper, progress, max_trials, exact_limit, quantiles, entropy,
                             batches_per_round)
    trials = 1_000_000 if trials is None else _check_int("trials", trials, 2)
    return _run_fixed(common, root, trials, coverage, quantiles=quantiles, exact_limit=exact_limit,
                      chunk_size=chunk_size, mapper=mapper, in_process=map is None, progress=progress,
                      entropy=entropy)


def _run_fixed(common, root, trials, coverage, *, quantiles, exact_limit, chunk_size, mapper, in_process, progress,
               entropy) -> MCResult:
    """A run of a fixed number of ``trials`` (see :func:`run_mc`; arguments already checked)."""
    model, inp = common["model"], common["inputs"]
    hist_bins, nonfinite = common["hist_bins"], common["nonfinite"]
    # k from a 16-trial probe on its own seed branch (does not touch the blocks' streams)
    probe_gen = np.random.Generator(np.random.PCG64(
        np.random.SeedSequence(root.entropy, spawn_key=tuple(root.spawn_key) + (_PROBE_KEY,))))
    probe = np.asarray(model(**{nm: d.sample(probe_gen, 16) for nm, d in inp}), dtype=float)
    if probe.ndim not in (1, 2) or probe.shape[0] != 16:
        raise MultilatError(f"model must return shape (n,) or (n, k) with n = 16, got {probe.shape}")
    k = 1 if probe.ndim == 1 else probe.shape[1]
    exact = quantiles == "exact" or (quantiles == "auto" and trials * k <= exact_limit)
    lo = hi = edges = None
    if not exact:  # histogram range from block 0 (deterministic, independent of chunking)
        pilot = _eval_block(_ChunkSpec(**common, block_start=0, block_stop=1, trials=trials, keep_samples=False,
                                       hist_lo=None, hist_hi=None), 0)
        p2 = pilot.reshape(pilot.shape[0], -1)
        p2 = p2[np.isfinite(p2).all(axis=1)]
        if p2.shape[0] == 0:
            raise MultilatError("model returned no finite value in block 0")
        lo, hi, edges = _hist_range(p2, hist_bins, coverage)

    store = np.empty((trials,) if probe.ndim == 1 else (trials, k)) if exact else None
    # in-process, the chunks write their samples straight into the store (one copy, one allocation)
    direct = exact and in_process and nonfinite == "raise"
    sink = _Store(store, coverage, tails=True) if direct else None
    specs = (
        _ChunkSpec(**common, block_start=start, block_stop=stop, trials=trials,
                   keep_samples=exact, hist_lo=lo, hist_hi=hi, out=sink)
        for start, stop in chunk_ranges(trials, chunk_size)
    )
    n, mean, m2, rejected, counts, out_ndim = 0, None, None, 0, None, 1
    filled = 0
    done = 0
    for part in mapper(_run_chunk, specs):
        out_ndim = part.out_ndim
        n, mean, m2 = _merge_blocks(n, mean, m2, part.blocks)
        rejected += part.n_rejected
        if exact:
            if not direct:
                dest = store[filled : filled + part.n]
                dest[...] = part.samples.reshape(dest.shape)
            filled += part.n
        else:
            counts = part.counts if counts is None else counts + part.counts
        done += part.n + part.n_rejected
        if progress is not None:
            progress(done, trials)
    samples = store[:filled] if exact else None
    return _finish(n, mean, m2, coverage, samples=samples, counts=counts, edges=edges, out_ndim=out_ndim,
                   tail_candidates=sink.candidates() if sink is not None else None,
                   seed_entropy=entropy, n_rejected=rejected, seed_spawn_key=tuple(root.spawn_key))
