"""Regenerate the campaign example files (deterministic): ``python examples/campaign/make_example.py``.

- ``raw.csv``          56 raw optical paths of the simulated large-volume campaign (seed 000 §4.2
                       conditions), with times and elevation angles, sensor and instrument errors drawn
                       with seed 2020;
- ``environment.csv``  the sensor log (4 sensors at 0.3/0.7/1.4/2.4 m, one reading every 5 min);
- ``heights.csv``      heights of the heads and targets in the sensors' frame (network z + 1.10 m);
- ``truth.csv``        the true distances (with the heads' offsets), for comparison;
- ``two_face.csv``     a two-face session of head A (explicit 3D gimbal, Table III-size offsets/tilts).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from multilat import gimbal, instrument
from multilat.campaign.worked import (large_volume_geometry, simulate_campaign, write_environment_csv,
                                      write_heights_csv, write_raw_csv)
from multilat.io import write_csv_atomic

HERE = Path(__file__).resolve().parent


def main(seed: int = 2020) -> None:
    inst = instrument.load_instrument("seed2020")
    sids, sxyz, tids, txyz, off, floor = large_volume_geometry()
    camp = simulate_campaign(sids, sxyz, tids, txyz, offset_m=off, instrument=inst, rng=seed,
                             sensor_errors=True, model_errors=True, exact_path=False, floor_offset_m=floor)
    write_raw_csv(HERE / "raw.csv", camp)
    write_environment_csv(HERE / "environment.csv", camp.log)
    write_heights_csv(HERE / "heights.csv", camp.heights)
    write_csv_atomic(HERE / "truth.csv", ["station", "target", "true_distance_m", "offset_m"],
                     zip(camp.raw.station_ids, camp.raw.target_ids, camp.true_distance_m, camp.offset_m))

    rng = np.random.default_rng(seed)
    kw = dict(a_m=150e-6, c_m=-200e-6, alpha_rad=np.radians(0.1), gamma_rad=np.radians(-0.05))
    rows = []
    for j, (r, phi) in enumerate([(2.0, 0.05), (5.0, -0.1), (9.0, 0.2)]):
        for face, ang in (("I", phi), ("II", np.pi - phi)):
            for _ in range(5):
                d = float(gimbal.head_measured_distance_3d(r, toh_m=inst.heads["A"].toh_m, elevation_rad=ang, **kw))
                rows.append(["A", f"T{j + 1}", face, d + rng.normal(0, 1e-6), phi, 1e-6, r if j == 0 else ""])
    write_csv_atomic(HERE / "two_face.csv", ["head", "target", "face", "distance_m", "elevation_rad", "sigma_m",
                                             "reference_distance_m"], rows)


if __name__ == "__main__":
    main()
