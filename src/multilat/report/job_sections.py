"""Results sections of the job reports, one function per command, each reading the command's JSON
document (every number a :class:`~multilat.report.html.Num` naming its JSON path) and adding the
figures. Called by :func:`multilat.report.job.build_report`."""

from __future__ import annotations

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
def adjust(doc: dict, result=None, options=None) -> list[Section]:
    """The adjust report: verdicts first, then reliability, heads, angles, bars and control, frame
    and datum, coordinates, figures (:mod:`multilat.report.adjust_sections`)."""
    from multilat.report import adjust_sections

    return adjust_sections.sections(doc, result, options)


def _network_figures(result) -> Section:
    from multilat.report import network_figures as nf

    sec = Section("Figures", key="figures")
    ax = nf.plot_residuals(result)
    sec.figure(ax.figure, caption="Residuals (measured − adjusted) per target, one marker per station "
                                  "(its head in brackets where a head occupied several stations)")
    ax = nf.plot_top_view(result)
    sec.figure(ax.figure, caption="Top view with the 95 % ellipses, magnified separately for stations and "
                                  "targets (factors in the legend)")
    _view_3d(sec, result)
    return sec


def _view_3d(sec: Section, result, occluders=()) -> None:
    from multilat.report import view3d

    frag = view3d.html_fragment(result, occluders)
    if frag is None:
        from multilat.report.design_figures import plot_layout_3d

        ax = plot_layout_3d(result, occluders)
        sec.figure(ax.figure, caption="3-D view (static: install the 'report' extra, plotly, for an "
                                      "interactive one)")
    else:
        sec.paragraph("Interactive 3-D view (drag to rotate, scroll to zoom): stations, targets and their "
                      "95 % ellipsoids, magnified per class as stated in the legend.")
        sec.raw(frag)


# ------------------------------------------------------------------------------------- propagate
def propagate(doc: dict, result=None, options=None) -> list[Section]:
    sec = Section("Monte Carlo", key="montecarlo")
    sec.table(("quantity", "value"), [
        ("source", doc["source"]), ("trials kept", doc["trials"]), ("failed to converge", doc["n_failed"]),
        ("noise", doc["noise"]), ("coverage probability", _plain(doc, "coverage", digits=2)),
        ("σ0 of the nominal adjustment", _plain(doc, "sigma0_nominal", digits=3)),
        ("σ0 mean over the trials", _plain(doc, "sigma0_mean", digits=3)),
        ("quantities whose MC std agrees with the linear one",
         f"{doc['summary']['n_agree']} / {doc['summary']['n_quantities']}"),
    ], caption="Run")
    rows = []
    pts = doc["points"]                                 # {id: point} (propagate/2)
    ids = list(pts)
    for q in (ids[i] for i in _worst([pts[p] for p in ids], lambda p: p["semi_axes_95_m"][0])):
        rows.append((q, *(_um(doc, "points", q, "cov_mc_m2", i, i, op="sqrt") for i in range(3)),
                     *(_um(doc, "points", q, "cov_lin_m2", i, i, op="sqrt") for i in range(3)),
                     *(_um(doc, "points", q, "semi_axes_95_m", i) for i in range(3)),
                     _plain(doc, "points", q, "ellipsoid_coverage_mc")))
    sec.table(("point", "u_x MC", "u_y MC", "u_z MC", "u_x lin", "u_y lin", "u_z lin", "a1 95 %", "a2 95 %",
               "a3 95 %", "in MC ellipsoid"), rows,
              caption="Points (µm): MC and linear standard uncertainties; semi-axes of the MC 95 % ellipsoid; "
                      "fraction of the trials inside it")
    _propagate_parameters(sec, doc)
    _propagate_distances(sec, doc)
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


AGREES = "'agrees': |u MC − u lin| within 3 MC standard errors"


def _propagate_parameters(sec: Section, doc: dict) -> None:
    """Offsets (µm) and scale factors (µm/m): nominal, u, s.e. and the 95 % interval in one unit."""
    for suffix, unit, what in ((".offset", "µm", "Offsets"), (".scale", "µm/m", "Scale factors")):
        rows = []
        for i, r in enumerate(doc["parameters"]):
            if not r["label"].endswith(suffix):
                continue
            rows.append((r["label"], _um(doc, "parameters", i, "nominal_m", sign=True),
                         _um(doc, "parameters", i, "std_mc_m"), _um(doc, "parameters", i, "std_mc_se_m", digits=3),
                         _um(doc, "parameters", i, "std_lin_m"),
                         _um(doc, "parameters", i, "interval_symmetric_m", 0, sign=True),
                         _um(doc, "parameters", i, "interval_symmetric_m", 1, sign=True), _verdict(r["agrees"])))
        if rows:
            sec.table(("quantity", f"nominal ({unit})", f"u MC ({unit})", f"s.e. ({unit})", f"u lin ({unit})",
                       f"95 % low ({unit})", f"95 % high ({unit})", "MC agrees with linear"), rows[:MAX_ROWS],
                      caption=f"{what} ({unit}): the 95 % interval is probabilistically symmetric (JCGM 101); "
                              + AGREES, name=what.lower().replace(" ", "-"))


def _propagate_distances(sec: Section, doc: dict) -> None:
    """Interpoint distances: lengths and their interval in m (0.1 µm), uncertainties in µm."""
    rows = [(r["label"], _m(doc, "distances", i, "nominal_m", digits=7), _um(doc, "distances", i, "std_mc_m"),
             _um(doc, "distances", i, "std_mc_se_m", digits=3), _um(doc, "distances", i, "std_lin_m"),
             _m(doc, "distances", i, "interval_symmetric_m", 0, digits=7),
             _m(doc, "distances", i, "interval_symmetric_m", 1, digits=7), _verdict(r["agrees"]))
            for i, r in enumerate(doc["distances"][:MAX_ROWS])]
    if rows:
        sec.table(("points", "length (m)", "u MC (µm)", "s.e. (µm)", "u lin (µm)", "95 % low (m)", "95 % high (m)",
                   "MC agrees with linear"), rows,
                  caption="Interpoint distances: lengths and the 95 % interval in m, their uncertainties in µm; "
                          + AGREES, name="distances")


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
    pc = doc.get("poorly_controlled")
    if pc and pc["n_targets"]:
        sec.table(("target", "poorly controlled distances", "smallest redundancy", "largest MDB (µm)", "MDB / σ"),
                  [(t["id"], t["n_obs"], f"{t['redundancy']:.3g}",       # MDB null: infinite (r = 0)
                    "∞" if t["mdb_m"] is None else f"{t['mdb_m'] * UM:.1f}",
                    "∞" if t["mdb_sigma"] is None else f"{t['mdb_sigma']:.3g}")
                   for t in pc["targets"]],
                  caption=f"Warning: {pc['n_targets']} targets poorly controlled (redundancy < {pc['r_min']:g} or "
                          f"MDB > {pc['mdb_limit_sigma']:g} σ): a blunder in their distances would not show")
    if doc.get("lengths"):
        sec.table(("a", "b", "length (m)", "u (µm)", f"U, k = {K:g} (µm)"),
                  [(L["a"], L["b"], _m(doc, "lengths", i, "length_m"), _um(doc, "lengths", i, "length_std_m"),
                    _um(doc, "lengths", i, "length_std_m", k=K)) for i, L in enumerate(doc["lengths"])],
                  caption="Predicted lengths")
    out = [sec]
    if result is not None:
        from multilat.report import network_figures as nf

        from multilat.report.design_figures import draw_occluders

        f = Section("Figures")
        occ = getattr(result, "occluders", ())
        ax = draw_occluders(nf.plot_top_view(result.best), occ)
        f.figure(ax.figure, caption="Top view with the predicted 95 % ellipses, magnified per class"
                 + (" and the declared obstructions (dashed)" if occ else ""))
        _view_3d(f, result.best, occ)
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


def sections(command: str, doc: dict, *, result=None, options=None, warnings=()) -> list[Section]:
    """The results sections of ``command``'s report (``warnings``: every warning of the job, which
    the adjust report counts among its verdicts)."""
    if command == "adjust":
        from multilat.report import adjust_sections

        return adjust_sections.sections(doc, result, options, warnings=warnings)
    return SECTIONS[command](doc, result, options)
