"""Write a *synthetic* LBB-vs-CMM data set for ``multilat lbb compare`` (the paper's data are lost).

The 75 comparison points of the default config are the CMM reference (``m60_reference.csv``). For each point
one LBB measurement is simulated with the direct model: the true edges behind the nominal readings differ
from the nominal edges by ``e``; a bar reading the true geometry then reports ``edges - e``
(``m60_edges.csv``). Run: ``python examples/lbb/make_synthetic_m60.py`` then::

    multilat lbb compare examples/lbb/m60_edges.csv examples/lbb/m60_reference.csv --out lbb-compare
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from multilat.io import write_csv_atomic
from multilat.lbb.config import load_config
from multilat.lbb.model import BarModel, initialization_length, true_side_lengths
from multilat.lbb.simulate import direct_inputs, nominal_geometry

HERE = Path(__file__).resolve().parent


def main(seed: int = 2007) -> None:
    cfg = load_config()
    pts = cfg.comparison.points()
    edges, els = nominal_geometry(cfg, pts)
    rng = np.random.default_rng(seed)
    bar = BarModel.from_config(cfg)
    p = len(pts)
    d = {k: v.sample(rng, p) for k, v in direct_inputs(cfg).items()}
    cos = {"cos_theta": d["cos_theta"], "cos_phi": d["cos_phi"]}
    l0 = initialization_length(cfg, bar, d, **cos)
    true = true_side_lengths(cfg, bar, l0, edges, els, d, base_dt_c=d["base_dt"], **cos)
    measured = edges - (true - edges)
    ids = [f"M{i + 1:02d}" for i in range(p)]
    write_csv_atomic(HERE / "m60_reference.csv", ["point", "x_m", "y_m", "z_m"],
                     [[i, *map(float, q)] for i, q in zip(ids, pts)])
    write_csv_atomic(HERE / "m60_edges.csv", ["point", "l12_m", "l13_m", "l23_m", "l1_m", "l2_m", "l3_m"],
                     [[i, *map(float, q)] for i, q in zip(ids, measured)])


if __name__ == "__main__":
    main()
