"""Results to files and JSON: per-point CSVs, a summary JSON, the Fig. 7-9 PNGs (all atomic)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from multilat.io import atomic_path, write_csv_atomic, write_json_atomic
from multilat.lbb.config import LBBConfig
from multilat.lbb.files import EdgeTable, ReferenceTable, match_points
from multilat.lbb.simulate import LBBSimulation, base_xyz, simulate
from multilat.lbb.trilateration import trilaterate

__all__ = ["summary", "write_simulation", "Comparison", "compare_reference", "write_comparison"]


def summary(sim: LBBSimulation) -> dict:
    """The JSON summary: ``points`` (``nominal_m``, ``error_mean_m``, ``std_m``, ``cov_m2``),
    ``std_max_m``, ``error_mean_max_m``, ``trials``, ``method``, L0 statistics, seed entropy."""
    pts = [{"nominal_m": sim.nominal_m[i], "error_mean_m": sim.mean_error_m[i], "std_m": sim.std_m[i],
            "cov_m2": sim.cov_m2[i]} for i in range(len(sim.nominal_m))]
    return {"method": sim.method, "trials": sim.trials, "n_points": len(pts),
            "std_max_m": sim.max_std_m, "error_mean_max_m": float(np.max(sim.error_magnitude_m)),
            "l0_error_mean_m": sim.l0_mean_error_m, "l0_std_m": sim.l0_std_m,
            "seed": sim.seed_entropy, "points": pts}


def _save(fig, path):
    import matplotlib.pyplot as plt

    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)


def write_simulation(out_dir, sim: LBBSimulation, cfg: LBBConfig, *, marks_m=None) -> list[Path]:
    """Write ``points.csv``, ``sides.csv``, ``summary.json``, ``fig8_mean_error.png``,
    ``fig8_std.png``, ``fig9_cdf.png`` into ``out_dir`` (each file whole or not at all)."""
    from multilat.lbb import figures as F

    out = Path(out_dir)
    files = []
    rows = [[*(sim.nominal_m[i]), *(sim.mean_error_m[i]), *(sim.std_m[i]), sim.error_magnitude_m[i]]
            for i in range(len(sim.nominal_m))]
    p = out / "points.csv"
    write_csv_atomic(p, ["x_m", "y_m", "z_m", "error_x_mean_m", "error_y_mean_m", "error_z_mean_m",
                         "x_std_m", "y_std_m", "z_std_m", "error_magnitude_mean_m"], rows)
    files.append(p)
    names = ["l12", "l13", "l23", "l1", "l2", "l3"]
    rows = [[*(sim.nominal_m[i]), *(sim.nominal_edges_m[i]), *(sim.side_mean_error_m[i]), *(sim.side_std_m[i])]
            for i in range(len(sim.nominal_m))]
    p = out / "sides.csv"
    write_csv_atomic(p, ["x_m", "y_m", "z_m"] + [f"{n}_nominal_m" for n in names]
                     + [f"{n}_error_mean_m" for n in names] + [f"{n}_std_m" for n in names], rows)
    files.append(p)
    p = out / "summary.json"
    from multilat.vocabulary import stamp

    write_json_atomic(p, stamp(summary(sim), "lbb-simulate"))      # the same document as --json
    files.append(p)
    b = base_xyz(cfg)
    for name, q in (("fig8_mean_error.png", "mean"), ("fig8_std.png", "std")):
        _save(F.volume_map(sim, b, quantity=q, marks_m=marks_m), out / name)
        files.append(out / name)
    ax = F.error_cdf(sim)
    _save(ax.figure, out / "fig9_cdf.png")
    files.append(out / "fig9_cdf.png")
    return files


@dataclass(frozen=True)
class Comparison:
    """LBB coordinates (trilaterated from measured edges) against reference coordinates.

    Attributes
    ----------
    points : tuple of str
    measured_m, reference_m, difference_m : ndarray (p, 3)
        Trilaterated, reference, and measured - reference (m).
    simulation : LBBSimulation
        The model at the reference points (mean error and std of each coordinate).
    inside_2sigma : ndarray (p, 3) of bool
        Whether the difference lies within the simulated mean ± 2σ.
    """

    points: tuple
    measured_m: np.ndarray
    reference_m: np.ndarray
    difference_m: np.ndarray
    simulation: LBBSimulation
    inside_2sigma: np.ndarray

    @property
    def normalised_m(self) -> np.ndarray:
        """(difference - simulated mean error) / simulated std, shape (p, 3): N(0, 1)-like per axis
        when the model's uncertainty is right for that axis."""
        return (self.difference_m - self.simulation.mean_error_m) / self.simulation.std_m

    @property
    def inside_fraction_per_axis(self) -> np.ndarray:
        """Share of points inside mean ± 2σ, per axis x, y, z, shape (3,)."""
        return self.inside_2sigma.mean(axis=0)

    @property
    def normalised_rms_per_axis(self) -> np.ndarray:
        """RMS of :attr:`normalised_m` per axis, shape (3,): about 1 when the simulated σ of that
        axis matches the scatter of the differences; < 1 the model overstates, > 1 understates it.
        A pooled fraction inside ± 2σ can look right while the axes disagree in opposite senses."""
        return np.sqrt(np.mean(self.normalised_m ** 2, axis=0))


def compare_reference(cfg: LBBConfig, edges: EdgeTable, ref: ReferenceTable, *, method="procedure",
                      rng=None, trials=None, progress=None) -> Comparison:
    """Fig. 7: trilaterate the measured edges, difference from the reference, simulate at the
    reference points for the 2σ bars."""
    idx = match_points(edges, ref)
    e = edges.edges_m[idx]
    tri = trilaterate(*e.T, on_singular="raise", labels=[edges.line_labels[i] for i in idx],
                      min_height_ratio=cfg.monte_carlo.min_height_ratio)
    sim = simulate(cfg, ref.xyz_m, method=method, rng=rng, trials=trials, progress=progress)
    diff = tri.xyz_m - ref.xyz_m
    inside = np.abs(diff - sim.mean_error_m) <= 2 * sim.std_m
    return Comparison(ref.points, tri.xyz_m, ref.xyz_m, diff, sim, inside)


def write_comparison(out_dir, comp: Comparison) -> list[Path]:
    """``comparison.csv`` and ``fig7_comparison.png`` into ``out_dir``."""
    from multilat.lbb import figures as F

    out = Path(out_dir)
    s = comp.simulation
    rows = [[comp.points[i], *comp.reference_m[i], *comp.difference_m[i], *s.mean_error_m[i], *s.std_m[i],
             *comp.inside_2sigma[i].astype(int)] for i in range(len(comp.points))]
    p = out / "comparison.csv"
    write_csv_atomic(p, ["point", "x_ref_m", "y_ref_m", "z_ref_m", "dx_m", "dy_m", "dz_m",
                         "error_x_mean_mc_m", "error_y_mean_mc_m", "error_z_mean_mc_m", "x_std_mc_m", "y_std_mc_m",
                         "z_std_mc_m", "inside_x", "inside_y", "inside_z"], rows)
    f = out / "fig7_comparison.png"
    _save(F.reference_comparison(comp.points, comp.difference_m, s.mean_error_m, s.std_m), f)
    return [p, f]
