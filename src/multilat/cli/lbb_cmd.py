"""``multilat lbb``: laser ball bar trilateration and its Monte Carlo uncertainty (seed 003)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer
from rich.table import Table

from multilat.cli import checks, report_opt
from multilat.cli.app import app, console, emit_json, progress
from multilat.errors import MultilatError

lbb = typer.Typer(help="Laser ball bar: trilateration from six edges, HTM error model, Monte Carlo "
                       "uncertainty over the work volume (Canning et al. 2007).",
                  no_args_is_help=True)
app.add_typer(lbb, name="lbb")


@lbb.command()
def trilaterate(
    edges: Path = typer.Argument(..., help="CSV: point,l12_m,l13_m,l23_m,l1_m,l2_m,l3_m (metres)."),
    on_singular: str = typer.Option("report", "--on-singular",
                                    help="report: every point, singular ones flagged (valid = false, "
                                         "xyz_m null) and exit code 3 if any; error: stop at the first "
                                         "with a one-line error, exit 2."),
    json_out: bool = typer.Option(False, "--json", help="Print JSON: points [{point, xyz_m, valid, "
                                                        "z_squared_m2, reason}]."),
) -> int:
    """Tool-socket coordinates in the base frame (socket 1 origin, 2 on +x, 3 in xy with y > 0, z > 0).

    A point at the base plane (the trilateration singularity) or whose edges do not close a
    tetrahedron is reported as such, never returned as NaN. Malformed rows (negative lengths, a face
    violating the triangle inequality) are always a one-line error naming the line."""
    from multilat.lbb.files import read_edges
    from multilat.lbb.trilateration import trilaterate as tri

    if on_singular not in ("report", "error"):
        raise MultilatError(f"--on-singular must be report or error, got {on_singular!r}")
    t = read_edges(edges)
    res = tri(*t.edges_m.T, on_singular="raise" if on_singular == "error" else "mask",
              labels=t.line_labels, validate=False)
    pts = []
    for i, p in enumerate(t.points):
        ok = bool(res.valid[i])
        reason = None if ok else ("edges do not close a tetrahedron" if res.z_squared_m2[i] < 0
                                  else "at the base plane (trilateration singularity)")
        pts.append({"point": p, "xyz_m": res.xyz_m[i] if ok else None, "valid": ok,
                    "z_squared_m2": float(res.z_squared_m2[i]), "reason": reason})
    n_bad = sum(not q["valid"] for q in pts)
    if json_out:
        emit_json(command="lbb-trilaterate", obj={"frame": "base: socket 1 origin, socket 2 on +x, socket 3 in xy (y > 0), z > 0",
                   "points": pts, "n_singular": n_bad})
        return 3 if n_bad else 0
    table = Table(title=f"{edges}: tool socket in the base frame")
    for c in ("point", "x (mm)", "y (mm)", "z (mm)", "note"):
        table.add_column(c, justify="right")
    for p in pts:
        if p["valid"]:
            table.add_row(p["point"], *(f"{v * 1e3:.6f}" for v in p["xyz_m"]), "")
        else:
            table.add_row(p["point"], "-", "-", "-", f"{p['reason']} (z² = {p['z_squared_m2']:.3g} m²)")
    console.print(table)
    if n_bad:
        console.print(f"{n_bad} of {len(pts)} point(s) not trilaterated (see note); exit code 3")
    return 3 if n_bad else 0


def _points(cfg, where: str, grid: int | None):
    from multilat.lbb.simulate import volume_points

    if where == "volume":
        if grid is not None:
            checks.count(grid, "--grid", lo=2, hi=10**6)
            # the lattice, its masks and per-point results: ~200 bytes a lattice point
            checks.memory(grid * grid * len(cfg.volume.z_levels_m) * 200.0, f"--grid {grid}")
        return volume_points(cfg, grid)
    if where == "comparison":
        return cfg.comparison.points()
    raise MultilatError(f"--where must be 'volume' or 'comparison', got {where!r}")


@lbb.command()
def simulate(
    config: Path = typer.Option(None, "--config", help="TOML config (default: the 2007 paper's set-up)."),
    grid: int = typer.Option(None, "--grid", help="Lattice points per horizontal axis of the work volume "
                             "(default: the config's nx, ny)."),
    trials: int = typer.Option(None, "--trials", help="Points per cloud: step-7 draws (procedure) or trials "
                               "(direct); default from the config."),
    seed: int = typer.Option(20070101, "--seed", help="Seed of the Monte Carlo."),
    method: str = typer.Option("procedure", "--method", help="procedure (the paper's steps 1-8) or direct."),
    where: str = typer.Option("volume", "--where", help="volume (Fig. 8 lattice) or comparison (75 points)."),
    json_out: bool = typer.Option(False, "--json", help="Print JSON (points, max_std_m, trials, ...)."),
    out: Path = typer.Option(None, "--out", "-o", help="Directory for points.csv, sides.csv, summary.json, "
                             "fig8_*.png, fig9_cdf.png."),
    report: Path = typer.Option(None, "--report", help=report_opt.HELP),
) -> None:
    """Monte Carlo coordinate uncertainty of LBB trilateration over the work volume."""
    from multilat.lbb.config import load_config
    from multilat.lbb.outputs import summary, write_simulation
    from multilat.lbb.simulate import simulate as run

    checks.seed(seed)
    checks.trials(trials, lo=2)
    report_opt.check_report_path(report, [config])
    if out is not None:
        from multilat.io import check_output_dir

        check_output_dir(out, inputs=[config])
    cfg = load_config(config)
    pts = _points(cfg, where, grid)
    with progress() as p:
        task = p.add_task(f"LBB {method}", total=len(pts))
        sim = run(cfg, pts, method=method, rng=seed, trials=trials,
                  progress=lambda done, total: p.update(task, completed=done))
    if out is not None:
        from multilat.io import staging_dir

        marks = cfg.comparison.points() if where == "volume" else None
        with staging_dir(out, inputs=[config]) as tmp:
            write_simulation(tmp, sim, cfg, marks_m=marks)
    report_opt.write_report(report, "lbb simulate", summary(sim), result=(sim, cfg))
    if json_out:
        emit_json(summary(sim), "lbb-simulate")
        return
    table = Table(title=f"LBB {method}: {len(pts)} points, {sim.trials} per cloud (µm)")
    for c in ("x (mm)", "y (mm)", "z (mm)", "mean err x", "mean err y", "mean err z", "std x", "std y", "std z"):
        table.add_column(c, justify="right")
    show = np.argsort(-np.max(sim.std_m, axis=1))[:15]
    for i in show:
        table.add_row(*(f"{v * 1e3:.1f}" for v in sim.nominal_m[i]),
                      *(f"{v * 1e6:.3f}" for v in sim.mean_error_m[i]),
                      *(f"{v * 1e6:.3f}" for v in sim.std_m[i]))
    console.print(table)
    console.print(f"largest std {sim.max_std_m * 1e6:.3f} µm; largest |mean error| "
                  f"{np.max(sim.error_magnitude_m) * 1e6:.3f} µm (15 points with the largest std shown)")
    if out is not None:
        console.print(f"wrote {out}/")


@lbb.command()
def compare(
    edges: Path = typer.Argument(..., help="CSV of measured edges: point,l12_m,...,l3_m."),
    reference: Path = typer.Argument(..., help="CSV of reference coordinates in the base frame: "
                                     "point,x_m,y_m,z_m."),
    config: Path = typer.Option(None, "--config", help="TOML config (default: the 2007 paper's set-up)."),
    trials: int = typer.Option(None, "--trials", help="Points per simulated cloud."),
    seed: int = typer.Option(20070101, "--seed", help="Seed of the Monte Carlo."),
    method: str = typer.Option("procedure", "--method", help="procedure or direct."),
    json_out: bool = typer.Option(False, "--json", help="Print JSON."),
    out: Path = typer.Option(None, "--out", "-o", help="Directory for comparison.csv and fig7_comparison.png."),
    report: Path = typer.Option(None, "--report", help=report_opt.HELP),
) -> None:
    """LBB coordinates vs reference coordinates with simulated 2σ bars (the paper's Fig. 7)."""
    from multilat.lbb.config import load_config
    from multilat.lbb.files import read_edges, read_reference
    from multilat.lbb.outputs import compare_reference, write_comparison

    checks.seed(seed)
    checks.trials(trials, lo=2)
    report_opt.check_report_path(report, [edges, reference, config])
    if out is not None:
        from multilat.io import check_output_dir

        check_output_dir(out, inputs=[edges, reference, config])
    cfg = load_config(config)
    e = read_edges(edges)
    r = read_reference(reference)
    with progress() as p:
        task = p.add_task("LBB comparison", total=len(r.points))
        comp = compare_reference(cfg, e, r, method=method, rng=seed, trials=trials,
                                 progress=lambda d, t: p.update(task, completed=d))
    if out is not None:
        from multilat.io import staging_dir

        with staging_dir(out, inputs=[edges, reference, config]) as tmp:
            write_comparison(tmp, comp)
    frac = float(np.mean(comp.inside_2sigma))
    doc = {"points": [{"point": pt, "difference_m": comp.difference_m[i],
                       "error_mean_mc_m": comp.simulation.mean_error_m[i],
                       "std_mc_m": comp.simulation.std_m[i], "inside_2sigma": comp.inside_2sigma[i]}
                      for i, pt in enumerate(comp.points)],
           "fraction_inside_2sigma": frac,
           "fraction_inside_2sigma_per_axis": dict(zip("xyz", comp.inside_fraction_per_axis)),
           "normalised_rms_per_axis": dict(zip("xyz", comp.normalised_rms_per_axis)),
           "method": method, "trials": comp.simulation.trials}
    report_opt.write_report(report, "lbb compare", doc, result=comp)
    if json_out:
        emit_json(doc, "lbb-compare")
        return
    table = Table(title="LBB - reference (µm) and simulated 2σ")
    for c in ("point", "dx", "dy", "dz", "2σ x", "2σ y", "2σ z"):
        table.add_column(c, justify="right")
    for i, pt in enumerate(comp.points):
        table.add_row(pt, *(f"{v * 1e6:.2f}" for v in comp.difference_m[i]),
                      *(f"{2 * v * 1e6:.2f}" for v in comp.simulation.std_m[i]))
    console.print(table)
    console.print(f"{frac:.0%} of the coordinate differences lie within the simulated mean ± 2σ "
                  f"({method}); per axis x/y/z: "
                  + " / ".join(f"{v:.0%}" for v in comp.inside_fraction_per_axis))
    console.print("RMS of (difference - mean) / σ per axis x/y/z (1 = the simulated σ fits the scatter): "
                  + " / ".join(f"{v:.2f}" for v in comp.normalised_rms_per_axis))
