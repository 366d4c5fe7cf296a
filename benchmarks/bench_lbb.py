"""Benchmark of the laser ball bar (seed 003).

Rows
----
* ``trilaterate_1M``: the vectorised closed form (eq. 1) for 10^6 edge sets; baseline: a per-point
  iterative solve (``scipy.optimize.least_squares`` from the centroid, 2000 points, scaled to 10^6),
  the way a generic multilateration code would do it.
* ``procedure_volume``: the §5 procedure (2000 / 100 / 100 draws) over the default work volume;
  baseline: the direct propagation with the same cloud size (100 trials) at the same points.
* ``length_change_100k``: 10^5 evaluations of the HTM length-change model (§4.1: two poses, the
  reading solver, gravity sag by Castigliano's method).
"""

from __future__ import annotations

import statistics
import time

import numpy as np

SEED = 2007


def _median_time(fn, repeats):
    ts = []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), out


def run(quick: bool = False) -> list[dict]:
    from scipy.optimize import least_squares

    from multilat.lbb.config import load_config
    from multilat.lbb.model import MECH_SOURCES, BarModel, pose_distributions, true_length_change
    from multilat.lbb.simulate import base_xyz, run_direct, run_procedure, volume_points
    from multilat.lbb.trilateration import edges_from_points, trilaterate

    cfg = load_config()
    rng = np.random.default_rng(SEED)
    repeats = 1 if quick else 3
    rows = []

    # trilateration
    n = 100_000 if quick else 1_000_000
    base = base_xyz(cfg)
    pts = np.c_[rng.uniform(0, 0.564, n), rng.uniform(0, 0.488, n), rng.uniform(0.05, 0.4, n)]
    e = edges_from_points(base, pts)
    t_ours, res = _median_time(lambda: trilaterate(*e.T, validate=False), repeats)
    err = float(np.max(np.abs(res.xyz_m - pts)))
    m = 200 if quick else 2000

    def baseline():
        out = np.empty((m, 3))
        for i in range(m):
            d = e[i, 3:]
            out[i] = least_squares(lambda p: np.linalg.norm(base - p, axis=1) - d,
                                   x0=np.array([0.282, 0.163, 0.2]), xtol=1e-15, ftol=1e-15).x
        return out

    t_b, out_b = _median_time(baseline, 1)
    t_b_scaled = t_b * n / m
    rows.append({"name": f"trilaterate_{n // 1000}k", "median_s": t_ours, "baseline": "scipy least_squares per point",
                 "baseline_median_s": t_b_scaled, "ratio": t_b_scaled / t_ours,
                 "extra": {"points_per_s": n / t_ours, "max_roundtrip_error_m": err,
                           "baseline_points_timed": m,
                           "baseline_max_error_m": float(np.max(np.abs(out_b - pts[:m])))}})

    # procedure over the volume vs direct with the same cloud size
    vp = volume_points(cfg, 4 if quick else None)
    t_p, sim = _median_time(lambda: run_procedure(cfg, vp, rng=SEED), repeats)
    t_d, _ = _median_time(lambda: run_direct(cfg, vp, trials=cfg.monte_carlo.point_draws, rng=SEED), repeats)
    rows.append({"name": "procedure_volume", "median_s": t_p, "baseline": "direct, same cloud size",
                 "baseline_median_s": t_d, "ratio": t_d / t_p,
                 "extra": {"points": len(vp), "points_per_s": len(vp) / t_p,
                           "max_std_um": sim.max_std_m * 1e6}})

    # HTM length-change model
    k = 20_000 if quick else 100_000
    bar = BarModel.from_config(cfg)
    d = pose_distributions(cfg)
    pf = {s: d[s].sample(rng, k) for s in MECH_SOURCES}
    pt = {s: d[s].sample(rng, k) for s in MECH_SOURCES}

    def dl():
        return true_length_change(bar, from_length_m=0.3, from_elevation_rad=0.0, from_pose=dict(pf),
                                  to_length_m=0.6, to_elevation_rad=0.5, to_pose=dict(pt),
                                  thermal_m=d["thermal_m"].sample(rng, k), dmi_m=d["dmi_m"].sample(rng, k))

    t_l, _ = _median_time(dl, repeats)
    rows.append({"name": f"length_change_{k // 1000}k", "median_s": t_l, "baseline": None,
                 "baseline_median_s": None, "ratio": None,
                 "extra": {"evaluations_per_s": k / t_l}})
    return rows


if __name__ == "__main__":
    for r in run(quick=True):
        print(r)
