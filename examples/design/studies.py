"""The studies of docs/design.md: the paper's small volume against optimised heads, and
Takatsuji's regular-tetrahedron claim for a cubic target volume. Modest CPU (a few minutes)."""

import itertools
import sys

import numpy as np

from multilat.instrument import load_instrument
from multilat.network.synthetic import configs
from multilat.network.design import Layout, SigmaModel, optimise_heads, preanalyse

sigma = SigmaModel(instrument=load_instrument("seed2020"))
um = 1e6


def edges(h):
    e = np.array([np.linalg.norm(h[i] - h[j]) for i, j in itertools.combinations(range(len(h)), 2)])
    return e, e.std() / e.mean()


which = sys.argv[1:] or ["small", "cube"]
if "small" in which:
    cfg = configs.small_volume()
    pts = np.vstack([cfg.station_xyz_m, cfg.target_xyz_m])
    for crit in ("max_u95", "rms_u"):
        r = optimise_heads(cfg.target_xyz_m, count=4, box_min_m=pts.min(0), box_max_m=pts.max(0),
                           sigma=sigma, target_ids=cfg.target_ids, start=cfg.station_xyz_m, criterion=crit,
                           min_range_m=0.2, starts=6, max_evaluations=9000, rng=1)
        e, dev = edges(r.layout.station_xyz_m)
        print(f"small {crit}: paper {r.start_criterion_m * um:.2f} um, optimised {r.criterion_m * um:.2f} um, "
              f"gain {r.gain:.2f}x, evals {r.evaluations}; heads {np.round(r.layout.station_xyz_m, 3).tolist()}; "
              f"edges {np.round(e, 3).tolist()} cv {dev:.3f}")
    e, dev = edges(cfg.station_xyz_m)
    print(f"paper heads edges {np.round(e, 3).tolist()} cv {dev:.3f}")
if "cube" in which:
    g = np.stack(np.meshgrid(*[np.linspace(0, 1, 3)] * 3, indexing="ij"), -1).reshape(-1, 3)
    reg = np.array([[0, 0, 0], [1, 1, 0], [1, 0, 1], [0, 1, 1]], float)
    for crit in ("max_u95", "rms_u"):
        for name, c in (("regular tetrahedron x1.5 about the centre", 0.5 + 1.5 * (reg - 0.5)),
                        ("regular tetrahedron x3 about the centre",
                                                0.5 + 3 * (reg - 0.5))):
            v = preanalyse(Layout("ABCD", c, [f"T{k}" for k in range(27)], g), sigma).criterion(crit)
            print(f"cube {crit}: {name}: {v * um:.2f} um")
        r = optimise_heads(g, count=4, box_min_m=[-1.5] * 3, box_max_m=[2.5] * 3, sigma=sigma,
                           criterion=crit, min_range_m=0.2, starts=6, max_evaluations=6000, rng=2)
        e, dev = edges(r.layout.station_xyz_m)
        print(f"cube {crit}: start {r.start_criterion_m * um:.2f} um, optimum {r.criterion_m * um:.2f} um, "
              f"evals {r.evaluations}, starts {[round(s.end_criterion_m * um, 2) for s in r.starts]}; heads "
              f"{np.round(r.layout.station_xyz_m, 3).tolist()}; edges {np.round(e, 3).tolist()} "
              f"cv {dev:.3f}")
