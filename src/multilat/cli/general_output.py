"""The outputs of ``multilat adjust`` on the general path (schema ``multilat.adjust-general/3``): the
``--out`` directory, the JSON's observation listing and the printed summary.

The rule of the distance path's ``multilat.adjust/2`` (:mod:`multilat.cli.adjust_output`): the document
carries the summaries, every point and parameter, and only the observations that matter (rejected,
failing w-tests, poorly controlled), with ``observation_counts``
(:func:`multilat.network.adjust.general.report.list_observations`); every row is in the ``observations``
table under ``--out`` (Parquet when pyarrow is installed, else CSV; ``--tables``), named with its row
count and sha256 in ``result.json``'s ``tables``, and in the document with ``--observations``.
The summary reads the adjustment's full document (every row).
"""

from __future__ import annotations

import numpy as np

from multilat.cli.general_adjust import _METHOD_NAMES, _names

__all__ = ["write_out", "write_report", "print_summary", "snooping_lines", "reliability_lines", "variance_lines",
           "not_computed_line"]


def write_out(out, inputs, doc, full: dict, fmt: str = "auto") -> None:
    """``result.json``, ``points.csv`` and the ``observations`` table (every row of ``full``, the
    adjustment's document before listing: :func:`multilat.network.adjust.general.report.observation_table`;
    ``fmt``: ``--tables``) into ``out``, all or nothing (:func:`multilat.io.staging_dir`); the table's
    name, file, format, row count and sha256 go to ``doc["tables"]`` (in ``result.json`` too)."""
    from multilat.cli.adjust_output import table_records
    from multilat.io import staging_dir, write_csv_atomic, write_json_atomic, write_table_atomic
    from multilat.network.io.files import table_format
    from multilat.network.adjust.general.report import observation_table

    tables = {"observations": observation_table(full)}
    with staging_dir(out, inputs=list(inputs) if isinstance(inputs, (list, tuple)) else [inputs]) as tmp:
        paths = [write_table_atomic(tmp / name, cols, table_format(name, fmt)) for name, cols in tables.items()]
        doc["tables"] = table_records(paths, tables)
        write_json_atomic(tmp / "result.json", doc)
        rows = [[p, *v["xyz_m"], *v["xyz_std_m"], v["semi_axes_95_m"][2], v["status"], " ".join(v["roles"])]
                for p, v in doc["points"].items()]
        write_csv_atomic(tmp / "points.csv", ["point", "x_m", "y_m", "z_m", "x_std_m", "y_std_m", "z_std_m",
                                              "semi_axis_max_95_m", "status", "roles"], rows)


def write_report(path, doc: dict, full: dict, adj, applies) -> None:
    """``--report FILE.html`` (nothing when ``path`` is None): the page from the document the command
    prints (``doc``, listed) and every observation row of the result (``full``'s rows as the
    ``observations`` table has them, :func:`multilat.network.adjust.general.report.list_observations` with
    ``"all"``), so its numbers are the JSON's with or without ``--observations``
    (:mod:`multilat.report.general_sections`)."""
    if path is None:
        return
    import functools

    from multilat.cli import report_opt
    from multilat.network.adjust.general.report import list_observations
    from multilat.report.general_sections import build_report

    rows = list_observations(full, "all")["observations"]
    report_opt.write_report(path, "adjust", doc, result=adj,
                            build=functools.partial(build_report, applies=applies, rows=rows))


def print_summary(doc, adj, stats, out) -> None:
    from rich.table import Table

    from multilat.cli.app import console
    from multilat.network.adjust.general.report import constant_words, zero_redundancy_points

    say = lambda s: console.print(s, markup=False)  # noqa: E731
    kinds = {}
    for o in doc["observations"]:
        kinds[o["kind"]] = kinds.get(o["kind"], 0) + 1
    say(f"adjusted {doc['n_points']} points from {doc['n_obs']} observation rows ("
        + ", ".join(f"{n} {k.replace('_', ' ')}" for k, n in kinds.items())
        + f") of {doc['input']} ({doc['format']}; general model)")
    say(f"  datum: {doc['datum']}")
    say(f"  frame: {doc['frame']['axes']}")              # the JSON's words (general/report.py)
    say(f"  scale: {doc['frame']['scale']}")
    if "azimuth_sense" in doc:
        say(f"  azimuths read {doc['azimuth_sense']['sense']} ({doc['azimuth_sense']['source']})")
    gt, t = doc["global_test"], doc["tests"]
    if gt["statistic"] is None:
        say(f"  σ0 = {doc['sigma0']:.4g}, dof = {doc['dof']} (no global test without redundancy)")
    elif doc["variance_factor"] == "unknown":
        say(f"  σ0 = {doc['sigma0']:.4f} (estimated: variance factor unknown; covariances and MDBs scaled by σ0²), "
            f"dof = {doc['dof']}")
        say(f"  global χ² test (information only): {gt['statistic']:.2f} vs {gt['critical']:.2f} "
            f"(α = {gt['alpha']:.3g})")
        say(f"  Pope's τ-test: α0 = {t['alpha0']:g}, critical |τ| {t['critical']:.3f}")
    else:
        say(f"  σ0 = {doc['sigma0']:.4f} (ratio to the a-priori σ), dof = {doc['dof']}; global χ² test: "
            f"{gt['statistic']:.2f} {'<=' if gt['passed'] else '>'} {gt['critical']:.2f} (α = {gt['alpha']:.3g}, "
            f"{_METHOD_NAMES.get(gt['method'], gt['method'])}): {'passed' if gt['passed'] else 'FAILED'}")
        say(f"  w-test: α0 = {t['alpha0']:.3g}, critical |w| {t['critical']:.2f}, λ0 = {t['lambda0']:.2f}")
    say(f"  test procedure: {t['rule']}")
    red = stats.redundancy
    say(f"  redundancy {max(red.min(), 0.0):.3f}..{red.max():.3f}; {int((red <= 1e-9).sum())} uncontrolled row(s) "
        f"(r = 0); {t['n_failed']} test(s) above the critical value"
        + ("" if doc["snooping"] else " (listed in the JSON; data snooping not requested: --no-snooping)"))
    if inst := constant_words({n: v for n, v in doc["parameters"].items() if n.startswith("offset:")}):
        say("  additive constants: " + "; ".join(inst))
    zero = zero_redundancy_points(doc["observations"], doc["points"])
    if zero:
        say(f"  kept without control (every row r = 0, e.g. one polar reading; a blunder cannot show): "
            f"{_names(zero, 8)}")
    for e in doc["excluded"]:
        say(f"  left out: point {e['id']} ({e['reason']}; {e['n_obs']} observation rows)")
    for note in doc["notes"]:
        say(f"  note: {note}")
    for line in snooping_lines(doc) + reliability_lines(doc) + variance_lines(doc) + not_computed_line(doc):
        say(line)
    _worst(say, doc, stats)
    tb = Table(title="points", title_justify="left")
    for c in ("point", "status", "roles", "x (m)", "y (m)", "z (m)", "95 % max (mm)"):
        tb.add_column(c, justify="right")
    for p, v in doc["points"].items():
        x = v["xyz_m"]
        tb.add_row(p, v["status"], ",".join(v["roles"]), f"{x[0]:.5f}", f"{x[1]:.5f}", f"{x[2]:.5f}",
                   f"{v['semi_axes_95_m'][2] * 1e3:.2f}")
    console.print(tb)
    if out is not None:
        say(f"results written to {out}")
        for t in doc.get("tables", []):
            c = doc["observation_counts"]
            listed = ("all of them (--observations)" if c["listing"] == "all" else
                      f"the {c['n_flagged']:,} that matter (rejected, failing w-tests, poorly controlled)")
            say(f"  {t['n_rows']:,} observations in {t['file']}; result.json lists {listed}")


def _ends(o: dict) -> str:
    return "->".join(o[e] for e in ("from", "to", "point", "bs", "fs") if e in o)


def snooping_lines(doc) -> list[str]:
    """The data snooping part of the summary: the rejected rows in order, or why none was."""
    if not doc["snooping"]:
        return []
    out, steps = [], doc["tests"]["steps"]
    if doc["outliers"]:
        out.append("  rejected by data snooping, in order:")
        for o in doc["outliers"]:
            res = o["residual"] if isinstance(o["residual"], (int, float)) else None
            what = f", residual {res:+.4g} {o['unit']}" if res is not None else ""
            block = f" with its correlated block ({o['n_rows']} rows)" if o["n_rows"] > 1 else ""
            left = f"; point(s) left out with it: {', '.join(o['points_left_out'])}" if o["points_left_out"] else ""
            out.append(f"    {o['order']}. {o['label'] or '(no label)'} {o['kind'].replace('_', ' ')} {_ends(o)}{block}: "
                       f"{o['test']} = {o['statistic']:+.2f} > {o['critical']:.2f}{what}{left}")
    elif steps and steps[0]["detection_passed"]:
        out.append("  detection passed: no data snooping")
    if doc["unlocated"]:
        names = "; ".join(f"{u['label'] or u['kind']} {_ends(u)} (w = {u['w']:+.2f})" for u in doc["unlocated"])
        out.append(f"  not rejected: {names}: {doc['unlocated_reason']}")
    if doc["tests"]["snooping_note"]:
        out.append(f"  {doc['tests']['snooping_note']}")
    return out


def reliability_lines(doc, n: int = 3) -> list[str]:
    """External reliability: the rows whose MDB moves a point most."""
    er = doc["external_reliability"]
    if not er["largest"]:
        return []
    parts = [f"{o['label']} {o['kind'].replace('_', ' ')} {_ends(o)} moves {o['shift_point']} by {o['shift_max_m'] * 1e3:.3f} mm"
             for o in er["largest"][:n]]
    return [f"  external reliability (shift by an undetected MDB; {er['n_uncontrolled']} uncontrolled row(s) "
            "without one): " + "; ".join(parts)]


def not_computed_line(doc) -> list[str]:
    """One line naming the statistics the back end left out (``not_computed``), and why."""
    if not doc.get("not_computed"):
        return []
    import importlib

    bound = importlib.import_module("multilat.network.adjust.general.adjust").EXTERNAL_MAX_WORK
    return [f"  not computed: {', '.join(doc['not_computed'])} (the {doc['backend']} back end leaves it out above "
            f"{bound:.0e} rows x unknowns, {doc['n_obs']} rows here: it needs Q Jᵀ for every row; its JSON fields "
            "are null)"]


def variance_lines(doc) -> list[str]:
    v = doc.get("variance_components")
    if not v:
        return []
    parts = [f"{c['group']} factor {c['variance_factor']:.3f} ± {c['variance_factor_std']:.3f} (σ × "
             f"{c['sigma_scale']:.3f}, r = {c['redundancy']:.1f}{', differs from 1' if c['differs_from_1'] else ''})"
             for c in v["components"]]
    return [f"  variance components by {v['grouping']} (Förstner, {v['iterations']} iterations; test against 1 "
            f"at α = {v['alpha']:g}): " + "; ".join(parts)]


def _worst(say, doc, stats, n: int = 3) -> None:
    """The rows with the largest |test statistic|."""
    order = np.argsort(-np.abs(stats.statistic))[:n]
    obs = doc["observations"]
    parts = []
    for k in order:
        o = obs[int(k)]
        ends = "->".join(o[e] for e in ("from", "to", "point", "bs", "fs") if e in o)
        parts.append(f"{o['kind'].replace('_', ' ')} {ends} {doc['tests']['test']} = {o['statistic']:+.2f}")
    if parts:
        say("  largest tests: " + "; ".join(parts))
