"""Benchmark of the network adjustment (``multilat.network.adjust.distance.adjust``).

Rows
----
* ``adjust_s{s}_t{t}``: one full adjustment (Gauss-Newton on the Schur-reduced normal equations,
  covariances of every point, redundancy numbers, no data snooping) of a random network with
  ``s`` stations, ``t`` targets, 20 % of the observations missing, from initial values 1 mm off.
  Baseline (up to 300 targets): ``scipy.optimize.least_squares`` (trust-region, analytic dense
  Jacobian, no covariance) on the same problem and starting point -- what a generic code would do;
  ``extra`` gives both solutions' largest coordinate difference.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

SEED = 2020


def _median_time(fn, repeats):
    ts, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), out


def _scipy_baseline(obs, start):
    from scipy.optimize import least_squares

    from multilat.network.model.distance import dense_jacobian, residuals_and_jacobian

    s, t = obs.n_stations, obs.n_targets
    # 3-2-1 on stations 0, 1, 2 held at the start values (the same datum defect removed)
    free = np.ones(5 * s + 3 * t, bool)
    free[4:5 * s:5] = False
    free[[0, 1, 2, 6, 7, 12]] = False
    x0 = np.concatenate([np.column_stack([start.station_xyz_m, start.offset_m, np.zeros(s)]).ravel(),
                         start.target_xyz_m.ravel()])

    def unpack(xf):
        x = x0.copy()
        x[free] = xf
        g = x[:5 * s].reshape(s, 5)
        return g[:, :3], x[5 * s:].reshape(t, 3), g[:, 3], g[:, 4]

    def fun(xf):
        H, T, o, k = unpack(xf)
        r, _, _ = residuals_and_jacobian(obs.distance_m, H, T, o, k, obs.station_index, obs.target_index)
        return r / obs.sigma_m

    def jac(xf):
        H, T, o, k = unpack(xf)
        _, Js, Jt = residuals_and_jacobian(obs.distance_m, H, T, o, k, obs.station_index, obs.target_index)
        J = dense_jacobian(Js, Jt, obs.station_index, obs.target_index, s, t)
        return -J[:, free] / obs.sigma_m[:, None]

    sol = least_squares(fun, x0[free], jac=jac, method="trf", xtol=1e-10, ftol=1e-10, gtol=1e-10)
    H, T, _, _ = unpack(sol.x)
    return H, T


def run(quick: bool = False) -> list[dict]:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from network_truth import perturbed_start, random_network

    from multilat.network.adjust.distance.adjust import adjust
    from multilat.network.model.datum import rigid_fit

    sizes = [(6, 100)] if quick else [(6, 100), (8, 300), (8, 1000), (8, 10000), (12, 50000)]
    rows = []
    for s, t in sizes:
        tr = random_network(SEED, n_stations=s, n_targets=t, gap_fraction=0.2)
        start = perturbed_start(tr, SEED + 1, scale_m=1e-3)
        reps = 3 if t <= 1000 else 1
        med, res = _median_time(lambda: adjust(tr.obs, initial=start, snooping=False), reps)
        extra = {"stations": s, "targets": t, "observations": tr.obs.n_obs, "iterations": res.iterations,
                 "sigma0": round(res.sigma0, 4), "us_per_target": round(med / t * 1e6, 1)}
        base, ratio, bname = None, None, None
        if t <= 300:
            bname = "scipy least_squares (dense Jacobian, no covariance)"
            base, (H, T) = _median_time(lambda: _scipy_baseline(tr.obs, start), 1)
            a = np.vstack([res.station_xyz_m, res.target_xyz_m])
            b = np.vstack([H, T])
            R, tv = rigid_fit(b, a)
            extra["max_coord_diff_vs_baseline_m"] = float(np.abs(b @ R.T + tv - a).max())
            ratio = base / med
        rows.append({"name": f"adjust_s{s}_t{t}", "median_s": med, "baseline": bname,
                     "baseline_median_s": base, "ratio": ratio, "extra": extra})
    return rows


if __name__ == "__main__":
    for r in run(quick="--quick" in sys.argv):
        print(r)
