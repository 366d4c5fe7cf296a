"""The general Monte Carlo (issue 27 item 2) beside today's compiled distance-only one, same run.

The general network: the small volume's 4 stations and 14 targets with two heads each moved over two
stations, azimuths and elevations from two unlevelled set-ups, the nine scale bars and three weighted
control points (``tests/general_tracker_network.py``: 130 observation rows, 62 unknowns). Today's
compiled Monte Carlo takes none of those; its network of the same size is the distance-only small
volume (the same 18 points, its 56 distances, 58 unknowns: ``problem_from_config(small_volume())``).

Rows (trials/s; ``ratio`` = general trials/s / distance-only trials/s; the goal is >= 0.8):

* ``general_solve_vs_distance_only``: the solvers alone on pre-drawn observations, in-process:
  :func:`multilat.network.montecarlo.general.propagate.solve` (compiled chord steps) against
  :meth:`BatchedNetwork.solve` (compiled frozen Schur steps); runs interleaved (A B A B ...), medians.
* ``general_solve_distance_only_network``: the general solver on the distance-only small volume itself
  (the same 56 distances, one head per station, free network), against the same baseline: the price
  of the general kernel alone, without the 74 extra observation rows.
* ``general_solve_vs_distance_only_same_rows``: the same general solve against the compiled
  distance-only solver on a network with as many observation rows: the small volume's 4 stations
  and 33 targets (its 14 and 19 more drawn in the same volume, seed 7): 132 distances, 115 unknowns
  ("a network of the same size" read as the same number of rows; the first row reads it as the same points).
* ``general_propagate_vs_distance_only``: the whole in-process ``propagate`` of each (drawing, solving,
  summaries; gaussian noise; default map: threads), same trials, as many interleaved repeats as the
  solver rows (3 let one burst of load set the median: 0.55 in one run of 2026-11-27).

Every row also records ``cpu_ratio``: the ratio of the median process CPU seconds (all threads) of
the two, the work done; the wall ``ratio`` is the goal's measure.

Each row records the 1-minute load average before it ran (the machine is shared: compare ratios).
Quick mode: 10 000 trials, 7 interleaved repeats (3 left the median of a 0.1 s run at the mercy of one
burst of load on the shared machine: 0.67-0.89 in five runs); full: 100 000 trials, 5.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from common import load_avg

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))


def _interleaved(fa, fb, reps):
    """Medians of ``reps`` interleaved runs (A B A B ...): wall seconds of each, their runs, and the
    ratio of the medians of the process CPU seconds (all threads: the work, less at the mercy of the
    shared machine's load than the wall time)."""
    ta, tb, ca, cb = [], [], [], []
    for _ in range(reps):
        for f, out, cpu in ((fa, ta, ca), (fb, tb, cb)):
            c0, t0 = time.process_time(), time.perf_counter()
            f()
            out.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
    return float(np.median(ta)), float(np.median(tb)), ta, tb, float(np.median(cb) / np.median(ca))


def _row(name, t_new, t_old, trials, baseline, **extra):
    return {"name": name, "median_s": t_new, "baseline": baseline, "baseline_median_s": t_old,
            "ratio": t_old / t_new,
            "extra": {"trials": trials, "trials_per_s": trials / t_new, "baseline_trials_per_s": trials / t_old,
                      **extra}}


def _same_rows(cfg):
    """The small volume with 19 more targets drawn uniformly in its targets' bounding box (seed 7):
    4 x 33 = 132 distances, about the general network's 130 rows."""
    import dataclasses

    lo, hi = cfg.target_xyz_m.min(0), cfg.target_xyz_m.max(0)
    extra = lo + np.random.default_rng(7).random((19, 3)) * (hi - lo)
    return dataclasses.replace(cfg, target_ids=cfg.target_ids + tuple(f"x{k}" for k in range(19)),
                               target_xyz_m=np.vstack([cfg.target_xyz_m, extra]))


def run(quick: bool = False) -> list[dict]:
    from general_tracker_network import tracker_network

    from multilat.network.synthetic.configs import small_volume
    from multilat.network.adjust.general import adjust_network
    from multilat.network.adjust.general.adjust import AdjustOptions
    from multilat.network.montecarlo.general.propagate import draw, freeze, propagate, solve
    from multilat.network.montecarlo.propagate import problem_from_config
    from multilat.network.montecarlo.propagate import propagate as old_propagate

    trials = 10_000 if quick else 100_000
    reps = 7 if quick else 5
    rows = []
    adj = adjust_network(tracker_network()[0])
    fr = freeze(adj.system, adj.result)
    obs = draw(fr, trials, np.random.default_rng(1))
    pb = problem_from_config(small_volume(), sigma_m=4.7e-6)
    net = pb.network
    dist = pb.distance_m + np.random.default_rng(2).standard_normal((trials, pb.distance_m.size)) * 4.7e-6
    solve(fr, obs[:100])                                   # compile / load the kernels
    net.solve(dist[:100])
    sol = solve(fr, obs[:2000])
    size = dict(rows_general=fr.n_rows, unknowns_general=int(len(fr.free)), rows_distance_only=int(net.n_obs),
                unknowns_distance_only=int(net.n_params),
                chord_steps_mean=float(sol.iterations.mean()), full_gauss_newton=int(sol.full_gauss_newton.sum()),
                distance_only_iterations_mean=float(net.solve(dist[:2000]).iterations.mean()))
    load = load_avg()
    t_new, t_old, ta, tb, cpu = _interleaved(lambda: solve(fr, obs), lambda: net.solve(dist), reps)
    rows.append(_row("general_solve_vs_distance_only", t_new, t_old, trials,
                     "compiled distance-only BatchedNetwork.solve, small volume (same points)", load_avg_1min=load,
                     goal_ratio=0.8, runs_s=ta, baseline_runs_s=tb, cpu_ratio=cpu, **size))

    pb_rows = problem_from_config(_same_rows(small_volume()), sigma_m=4.7e-6)
    dist_rows = pb_rows.distance_m + np.random.default_rng(4).standard_normal((trials, pb_rows.distance_m.size)) * 4.7e-6
    pb_rows.network.solve(dist_rows[:100])
    load = load_avg()
    t_new, t_old, ta, tb, cpu = _interleaved(lambda: solve(fr, obs), lambda: pb_rows.network.solve(dist_rows), reps)
    rows.append(_row("general_solve_vs_distance_only_same_rows", t_new, t_old, trials,
                     "compiled distance-only BatchedNetwork.solve, 4 stations x 33 targets (same number of rows)",
                     load_avg_1min=load, goal_ratio=0.8, runs_s=ta, baseline_runs_s=tb, cpu_ratio=cpu,
                     rows_general=fr.n_rows,
                     rows_distance_only=int(pb_rows.network.n_obs), unknowns_distance_only=int(pb_rows.network.n_params),
                     distance_only_iterations_mean=float(pb_rows.network.solve(dist_rows[:2000]).iterations.mean())))

    plain = adjust_network(tracker_network(extras=False)[0], options=AdjustOptions(datum="free"))
    fp = freeze(plain.system, plain.result)
    obs_p = draw(fp, trials, np.random.default_rng(3))
    solve(fp, obs_p[:100])
    load = load_avg()
    t_new, t_old, ta, tb, cpu = _interleaved(lambda: solve(fp, obs_p), lambda: net.solve(dist), reps)
    rows.append(_row("general_solve_distance_only_network", t_new, t_old, trials,
                     "compiled distance-only BatchedNetwork.solve, same network", load_avg_1min=load,
                     runs_s=ta, baseline_runs_s=tb, cpu_ratio=cpu, rows_general=fp.n_rows,
                     unknowns_general=int(len(fp.free))))

    propagate(adj.system, adj.result, trials=1000, rng=1, pairs=())
    old_propagate(pb, trials=1000, rng=1, noise="gaussian")
    load = load_avg()
    t_new, t_old, ta, tb, cpu = _interleaved(lambda: propagate(adj.system, adj.result, trials=trials, rng=1, pairs=()),
                                        lambda: old_propagate(pb, trials=trials, rng=1, noise="gaussian",
                                                              keep_samples=False), reps)
    rows.append(_row("general_propagate_vs_distance_only", t_new, t_old, trials,
                     "multilat.network.montecarlo.propagate.propagate (distance-only, compiled), gaussian, small volume",
                     load_avg_1min=load, runs_s=ta, baseline_runs_s=tb, cpu_ratio=cpu))
    return rows


if __name__ == "__main__":  # pragma: no cover
    for r in run(quick="--quick" in sys.argv):
        print(r)
