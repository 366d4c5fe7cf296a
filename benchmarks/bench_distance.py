"""Benchmark of the distance budget (seed 000 section 3.4): the paper's 26 x 200 000 trials of the
telemetric + head + target (+ air) model, through the engine, against plain numpy on the same model.

Rows
----
* ``budget_5.2M_stratified``: ``budget.distance_budget`` (one ``run_mc`` per distance, samples pooled);
  baseline: the same model drawn with ``numpy.random.default_rng`` per distance and pooled with numpy
  (no engine, no seeding scheme, no coverage intervals beyond ``np.quantile``).
* ``budget_5.2M_streamed``: the memory-bounded mode (distance as a random input, histogram quantiles).
* ``sample_distance_errors_1M``: the helper other modules call, one draw for each of 10^6 distances.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

SEED = 2020


def _median_time(fn, repeats):
    ts = []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), out


def numpy_baseline(inst, n, seed):
    """Plain numpy: per distance, draw every input and evaluate the same group model; pool; summarise."""
    from multilat import budget

    p = budget._params(inst, "A")
    inputs = budget.group_inputs(inst, "A")
    gen = np.random.default_rng(seed)
    parts = []
    for L in inst.budget.distances_m:
        draws = {k: d.sample(gen, n) for k, d in inputs.items()}
        parts.append(budget.group_errors(p, float(L), **draws))
    out = np.concatenate(parts)
    tot = out[:, :3].sum(axis=1)
    return float(np.sqrt(np.mean(tot ** 2))), np.quantile(tot, [0.025, 0.975])


def run(quick: bool = False) -> list[dict]:
    from multilat import budget
    from multilat.instrument import load_instrument

    inst = load_instrument("seed2020")
    n = 20_000 if quick else 200_000
    total = n * inst.budget.distances_m.size
    repeats = 1 if quick else 3
    rows = []
    budget._air_cached(inst)  # warm the air-index cache

    t_np, (u_np, _) = _median_time(lambda: numpy_baseline(inst, n, SEED), repeats)
    t_st, res = _median_time(lambda: budget.distance_budget(inst, trials=n, rng=SEED), repeats)
    rows.append(dict(
        name=f"budget_{total / 1e6:g}M_stratified", median_s=t_st, baseline="numpy_per_distance",
        baseline_median_s=t_np, ratio=t_np / t_st,
        extra=dict(trials=total, mtrials_per_s=total / t_st / 1e6, baseline_mtrials_per_s=total / t_np / 1e6,
                   overhead_pct=100 * (t_st / t_np - 1), combined_um=res.error_rms_m * 1e6,
                   baseline_combined_um=u_np * 1e6, repeats=repeats),
    ))

    old = budget.STRATIFIED_LIMIT
    budget.STRATIFIED_LIMIT = 0
    try:
        t_sm, res2 = _median_time(lambda: budget.distance_budget(inst, trials=n, rng=SEED), repeats)
    finally:
        budget.STRATIFIED_LIMIT = old
    rows.append(dict(
        name=f"budget_{total / 1e6:g}M_streamed", median_s=t_sm, baseline="numpy_per_distance",
        baseline_median_s=t_np, ratio=t_np / t_sm,
        extra=dict(trials=total, mtrials_per_s=total / t_sm / 1e6, combined_um=res2.error_rms_m * 1e6,
                   repeats=repeats),
    ))

    m = 100_000 if quick else 1_000_000
    d = np.random.default_rng(1).uniform(0.2, 20.0, m)
    t_s, _ = _median_time(lambda: budget.sample_distance_errors(inst, d, rng=SEED), repeats)
    rows.append(dict(
        name=f"sample_distance_errors_{m:.0e}".replace("+0", ""), median_s=t_s, baseline=None,
        baseline_median_s=None, ratio=None, extra=dict(draws=m, mdraws_per_s=m / t_s / 1e6),
    ))
    return rows


if __name__ == "__main__":
    for r in run(quick=True):
        print(r)
