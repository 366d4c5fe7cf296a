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
        "stations": {sid: {"head": run.heads[i] if run.heads else sid, "xyz_m": b.station_xyz_m[i],
                           "cov_m2": b.station_cov_m2[i], "offset_std_m": b.offset_std_m[i],
                           "targets": [t for j, t in enumerate(b.target_ids) if b.layout.visible[i, j]]}
                     for i, sid in enumerate(b.station_ids)},
        "targets": {tid: {"xyz_m": b.target_xyz_m[j], "cov_m2": b.target_cov_m2[j],
                          "u95_max_m": b.u95_max_m[j], "seen_by": int(b.layout.visible[:, j].sum())}
                    for j, tid in enumerate(b.target_ids)},
        "lengths": [{"a": a, "b": c, "length_m": L, "length_std_m": u} for a, c, L, u in b.lengths],
        "reliability": {"redundancy_min": float(b.redundancy.min()), "mdb_max_m": float(b.mdb_m.max()),
                        "external_max_m": float(b.external_m.max())},
        "poorly_controlled": poorly_controlled_document(run),
    }
    if run.selection is not None:
        sel = run.selection
        doc["target_selection"] = {"method": sel.method, "wanted_u95_m": sel.wanted_u95_m,
                                   "feasible": sel.feasible, "count": len(sel.target_ids),
                                   "candidates": len(b.target_ids), "targets": list(sel.target_ids),
                                   "u95_m": sel.u95_m, "all_candidates_u95_m": sel.all_u95_m,
                                   "path": [{"count": n, "u95_m": v, "removed": r} for n, v, r in sel.path],
                                   "evaluations": sel.evaluations}
    if run.search is not None:
        from multilat.network.design.search import PENALTY_M

        s = run.search
        doc["search"] = {"method": s.method, "evaluations": s.evaluations,
                         "starts": [{"start_criterion_m": r.start_criterion_m,
                                     "start_unsolvable": r.start_unsolvable,
                                     "end_criterion_m": r.end_criterion_m, "evaluations": r.evaluations}
                                    for r in s.starts],
                         "history_m": [None if v >= PENALTY_M else float(v) for v in s.history_m],
                         "start_stations": {sid: {"xyz_m": s.start_layout.station_xyz_m[i]}
                                            for i, sid in enumerate(s.start_layout.station_ids)}}
    return doc


def poorly_controlled_document(run) -> dict:
    """The ``poorly_controlled`` block: the thresholds and the targets owning a poorly controlled
    distance (:func:`~multilat.network.design.config.poorly_controlled_targets`)."""
    from multilat.network.adjust.distance.reliability import MDB_LIMIT_SIGMA, R_MIN

    return {"r_min": R_MIN, "mdb_limit_sigma": MDB_LIMIT_SIGMA, "n_targets": len(run.poorly_controlled),
            "targets": list(run.poorly_controlled)}


def poorly_controlled_line(doc: dict) -> str | None:
    """The warning naming the poorly controlled targets (worst first), None if none."""
    pc = doc["poorly_controlled"]
    if not pc["n_targets"]:
        return None
    ts = pc["targets"]
    names = ", ".join(f"{t['id']} (r {t['redundancy']:.2g})" for t in ts[:12]) + \
        (f" and {len(ts) - 12} more" if len(ts) > 12 else "")
    return (f"{pc['n_targets']} of {len(doc['targets'])} targets poorly controlled (a distance with "
            f"redundancy < {pc['r_min']:g} or MDB > {pc['mdb_limit_sigma']:g} σ: a blunder in it would not "
            f"show): {names}")


def simulation_document(sim) -> dict:
    """The ``simulation`` block of the design JSON (:class:`~multilat.network.design.confirm.DesignSimulation`)."""
    doc = sim.summary()
    doc["targets"] = {t: {"std_lin_m": sim.predicted_std_m[j], "std_mc_m": sim.mc_std_m[j],
                          "std_mc_se_m": sim.mc_std_se_m[j], "z": sim.z[j],
                          "u95_max_lin_m": sim.predicted_u95_max_m[j],
                          "u95_max_mc_m": sim.mc_u95_max_m[j],
                          "ellipsoid_coverage": sim.ellipsoid_coverage_pred[j]}
                      for j, t in enumerate(sim.target_ids)}
    return doc


@app.command("design")
def design_cmd(
    config: Optional[Path] = typer.Argument(None, help="Design TOML (targets, heads, instrument, criterion), or a "
                                            "planned general network (gama-local XML or network directory)."),
    evaluate: Optional[Path] = typer.Option(None, "--evaluate",
                                            help="Heads CSV (point,x_m,y_m,z_m): score this layout, no search; or "
                                                 "a planned general network: its pre-analysis."),
    seed: int = typer.Option(1, "--seed", help="Seed of the search."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Directory for design.json, stations.csv (where "
                                                                "each head stands, for the crew) and the figures."),
    simulate: int = typer.Option(0, "--simulate", min=0,
                                 help="Confirm the returned layout by a Monte Carlo of this many trials (propagate)."),
    noise: Optional[str] = typer.Option(None, "--noise",
                                        help="Monte Carlo distance errors: gaussian or model (default: model "
                                             "with an instrument, else gaussian)."),
    report: Optional[Path] = typer.Option(None, "--report", help=report_opt.HELP),
) -> None:
    """Predict a layout's uncertainty (pre-analysis) and optimise where the heads go."""
    from multilat.cli import general_design
    if general_design.wants_general(config, evaluate):    # a planned general network: cli/general_design.py
        return general_design.run(**locals())
    if config is None:
        from multilat.errors import MultilatError

        raise MultilatError("design needs a config TOML (or --evaluate NET.xml: a planned general network)")
    from multilat.cli import checks
    from multilat.network.design.config import design_memory_bytes, load_design_config, run_design

    checks.seed(seed)
    report_opt.check_report_path(report, [config, evaluate])
    cfg = load_design_config(config)
    need = design_memory_bytes(cfg)
    if need is not None:
        checks.memory(need, f"{config}: targets.grid x heads.count")
    heads = None
    if evaluate is not None:
        from multilat.network.io.files import read_points

        heads = read_points(evaluate)
    if noise is not None and noise not in ("gaussian", "model"):
        from multilat.errors import MultilatError

        raise MultilatError(f"--noise must be gaussian or model, got {noise!r}")
    run = run_design(cfg, base_dir=config.parent, evaluate=heads, rng=seed, source=str(config))
    doc = design_document(run)
    warn = poorly_controlled_line(doc)
    if warn is not None:        # stderr (with --json too) and the report's warnings
        import warnings

        warnings.warn(warn, stacklevel=1)
    sim = None
    if simulate:
        from multilat.network.design.confirm import simulate_design

        inst = run.sigma.instrument
        sim = simulate_design(run.best, trials=simulate, rng=seed,
                              noise=noise or ("model" if inst is not None else "gaussian"), instrument=inst)
        doc["simulation"] = simulation_document(sim)
    if out is not None:
        import json

        from multilat.io import staging_dir, to_jsonable
        from multilat.vocabulary import stamp
        from multilat.report.design_figures import save_design_figures

        tx = run.best.target_xyz_m
        h = cfg.heads
        with staging_dir(out) as tmp:
            (tmp / "design.json").write_text(json.dumps(to_jsonable(stamp(doc, "design")), indent=2) + "\n",
                                             encoding="utf-8")
            (tmp / "stations.csv").write_text(stations_csv(doc), encoding="utf-8")
            save_design_figures(run.best, tmp, box_min_m=tx.min(axis=0), box_max_m=tx.max(axis=0),
                                min_range_m=h.min_range_m,
                                max_range_m=np.inf if h.max_range_m is None else h.max_range_m,
                                occluders=[(o.box_min_m, o.box_max_m) for o in cfg.occluders])
    report_opt.write_report(report, "design", doc, result=run)
    if as_json:
        emit_json(doc, "design")
        return
    _print_summary(run, doc, sim)
    if out is not None:
        console.print(f"wrote {out}/design.json, {out}/stations.csv and figures")


def _print_summary(run, doc: dict, sim) -> None:
    """The terminal's summary of a design."""
    um = 1e6
    console.print(f"criterion {run.criterion}: {doc['criterion_m'] * um:.2f} µm"
                  + (f" (start layout {doc['start_criterion_m'] * um:.2f} µm)"
                     if doc["start_criterion_m"] is not None and run.search is not None else "")
                  + f"; {run.sigma.describe()}; dof {run.best.dof}")
    tab = Table("station", "head", "x (m)", "y (m)", "z (m)", "u offset (µm)", "targets seen")
    for sid, v in doc["stations"].items():
        tab.add_row(sid, v["head"], *(f"{c:.4f}" for c in v["xyz_m"]), f"{v['offset_std_m'] * um:.2f}",
                    str(len(v["targets"])))
    console.print(tab)
    u = run.best.u95_max_m
    console.print(f"targets: {len(u)}, largest 95 % semi-axis max {u.max() * um:.2f} µm, "
                  f"median {np.median(u) * um:.2f} µm; smallest redundancy "
                  f"{doc['reliability']['redundancy_min']:.3f}, largest MDB "
                  f"{doc['reliability']['mdb_max_m'] * um:.1f} µm")
    if run.search is not None:
        n_bad = sum(r.start_unsolvable for r in run.search.starts)
        console.print(f"search: {run.search.method}, {run.search.evaluations} evaluations"
                      + (f"; {n_bad} of {len(run.search.starts)} start layouts unsolvable (a target seen "
                         "by fewer than 3 heads)" if n_bad else ""))
    if run.selection is not None:
        sel = run.selection
        if sel.feasible:
            console.print(f"targets for a work-volume 95 % semi-axis <= {sel.wanted_u95_m * um:.2f} µm: "
                          f"{len(sel.target_ids)} of {len(u)} ({sel.u95_m * um:.2f} µm; greedy removal, "
                          f"a heuristic): {', '.join(sel.target_ids)}")

    if sim is not None:
        sm = doc["simulation"]
        console.print(f"Monte Carlo ({sm['noise']}, {sm['trials']} trials): largest 95 % semi-axis "
                      f"{sm['u95_max_mc_m'] * um:.2f} µm (predicted {sm['u95_max_lin_m'] * um:.2f}); "
                      f"target std MC/predicted {sm['ratio_mean']:.4f} on average, largest |z| "
                      f"{sm['z_abs_max']:.2f} MC standard errors; predicted 95 % ellipsoids hold "
                      f"{sm['ellipsoid_coverage_mean'] * 100:.2f} % of the trials")


def stations_csv(doc: dict) -> str:
    """The crew's file: one row per station (``station, head, x_m, y_m, z_m, n_targets, targets``;
    ``targets`` the ids the head must see from there, separated by spaces), metres to 0.1 mm."""
    import csv
    import io

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["station", "head", "x_m", "y_m", "z_m", "n_targets", "targets"])
    for sid, v in doc["stations"].items():
        w.writerow([sid, v["head"], *(f"{c:.4f}" for c in v["xyz_m"]), len(v["targets"]), " ".join(v["targets"])])
    return buf.getvalue()

