"""Regenerate this example's files from multilat.network.synthetic.generator.synthetic_network
(population "sequential", seed 2026).

    PYTHONPATH=src python examples/network/sequential/generate.py

Writes obs.csv (station,target,head,distance_m,sigma_m), truth.csv (point,x_m,y_m,z_m) and
heads_truth.csv (head,offset_m) beside this script. tests/test_network_heads.py checks that the
shipped files are this function's output.
"""

from pathlib import Path

import numpy as np

from multilat.io import write_csv_atomic
from multilat.network.synthetic.generator import synthetic_network

SEED = 2026


def main(out: Path = Path(__file__).resolve().parent) -> None:
    net = synthetic_network(np.random.default_rng(SEED), population="sequential")
    o = net.obs
    heads = o.head_of_station
    write_csv_atomic(out / "obs.csv", ["station", "target", "head", "distance_m", "sigma_m"],
                     [[o.station_ids[i], o.target_ids[j], heads[i], f"{d:.9f}", f"{s:.1e}"]
                      for i, j, d, s in zip(o.station_index, o.target_index, o.distance_m, o.sigma_m)])
    write_csv_atomic(out / "truth.csv", ["point", "x_m", "y_m", "z_m"],
                     [[p, *(f"{v:.9f}" for v in x)] for p, x in
                      zip(o.station_ids + o.target_ids, np.vstack([net.station_xyz_m, net.target_xyz_m]))])
    first = {h: i for i, h in reversed(list(enumerate(heads)))}
    write_csv_atomic(out / "heads_truth.csv", ["head", "offset_m"],
                     [[h, f"{net.offset_m[first[h]]:.9f}"] for h in o.head_ids])


if __name__ == "__main__":
    main()
