"""The adjust report's sections on angles and orientations, on scale bars and control (observations
of the adjustment, with their residuals and w) against the independent reference lengths (checks
not in the adjustment), and on the coordinate frame and datum in words (the JSON's ``frame``, worded
once in :mod:`multilat.network.model.frame_words`).

As in :mod:`multilat.report.adjust_sections`: numbers from the JSON document, verdicts from the
numbers printed beside them, no statistic computed here.
"""

from __future__ import annotations

from multilat.report.adjust_sections import independent_references, w_critical, w_verdict
from multilat.report.html import Num, Section, Verdict
from multilat.report.job_sections import K, MAX_ROWS, _m, _plain, _um, ptr

URAD = 1e6
#: the orientation parameters of a station, as named in the JSON, and their symbols
ANGLE_NAMES = (("omega", "ω"), ("phi", "φ"), ("kappa", "κ"))


def _urad(doc, *path, digits=1, sign=False):
    p = ptr(*path)
    from multilat.report.job_sections import resolve

    return Num(resolve(doc, p), p, URAD, digits, 1.0, "", sign)


# ------------------------------------------------------------------------------------------ angles
def angles_section(doc: dict) -> Section:
    sec = Section("Angles and orientations", key="angles")
    oriented = {sid: s for sid, s in doc["stations"].items() if s.get("orientation_rad") is not None}
    angles = doc.get("angles") or []
    if not oriented and not angles:
        sec.paragraph("No angle was observed: the network is from distances alone, no station has an "
                      "orientation unknown.")
        return sec
    if oriented:
        rows = []
        for sid, s in oriented.items():
            names = list(s.get("parameters") or [n for n, _ in ANGLE_NAMES][:len(s["orientation_rad"])])
            row = [sid]
            for n, _ in ANGLE_NAMES:
                if n in names:
                    q = names.index(n)
                    row += [_urad(doc, "stations", sid, "orientation_rad", q, sign=True),
                            _urad(doc, "stations", sid, "orientation_std_rad", q)]
                else:
                    row += ["not estimated", "-"]
            rows.append(row)
        sec.table(("station", *(h for _, s in ANGLE_NAMES for h in (f"{s} (µrad)", f"u({s}) (µrad)"))), rows,
                  caption="Orientation of each station that observed angles: R = Rz(κ) Ry(φ) Rx(ω), "
                          "angles and their standard uncertainties in µrad", name="orientations")
    if angles:
        _, crit = w_critical(doc)
        order = sorted(range(len(angles)), key=lambda k: -abs(angles[k].get("w") or 0.0))[:MAX_ROWS]
        sec.table(("station", "target", "kind", "σ (µrad)", "residual (µrad)", "redundancy", "w", "MDB (µrad)",
                   "verdict"),
                  [(angles[k]["station"], angles[k]["target"], angles[k]["kind"],
                    _urad(doc, "angles", k, "sigma_rad"), _urad(doc, "angles", k, "residual_rad", sign=True),
                    _plain(doc, "angles", k, "redundancy"), _plain(doc, "angles", k, "w"),
                    _urad(doc, "angles", k, "mdb_rad"),
                    w_verdict(angles[k]["w"], crit) if crit is not None else Verdict("-"))
                   for k in order],
                  caption=f"Angle observations ({len(angles)}"
                          + ("" if len(order) == len(angles) else f", the {len(order)} with the largest |w|")
                          + "): residual = measured − adjusted, in µrad", name="angles")
    return sec


# ------------------------------------------------------------------------------- bars and control
def bars_and_control_section(doc: dict, options: dict) -> Section:
    sec = Section("Scale bars and control", key="bars")
    _, crit = w_critical(doc)
    bars = doc.get("scale_bars") or []
    if bars:
        sec.table(("bar", "length (m)", "σ (µm)", "adjusted (m)", "residual (µm)", "redundancy", "w", "verdict"),
                  [(f"{b['target_a']}-{b['target_b']}", _m(doc, "scale_bars", i, "length_m", digits=7),
                    _um(doc, "scale_bars", i, "sigma_m", digits=2), _m(doc, "scale_bars", i, "adjusted_m", digits=7),
                    _um(doc, "scale_bars", i, "residual_m", digits=2, sign=True),
                    _plain(doc, "scale_bars", i, "redundancy"),
                    _plain(doc, "scale_bars", i, "w") if b.get("w") is not None else "-",
                    w_verdict(b["w"], crit) if crit is not None and b.get("w") is not None else Verdict("-"))
                   for i, b in enumerate(bars)],
                  caption="Scale bars used as observations (in the adjustment, so not independent checks): "
                          "residual = given − adjusted", name="scale-bars")
    ctrl = doc.get("weighted_control") or []
    if ctrl:
        rows = []
        for q, c in enumerate(ctrl):
            for a in range(3):
                w = (c.get("w") or [None] * 3)[a]
                rows.append((c["point"], "xyz"[a], _m(doc, "weighted_control", q, "xyz_m", a),
                             _um(doc, "weighted_control", q, "std_m", a, digits=1),
                             _um(doc, "weighted_control", q, "residual_m", a, digits=2, sign=True),
                             _plain(doc, "weighted_control", q, "redundancy", a),
                             _plain(doc, "weighted_control", q, "w", a) if w is not None else "-",
                             w_verdict(w, crit) if crit is not None and w is not None else Verdict("-")))
        sec.table(("point", "axis", "given (m)", "σ (µm)", "residual (µm)", "redundancy", "w", "verdict"), rows,
                  caption="Weighted control: coordinates observed with their σ (in the adjustment); "
                          "residual = given − adjusted", name="weighted-control")
    if doc["datum"].startswith("fixed control"):
        pts = options.get("points")
        weighted = {c["point"] for c in ctrl}
        sec.paragraph("Hard control: the points of " + (f"--points {pts}" if pts else "the control file")
                      + (" without sx_m, sy_m, sz_m" if weighted else "") + " are held fixed (no residual, "
                      "zero variance)" + (f"; weighted: {', '.join(sorted(weighted))}" if weighted else "") + ".")
    _reference_table(sec, doc)
    if not bars and not ctrl and not doc.get("reference_lengths"):
        sec.paragraph("No scale bar, no weighted control and no reference length: the scale comes from the "
                      "distances alone, nothing external checks it.")
    return sec


def _reference_table(sec: Section, doc: dict) -> None:
    refs = doc.get("reference_lengths") or []
    checks = independent_references(doc)
    if refs and not checks:
        sec.paragraph("Every reference length of --references was used as a scale bar (an observation, "
                      "above): none is left as an independent check of the scale.", cls="warn")
    if not checks:
        return
    rows = []
    for i, uc, ok in checks:
        c = refs[i]
        rows.append((f"{c['target_a']}-{c['target_b']}", _m(doc, "reference_lengths", i, "length_m", digits=7),
                     _um(doc, "reference_lengths", i, "length_std_m", digits=1),
                     _um(doc, "reference_lengths", i, "length_std_m", digits=1, k=K),
                     _m(doc, "reference_lengths", i, "reference_m", digits=7),
                     _um(doc, "reference_lengths", i, "reference_std_m", digits=1)
                     if c.get("reference_std_m") is not None else "-",
                     _um(doc, "reference_lengths", i, "difference_m", digits=1, sign=True),
                     f"{uc * 1e6:.1f}", f"{K * uc * 1e6:.1f}",
                     Verdict("yes" if ok else "NO", ok)))
    n_used = len(refs) - len(checks)
    sec.table(("points", "adjusted (m)", "u (µm)", f"U, k = {K:g} (µm)", "reference (m)", "u ref (µm)",
               "difference (µm)", "u_c (µm)", f"{K:g} u_c (µm)", f"|d| <= {K:g} u_c"), rows,
              caption="Independent checks: reference lengths not in the adjustment, against the adjusted "
                      "interpoint distances; u_c = sqrt(u² + u_ref²)"
                      + (f" ({n_used} other reference length(s) were scale bars)" if n_used else ""),
              name="reference-lengths")


# ------------------------------------------------------------------------------- frame and datum
def frame_section(doc: dict, options: dict) -> Section:
    """The frame and the scale in the JSON's words (``frame``, :mod:`multilat.network.model.frame_words`)."""
    sec = Section("Frame and datum", key="frame")
    fr = doc.get("frame") or {"axes": "not recorded (a result written before the key frame)",
                              "scale": "not recorded"}
    init = (doc.get("initial") or {}).get("method", "not recorded")
    from multilat.network.model.sigma_source import describe

    items = [f"datum: {doc['datum']}", f"frame: {fr['axes']}", f"scale: {fr['scale']}",
             f"initial values: {init}",
             "units: coordinates in metres in a right-handed x, y, z frame; uncertainties in µm; angles in µrad",
             f"variance factor: {doc.get('variance_factor', 'known')}"
             + (" (σ̂0 scales the covariances and MDBs)" if doc.get("variance_factor") == "unknown"
                else " (the a-priori σ are taken as right; the global test checks them)")]
    if doc.get("sigma_source"):
        items.append(describe(doc["sigma_source"]))
    sec.items(items)
    return sec


__all__ = ["angles_section", "bars_and_control_section", "frame_section"]
