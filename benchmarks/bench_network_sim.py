"""Network-simulation benchmarks (issue 3 items 4 and 7).

* ``initial_values_random``: :func:`multilat.network.adjust.approximate.initial.initial_values` from distances alone on
  random well-conditioned networks (4-8 stations x 10-30 targets, gaps, ±5 mm offsets, 5 um noise;
  :func:`multilat.network.synthetic.generator.synthetic_network`, "well-conditioned"). ``median_s`` per network; ``extra``: the rate of
  networks whose adjustment from these values reaches the minimum reached from the truth (1e-8 m).
  Baseline: the naive method, random restarts (20) of the same Levenberg-Marquardt refinement, the
  lowest RMS kept — same networks, same run, same success criterion.
* ``simulate_small_volume_50``: the paper's §4.4 study (50 simulations of the small volume: initial
  values from distances + adjustment each); baseline: the same with every adjustment started from
  the truth (the cost of finding the initial values).

The machine is shared: each row records the 1-minute load average before it ran.
"""

from __future__ import annotations

import statistics
import time
from types import SimpleNamespace

import numpy as np

from common import load_avg as _load

SEED = 20200808




def _converged(net, iv):
    from multilat.network.adjust.distance.adjust import adjust

    truth = SimpleNamespace(station_xyz_m=net.station_xyz_m, target_xyz_m=net.target_xyz_m,
                            offset_m=net.offset_m)
    try:
        r1 = adjust(net.obs, initial=iv, snooping=False)
    except Exception:  # noqa: BLE001 - a failed adjustment is a failure to converge
        return False
    r0 = adjust(net.obs, initial=truth, snooping=False)
    P1 = np.vstack([r1.station_xyz_m, r1.target_xyz_m])
    P0 = np.vstack([r0.station_xyz_m, r0.target_xyz_m])
    D1 = np.linalg.norm(P1[:, None] - P1[None], axis=2)
    D0 = np.linalg.norm(P0[:, None] - P0[None], axis=2)
    return max(np.abs(D1 - D0).max(), np.abs(r1.offset_m - r0.offset_m).max()) < 1e-8


def _bench_initial(quick):
    from multilat.network.adjust.approximate import initial as ini
    from multilat.network.synthetic.generator import synthetic_network

    n = 30 if quick else 200
    load = _load()
    seeds = np.random.SeedSequence(SEED).spawn(n)
    nets = [synthetic_network(np.random.default_rng(c), population="well-conditioned") for c in seeds]
    ours_t, ours_ok, base_t, base_ok = [], 0, [], 0
    for k, net in enumerate(nets):
        t0 = time.perf_counter()
        iv = ini.initial_values(net.obs, rng=k)
        ours_t.append(time.perf_counter() - t0)
        ours_ok += _converged(net, iv)
        D, W = ini._distance_matrix(net.obs)
        t0 = time.perf_counter()
        best = ini._restarts(D, W, rng=np.random.default_rng(k), restarts=20)
        base_t.append(time.perf_counter() - t0)
        if best is not None:
            H, T, o, frame, rms, _ = best
            base_ok += _converged(net, SimpleNamespace(station_xyz_m=H, target_xyz_m=T, offset_m=o))
    mo, mb = statistics.median(ours_t), statistics.median(base_t)
    return {"name": "initial_values_random", "median_s": mo, "baseline": "random_restarts_20",
            "baseline_median_s": mb, "ratio": mb / mo,
            "extra": {"networks": n, "converged_rate": ours_ok / n, "baseline_converged_rate": base_ok / n,
                      "load_1min": load}}


def _bench_simulate(quick):
    from multilat.network.synthetic.configs import small_volume
    from multilat.network.montecarlo.simulate import simulate

    trials = 10 if quick else 50
    cfg = small_volume()
    load = _load()
    reps = 1 if quick else 3
    ours, base = [], []
    for _ in range(reps):
        t0 = time.perf_counter()
        simulate(cfg, trials=trials, rng=SEED)
        ours.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        simulate(cfg, trials=trials, rng=SEED, initial="truth")
        base.append(time.perf_counter() - t0)
    mo, mb = statistics.median(ours), statistics.median(base)
    return {"name": f"simulate_small_volume_{trials}", "median_s": mo, "baseline": "start_from_truth",
            "baseline_median_s": mb, "ratio": mb / mo,
            "extra": {"simulations_per_s": trials / mo, "load_1min": load}}


def run(quick: bool = False) -> list[dict]:
    """The benchmark rows (see the module docstring)."""
    return [_bench_initial(quick), _bench_simulate(quick)]


if __name__ == "__main__":  # pragma: no cover
    import json
    import sys

    print(json.dumps(run("--quick" in sys.argv), indent=2))
