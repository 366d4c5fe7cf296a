"""Regenerate this example's files from multilat.network.synthetic.generator.synthetic_network
(population "mixed", seed 2028).

    PYTHONPATH=src python examples/network/mixed/generate.py

A mixed campaign: four multilateration heads (distances) and two laser trackers (distance, azimuth and
elevation to every target, σ from their MPE specification: the trackers of
examples/instruments/heads_and_trackers.toml). Writes obs.csv (station,target,distance_m,sigma_m,
azimuth_rad,elevation_rad,sigma_azimuth_rad,sigma_elevation_rad; the heads' rows have no angles),
truth.csv (point,x_m,y_m,z_m), offsets_truth.csv (station,offset_m) and orientation_truth.csv
(station,omega_rad,phi_rad,kappa_rad) beside this script. tests/test_angles_adjust.py checks that the
shipped files are this function's output and that the adjustment recovers the truth.
"""

from pathlib import Path

import numpy as np

from multilat.io import write_csv_atomic
from multilat.network.synthetic.generator import synthetic_network

SEED = 2028


def _f(v):
    return "" if not np.isfinite(v) else f"{v:.12g}"


def main(out: Path = Path(__file__).resolve().parent) -> None:
    net = synthetic_network(np.random.default_rng(SEED), population="mixed")
    ori = net.orientation_rad
    o = net.obs
    write_csv_atomic(out / "obs.csv", ["station", "target", "distance_m", "sigma_m", "azimuth_rad", "elevation_rad",
                                       "sigma_azimuth_rad", "sigma_elevation_rad"],
                     [[o.station_ids[i], o.target_ids[j], f"{d:.9f}", f"{s:.4e}", _f(a), _f(e), _f(sa), _f(se)]
                      for i, j, d, s, a, e, sa, se in zip(o.station_index, o.target_index, o.distance_m, o.sigma_m,
                                                          o.azimuth_rad, o.elevation_rad, o.sigma_azimuth_rad,
                                                          o.sigma_elevation_rad)])
    write_csv_atomic(out / "truth.csv", ["point", "x_m", "y_m", "z_m"],
                     [[p, *(f"{v:.9f}" for v in x)] for p, x in
                      zip(o.station_ids + o.target_ids, np.vstack([net.station_xyz_m, net.target_xyz_m]))])
    write_csv_atomic(out / "offsets_truth.csv", ["station", "offset_m"],
                     [[sid, f"{net.offset_m[i]:.9f}"] for i, sid in enumerate(o.station_ids)])
    write_csv_atomic(out / "orientation_truth.csv", ["station", "omega_rad", "phi_rad", "kappa_rad"],
                     [[sid, *(f"{v:.12g}" for v in ori[i])] for i, sid in enumerate(o.station_ids)
                      if np.isfinite(o.sigma_azimuth_rad[o.station_index == i]).any()])


if __name__ == "__main__":
    main()
