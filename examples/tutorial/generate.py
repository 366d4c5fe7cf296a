"""Regenerate the tutorial's files (docs/tutorial.md; seed 2028) beside this script:

    python examples/tutorial/generate.py

A hall 8 x 5 x 3 m (x east, y north, z up, floor at z = 0, metres). Six multilateration heads H1..H6
on tripods around 15 targets P01..P15 (four of them on the floor), each head reading every target
once: ``obs.csv`` (distance, σ 5 µm; each head has an additive offset; ``obs_no_sigma.csv`` the
same without the σ column). ``points.csv``: four
targets (P01, P02 on the floor, P05, P09 raised) measured in the hall's frame to 1 µm, as a surveyor
would hand them over, and every other head and target to about 2 cm (a tape, a drawing).
``trackers.csv``: two levelled laser trackers T1, T2 on the same 15 targets, distance + azimuth +
elevation (σ 10 µm, 5 µrad; azimuth counter-clockwise from the tracker's own zero, which is turned
by its heading κ). ``heads.csv``: the heads' rows of points.csv (where
this campaign put them, for ``multilat design --evaluate``). ``truth.csv`` and ``offsets_truth.csv``: what the adjustment should recover.
tests/test_tutorial.py checks that the shipped files are this script's output.
"""

import csv
from pathlib import Path

import numpy as np

SEED = 2028
SIG_D = 5e-6  # m, heads
SIG_TD, SIG_TA = 10e-6, 5e-6  # m, rad: trackers
HEADS = {  # head: (x, y, z) m, additive offset m
    "H1": ((-0.8, -0.6, 1.2), 0.412e-3),
    "H2": ((4.1, -0.9, 2.4), -0.231e-3),
    "H3": ((8.7, -0.4, 1.4), 1.050e-3),
    "H4": ((8.9, 5.6, 2.6), 0.080e-3),
    "H5": ((3.8, 6.0, 1.1), -0.540e-3),
    "H6": ((-0.9, 5.4, 2.3), 0.765e-3),
}
CONTROL = (0, 1, 4, 8)  # two floor targets and two raised ones: control in one plane leaves a mirror image
TRACKERS = {"T1": ((1.0, 1.0, 1.5), 0.3, 0.15e-3), "T2": ((7.0, 4.2, 1.6), 2.1, -0.08e-3)}  # xyz, κ rad, offset m


def targets(rng: np.random.Generator) -> np.ndarray:
    floor = np.column_stack([rng.uniform(1, 7, 4), rng.uniform(0.5, 4.5, 4), np.zeros(4)])
    raised = np.column_stack([rng.uniform(0.5, 7.5, 11), rng.uniform(0.3, 4.7, 11), rng.uniform(0.4, 2.6, 11)])
    return np.vstack([floor, raised])


def _write(path: Path, header: list[str], rows: list[list]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(header)
        w.writerows(rows)


def main(out: Path = Path(__file__).resolve().parent) -> None:
    rng = np.random.default_rng(SEED)
    tg = targets(rng)
    names = [f"P{j + 1:02d}" for j in range(len(tg))]
    obs = []
    for h, (xyz, off) in HEADS.items():
        for n, t in zip(names, tg):
            d = np.linalg.norm(t - np.array(xyz)) + off + SIG_D * rng.standard_normal()
            obs.append([h, n, f"{d:.9f}", f"{SIG_D:.1e}"])
    _write(out / "obs.csv", ["station", "target", "distance_m", "sigma_m"], obs)
    _write(out / "obs_no_sigma.csv", ["station", "target", "distance_m"], [r[:3] for r in obs])
    trk = []
    for s, (xyz, kappa, off) in TRACKERS.items():
        for n, t in zip(names, tg):
            d = t - np.array(xyz)
            az = np.angle(np.exp(1j * (np.arctan2(d[1], d[0]) - kappa + SIG_TA * rng.standard_normal())))
            el = np.arctan2(d[2], np.hypot(d[0], d[1])) + SIG_TA * rng.standard_normal()
            dist = np.linalg.norm(d) + off + SIG_TD * rng.standard_normal()
            trk.append([s, n, f"{dist:.9f}", f"{SIG_TD:.0e}", f"{az:.10f}", f"{el:.10f}", f"{SIG_TA:.0e}", f"{SIG_TA:.0e}"])
    _write(out / "trackers.csv", ["station", "target", "distance_m", "sigma_m", "azimuth_rad", "elevation_rad",
                                  "sigma_azimuth_rad", "sigma_elevation_rad"], trk)
    approx = [[h, *(f"{v:.2f}" for v in np.array(xyz) + 0.02 * rng.standard_normal(3))] for h, (xyz, _) in HEADS.items()]
    approx += [[n, *(f"{v:.2f}" for v in t + 0.02 * rng.standard_normal(3))]
               for j, (n, t) in enumerate(zip(names, tg)) if j not in CONTROL]
    _write(out / "heads.csv", ["point", "x_m", "y_m", "z_m"], approx[:len(HEADS)])
    _write(out / "points.csv", ["point", "x_m", "y_m", "z_m"],
           [[names[j], *(f"{v:.6f}" for v in tg[j])] for j in CONTROL] + approx)
    pts = [[h, *(f"{v:.6f}" for v in xyz)] for h, (xyz, _) in HEADS.items()]
    pts += [[s, *(f"{v:.6f}" for v in xyz)] for s, (xyz, _, _) in TRACKERS.items()]
    _write(out / "truth.csv", ["point", "x_m", "y_m", "z_m"], pts + [[n, *(f"{v:.6f}" for v in t)] for n, t in zip(names, tg)])
    _write(out / "offsets_truth.csv", ["head", "offset_um"],
           [[h, f"{off * 1e6:.1f}"] for h, (_, off) in HEADS.items()] + [[s, f"{off * 1e6:.1f}"] for s, (_, _, off) in TRACKERS.items()])


if __name__ == "__main__":
    main()
