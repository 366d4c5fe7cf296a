"""The outputs of ``multilat adjust`` on the distance path (schema ``multilat.adjust/3``): the JSON
document, the ``--out`` directory (tables, figures, ``result.json`` with each table's row count and
sha256) and the printed summary.

JSON for summaries, tables for rows: the document carries the summaries, every point, head and
orientation, and only the observations that matter (rejected, failing w-tests, poorly controlled;
those of points left out before solving), with their counts (:mod:`multilat.network.io.result_rows`);
every observation's row is in the ``observations`` table under ``--out`` (Parquet when pyarrow is
installed, else CSV), and in the document with ``--observations``.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
from rich.table import Table

from multilat.cli.app import console, emit_json
from multilat.errors import MultilatError

__all__ = ["adjust_document", "check_listing", "write_out", "table_records", "finish", "print_summary",
           "print_extras", "test_lines", "reliability_lines"]


def check_listing(all_observations: bool, as_json: bool, out) -> str:
    """``--observations`` lists every row in the JSON documents: refused without ``--json`` or ``--out``
    (nothing would show it). Returns the listing, "all" or "flagged"."""
    if all_observations and not as_json and out is None:
        raise MultilatError("--observations lists every observation in the JSON: give --json or --out DIR")
    return "all" if all_observations else "flagged"


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def table_records(paths, tables: dict) -> list[dict]:
    """``[{"name", "file", "format", "n_rows", "sha256"}]`` of the table files written (``paths``, in the
    order of ``tables``: the columns each was written from, which give the row count)."""
    out = []
    for path, (name, cols) in zip(paths, tables.items()):
        first = next(iter(cols.values()))
        n = len(first[1]) if isinstance(first, tuple) else len(first)
        out.append({"name": name, "file": path.name, "format": path.suffix[1:], "n_rows": int(n),
                    "sha256": _sha256(path)})
    return out


def write_out(out: Path, res, doc: dict, refs, fmt: str, inputs, *, indent: bool) -> None:
    """The ``--out`` directory, whole or not at all (:func:`multilat.io.staging_dir`): the tables
    (:func:`multilat.network.io.files.result_tables`), the figures and ``result.json``, which lists each
    table's name, file, format, row count and sha256 under ``tables`` (added to ``doc`` too)."""
    from multilat.io import staging_dir, write_json_atomic, write_table_atomic
    from multilat.network.io.files import result_tables, table_format
    from multilat.report.network_figures import save_figures

    tables = result_tables(res, references=refs)
    with staging_dir(out, inputs=inputs) as tmp:
        paths = [write_table_atomic(tmp / name, cols, table_format(name, fmt)) for name, cols in tables.items()]
        doc["tables"] = table_records(paths, tables)
        save_figures(res, tmp)
        write_json_atomic(tmp / "result.json", doc, indent=indent)


def finish(res, doc: dict, refs, *, out, tables: str, inputs, report, as_json: bool, vc) -> None:
    """Write and print what ``adjust`` was asked for: ``--out``, ``--report``, ``--json`` or the summary."""
    from multilat.cli import report_opt
    from multilat.io import INDENT_MAX_ROWS

    indent = len(doc["observations"]) <= INDENT_MAX_ROWS and res.obs.n_targets <= INDENT_MAX_ROWS
    if out is not None:
        write_out(out, res, doc, refs, tables, inputs, indent=indent)
    report_opt.write_report(report, "adjust", doc, result=res)
    if as_json:
        emit_json(doc, "adjust", indent=indent)
        return
    print_summary(res, doc, out)
    print_extras(doc, vc)


def adjust_document(res, refs, obs, opts, instrument, sigma_note, vc, corrected, averaged, *,
                    listing: str = "flagged") -> dict:
    """The ``adjust --json`` document (``multilat.adjust/3``): the result's, with the azimuth sense, the
    default-σ warning, variance components, the sensors' correlations and the repeats' scatter where
    they apply. ``listing``: "flagged" (the observations that matter) or "all" (``--observations``);
    ``obs``: the observations adjusted (those of points left out before solving are listed)."""
    from multilat.network.adjust.distance import azimuth_sense as _az
    from multilat.network.adjust.distance.result import result_to_json
    from multilat.vocabulary import stamp

    doc = stamp(result_to_json(res, refs, observations=listing, given=obs), "adjust")
    if (az_rec := _az.record(obs, *_az.resolve(opts.azimuth_sense, instrument))) is not None:
        doc["azimuth_sense"] = az_rec
    if sigma_note:
        doc["warnings"] = [sigma_note, *doc["warnings"]]
    if vc is not None:
        doc["variance_components"] = vc.to_json()
    if corrected is not None:
        from multilat.campaign.correlated import correlated_json

        c = corrected.covariance_m2 if averaged is None else averaged.matrix @ corrected.covariance_m2 @ averaged.matrix.T
        doc["with_correlations"] = correlated_json(res, c, refs)
    if averaged is not None:
        doc["repeats"] = averaged.scatter_json()
    return doc


def print_extras(doc: dict, vc) -> None:
    """The summary's last lines: the azimuth sense, variance components, the sensors' correlations."""
    if "azimuth_sense" in doc:
        console.print(f"azimuths read {doc['azimuth_sense']['sense']} ({doc['azimuth_sense']['source']})",
                      markup=False)
    if vc is not None:
        console.print(f"variance components by {vc.grouping} (Förstner, {vc.iterations} iterations): "
                      + "; ".join(f"{c.group} σ × {c.sigma_scale:.3f} (factor {c.variance_factor:.3f} ± "
                                  f"{c.variance_factor_std:.3f}, r = {c.redundancy:.1f})" for c in vc.components),
                      markup=False)
    if "with_correlations" in doc:
        wc = doc["with_correlations"]
        offs = ", ".join(f"{sid} {v['offset_std_m'] * 1e6:.1f}" for sid, v in wc["stations"].items())
        console.print(f"with the sensors' correlations (G C Gᵀ): u(offset) µm: {offs}; largest target "
                      f"std {wc['target_std_max_m'] * 1e6:.1f} µm (diagonal weights only: "
                      f"{wc['target_std_diagonal_max_m'] * 1e6:.1f} µm)", markup=False)




def _left_out_lines(res) -> list[str]:
    """The summary's lines for what was left out before solving and for mirror-ambiguous points."""
    lines = []
    if res.excluded:
        lines.append("  left out before solving: " + "; ".join(f"{e.kind} {e.id} ({e.reason})"
                                                             for e in res.excluded))
    if res.ambiguous:
        lines.append(f"  warning: ambiguous geometry, {len(res.ambiguous)} point(s) placed only up to a mirror "
                     f"that fits equally: {', '.join(a.id for a in res.ambiguous[:8])}"
                     f"{' ...' if len(res.ambiguous) > 8 else ''} (JSON 'ambiguous')")
    return lines


def print_summary(res, doc, out):
    console.print(f"adjusted {res.obs.n_stations} stations, {res.obs.n_targets} targets from "
                  f"{int(res.used.sum())}/{res.obs.n_obs} distances ({res.cost} cost; {res.datum.describe()})",
                  markup=False)
    cv = res.convergence
    console.print(f"  {res.solver} solver: {cv.iterations} iterations, {cv.reason}; initial values: "
                  f"{res.initial.get('method', '?')}", markup=False)
    console.print(f"  frame: {doc['frame']['axes']}", markup=False)      # the JSON's words (frame_words.py)
    console.print(f"  scale: {doc['frame']['scale']}", markup=False)
    for line in _left_out_lines(res):
        console.print(line, markup=False)
    if res.cost == "squared":
        console.print(f"  σ0 = {res.sigma0:.4g} m² (unweighted squared-distance residuals, eq. 6), "
                      f"dof = {res.dof}; no global test for this cost")
        console.print("  data snooping not done for this cost")
    else:
        for line in test_lines(res):
            console.print(line, markup=False)
    if res.sigma_source:
        from multilat.network.model.sigma_source import describe

        console.print("  " + describe(res.sigma_source), markup=False)
    for line in angle_lines(res):
        console.print(line, markup=False)
    if res.reliability is not None:
        for line in reliability_lines(res):
            console.print(line, markup=False)
    if (res.w_failure_groups and res.global_test.passed and not res.outliers
            and res.tests.get("detection") != "max |w|"):       # under Šidák the largest |w| detects
        n = sum(len(g) for g in res.w_failure_groups)
        console.print(f"  the global test passes: {n} w-test(s) above the critical value are not acted on "
                      f"(about α = {res.tests.get('alpha0', res.alpha):g} of all tests fail by chance); "
                      "listed in w_failures", markup=False)
    if res.unlocated:
        ids = ", ".join(f"{o.station}->{o.target}" for o in res.unlocated)
        if len(res.unlocated) > 1:
            console.print(f"  w-test failure that cannot be located (perfectly correlated "
                          f"tests, |w| = {abs(res.unlocated[0].w):.1f}): one of {ids}; none rejected")
        else:
            console.print(f"  w-test failure not rejected: {ids} (|w| = "
                          f"{abs(res.unlocated[0].w):.1f}): {res.unlocated_reason}")
    t = Table(title="stations", title_justify="left")
    for c in ("station", "x (m)", "y (m)", "z (m)", "offset (µm)", "u(offset) (µm)", "95 % max (µm)"):
        t.add_column(c, justify="right")
    (sa, _), (ta, _) = res.ellipsoids()
    for i, sid in enumerate(res.station_ids):
        x = res.station_xyz_m[i]
        fixed = "" if res.offset_estimated[i] else " (fixed)"
        t.add_row(sid, f"{x[0]:.6f}", f"{x[1]:.6f}", f"{x[2]:.6f}", f"{res.offset_m[i] * 1e6:+.1f}{fixed}",
                  f"{res.offset_std_m[i] * 1e6:.1f}", f"{sa[i, 2] * 1e6:.1f}")
    console.print(t)
    order = np.argsort(-ta[:, 2])[:5]
    t = Table(title="worst targets (largest 95 % semi-axis)", title_justify="left")
    for c in ("target", "x (m)", "y (m)", "z (m)", "95 % max (µm)"):
        t.add_column(c, justify="right")
    for j in order:
        x = res.target_xyz_m[j]
        t.add_row(res.target_ids[j], f"{x[0]:.6f}", f"{x[1]:.6f}", f"{x[2]:.6f}", f"{ta[j, 2] * 1e6:.1f}")
    console.print(t)
    if doc["reference_lengths"]:
        t = Table(title="interpoint distances vs reference lengths", title_justify="left")
        for c in ("points", "adjusted (m)", "u (µm)", "reference (m)", "difference (µm)"):
            t.add_column(c, justify="right")
        for c in doc["reference_lengths"]:
            t.add_row(f"{c['target_a']}-{c['target_b']}", f"{c['length_m']:.6f}", f"{c['length_std_m'] * 1e6:.1f}",
                      f"{c['reference_m']:.6f}", f"{c['difference_m'] * 1e6:+.1f}")
        console.print(t)
    if out is not None:
        console.print(f"results and figures written to {out}")
        rec = next(t for t in doc["tables"] if t["name"] == "observations")
        c = doc["observation_counts"]
        listed = ("all of them (--observations)" if c["listing"] == "all" else
                  f"the {c['n_flagged']:,} that matter (rejected, failing w-tests, poorly controlled)")
        console.print(f"  {rec['n_rows']:,} observations in {rec['file']}; result.json lists {listed}", markup=False)


def angle_lines(res) -> list[str]:
    """The summary's lines on angle observations and the orientations of the set-ups."""
    lines: list[str] = []
    if not res.angles:
        return lines
    ws = np.array([a["w"] for a in res.angles])
    vt = sum((a["residual_rad"] / a["sigma_rad"]) ** 2 for a in res.angles)
    lines.append(f"  angles: {len(res.angles)} observations, vᵀPv {vt:.1f} of "
                 f"{res.sigma0 ** 2 * res.dof:.1f}, largest |w| {np.max(np.abs(ws)):.2f} "
                 f"({sum(not a['w_test_passed'] for a in res.angles)} failing; "
                 f"{len(res.angle_outliers)} rejected by data snooping)")
    for sid, o in res.orientations.items():
        v, u = o["orientation_rad"], o["orientation_std_rad"]
        lines.append(f"  orientation of {sid}: " + ", ".join(
            f"{n} {a:+.6f} rad (u {b * 1e6:.1f} µrad)" for n, a, b in zip("ωφκ", v, u)))
    return lines


def test_lines(res) -> list[str]:
    """The summary's lines on the test procedure (detection, identification, adaptation)."""
    gt, t = res.global_test, res.tests
    out = []
    if gt.statistic is None:
        return [f"  σ0 = {res.sigma0:.4g}, dof = {res.dof} (no global test without redundancy)"]
    how = {"b-method": "B-method: α_global for equal power to the w-test",
           "sidak": "Šidák: the variance factor's test; the largest |w| detects"}.get(t.get("method"), "fixed α_global")
    pw = "" if gt.power is None else f", power {gt.power:.2f} at λ0 = {gt.lambda0:.2f}"
    if res.variance_factor == "unknown":
        out.append(f"  σ0 = {res.sigma0:.3f} (estimated: variance factor unknown; covariances and MDBs "
                   f"scaled by σ0²), dof = {res.dof}")
        out.append(f"  global χ² test (information only, not a decision here): {gt.statistic:.2f} vs "
                   f"{gt.critical:.2f} (α = {gt.alpha:.3g})")
        out.append(f"  Pope's τ-test: α0 = {t['alpha0']:g} per observation, critical |τ| "
                   f"{t['tau_critical']:.3f} (dof {res.dof})")
    else:
        out.append(f"  σ0 = {res.sigma0:.3f} (ratio to the a-priori uncertainties), dof = {res.dof}; "
                   f"global χ² test: {gt.statistic:.2f} {'in' if gt.passed else 'not in'} "
                   f"[{gt.critical_low:.2f}, {gt.critical:.2f}] "
                   f"(α = {gt.alpha:.3g}, lower tail {gt.alpha_low:g}; {how}{pw}): "
                   f"{'passed' if gt.passed else f'FAILED ({gt.side} tail)'}")
        out.append(f"  w-test: α0 = {t['alpha0']:.3g}, critical |w| {t['w_critical']:.2f}, power "
                   f"{t['power']:.2f}, λ0 = {t.get('lambda0_w', t['lambda0']):.2f} (MDBs at α0 = "
                   f"{t.get('alpha0_given', t['alpha0']):g}, λ0 = {t['lambda0']:.2f})")
    if t.get("rule"):
        out.append(f"  test procedure: {t['rule']}")
    chk = res.sigma0_check or {}
    if chk.get("verdict") in ("too low", "too high"):
        out.append(f"  σ0 {chk['verdict']}: " + ("accepted (--variance-factor unknown)" if chk.get("accepted")
                                                 else "IMPLAUSIBLE (see the warning)"))
    if not res.snooping:
        out.append("  data snooping not requested (--no-snooping)")
        return out
    steps = t.get("steps", [])
    if steps and steps[0]["detection_passed"] and not res.outliers and not res.angle_outliers:
        out.append("  detection passed: no data snooping")
    if res.outliers:
        out.append("  rejected distances, in order:")
        for n, o in enumerate(res.outliers, 1):
            stat = f"{o.test} = {o.statistic:+.2f} > {o.critical:.2f}" if o.statistic is not None else f"w = {o.w:+.2f}"
            out.append(f"    {n}. {o.station}->{o.target}: {stat}, residual {o.residual_m * 1e6:+.1f} µm")
    if res.angle_outliers:
        out.append("  rejected angles, in order:")
        for a in res.angle_outliers:
            out.append(f"    {a['order']}. {a['station']}->{a['target']} {a['kind']}: {a['test']} = "
                       f"{a['statistic']:+.2f} > {a['critical']:.2f}, residual {a['residual_rad'] * 1e6:+.1f} µrad "
                       f"(snooping round {a['step']})")
    if not (res.outliers or res.angle_outliers) and not (steps and steps[0]["detection_passed"]):
        out.append("  no observation rejected")
    return out


def reliability_lines(res, limit: int = 8) -> list[str]:
    """The summary's lines on internal and external reliability: the poorly controlled targets."""
    rel = res.reliability
    u = res.used
    red = rel.redundancy[u]
    out = [f"  reliability: redundancy {red.min():.3f}..{red.max():.3f}; MDB "
           f"{np.nanmin(rel.mdb_m[u]) * 1e6:.1f}..{np.nanmax(rel.mdb_m[u]) * 1e6:.1f} µm "
           f"({np.nanmin(rel.mdb_sigma[u]):.1f}..{np.nanmax(rel.mdb_sigma[u]):.1f} σ)"
           + (f"; largest coordinate shift an undetected MDB would cause "
              f"{np.nanmax(rel.shift_max_m[u]) * 1e6:.1f} µm" if rel.shifts_computed else "")]
    if rel.poor_targets:
        out.append(f"  poorly controlled (redundancy < {rel.r_min:g} or MDB > {rel.mdb_limit_sigma:g} σ): "
                   f"{len(rel.poor_obs)} observation(s) at {len(rel.poor_targets)} target(s):")
        for t in rel.poor_targets[:limit]:
            sh = "" if t["shift_max_m"] is None else f", shift up to {t['shift_max_m'] * 1e6:.1f} µm"
            out.append(f"    {t['id']}: {t['n_obs']} obs, redundancy min {t['redundancy_min']:.3f}, MDB up to "
                       f"{t['mdb_max_m'] * 1e6:.1f} µm ({t['mdb_max_sigma']:.1f} σ){sh}")
        if len(rel.poor_targets) > limit:
            out.append(f"    ... {len(rel.poor_targets) - limit} more in the JSON (reliability.poor_targets)")
    else:
        out.append(f"  every observation controlled (redundancy >= {rel.r_min:g}, MDB <= "
                   f"{rel.mdb_limit_sigma:g} σ)")
    return out


