"""Results sections of the job reports, one function per command, each reading the command's JSON
document (every number a :class:`~multilat.report.html.Num` naming its JSON path) and adding the
figures. Called by :func:`multilat.report.job.build_report`."""

from __future__ import annotations

import math

import numpy as np

from multilat.report.html import Num, Section

K = 2.0                       # multilat.report.job.K_EXPANDED (not imported: job imports this module)
UM = 1e6
MAX_ROWS = 200                # longest table in a report; the rest is in the JSON / CSV outputs


def ptr(*parts) -> str:
    """A JSON-pointer-like path: parts joined by ``/`` (``~`` -> ``~0``, ``/`` -> ``~1`` in keys)."""
    return "/".join(str(p).replace("~", "~0").replace("/", "~1") for p in parts)


def resolve(doc, path: str):
    """The value at ``path`` (as made by :func:`ptr`) in ``doc``."""
    v = doc
    for raw in path.split("/"):
        key = raw.replace("~1", "/").replace("~0", "~")
        v = v[int(key)] if isinstance(v, list) else v[key]
    return v


def _get(d: dict, *names):
    """The first of ``names`` present in ``d`` (the key and its value)."""
    for n in names:
        if n in d:
            return n, d[n]
    return names[0], None


def _um(doc, *path, digits=2, k=1.0, op="", sign=False):
    p = ptr(*path)
    return Num(resolve(doc, p), p, UM, digits, k, op, sign)


def _urad(doc, *path, digits=1):
    p = ptr(*path)
    return Num(resolve(doc, p), p, UM, digits, 1.0, "", True)       # rad -> µrad, the same factor as m -> µm


def _m(doc, *path, digits=6):
    p = ptr(*path)
    return Num(resolve(doc, p), p, 1.0, digits)


def _plain(doc, *path, digits=3):
    p = ptr(*path)
    return Num(resolve(doc, p), p, 1.0, digits)


def _verdict(ok) -> str:
    return "-" if ok is None else ("yes" if ok else "NO")


def _worst(items, key, n=MAX_ROWS):
    """Indices of the ``n`` items with the largest ``key`` (all when there are fewer)."""
    if len(items) <= n:
        return list(range(len(items)))
    vals = np.array([key(x) for x in items], float)
    return sorted(np.argsort(-np.nan_to_num(vals, nan=np.inf))[:n].tolist())


# ---------------------------------------------------------------------------------------- adjust
def _sigma0_line(doc: dict) -> str:
    """The σ0 check in one line: the verdict, and for an implausible σ0 the σ source."""
    from multilat.network.sigma_source import describe

    c = doc.get("sigma0_check") or {}
    v = c.get("verdict", "-")
    if v in ("too low", "too high"):
        how = "accepted (--variance-factor unknown)" if c.get("accepted") else "IMPLAUSIBLE"
        return f"{how}: σ0 {v} ({describe(doc.get('sigma_source') or {})})"
    return v


def adjust(doc: dict, result=None, options=None) -> list[Section]:
    sec = Section("Adjustment")
    gt = doc.get("global_test") or {}
    sec.table(("quantity", "value"), [
        ("datum", doc["datum"]), ("cost", doc["cost"]), ("solver", doc.get("solver", "-")),
        ("distances used / given", f"{doc['n_used']} / {doc['n_obs']}"),
        ("convergence", f"{doc['convergence']['iterations']} iterations, {doc['convergence']['reason']}"),
        ("σ0 (ratio to the a-priori σ)" if doc["cost"] != "squared" else "σ0 (m², eq. 6)",
         _plain(doc, "sigma0", digits=4)),
        ("degrees of freedom", doc["dof"]),
        ("global χ² test statistic", _plain(doc, "global_test", "statistic", digits=3)
         if gt.get("statistic") is not None else "-"),
        ("critical value", _plain(doc, "global_test", "critical", digits=3)
         if gt.get("critical") is not None else "-"),
        ("lower-tail critical value (α = %g)" % gt.get("alpha_low", float("nan")),
         _plain(doc, "global_test", "critical_low", digits=3) if gt.get("critical_low") is not None else "-"),
        ("global test (α = %g, both tails) passed" % gt.get("alpha", float("nan")),
         _verdict(gt.get("passed")) + (f" ({gt['failed_tail']} tail)" if gt.get("failed_tail") else "")),
        ("test procedure", (doc.get("tests") or {}).get("rule", "-")),
        ("σ0 plausibility", _sigma0_line(doc)),
    ], caption="Statistics")
    rows = []
    for sid, s in doc["stations"].items():
        ku, _ = _get(s, "offset_std_m")
        rows.append((sid, *(_m(doc, "stations", sid, "xyz_m", i) for i in range(3)),
                     *(_um(doc, "stations", sid, "cov_m2", i, i, op="sqrt", digits=1) for i in range(3)),
                     _um(doc, "stations", sid, "offset_m", digits=1, sign=True),
                     _um(doc, "stations", sid, ku, digits=1),
                     _um(doc, "stations", sid, ku, digits=1, k=K),
                     "estimated" if s.get("offset_estimated", True) else "held"))
    sec.table(("station", "x (m)", "y (m)", "z (m)", "u_x (µm)", "u_y (µm)", "u_z (µm)", "offset (µm)",
               "u(offset) (µm)", f"U(offset), k = {K:g} (µm)", "offset"), rows,
              caption="Stations: coordinates, standard uncertainties (k = 1), offsets with u and U")
    tids = list(doc["targets"])
    keep = _worst(tids, lambda t: max(np.diag(np.asarray(doc["targets"][t]["cov_m2"], float))))
    rows = []
    for j in keep:
        t = tids[j]
        tgt = doc["targets"][t]
        rows.append((t, *(_m(doc, "targets", t, "xyz_m", i) for i in range(3)),
                     *(_um(doc, "targets", t, "cov_m2", i, i, op="sqrt", digits=1) for i in range(3)),
                     *(_um(doc, "targets", t, "cov_m2", i, i, op="sqrt", digits=1, k=K) for i in range(3)),
                     tgt.get("n_obs", "-"),
                     _plain(doc, "targets", t, "redundancy", digits=3) if "redundancy" in tgt else "-"))
    more = "" if len(keep) == len(tids) else f" ({len(keep)} of {len(tids)}: the largest u shown)"
    sec.table(("target", "x (m)", "y (m)", "z (m)", "u_x", "u_y", "u_z", "U_x", "U_y", "U_z",
               "distances", "redundancy"), rows,
              caption=f"Targets: u and U (k = {K:g}) in µm{more}")
    sections = [sec, _adjust_reliability(doc)]
    if doc.get("reference_lengths"):
        sections.append(_reference_lengths(doc))
    if result is not None:
        sections.append(_network_figures(result))
    return sections


def _adjust_reliability(doc) -> Section:
    sec = Section("Reliability and data snooping")
    red = [t.get("redundancy") for t in doc["targets"].values() if t.get("redundancy") is not None]
    if red:
        sec.paragraph(f"Smallest redundancy number of a target's distances: {min(red):.3f} (0: the "
                      "distance is not checked by the others; 1: fully checked).")
    if not doc.get("snooping"):
        sec.paragraph("Data snooping was not done.")
    if doc.get("snooping") and doc.get("outliers"):
        sec.table(("station", "target", "w", "residual (µm)"),
                  [(o["station"], o["target"], _plain(doc, "outliers", i, "w", digits=2),
                    _um(doc, "outliers", i, "residual_m", digits=1, sign=True))
                   for i, o in enumerate(doc["outliers"])],
                  caption=f"Rejected by data snooping (α = {doc['alpha']:g})")
    if doc.get("angle_outliers"):
        sec.table(("station", "target", "kind", "w", "residual (µrad)"),
                  [(o["station"], o["target"], o["kind"], _plain(doc, "angle_outliers", i, "w", digits=2),
                    _urad(doc, "angle_outliers", i, "residual_rad")) for i, o in enumerate(doc["angle_outliers"])],
                  caption=f"Angles rejected by data snooping (α = {doc['alpha']:g})")
    if doc.get("snooping") and not doc.get("outliers") and not doc.get("angle_outliers"):
        sec.paragraph(f"No observation rejected by data snooping (α = {doc['alpha']:g}).")
    if doc.get("unlocated"):
        sec.paragraph("w-test failure that could not be located: " + ", ".join(
            f"{o['station']}->{o['target']}" for o in doc["unlocated"]) + f"; {doc.get('unlocated_reason', '')}")
    if doc.get("excluded"):
        sec.items([f"{e.get('kind')} {e.get('id')}: {e.get('reason')}" for e in doc["excluded"]])
    return sec


def _reference_lengths(doc) -> Section:
    sec = Section("Interpoint distances against reference lengths")
    rows = []
    for i, c in enumerate(doc["reference_lengths"]):
        ku, u = _get(c, "length_std_m")
        kr, ur = _get(c, "reference_std_m")
        comb = math.sqrt(u ** 2 + (ur or 0.0) ** 2)
        ok = abs(c["difference_m"]) <= K * comb
        rows.append((f"{c['target_a']}-{c['target_b']}", _m(doc, "reference_lengths", i, "length_m"),
                     _um(doc, "reference_lengths", i, ku, digits=1),
                     _um(doc, "reference_lengths", i, ku, digits=1, k=K),
                     _m(doc, "reference_lengths", i, "reference_m"),
                     _um(doc, "reference_lengths", i, kr, digits=1) if ur is not None else "-",
                     _um(doc, "reference_lengths", i, "difference_m", digits=1, sign=True),
                     f"{abs(c['difference_m']) / comb:.2f}" if comb > 0 else "-",
                     _verdict(ok)))
    sec.table(("points", "adjusted (m)", "u (µm)", f"U, k = {K:g} (µm)", "reference (m)", "u ref (µm)",
               "difference (µm)", "|d| / u_c", f"|d| <= {K:g} u_c"), rows,
              caption="u_c = sqrt(u² + u_ref²); the verdict is computed from the numbers in the row")
    return sec


def _network_figures(result) -> Section:
    from multilat.report import network_figures as nf

    sec = Section("Figures")
    ax = nf.plot_residuals(result)
    sec.figure(ax.figure, caption="Residuals (measured − adjusted) per target and head")
    ax = nf.plot_top_view(result)
    sec.figure(ax.figure, caption="Top view with the 95 % ellipses, magnified separately for stations and "
                                  "targets (factors in the legend)")
    _view_3d(sec, result)
    return sec


def _view_3d(sec: Section, result) -> None:
    from multilat.report import view3d

    frag = view3d.html_fragment(result)
    if frag is None:
        from multilat.report import network_figures as nf

        ax = nf.plot_3d(result)
        sec.figure(ax.figure, caption="3-D view (static: install the 'report' extra, plotly, for an "
                                      "interactive one)")
    else:
        sec.paragraph("Interactive 3-D view (drag to rotate, scroll to zoom): stations, targets and their "
                      "95 % ellipsoids, magnified per class as stated in the legend.")
        sec.raw(frag)


# ------------------------------------------------------------------------------------- propagate
def propagate(doc: dict, result=None, options=None) -> list[Section]:
    sec = Section("Monte Carlo")
    sec.table(("quantity", "value"), [
        ("source", doc["source"]), ("trials kept", doc["trials"]), ("failed to converge", doc["n_failed"]),
        ("noise", doc["noise"]), ("coverage probability", _plain(doc, "coverage", digits=2)),
        ("σ0 of the nominal adjustment", _plain(doc, "sigma0_nominal", digits=3)),
        ("σ0 mean over the trials", _plain(doc, "sigma0_mean", digits=3)),
        ("quantities whose MC std agrees with the linear one",
         f"{doc['summary']['n_agree']} / {doc['summary']['n_quantities']}"),
    ], caption="Run")
    rows = []
    pts = doc["points"]
    for q in _worst(pts, lambda p: p["semi_axes_95_m"][0]):
        p = pts[q]
        rows.append((p["id"], *(_um(doc, "points", q, "cov_mc_m2", i, i, op="sqrt") for i in range(3)),
                     *(_um(doc, "points", q, "cov_lin_m2", i, i, op="sqrt") for i in range(3)),
                     *(_um(doc, "points", q, "semi_axes_95_m", i) for i in range(3)),
                     _plain(doc, "points", q, "ellipsoid_coverage_mc")))
    sec.table(("point", "u_x MC", "u_y MC", "u_z MC", "u_x lin", "u_y lin", "u_z lin", "a1 95 %", "a2 95 %",
               "a3 95 %", "in MC ellipsoid"), rows,
              caption="Points (µm): MC and linear standard uncertainties; semi-axes of the MC 95 % ellipsoid; "
                      "fraction of the trials inside it")
    rows = []
    for group in ("parameters", "distances"):
        for i, r in enumerate(doc[group]):
            if group == "parameters" and not r["label"].endswith((".offset", ".scale")):
                continue
            p_lo, p_hi = ptr(group, i, "interval_symmetric_m", 0), ptr(group, i, "interval_symmetric_m", 1)
            rows.append((r["label"], _m(doc, group, i, "nominal_m"), _um(doc, group, i, "std_mc_m"),
                         _um(doc, group, i, "std_mc_se_m", digits=3), _um(doc, group, i, "std_lin_m"),
                         Num(resolve(doc, p_lo), p_lo, 1.0, 6), Num(resolve(doc, p_hi), p_hi, 1.0, 6),
                         _verdict(r["agrees"])))
    sec.table(("quantity", "nominal (m)", "u MC (µm)", "s.e. (µm)", "u lin (µm)", "95 % low (m)",
               "95 % high (m)", "MC agrees with linear"), rows[:MAX_ROWS],
              caption="Offsets and interpoint distances: the 95 % interval is probabilistically symmetric "
                      "(JCGM 101); 'agrees': |u MC − u lin| within 3 MC standard errors")
    out = [sec]
    if result is not None and getattr(result, "samples", None) is not None:
        from multilat.report.propagate_figures import clouds_figure

        ids = (options or {}).get("cloud_points")
        f = Section("Figures")
        f.figure(clouds_figure(result, points=_split_ids(ids)),
                 caption="Monte Carlo clouds (deviation from nominal) in the planes x-y, x-z, y-z with the "
                         "MC (solid) and linear (dashed) 95 % ellipsoids; red: stations, blue: targets")
        out.append(f)
    return out


def _split_ids(text):
    if not text:
        return None
    return [s.strip() for s in str(text).split(",") if s.strip()]


# -------------------------------------------------------------------------------------- simulate
def simulate(doc: dict, result=None, options=None) -> list[Section]:
    sec = Section("Simulation")
    s = doc["interpoint_std_m"]
    rows = [("multilat", *(_um(doc, "interpoint_std_m", k, digits=2) for k in ("min", "mean", "max")),
             _um(doc, "interpoint_std_se_m", digits=2))]
    if doc.get("paper_m"):
        rows.append((f"paper ({doc['paper_m']['trials']} simulations)",
                     *(_um(doc, "paper_m", k, digits=1) for k in ("min", "mean", "max")), "-"))
    sec.table(("", "min (µm)", "mean (µm)", "max (µm)", "s.e. of the mean (µm)"), rows,
              caption=f"Standard deviation of the interpoint-distance errors per simulation "
                      f"({doc['converged']} of {doc['trials']} simulations converged)")
    sec.paragraph(f"First-order prediction of the rms per-simulation std: "
                  f"{doc['interpoint_std_lin_rms_m'] * UM:.2f} µm (Monte Carlo rms "
                  f"{doc['interpoint_std_rms_m'] * UM:.2f} µm); "
                  f"the mean lies within 3 s.e. of the paper's: "
                  + (_verdict(abs(s["mean"] - doc["paper_m"]["mean"]) <= 3 * doc["interpoint_std_se_m"])
                     if doc.get("paper_m") else "no paper value for this configuration"))
    sec.table(("pair", "rms error (µm)", f"U = {K:g} × rms (µm)"),
              [(k, _um(doc, "pair_error_rms_m", k), _um(doc, "pair_error_rms_m", k, k=K))
               for k in doc["pair_error_rms_m"]], caption="Interpoint distances: rms error over the simulations")
    sec.table(("station", "rms offset error (µm)", f"U = {K:g} × rms (µm)"),
              [(k, _um(doc, "offset_error_rms_m", k), _um(doc, "offset_error_rms_m", k, k=K))
               for k in doc["offset_error_rms_m"]], caption="Offsets: rms error over the simulations")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.4))
    ax.hist(np.asarray(doc["per_simulation_std_m"], float) * UM, bins=20, color="C0", alpha=0.8)
    if doc.get("paper_m"):
        for k in ("min", "mean", "max"):
            ax.axvline(doc["paper_m"][k] * UM, color="k", ls="--" if k != "mean" else "-", lw=1)
    ax.set_xlabel("std of the interpoint-distance errors per simulation (µm)")
    ax.set_ylabel("simulations")
    sec.figure(fig, caption="Per-simulation std (bars); black lines: the paper's min, mean, max")
    return [sec]


# ---------------------------------------------------------------------------------------- design
def design(doc: dict, result=None, options=None) -> list[Section]:
    sec = Section("Design")
    sec.table(("quantity", "value"), [
        ("criterion", doc["criterion"]), ("criterion value (µm)", _um(doc, "criterion_m")),
        ("start layout's value (µm)", _um(doc, "start_criterion_m") if doc.get("start_criterion_m") is not None
         else "-"),
        ("degrees of freedom", doc["dof"]),
        ("smallest redundancy number", _plain(doc, "reliability", "redundancy_min")),
        ("largest minimal detectable bias (µm)", _um(doc, "reliability", "mdb_max_m", digits=1)),
        ("largest external reliability (µm)", _um(doc, "reliability", "external_max_m", digits=1)),
    ], caption="Predicted (no measurement yet: the uncertainties follow from the layout and σ)")
    sec.table(("head", "x (m)", "y (m)", "z (m)", "u_x (µm)", "u_y (µm)", "u_z (µm)", "u(offset) (µm)",
               f"U(offset), k = {K:g} (µm)"),
              [(sid, *(_m(doc, "stations", sid, "xyz_m", i, digits=4) for i in range(3)),
                *(_um(doc, "stations", sid, "cov_m2", i, i, op="sqrt") for i in range(3)),
                _um(doc, "stations", sid, "offset_std_m"), _um(doc, "stations", sid, "offset_std_m", k=K))
               for sid in doc["stations"]], caption="Heads")
    tids = list(doc["targets"])
    keep = _worst(tids, lambda t: doc["targets"][t]["u95_max_m"])
    sec.table(("target", "x (m)", "y (m)", "z (m)", "u_x (µm)", "u_y (µm)", "u_z (µm)",
               "95 % ellipsoid, largest semi-axis (µm)", "heads seeing it"),
              [(t, *(_m(doc, "targets", t, "xyz_m", i, digits=4) for i in range(3)),
                *(_um(doc, "targets", t, "cov_m2", i, i, op="sqrt") for i in range(3)),
                _um(doc, "targets", t, "u95_max_m"), doc["targets"][t]["seen_by"]) for t in
               (tids[j] for j in keep)], caption="Targets")
    if doc.get("lengths"):
        sec.table(("a", "b", "length (m)", "u (µm)", f"U, k = {K:g} (µm)"),
                  [(L["a"], L["b"], _m(doc, "lengths", i, "length_m"), _um(doc, "lengths", i, "length_std_m"),
                    _um(doc, "lengths", i, "length_std_m", k=K)) for i, L in enumerate(doc["lengths"])],
                  caption="Predicted lengths")
    out = [sec]
    if result is not None:
        from multilat.report import network_figures as nf

        f = Section("Figures")
        ax = nf.plot_top_view(result.best)
        f.figure(ax.figure, caption="Top view with the predicted 95 % ellipses, magnified per class")
        _view_3d(f, result.best)
        out.append(f)
    return out


# ---------------------------------------------------------------------------------------- budget
def budget(doc: dict, result=None, options=None) -> list[Section]:
    sec = Section("Budget")
    rows = []
    for g in doc["components"]:
        label = g + (" (not in the combined)" if g == "air" and not doc.get("include_air") else "")
        rows.append((label, _um(doc, "components", g), _um(doc, "components", g, k=K),
                     _um(doc, "component_error_mean_m", g, sign=True), _um(doc, "component_error_std_m", g)))
    ku, _ = _get(doc, "error_rms_m")
    rows.append(("combined" + (" (incl. air)" if doc.get("include_air") else ""), _um(doc, ku), _um(doc, ku, k=K),
                 _um(doc, "error_mean_m", sign=True), _um(doc, "error_std_m")))
    sec.table(("group", "u (µm)", f"U, k = {K:g} (µm)", "mean (µm)", "standard deviation (µm)"), rows,
              caption=f"{doc['instrument']}, head {doc['head']}, {doc['trials']:,} trials over "
                      f"{len(doc['distances_m'])} distances; u = sqrt(mean² + variance): an uncorrected bias "
                      "counts (Guillory et al. 2020, Precision Engineering 66, §3.4)")
    if doc.get("input_budget"):
        from multilat.report.budget_tables import input_budget_table

        input_budget_table(sec, doc)
    sec.table(("interval", "low (µm)", "high (µm)"),
              [("95 % probabilistically symmetric", _um(doc, "coverage_95_m", 0, sign=True),
                _um(doc, "coverage_95_m", 1, sign=True)),
               ("95 % shortest", _um(doc, "coverage_shortest_95_m", 0, sign=True),
                _um(doc, "coverage_shortest_95_m", 1, sign=True))],
              caption="Coverage intervals of the combined error from the simulated distribution (JCGM 101)")
    if result is not None and getattr(result, "samples", None) is not None:
        from multilat.report.distance_figures import plot_budget

        sec.figure(plot_budget(result), caption="Error distributions of the groups and of their sum")
    return [sec]


# --------------------------------------------------------------------------------------- correct
def correct(doc: dict, result=None, options=None) -> list[Section]:
    sec = Section("Corrected distances")
    n = len(doc["distance_m"])
    keep = list(range(n))[:MAX_ROWS]
    sec.table(("head", "target", "T (°C)", "air correction (µm)", "distance (m)", "σ air (µm)", "u (µm)",
               f"U, k = {K:g} (µm)"),
              [(doc["station_ids"][i], doc["target_ids"][i],
                _plain(doc, "environment", "temperature_c", i, digits=3),
                _um(doc, "index_correction_m", i, digits=1, sign=True), _m(doc, "distance_m", i, digits=7),
                _um(doc, "sigma_air_m", i), _um(doc, "sigma_m", i), _um(doc, "sigma_m", i, k=K)) for i in keep],
              caption=f"{n} distances" + ("" if n <= MAX_ROWS else f" (first {MAX_ROWS} shown)")
                      + "; σ air is the sensors' part, correlated between distances (full covariance in "
                        "--cov / --json)")
    for note in doc.get("notes") or []:
        sec.paragraph(f"note: {note}")
    if result is not None:
        from multilat.report.campaign_figures import correction_figure

        res, log = result
        sec.figure(correction_figure(res, log), caption="Environment per sensor and each distance's index "
                                                        "correction with its uncertainty")
    return [sec]


# ------------------------------------------------------------------------------------------- lbb
def lbb_simulate(doc: dict, result=None, options=None) -> list[Section]:
    sec = Section("Monte Carlo over the work volume")
    sec.table(("quantity", "value"), [
        ("method", doc["method"]), ("draws per cloud", doc["trials"]), ("points", doc["n_points"]),
        ("largest coordinate std (µm)", _um(doc, "std_max_m", digits=3)),
        (f"largest U = {K:g} std (µm)", _um(doc, "std_max_m", digits=3, k=K)),
        ("largest |mean error| (µm)", _um(doc, "error_mean_max_m", digits=3)),
    ], caption="Summary")
    pts = doc["points"]
    keep = _worst(pts, lambda p: max(p["std_m"]), n=50)
    sec.table(("x (mm)", "y (mm)", "z (mm)", "mean err x", "mean err y", "mean err z", "u_x", "u_y", "u_z",
               "U_x", "U_y", "U_z"),
              [(*(Num(resolve(doc, ptr("points", i, "nominal_m", c)), ptr("points", i, "nominal_m", c), 1e3, 1)
                  for c in range(3)),
                *(_um(doc, "points", i, "error_mean_m", c, digits=3, sign=True) for c in range(3)),
                *(_um(doc, "points", i, "std_m", c, digits=3) for c in range(3)),
                *(_um(doc, "points", i, "std_m", c, digits=3, k=K) for c in range(3))) for i in keep],
              caption=f"Points (µm unless stated), the {len(keep)} with the largest std; U with k = {K:g}")
    if result is not None:
        from multilat.lbb.simulate import base_xyz
        from multilat.lbb import figures as F

        sim, cfg = result
        sec.figure(F.volume_map(sim, base_xyz(cfg), quantity="std"),
                   caption="Largest coordinate standard deviation over the work volume")
    return [sec]


def lbb_compare(doc: dict, result=None, options=None) -> list[Section]:
    sec = Section("Comparison with the reference coordinates")
    rows = []
    for i, p in enumerate(doc["points"]):
        rows.append((p["point"], *(_um(doc, "points", i, "difference_m", c, sign=True) for c in range(3)),
                     *(_um(doc, "points", i, "std_mc_m", c, k=2.0) for c in range(3)),
                     " ".join(_verdict(v) for v in p["inside_2sigma"])))
    sec.table(("point", "dx (µm)", "dy (µm)", "dz (µm)", "2σ x (µm)", "2σ y (µm)", "2σ z (µm)",
               "inside mean ± 2σ (x y z)"), rows,
              caption=f"LBB − reference; simulated σ ({doc['method']}, {doc['trials']} draws)")
    per = doc.get("fraction_inside_2sigma_per_axis") or {}
    sec.paragraph(f"{doc['fraction_inside_2sigma']:.0%} of the coordinate differences lie within the simulated "
                  "mean ± 2σ" + (" (x / y / z: " + " / ".join(f"{per[c]:.0%}" for c in "xyz" if c in per) + ")"
                                 if per else "") + ".")
    if result is not None:
        from multilat.lbb import figures as F

        s = result.simulation
        sec.figure(F.reference_comparison(result.points, result.difference_m, s.mean_error_m, s.std_m),
                   caption="Fig. 7 (ours): LBB − reference per axis with the simulated mean ± 2σ")
    return [sec]


SECTIONS = {"adjust": adjust, "propagate": propagate, "simulate": simulate, "design": design,
            "budget": budget, "correct": correct, "lbb simulate": lbb_simulate, "lbb compare": lbb_compare}


def sections(command: str, doc: dict, *, result=None, options=None) -> list[Section]:
    """The results sections of ``command``'s report."""
    return SECTIONS[command](doc, result, options)
