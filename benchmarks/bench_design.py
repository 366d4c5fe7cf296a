"""Network-design benchmarks (issue 11, speed goals).

* ``design_eval_4x14``: one pre-analysis criterion evaluation (``max_u95``) of the paper's small
  volume (4 heads x 14 targets, 56 distances, 58 free parameters), ``median_s`` over 200 calls.
  Baseline: :func:`multilat.network.adjust.distance.adjust.adjust` on the same exact distances started at the truth
  (the way to get the same covariance without the design module). Goal: <= 1 ms.
* ``design_cli_4x100``: the whole command ``multilat design CUBE100.toml --json`` (4 heads, 100
  targets on a 5 x 5 x 4 grid in a 1 m cube, heads in a 4 m box, sigma 4.7 um, multistart, 4 starts,
  4000 evaluations), subprocess wall time, with ``[search] evaluation = "auto"`` (the search's
  evaluator :mod:`multilat.network.design.fast`). Baseline in the same run: the same command with
  ``evaluation = "dense"`` (the former dense normal matrix). Goal: <= 30 s.
* ``design_cli_10x1000``: ``multilat design ROOM1000.toml --json``: 10 heads in a 10 x 7 x 3 m
  box around 1000 targets (10 x 10 x 10 grid in an 8 x 5 x 2.5 m volume), sigma 4.7 um, one
  multistart Powell search of 1500 evaluations. Baseline: one dense evaluation of the start
  layout times the evaluations used (the dense search would not finish: extrapolated, stated so).
  Goal: <= 5 min.

The machine is shared: each row records the 1-minute load average before it ran.
"""

from __future__ import annotations

import statistics
import time
from types import SimpleNamespace

import numpy as np

from common import load_avg as _load

SEED = 20200808




def _bench_eval(quick):
    from multilat.network.adjust.distance.adjust import adjust
    from multilat.network.synthetic.configs import small_volume
    from multilat.network.design import Layout, SigmaModel, criterion_value, layout_observations

    cfg = small_volume()
    lay = Layout(cfg.station_ids, cfg.station_xyz_m, cfg.target_ids, cfg.target_xyz_m)
    sig = SigmaModel(4.7e-6)
    load = _load()
    n = 20 if quick else 200
    ours = []
    for _ in range(n):
        t0 = time.perf_counter()
        criterion_value("max_u95", lay, sig)
        ours.append(time.perf_counter() - t0)
    obs = layout_observations(lay, 4.7e-6, cfg.offset_m)
    start = SimpleNamespace(station_xyz_m=cfg.station_xyz_m, target_xyz_m=cfg.target_xyz_m, offset_m=cfg.offset_m)
    base = []
    for _ in range(max(3, n // 20)):
        t0 = time.perf_counter()
        adjust(obs, initial=start, snooping=False)
        base.append(time.perf_counter() - t0)
    mo, mb = statistics.median(ours), statistics.median(base)
    return {"name": "design_eval_4x14", "median_s": mo, "baseline": "adjust_exact_from_truth",
            "baseline_median_s": mb, "ratio": mb / mo, "extra": {"load_1min": load, "goal_s": 1e-3}}


_CUBE100 = """
[targets]
box_min_m = [0, 0, 0]
box_max_m = [1, 1, 1]
grid = [5, 5, 4]
[heads]
count = 4
box_min_m = [-1.5, -1.5, 0]
box_max_m = [2.5, 2.5, 2.0]
min_range_m = 0.2
[instrument]
sigma_um = 4.7
[search]
starts = 4
max_evaluations = %d
evaluation = "%s"
"""

_ROOM1000 = """
[targets]
box_min_m = [1, 1, 0.25]
box_max_m = [9, 6, 2.75]
grid = [10, 10, 10]
[heads]
count = 10
box_min_m = [0, 0, 0]
box_max_m = [10, 7, 3]
min_range_m = 0.2
[instrument]
sigma_um = 4.7
[search]
starts = 1
max_evaluations = %d
evaluation = "%s"
"""


def _design_cli(text, tmp, name, timeout):
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    p = Path(tmp) / name
    p.write_text(text)
    exe = Path(sys.executable).with_name("multilat")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-c", "from multilat.cli import run; run()"]
    src = str(Path(__file__).resolve().parents[1] / "src")
    env = dict(os.environ, PYTHONPATH=src + os.pathsep + os.environ.get("PYTHONPATH", ""))
    for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):   # as run.py: small systems
        env.setdefault(k, "1")
    t0 = time.perf_counter()
    try:
        r = subprocess.run(cmd + ["design", str(p), "--json", "--seed", "1"], capture_output=True, text=True,
                           env=env, timeout=timeout)
    except subprocess.TimeoutExpired:
        return float("inf"), None          # a lower bound: the row says so
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise RuntimeError(f"multilat design failed: {r.stderr.strip()[-400:]}")
    return wall, json.loads(r.stdout)


def _bench_cli_4x100(quick):
    import tempfile

    evals = 400 if quick else 4000
    with tempfile.TemporaryDirectory() as tmp:
        load = _load()
        new, doc = _design_cli(_CUBE100 % (evals, "auto"), tmp, "new.toml", 1800)
        load2 = _load()
        old, doc_old = _design_cli(_CUBE100 % (evals, "dense"), tmp, "old.toml", 3600)
    return {"name": "design_cli_4x100", "median_s": new, "baseline": "same_command_dense_evaluation",
            "baseline_median_s": old, "ratio": old / new,
            "extra": {"evaluations": doc["search"]["evaluations"], "criterion_m": doc["criterion_m"],
                      "start_criterion_m": doc["start_criterion_m"],
                      "dense_criterion_m": None if doc_old is None else doc_old["criterion_m"],
                      "dense_timed_out_s": 3600 if doc_old is None else None,
                      "load_1min": load, "load_1min_before_baseline": load2, "goal_s": 30.0}}


def _bench_cli_10x1000(quick):
    import tempfile

    from multilat.network.design import Layout, SigmaModel, criterion_value
    from multilat.network.design.search import corner_start

    evals = 60 if quick else 1500
    with tempfile.TemporaryDirectory() as tmp:
        load = _load()
        wall, doc = _design_cli(_ROOM1000 % (evals, "auto"), tmp, "room.toml", 1800)
    g = np.stack(np.meshgrid(np.linspace(1, 9, 10), np.linspace(1, 6, 10), np.linspace(0.25, 2.75, 10),
                             indexing="ij"), -1).reshape(-1, 3)
    h = corner_start(10, [0, 0, 0], [10, 7, 3], np.random.default_rng(1))
    lay = Layout(tuple("ABCDEFGHIJ"), h, tuple(f"T{k + 1}" for k in range(len(g))), g)
    t0 = time.perf_counter()
    criterion_value("max_u95", lay, SigmaModel(4.7e-6), method="dense")
    dense1 = time.perf_counter() - t0
    n = doc["search"]["evaluations"]
    return {"name": "design_cli_10x1000", "median_s": wall, "baseline": "dense_eval_x_evaluations (extrapolated)",
            "baseline_median_s": dense1 * n, "ratio": dense1 * n / wall,
            "extra": {"evaluations": n, "dense_eval_s": dense1, "criterion_m": doc["criterion_m"],
                      "start_criterion_m": doc["start_criterion_m"], "load_1min": load, "goal_s": 300.0}}


def run(quick: bool = False) -> list[dict]:
    """The benchmark rows (see the module docstring)."""
    return [_bench_eval(quick), _bench_cli_4x100(quick), _bench_cli_10x1000(quick)]


if __name__ == "__main__":  # pragma: no cover
    import json
    import sys

    print(json.dumps(run("--quick" in sys.argv), indent=2))
