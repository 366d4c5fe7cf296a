"""Network-design benchmarks (issue 11, speed goals).

* ``design_eval_4x14``: one pre-analysis criterion evaluation (``max_u95``) of the paper's small
  volume (4 heads x 14 targets, 56 distances, 58 free parameters), ``median_s`` over 200 calls.
  Baseline: :func:`multilat.network.adjust.adjust` on the same exact distances started at the truth
  (the way to get the same covariance without the design module). Goal: <= 1 ms.
* ``design_optimise_4x100``: :func:`optimise_heads` for 4 heads and 100 targets (a 5 x 5 x 4 grid in
  a 1 m cube, heads in a 4 m box, sigma 4.7 um), multistart, 4 starts, 4000 evaluations. Goal: <= 30 s.
  Baseline: the time of 4000 single evaluations (the search's own overhead is the difference).

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
    from multilat.network.adjust import adjust
    from multilat.network.configs import small_volume
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


def _bench_optimise(quick):
    from multilat.network.design import Layout, SigmaModel, criterion_value, optimise_heads

    g = np.stack(np.meshgrid(np.linspace(0, 1, 5), np.linspace(0, 1, 5), np.linspace(0, 1, 4),
                             indexing="ij"), -1).reshape(-1, 3)
    evals = 400 if quick else 4000
    load = _load()
    t0 = time.perf_counter()
    r = optimise_heads(g, count=4, box_min_m=[-1.5, -1.5, 0], box_max_m=[2.5, 2.5, 2.0], sigma=4.7e-6,
                       starts=4, max_evaluations=evals, min_range_m=0.2, rng=SEED)
    mo = time.perf_counter() - t0
    lay = r.layout
    sig = SigmaModel(4.7e-6)
    t0 = time.perf_counter()
    for _ in range(50):
        criterion_value("max_u95", Layout(lay.station_ids, lay.station_xyz_m, lay.target_ids, g), sig)
    per = (time.perf_counter() - t0) / 50
    return {"name": "design_optimise_4x100", "median_s": mo, "baseline": "bare_evaluations",
            "baseline_median_s": per * r.evaluations, "ratio": per * r.evaluations / mo,
            "extra": {"evaluations": r.evaluations, "eval_s": per, "start_criterion_m": r.start_criterion_m,
                      "criterion_m": r.criterion_m, "load_1min": load, "goal_s": 30.0}}


def run(quick: bool = False) -> list[dict]:
    """The benchmark rows (see the module docstring)."""
    return [_bench_eval(quick), _bench_optimise(quick)]


if __name__ == "__main__":  # pragma: no cover
    import json
    import sys

    print(json.dumps(run("--quick" in sys.argv), indent=2))
