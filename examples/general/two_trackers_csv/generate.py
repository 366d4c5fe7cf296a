"""Regenerate this example's files (seed 2027): two levelled laser trackers T1, T2 on 15 common
targets, distance + azimuth + elevation to each, σ 10 µm and 5 µrad; each tracker has an additive
constant (0.2 mm, -0.1 mm). Writes obs.csv and truth.csv (point,x_m,y_m,z_m; the trackers' headings
κ are 0.3 and 2.1 rad) beside this script:

    python examples/general/two_trackers_csv/generate.py

tests/test_general_csv.py checks that the shipped files are this script's output.
"""

import csv
from pathlib import Path

import numpy as np

SEED = 2027
SIG_D, SIG_A = 10e-6, 5e-6


def main(out: Path = Path(__file__).resolve().parent) -> None:
    rng = np.random.default_rng(SEED)
    targets = np.column_stack([rng.uniform(0, 6, 15), rng.uniform(2, 8, 15), rng.uniform(-1, 2, 15)])
    stations = {"T1": (np.array([0.0, 0.0, 0.0]), 0.3, 0.2e-3), "T2": (np.array([6.2, 0.4, 0.15]), 2.1, -0.1e-3)}
    rows = []
    for sid, (h, kappa, c) in stations.items():
        for j, t in enumerate(targets):
            d = t - h
            az = np.angle(np.exp(1j * (np.arctan2(d[1], d[0]) - kappa + SIG_A * rng.standard_normal())))
            el = np.arctan2(d[2], np.hypot(d[0], d[1])) + SIG_A * rng.standard_normal()
            dist = np.linalg.norm(d) + c + SIG_D * rng.standard_normal()
            rows.append([sid, f"P{j + 1:02d}", f"{dist:.9f}", SIG_D, f"{az:.10f}", f"{el:.10f}", SIG_A, SIG_A])
    with open(out / "obs.csv", "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["station", "target", "distance_m", "sigma_m", "azimuth_rad", "elevation_rad",
                    "sigma_azimuth_rad", "sigma_elevation_rad"])
        w.writerows(rows)
    with open(out / "truth.csv", "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["point", "x_m", "y_m", "z_m"])
        for sid, (h, _, _) in stations.items():
            w.writerow([sid, *(f"{v:.9f}" for v in h)])
        for j, t in enumerate(targets):
            w.writerow([f"P{j + 1:02d}", *(f"{v:.9f}" for v in t)])


if __name__ == "__main__":
    main()
