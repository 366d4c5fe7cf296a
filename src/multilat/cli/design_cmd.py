"""``multilat design``: pre-analysis of a layout and the search for head positions."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.table import Table

from multilat.cli import report_opt
from multilat.cli.app import app, console, emit_json


def design_document(run) -> dict:
    """The JSON document of a :class:`~multilat.network.design.config.DesignRun`."""
    b = run.best
    doc = {
        "criterion": run.criterion,
        "criterion_m": b.criterion(run.criterion),
        "start_criterion_m": run.start.criterion(run.criterion) if run.start is not None else None,
        "sigma": run.sigma.describe(),
        "dof": b.dof,
        "stations": {sid: {"xyz_m": b.station_xyz_m[i], "cov_m2": b.station_cov_m2[i],
                           "offset_std_m": b.offset_std_m[i]} for i, sid in enumerate(b.station_ids)},
        "targets": {tid: {"xyz_m": b.target_xyz_m[j], "cov_m2": b.target_cov_m2[j],
                          "u95_max_m": b.u95_max_m[j], "seen_by": int(b.layout.visible[:, j].sum())}
                    for j, tid in enumerate(b.target_ids)},
        "lengths": [{"a": a, "b": c, "length_m": L, "u_m": u} for a, c, L, u in b.lengths],
        "reliability": {"redundancy_min": float(b.redundancy.min()), "mdb_max_m": float(b.mdb_m.max()),
                        "external_max_m": float(b.external_m.max())},
    }
    if run.search is not None:
        s = run.search
        doc["search"] = {"method": s.method, "evaluations": s.evaluations,
                         "starts": [{"start_criterion_m": r.start_criterion_m,
                                     "end_criterion_m": r.end_criterion_m, "evaluations": r.evaluations}
                                    for r in s.starts],
                         "history_m": s.history_m,
                         "start_stations": {sid: {"xyz_m": s.start_layout.station_xyz_m[i]}
                                            for i, sid in enumerate(s.start_layout.station_ids)}}
    return doc


@app.command("design")
def design_cmd(
    config: Path = typer.Argument(..., help="Design TOML (targets, heads, instrument, criterion)."),
    evaluate: Optional[Path] = typer.Option(None, "--evaluate",
                                            help="Heads CSV (point,x_m,y_m,z_m): score this layout, no search."),
    seed: int = typer.Option(1, "--seed", help="Seed of the search."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
    out: Optional[Path] = typer.Option(None, "--out", help="Directory for design.json and the figures."),
    report: Optional[Path] = typer.Option(None, "--report", help=report_opt.HELP),
) -> None:
    """Predict a layout's uncertainty (pre-analysis) and optimise where the heads go."""
    from multilat.network.design.config import load_design_config, run_design

    report_opt.check_report_path(report, [config, evaluate])
    cfg = load_design_config(config)
    heads = None
    if evaluate is not None:
        from multilat.network.files import read_points

        heads = read_points(evaluate)
    run = run_design(cfg, base_dir=config.parent, evaluate=heads, rng=seed, source=str(config))
    doc = design_document(run)
    if out is not None:
        import json

        from multilat.io import staging_dir, to_jsonable
        from multilat.report.design_figures import save_design_figures

        tx = run.best.target_xyz_m
        h = cfg.heads
        with staging_dir(out) as tmp:
            (tmp / "design.json").write_text(json.dumps(to_jsonable(doc), indent=2) + "\n", encoding="utf-8")
            save_design_figures(run.best, tmp, box_min_m=tx.min(axis=0), box_max_m=tx.max(axis=0),
                                min_range_m=h.min_range_m,
                                max_range_m=np.inf if h.max_range_m is None else h.max_range_m)
    report_opt.write_report(report, "design", doc, result=run)
    if as_json:
        emit_json(doc)
        return
    um = 1e6
    console.print(f"criterion {run.criterion}: {doc['criterion_m'] * um:.2f} µm"
                  + (f" (start layout {doc['start_criterion_m'] * um:.2f} µm)"
                     if doc["start_criterion_m"] is not None and run.search is not None else "")
                  + f"; {run.sigma.describe()}; dof {run.best.dof}")
    tab = Table("head", "x (m)", "y (m)", "z (m)", "u offset (µm)")
    for sid, v in doc["stations"].items():
        tab.add_row(sid, *(f"{c:.4f}" for c in v["xyz_m"]), f"{v['offset_std_m'] * um:.2f}")
    console.print(tab)
    u = run.best.u95_max_m
    console.print(f"targets: {len(u)}, largest 95 % semi-axis max {u.max() * um:.2f} µm, "
                  f"median {np.median(u) * um:.2f} µm; smallest redundancy "
                  f"{doc['reliability']['redundancy_min']:.3f}, largest MDB "
                  f"{doc['reliability']['mdb_max_m'] * um:.1f} µm")
    if run.search is not None:
        console.print(f"search: {run.search.method}, {run.search.evaluations} evaluations")
    if out is not None:
        console.print(f"wrote {out}/design.json and figures")
