"""Monte Carlo of the small volume end to end (issue 12 item 1): whole ``multilat propagate`` commands.

Rows (each beside its baseline, same run):

* ``draw_model_small_volume``: drawing the distance model's errors for T trials x 56 distances with
  :func:`multilat.distance_errors.draw_errors` (one compiled pass) against the plain-numpy draw of the
  same model, :func:`multilat.budget.sample_distance_errors` per head (the path ``propagate`` used
  before). ratio = numpy time / compiled time.
* ``cli_propagate_model``: ``multilat propagate small-volume --trials T --json > /dev/null`` as a
  subprocess (start-up, drawing, solving, statistics, JSON), trials/s; baseline: the batched solver
  alone on the same trials (:meth:`BatchedNetwork.solve` of gaussian distances, in-process), so the
  ratio says what the rest of the command costs next to the solve. Goal: >= 1e5 trials/s.
* ``cli_propagate_gaussian``: the same command with ``--noise gaussian``. Goal: >= 1.5e5 trials/s.
* ``solve_general_small_volume``: the general batched solver (:mod:`multilat.network.montecarlo.batched_coupled`:
  heads over several stations, scale bars, control; numpy chord iterations) on the same network and
  trials as the specialised batched solver (compiled), which is the baseline (ratio = batched time /
  general time: below 1, the price of generality).
* ``cli_propagate_model_dask2``: the model command with ``--workers 2`` (a local Dask cluster) against
  the in-process command of the row above (ratio = in-process time / Dask time). Goal: >= 1.8x.
* ``cli_propagate_model_dask2_over_dask1``: ``--workers 2`` against ``--workers 1`` (Dask's scaling
  with its worker count), 5x the trials in full mode, one run each.

With ``BENCH_BASELINE_SRC=/path/to/old/src`` the model and gaussian commands also run on that tree,
interleaved with the current one (rows gain ``before_median_s`` and ``before_over_after``).

Each row records the 1-minute load average before it ran (the machine is shared: compare ratios).
Quick mode: 20 000 trials, one repeat; full: 200 000 trials, median of 3.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from common import load_avg, median_time

ROOT = Path(__file__).resolve().parent.parent
CLI = [sys.executable, "-c", "from multilat.cli import run; run()"]


def _median(f, reps):
    return median_time(f, reps)[0]


#: With ``BENCH_BASELINE_SRC=/path/to/old/src`` the two in-process commands also run on that source
#: tree, interleaved with the current one (A B A B ...: the shared machine's drifts hit both alike);
#: the rows then record ``before_median_s`` and ``before_over_after``.
BASE_SRC = os.environ.get("BENCH_BASELINE_SRC")


def _command(*args, src=None):
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    if src:
        pp = os.environ.get("PYTHONPATH")
        env["PYTHONPATH"] = src if not pp else src + os.pathsep + pp

    def run():
        subprocess.run([*CLI, "propagate", "small-volume", *args, "--json"], check=True, env=env,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return run


def _interleaved(args, reps):
    """Median wall time of the command (current tree) and, with BENCH_BASELINE_SRC, of the baseline
    tree's, run alternately; extra keys for the row."""
    import time

    now, before = [], []
    cmds = [(_command(*args), now)] + ([(_command(*args, src=BASE_SRC), before)] if BASE_SRC else [])
    for _ in range(reps):
        for f, out in cmds:
            t0 = time.perf_counter()
            f()
            out.append(time.perf_counter() - t0)
    med = float(np.median(now))
    if not before:
        return med, {}
    mb = float(np.median(before))
    return med, {"before_median_s": mb, "before_over_after": mb / med, "before_src": BASE_SRC,
                 "runs_s": now, "before_runs_s": before}


def _row(name, t, baseline, tb, trials, **extra):
    return {"name": name, "median_s": t, "baseline": baseline, "baseline_median_s": tb,
            "ratio": None if tb is None else tb / t,
            "extra": {"trials": trials, "trials_per_s": trials / t, **extra}}


def run(quick: bool = False) -> list[dict]:
    from multilat import budget, instrument as instr
    from multilat.distance_errors import draw_errors, error_model
    from multilat.network.synthetic.configs import small_volume
    from multilat.network.montecarlo.propagate import problem_from_config

    trials = 20_000 if quick else 200_000
    reps = 1 if quick else 3
    rows = []
    pb = problem_from_config(small_volume(), sigma_m=4.7e-6)
    inst = instr.load_instrument("seed2020")
    d = pb.distance_m
    si = pb.network.station_index
    model = error_model(inst, pb.heads)
    draw_errors(model, si, d, 10, np.random.default_rng(0))          # compile / load the cache
    load = load_avg()
    t_fused = _median(lambda: draw_errors(model, si, d, trials, np.random.default_rng(1)), reps)

    def numpy_draw():
        rng = np.random.default_rng(1)
        for i, hd in enumerate(pb.heads):
            sel = np.nonzero(si == i)[0]
            budget.sample_distance_errors(inst, d[sel], rng=rng, head=hd, trials=trials)
    t_numpy = _median(numpy_draw, reps)
    rows.append(_row("draw_model_small_volume", t_fused, "numpy budget.sample_distance_errors", t_numpy, trials,
                     distances=int(d.size), load_avg_1min=load))

    net = pb.network
    rng = np.random.default_rng(2)
    dist = d + rng.standard_normal((trials, d.size)) * 4.7e-6
    net.solve(dist[:100])
    t_solve = _median(lambda: net.solve(dist), reps)

    from multilat.network.montecarlo.batched_coupled import CoupledBatchedNetwork

    s = net.n_stations
    gen = CoupledBatchedNetwork(net.station_index, net.target_index, net.sigma_m, np.arange(s),
                                net.station_xyz_m, net.offset_m, np.zeros(s), net.target_xyz_m,
                                np.zeros(s, bool), np.zeros(net.n_targets, bool), np.ones(s, bool),
                                np.zeros(s, bool), datum=net.datum)
    n_gen = trials // 10
    gen.solve(dist[:100])
    load = load_avg()
    t_gen = _median(lambda: gen.solve(dist[:n_gen]), reps)
    t_bat = _median(lambda: net.solve(dist[:n_gen]), reps)
    rows.append(_row("solve_general_small_volume", t_gen, "specialised batched solver, same trials", t_bat,
                     n_gen, load_avg_1min=load))

    _command("--trials", "2000")()                                    # warm caches once
    if BASE_SRC:
        _command("--trials", "2000", src=BASE_SRC)()
    load = load_avg()
    t_model, ex = _interleaved(("--trials", str(trials)), reps)
    rows.append(_row("cli_propagate_model", t_model, "batched solver alone (in-process)", t_solve, trials,
                     load_avg_1min=load, goal_trials_per_s=1e5, **ex))
    load = load_avg()
    t_gauss, ex = _interleaved(("--trials", str(trials), "--noise", "gaussian"), reps)
    rows.append(_row("cli_propagate_gaussian", t_gauss, "batched solver alone (in-process)", t_solve, trials,
                     load_avg_1min=load, goal_trials_per_s=1.5e5, **ex))
    load = load_avg()
    t_dask = _median(_command("--trials", str(trials), "--workers", "2"), reps)
    rows.append(_row("cli_propagate_model_dask2", t_dask, "the same command in-process", t_model, trials,
                     load_avg_1min=load, goal_speedup=1.8))
    # Dask's own scaling: 2 worker processes over 1 (the in-process run above already uses both cores,
    # so no number of processes on 2 cores can beat it by 1.8x); a longer run, where the cluster start
    # (~2 s) counts less
    n_dask = trials if quick else 5 * trials
    load = load_avg()
    t_d2 = _median(_command("--trials", str(n_dask), "--workers", "2"), 1)
    t_d1 = _median(_command("--trials", str(n_dask), "--workers", "1"), 1)
    rows.append(_row("cli_propagate_model_dask2_over_dask1", t_d2, "the same command, one Dask worker", t_d1,
                     n_dask, load_avg_1min=load))
    return rows


if __name__ == "__main__":  # pragma: no cover
    for r in run(quick="--quick" in sys.argv):
        print(r)
