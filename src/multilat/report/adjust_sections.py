"""The sections of an ``adjust`` report, in the order an auditor reads them: the verdicts and key
numbers first (σ0 and the global test, the w-tests, the worst point, the offset of each head, the
poorly controlled observations), then reliability, heads, angles and orientations, scale bars and
control, the frame and datum, the coordinates and the figures (``docs/report.md``).

Every number is read from the command's JSON document (a :class:`~multilat.report.html.Num` naming
its path); a verdict (:class:`~multilat.report.html.Verdict`) compares the numbers printed beside it
and nothing else. No statistic is computed here: the w of a scale bar or a control coordinate, the
critical values, the redundancy numbers and the MDBs are the adjustment's (``network/``); this module
only selects (the largest |w|, the largest u) and compares.
"""

from __future__ import annotations

import numpy as np

from multilat.report.html import Num, Section, Verdict
from multilat.report.job_sections import K, MAX_ROWS, _m, _plain, _um, ptr


def sections(doc: dict, result=None, options=None, *, warnings=()) -> list[Section]:
    """The adjust report's results sections (before the warnings and what was run); ``warnings``:
    every warning of the job (counted among the verdicts)."""
    from multilat.report import adjust_checks as ac

    out = [key_section(doc, warnings), reliability_section(doc), heads_section(doc), ac.angles_section(doc),
           ac.bars_and_control_section(doc, options or {}), ac.frame_section(doc, options or {}),
           coordinates_section(doc)]
    if result is not None:
        from multilat.report.job_sections import _network_figures

        out.append(_network_figures(result))
    return out


# ------------------------------------------------------------------------------------- selection
def largest_abs(rows, key, *, skip=None):
    """Index of the row with the largest finite ``|row[key]|`` (rows where ``skip(row)`` is true
    left out), or None."""
    best, k_best = -1.0, None
    for k, r in enumerate(rows):
        v = r.get(key)
        if v is None or (skip is not None and skip(r)) or not np.isfinite(v):
            continue
        if abs(v) > best:
            best, k_best = abs(v), k
    return k_best


def within(value: float, low: float | None, high: float | None) -> bool:
    """``low <= value <= high`` (a missing bound is no bound)."""
    return (low is None or value >= low) and (high is None or value <= high)


def w_critical(doc: dict):
    """(path, value) of the critical |w| of the run's w-tests, or (None, None) (no test, or the
    variance factor unknown: the τ-test decides, its statistic is not in the JSON)."""
    t = doc.get("tests") or {}
    if doc.get("variance_factor") == "unknown" or t.get("w_critical") is None:
        return None, None
    return ptr("tests", "w_critical"), t["w_critical"]


def w_verdict(w: float, crit: float) -> Verdict:
    return Verdict("|w| <= critical" if abs(w) <= crit else "|w| > critical", abs(w) <= crit)


# ---------------------------------------------------------------------------------- first section
def key_section(doc: dict, warnings=()) -> Section:
    """Verdicts and key numbers: what the reader must decide first."""
    sec = Section("Verdicts and key numbers", key="verdicts")
    sec.table(("check", "value", "lower limit", "upper limit", "verdict"), _verdict_rows(doc, len(warnings)),
              caption="Each verdict compares the value with the limits printed beside it", name="verdicts")
    sec.table(("quantity", "value"), _key_rows(doc), caption="Key numbers", name="key-numbers")
    heads = doc.get("heads") or {}
    sec.table(("head", "stations", "offset (µm)", "u(offset) (µm)", f"U(offset), k = {K:g} (µm)", "offset"),
              [(h, " ".join(v.get("stations", [])), _um(doc, "heads", h, "offset_m", digits=1, sign=True),
                _um(doc, "heads", h, "offset_std_m", digits=1), _um(doc, "heads", h, "offset_std_m", digits=1, k=K),
                "estimated" if v.get("offset_estimated", True) else "held") for h, v in heads.items()],
              caption="Offset of each head (u: standard uncertainty, k = 1)", name="head-offsets")
    rel = doc.get("reliability")
    if rel is not None and rel.get("poor_targets"):
        pts = rel["poor_targets"]
        sec.table(("target", "observations", "smallest redundancy", "largest MDB (µm)", "largest MDB / σ",
                   "largest shift (µm)"),
                  [(t["id"], t["n_obs"], _plain(doc, "reliability", "poor_targets", i, "redundancy_min"),
                    _um(doc, "reliability", "poor_targets", i, "mdb_max_m", digits=1),
                    _plain(doc, "reliability", "poor_targets", i, "mdb_max_sigma", digits=1),
                    _um(doc, "reliability", "poor_targets", i, "shift_max_m", digits=1))
                   for i, t in enumerate(pts[:MAX_ROWS])],
                  caption=f"Poorly controlled targets ({len(pts)}): an observation with redundancy < "
                          f"{rel['r_min']:g} or MDB > {rel['mdb_limit_sigma']:g} σ; the shift is the largest "
                          "coordinate change an undetected MDB would cause (observations in Reliability)",
                  name="poor-targets")
    elif rel is not None:
        sec.paragraph(f"Every observation is controlled (redundancy >= {rel['r_min']:g}, MDB <= "
                      f"{rel['mdb_limit_sigma']:g} σ).", cls="ok")
    return sec


def _verdict_rows(doc: dict, n_warnings: int) -> list:
    rows = []
    gt = doc.get("global_test") or {}
    if gt.get("statistic") is not None:
        ok = within(gt["statistic"], gt.get("critical_low"), gt.get("critical"))
        decides = gt.get("decides", True)
        text = ("passed" if ok else "FAILED") + ("" if decides else " (information only: variance factor "
                                                                     "unknown)")
        low = gt.get("alpha_low")
        rows.append((f"global χ² test of σ0 (α = {gt['alpha']:g}" + (f", lower tail {low:g}" if low else "")
                     + f", dof {gt['dof']})", _plain(doc, "global_test", "statistic"),
                     _plain(doc, "global_test", "critical_low") if gt.get("critical_low") is not None else "-",
                     _plain(doc, "global_test", "critical"), Verdict(text, ok if decides else None)))
    else:
        rows.append(("global χ² test of σ0", "-", "-", "-",
                     Verdict(f"not done ({doc.get('cost')} cost or no redundancy)", None)))
    rows.append(_sigma0_row(doc))
    crit_path, crit = w_critical(doc)
    for label, group, key, skip in (("distance", "observations", "w", lambda r: r.get("rejected")),
                                    ("angle", "angles", "w", None),
                                    ("scale bar", "scale_bars", "w", None)):
        items = doc.get(group) or []
        k = largest_abs(items, key, skip=skip)
        if k is None:
            continue
        w = items[k][key]
        who = f"{items[k].get('station', items[k].get('target_a'))}-{items[k].get('target', items[k].get('target_b'))}"
        rows.append((f"largest |w| of the {label}s kept ({who})", _plain(doc, group, k, key),
                     "-", Num(crit, crit_path, 1.0, 3) if crit is not None else "-",
                     w_verdict(w, crit) if crit is not None else Verdict("no w-test (τ-test: see Reliability)")))
    ctrl = doc.get("weighted_control") or []
    best = max(((abs(w), q, a) for q, c in enumerate(ctrl) for a, w in enumerate(c.get("w") or [])),
               default=None)
    if best is not None:
        _, q, a = best
        rows.append((f"largest |w| of the control coordinates ({ctrl[q]['point']} {'xyz'[a]})",
                     _plain(doc, "weighted_control", q, "w", a), "-",
                     Num(crit, crit_path, 1.0, 3) if crit is not None else "-",
                     w_verdict(ctrl[q]["w"][a], crit) if crit is not None else Verdict("no w-test")))
    n_out = len(doc.get("outliers") or []) + len(doc.get("angle_outliers") or [])
    rows.append(("observations rejected by data snooping", n_out, "-", "-",
                 Verdict("none" if n_out == 0 else f"{n_out} rejected: see Reliability", n_out == 0)
                 if doc.get("snooping") else Verdict("data snooping not done", None)))
    rel = doc.get("reliability")
    if rel is not None:
        n = len(rel.get("poor_observations") or [])
        rows.append((f"poorly controlled observations (redundancy < {rel['r_min']:g} or MDB > "
                     f"{rel['mdb_limit_sigma']:g} σ)", n, "-", 0,
                     Verdict("none" if n == 0 else f"{n} at {len(rel.get('poor_targets') or [])} target(s): "
                             "a blunder there would not show", n == 0)))
    checks = independent_references(doc)
    if checks:
        n_ok = sum(ok for _, _, ok in checks)
        rows.append((f"independent reference lengths within {K:g} u_c", n_ok, "-", len(checks),
                     Verdict("all agree" if n_ok == len(checks) else f"{len(checks) - n_ok} disagree",
                             n_ok == len(checks))))
    cv = doc.get("convergence") or {}
    rows.append(("solver converged", f"{cv.get('iterations', '-')} iterations", "-", "-",
                 Verdict(("yes: " if cv.get("converged") else "NO: ") + str(cv.get("reason", "")),
                         bool(cv.get("converged")))))
    nw = n_warnings
    rows.append(("warnings", nw, "-", 0, Verdict("none" if nw == 0 else f"{nw}: see Warnings", nw == 0)))
    return rows


def _sigma0_row(doc: dict):
    """σ0 against the plausibility band [1/f, f]; outside it, implausible when the χ² tail on that
    side is below α (the numbers in the row and the tails in the label)."""
    c = doc.get("sigma0_check") or {}
    if doc.get("cost") == "squared" or c.get("p_lower") is None:
        return ("σ0 plausibility", _plain(doc, "sigma0", digits=4), "-", "-", Verdict("not tested", None))
    s, f, a = doc["sigma0"], c["factor"], c["alpha"]
    low, high = s < 1.0 / f and c["p_lower"] < a, s > f and c["p_upper"] < a
    if not (low or high):
        v = Verdict("plausible" if within(s, 1.0 / f, f) else "outside the band, tail p >= α: plausible", True)
    elif c.get("accepted"):
        v = Verdict(f"too {'low' if low else 'high'}: accepted (variance factor unknown)", None)
    else:
        v = Verdict(f"IMPLAUSIBLE: too {'low' if low else 'high'} (check the unit of σ)", False)
    return (f"σ0 plausibility (χ² tails p = {c['p_lower']:.2g} below, {c['p_upper']:.2g} above; implausible "
            f"outside the band when that tail's p < {a:g})", _plain(doc, "sigma0", digits=4),
            Num(f, ptr("sigma0_check", "factor"), 1.0, 3, op="inv"), _plain(doc, "sigma0_check", "factor"), v)


def _key_rows(doc: dict) -> list:
    rows = [("σ0" + (" (m², eq. 6)" if doc.get("cost") == "squared" else " (ratio to the a-priori σ)"),
             _plain(doc, "sigma0", digits=4)),
            ("degrees of freedom", doc["dof"]),
            ("distances used / given", f"{doc['n_used']} / {doc['n_obs']}"),
            ("angles", len(doc.get("angles") or [])),
            ("scale bars / weighted control points", f"{len(doc.get('scale_bars') or [])} / "
                                                      f"{len(doc.get('weighted_control') or [])}"),
            ("datum", doc["datum"])]
    for group, what in (("stations", "station"), ("targets", "target")):
        pid, axis = worst_point(doc[group])
        if pid is None:
            continue
        rows.append((f"worst {what}: {pid}, largest coordinate u ({'xyz'[axis]}) (µm)",
                     _um(doc, group, pid, "cov_m2", axis, axis, op="sqrt", digits=1)))
        rows.append((f"worst {what}: {pid}, U = {K:g} u (µm)",
                     _um(doc, group, pid, "cov_m2", axis, axis, op="sqrt", digits=1, k=K)))
    return rows


def worst_point(points: dict):
    """(id, axis) of the point with the largest coordinate variance (the largest u), or (None, None)."""
    best, out = -1.0, (None, None)
    for pid, p in points.items():
        d = np.diag(np.asarray(p["cov_m2"], float))
        if np.all(np.isfinite(d)) and d.max() > best:
            best, out = float(d.max()), (pid, int(np.argmax(d)))
    return out


def independent_references(doc: dict) -> list:
    """``(index, u_c, agrees)`` of each reference length that was NOT an observation (a bar used as
    an observation is no independent check); agrees: ``|d| <= K u_c``, ``u_c = sqrt(u² + u_ref²)``
    (the combination of the two printed uncertainties, as the row shows it)."""
    bars = {frozenset((b["target_a"], b["target_b"])) for b in doc.get("scale_bars") or []}
    out = []
    for i, c in enumerate(doc.get("reference_lengths") or []):
        if frozenset((c["target_a"], c["target_b"])) in bars:
            continue
        uc = float(np.hypot(c["length_std_m"], c.get("reference_std_m") or 0.0))
        out.append((i, uc, abs(c["difference_m"]) <= K * uc))
    return out


# ----------------------------------------------------------------------------------- reliability
def reliability_section(doc: dict) -> Section:
    sec = Section("Reliability", key="reliability")
    t = doc.get("tests") or {}
    if t.get("rule"):
        sec.paragraph("Test procedure: " + t["rule"] + ".")
    if t.get("alpha0") is not None and t.get("w_critical") is not None:
        sec.table(("α0 per test", "critical |w|", "power", "λ0 of the w-test", "tests"),
                  [(_plain(doc, "tests", "alpha0", digits=7), _plain(doc, "tests", "w_critical"),
                    _plain(doc, "tests", "power", digits=2),
                    _plain(doc, "tests", "lambda0_w" if t.get("lambda0_w") is not None else "lambda0", digits=2),
                    t.get("n_tests", "-"))], caption="w-tests", name="w-tests")
    ext = doc.get("observation_extremes") or {}        # adjust/2: over every observation kept
    if ext:
        rows = []
        for label, key, scale, digits in (("redundancy number", "redundancy", 1.0, 3),
                                          ("MDB (µm)", "mdb_m", 1e6, 1), ("MDB / σ", "mdb_sigma", 1.0, 1),
                                          ("largest shift (µm)", "shift_max_m", 1e6, 1)):
            if key not in ext:
                continue
            lo, hi = ext[key]["smallest"], ext[key]["largest"]
            rows.append((label, Num(lo["value"], ptr("observation_extremes", key, "smallest", "value"), scale, digits),
                         f"{lo['station']}-{lo['target']}",
                         Num(hi["value"], ptr("observation_extremes", key, "largest", "value"), scale, digits),
                         f"{hi['station']}-{hi['target']}"))
        sec.table(("quantity", "smallest", "at", "largest", "at"), rows,
                  caption="Internal and external reliability of the distances kept (the rejected ones left "
                          "out)", name="reliability-ranges")
    rel = doc.get("reliability")
    if rel is not None:
        po = rel.get("poor_observations") or []
        if po:
            rows = []
            for i, o in enumerate(po[:MAX_ROWS]):
                why = [w for w, bad in ((f"r < {rel['r_min']:g}", o["redundancy"] < rel["r_min"]),
                                        (f"MDB > {rel['mdb_limit_sigma']:g} σ",
                                         o["mdb_sigma"] > rel["mdb_limit_sigma"])) if bad]
                rows.append((o["station"], o["target"],
                             _plain(doc, "reliability", "poor_observations", i, "redundancy"),
                             _um(doc, "reliability", "poor_observations", i, "mdb_m", digits=1),
                             _plain(doc, "reliability", "poor_observations", i, "mdb_sigma", digits=1),
                             _um(doc, "reliability", "poor_observations", i, "shift_max_m", digits=1),
                             o.get("shift_point", "-"), Verdict(" and ".join(why) or "-", False if why else None)))
            sec.table(("station", "target", "redundancy", "MDB (µm)", "MDB / σ", "largest shift (µm)", "at point",
                       "poorly controlled because"), rows,
                      caption=f"Poorly controlled observations ({len(po)})", name="poor-observations")
        else:
            sec.paragraph(f"Every observation is controlled (redundancy >= {rel['r_min']:g}, MDB <= "
                          f"{rel['mdb_limit_sigma']:g} σ).", cls="ok")
    _largest_w_table(sec, doc)
    _snooping_tables(sec, doc)
    return sec


def _largest_w_table(sec: Section, doc: dict) -> None:
    top = doc.get("largest_w") or []                   # adjust/2: the rows with the largest |w|, largest first
    if not top or top[0].get("w") is None:
        return
    _, crit = w_critical(doc)
    sec.table(("station", "target", "σ (µm)", "residual (µm)", "redundancy", "w", "MDB (µm)", "rejected",
               "verdict"),
              [(o["station"], o["target"], _um(doc, "largest_w", k, "sigma_m", digits=2),
                _um(doc, "largest_w", k, "residual_m", digits=2, sign=True),
                _plain(doc, "largest_w", k, "redundancy"), _plain(doc, "largest_w", k, "w"),
                _um(doc, "largest_w", k, "mdb_m", digits=1), "yes" if o.get("rejected") else "no",
                w_verdict(o["w"], crit) if crit is not None else Verdict("-"))
               for k, o in enumerate(top)],
              caption=f"The {len(top)} distances with the largest |w| (residual: measured − adjusted)",
              name="largest-w")


def _snooping_tables(sec: Section, doc: dict) -> None:
    if not doc.get("snooping"):
        sec.paragraph("Data snooping was not done.")
    if doc.get("outliers"):
        sec.table(("order", "station", "target", "w", "residual (µm)"),
                  [(o.get("order", i + 1), o["station"], o["target"], _plain(doc, "outliers", i, "w", digits=2),
                    _um(doc, "outliers", i, "residual_m", digits=1, sign=True))
                   for i, o in enumerate(doc["outliers"])],
                  caption=f"Distances rejected by data snooping (α0 = {doc['alpha']:g} given)", name="outliers")
    if doc.get("angle_outliers"):
        sec.table(("station", "target", "kind", "w", "residual (µrad)"),
                  [(o["station"], o["target"], o["kind"], _plain(doc, "angle_outliers", i, "w", digits=2),
                    Num(o["residual_rad"], ptr("angle_outliers", i, "residual_rad"), 1e6, 1, sign=True))
                   for i, o in enumerate(doc["angle_outliers"])],
                  caption="Angles rejected by data snooping", name="angle-outliers")
    if doc.get("snooping") and not doc.get("outliers") and not doc.get("angle_outliers"):
        sec.paragraph("No observation rejected by data snooping.", cls="ok")
    if doc.get("unlocated"):
        sec.paragraph("w-test failure that could not be located: " + ", ".join(
            f"{o['station']}->{o['target']}" for o in doc["unlocated"]) + f"; {doc.get('unlocated_reason', '')}",
            cls="warn")
    if doc.get("w_failures"):
        sec.items([f"w = {f['w']:+.2f}: " + ", ".join(f"{o.get('station')}->{o.get('target')}"
                                                      for o in f["observations"])
                   + ("" if f.get("located") else " (perfectly correlated tests: cannot be told apart)")
                   for f in doc["w_failures"]], cls="warn")
    if doc.get("excluded"):
        sec.items([f"left out before solving: {e.get('kind')} {e.get('id')}: {e.get('reason')}"
                   for e in doc["excluded"]], cls="warn")


# ------------------------------------------------------------------------------------------ heads
def heads_section(doc: dict) -> Section:
    sec = Section("Heads", key="heads")
    heads = doc.get("heads") or {}
    scaled = any(h.get("scale_estimated") for h in heads.values())
    header = ["head", "stations", "offset (µm)", "u(offset) (µm)", f"U(offset), k = {K:g} (µm)", "offset"]
    if scaled:
        header += ["scale (µm/m)", "u(scale) (µm/m)", "scale"]
    rows = []
    for h, v in heads.items():
        row = [h, " ".join(v.get("stations", [])), _um(doc, "heads", h, "offset_m", digits=1, sign=True),
               _um(doc, "heads", h, "offset_std_m", digits=1), _um(doc, "heads", h, "offset_std_m", digits=1, k=K),
               "estimated" if v.get("offset_estimated", True) else "held"]
        if scaled:
            row += [_um(doc, "heads", h, "scale", digits=2, sign=True), _um(doc, "heads", h, "scale_std", digits=2),
                    "estimated" if v.get("scale_estimated") else "held at 0"]
        rows.append(row)
    sec.table(header, rows, caption="Each head's additive offset (and scale): one unknown per head, shared by "
                                    "every station it occupied", name="heads")
    if heads and all(v.get("stations") == [h] for h, v in heads.items()):
        sec.paragraph("Each station is its own head (no head column in the observations).")
    return sec


# ------------------------------------------------------------------------------------ coordinates
def coordinates_section(doc: dict) -> Section:
    sec = Section("Coordinates", key="coordinates")
    rows = []
    for sid, s in doc["stations"].items():
        rows.append((sid, s.get("head", sid), *(_m(doc, "stations", sid, "xyz_m", i) for i in range(3)),
                     *(_um(doc, "stations", sid, "cov_m2", i, i, op="sqrt", digits=1) for i in range(3)),
                     *(_um(doc, "stations", sid, "cov_m2", i, i, op="sqrt", digits=1, k=K) for i in range(3))))
    sec.table(("station", "head", "x (m)", "y (m)", "z (m)", "u_x (µm)", "u_y (µm)", "u_z (µm)", "U_x (µm)",
               "U_y (µm)", "U_z (µm)"), rows,
              caption=f"Stations: coordinates, u (k = 1) and U (k = {K:g})", name="stations")
    tids = list(doc["targets"])
    from multilat.report.job_sections import _worst

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
    sec.table(("target", "x (m)", "y (m)", "z (m)", "u_x (µm)", "u_y (µm)", "u_z (µm)", "U_x (µm)", "U_y (µm)",
               "U_z (µm)", "distances", "redundancy"), rows,
              caption=f"Targets: coordinates, u and U (k = {K:g}); redundancy: the sum over the target's "
                      f"distances{more}", name="targets")
    return sec


__all__ = ["sections", "key_section", "reliability_section", "heads_section", "coordinates_section",
           "independent_references", "worst_point", "largest_abs"]
