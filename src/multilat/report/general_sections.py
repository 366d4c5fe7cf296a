"""The report of a general-network adjustment (``multilat adjust NET.xml|DIR|obs.csv --model general
--report FILE.html``, and ``--model auto`` when it takes the general layer), in the order an auditor
reads it: the verdicts and key numbers first (the global test, the largest test statistic of each
observation kind, data snooping, poorly controlled rows, points kept without control, points left
out), then the frame and datum in words, the points with their uncertainties, the instrument and
set-up parameters (heads' constants and scales, orientations) with theirs, reliability, the
residuals by kind and the w-tests (``docs/general-network.md``, "The HTML report").

Every number is read from the command's JSON document (``multilat.adjust-general``; a
:class:`~multilat.report.html.Num` names its path); a verdict compares the numbers printed beside
it. The observation rows come from the result, every row (:class:`Rows`: the ``observations``
table the command writes under ``--out``), whatever the JSON lists: a row the JSON lists (all with
``--observations``; else the rows that matter) names its path there, every row names its place in
the table (``data-row``, ``data-key``), so the page is the same with or without ``--observations``. No statistic is computed here: the tests, critical values, redundancy numbers, MDBs and shifts
are :mod:`multilat.network.adjust.general.quality`'s and ``reliability``'s; which rows are poorly
controlled and which points have no control is :mod:`multilat.network.adjust.general.report`'s rule. This
module only selects (the largest |w|, the largest u) and compares.
"""

from __future__ import annotations

import numpy as np

from multilat.report.adjust_sections import worst_point
import html as _html
from dataclasses import dataclass

from multilat.report.html import Num, Section, Verdict
from multilat.report.job_sections import K, MAX_ROWS, ptr, resolve

__all__ = ["sections", "build_report", "Rows", "rows_of", "TITLE", "LARGEST_ROWS"]

TITLE = "General network adjustment"
#: rows of the "largest test statistics" table
LARGEST_ROWS = 10
#: µm per m and µrad per rad: the unit of the small quantities (residuals, MDBs, u) in the tables
MICRO = 1e6
_UNIT = {"m": "µm", "rad": "µrad"}
_KIND_WORDS = {"offset": "additive constant", "scale": "scale", "omega": "set-up angle ω", "phi": "set-up angle φ",
               "kappa": "set-up angle κ (orientation)", "orientation": "direction-set orientation"}


def _num(doc, *path, scale=1.0, digits=3, k=1.0, op="", sign=False) -> Num:
    p = ptr(*path)
    return Num(resolve(doc, p), p, scale, digits, k, op, sign)


@dataclass(frozen=True)
class RowNum(Num):
    """A number of an observation row: the JSON path when the document lists the row (else none), and
    always the row's ``index`` in the ``observations`` table and the column (``data-row``, ``data-key``)."""

    row: int = -1
    key: str = ""

    def cell(self) -> str:
        attrs = (f' data-table="observations" data-row="{self.row}" data-key="{_html.escape(self.key)}"'
                 f' data-scale="{self.scale!r}" data-k="{self.k!r}" data-op="{self.op}"')
        if self.path:
            attrs += f' data-path="{_html.escape(self.path)}"'
        return f"<td{attrs}>{_html.escape(self.text())}</td>"


@dataclass(frozen=True)
class Rows:
    """The observation rows the report shows: ``obs`` every adjusted row of the result (the table's
    rows, those rejected by data snooping apart: they are the ``outliers``), ``table`` each one's
    ``index`` in the ``observations`` table, ``pos`` its position in the document's ``observations``
    (None where the document does not list it)."""

    obs: list
    table: list
    pos: list

    def num(self, k: int, key: str, *, scale=1.0, digits=3, mult=1.0, op="", sign=False) -> RowNum:
        """Row ``k``'s ``key`` as a cell."""
        p = self.pos[k]
        return RowNum(self.obs[k].get(key), "" if p is None else ptr("observations", p, key), scale, digits, mult,
                      op, sign, row=self.table[k], key=key)


def rows_of(doc: dict, rows=None) -> Rows:
    """:class:`Rows` of ``rows`` (every row of the ``observations`` table as dicts with their ``index``:
    :func:`multilat.network.adjust.general.report.list_observations` with ``"all"``), or of ``doc`` itself
    when None (a document listing every row)."""
    listed = doc["observations"]
    if rows is None:
        rows = listed
    where = {o.get("index", j): j for j, o in enumerate(listed)}
    keep = [(o.get("index", j), o) for j, o in enumerate(rows) if not o.get("rejected", False)]
    return Rows([o for _, o in keep], [t for t, _ in keep], [where.get(t) for t, _ in keep])


def _ends(o: dict) -> str:
    from multilat.network.adjust.general.report import row_ends

    return "->".join(row_ends(o))


def _what(o: dict) -> str:
    return o["kind"].replace("_", " ") + (f" ({o['component']})" if o.get("component") else "") + \
        (f" {o['axis']}" if o.get("axis") else "")


def _test_name(doc) -> str:
    return "|τ|" if doc["tests"]["test"] == "tau" else "|w|"


def sections(doc: dict, *, warnings=(), rows=None) -> list[Section]:
    """The results sections (before the warnings and what was run); ``warnings``: every warning of
    the job (counted among the verdicts); ``rows``: every row of the result (:func:`rows_of`)."""
    r = rows_of(doc, rows)
    out = [key_section(doc, r, warnings), frame_section(doc), points_section(doc, r), parameters_section(doc),
           reliability_section(doc, r), residuals_section(doc, r), tests_section(doc, r)]
    if doc.get("variance_components"):
        out.append(variance_section(doc))
    return out


def build_report(ctx, doc: dict, *, result=None, applies=None, rows=None) -> str:
    """The whole page: results (verdicts first), warnings, and last what was run (inputs with their
    sha256, options, version) — the machinery of :mod:`multilat.report.job`. ``doc``: the document the
    command prints; ``rows``: every observation row of the result (:func:`rows_of`; None: ``doc``
    lists every row). ``applies``: the names of the options the general path reads (the others, the
    distance path's, are not listed)."""
    import dataclasses

    from multilat.io import to_jsonable
    from multilat.report.html import render
    from multilat.report.job import job_warnings, meta_section, uncertainty_note, warnings_section

    doc = to_jsonable(doc)
    if applies is not None:
        ctx = dataclasses.replace(ctx, options={k: v for k, v in ctx.options.items() if k in applies})
    rows = None if rows is None else to_jsonable(list(rows))
    secs = [*sections(doc, warnings=job_warnings(ctx, doc), rows=rows), warnings_section(ctx, doc),
            meta_section(ctx, doc)]
    return render(f"multilat {ctx.command}: {TITLE}", secs, subtitle=uncertainty_note())


# ------------------------------------------------------------------------------------- selection
def _groups(rows) -> dict:
    """{(kind, component): [row indices]} in the order the kinds first appear."""
    out: dict = {}
    for k, o in enumerate(rows):
        out.setdefault((o["kind"], o.get("component", "")), []).append(k)
    return out


def _largest(rows, idx, key, *, controlled_only=False):
    """The index among ``idx`` with the largest finite |row[key]| (rows without redundancy left out
    when ``controlled_only``: their test statistic is 0 by construction), or None."""
    from multilat.network.adjust.statistics import R_ZERO

    best, at = -1.0, None
    for k in idx:
        v = rows[k].get(key)
        if v is None or not np.isfinite(v) or (controlled_only and rows[k]["redundancy"] <= R_ZERO):
            continue
        if abs(v) > best:
            best, at = abs(v), k
    return at


def _test_verdict(doc, stat: float) -> Verdict:
    crit = doc["tests"]["critical"]
    ok = abs(stat) <= crit
    return Verdict(f"{_test_name(doc)} <= critical" if ok else f"{_test_name(doc)} > critical", ok)


def _zero_points(doc, r: Rows) -> list[str]:
    from multilat.network.adjust.general.report import zero_redundancy_points

    return zero_redundancy_points(r.obs, doc["points"])


def _poor(r: Rows) -> list[int]:
    from multilat.network.adjust.general.report import poorly_controlled

    return poorly_controlled(r.obs)


def _limits() -> tuple[float, float]:
    from multilat.network.adjust.distance.reliability import MDB_LIMIT_SIGMA, R_MIN

    return R_MIN, MDB_LIMIT_SIGMA


# ---------------------------------------------------------------------------------- first section
def key_section(doc: dict, r: Rows, warnings=()) -> Section:
    """Verdicts and key numbers: what the reader must decide first."""
    sec = Section("Verdicts and key numbers", key="verdicts")
    sec.table(("check", "value", "lower limit", "upper limit", "verdict"), _verdict_rows(doc, r, len(warnings)),
              caption="Each verdict compares the value with the limits printed beside it", name="verdicts")
    sec.table(("quantity", "value"), _key_rows(doc, r), caption="Key numbers", name="key-numbers")
    for note in doc.get("notes") or []:
        if note.startswith("--model auto"):
            sec.paragraph(note, cls="warn")
    return sec


def _verdict_rows(doc: dict, r: Rows, n_warnings: int) -> list:
    gt, rows = doc["global_test"], []
    if gt.get("statistic") is None:
        rows.append(("global χ² test of σ0", "-", "-", "-", Verdict("not done (no redundancy)", None)))
    else:
        decides = gt.get("decides", True)
        text = ("passed" if gt["passed"] else "FAILED") + ("" if decides else " (information only: variance "
                                                                               "factor unknown)")
        rows.append((f"global χ² test of σ0 (vᵀPv against χ², α = {gt['alpha']:g}, dof {gt['dof']})",
                     _num(doc, "global_test", "statistic"), "-", _num(doc, "global_test", "critical"),
                     Verdict(text, gt["passed"] if decides else None)))
    obs = r.obs
    for (kind, comp), idx in _groups(obs).items():
        k = _largest(obs, idx, "statistic", controlled_only=True)
        if k is None:
            continue
        rows.append((f"largest {_test_name(doc)} of the {_what(obs[k])} rows ({obs[k]['label'] or _ends(obs[k])})",
                     r.num(k, "statistic", digits=2, sign=True), "-",
                     _num(doc, "tests", "critical"), _test_verdict(doc, obs[k]["statistic"])))
    n_out = len(doc["outliers"])
    rows.append(("observation rows rejected by data snooping", n_out, "-", "-",
                 Verdict("none" if n_out == 0 else f"{n_out} rejected: see Tests", n_out == 0)
                 if doc["snooping"] else Verdict("data snooping not done", None)))
    if doc["unlocated"]:
        rows.append(("test failures not located (not rejected)", len(doc["unlocated"]), "-", 0,
                     Verdict(f"{len(doc['unlocated'])}: see Tests", False)))
    r_min, limit = _limits()
    n = len(_poor(r))
    rows.append((f"poorly controlled observation rows (redundancy < {r_min:g} or MDB > {limit:g} σ)", n, "-", 0,
                 Verdict("none" if n == 0 else f"{n}: a blunder there would hardly show (see Reliability)", n == 0)))
    zero = _zero_points(doc, r)
    rows.append(("points kept without control (every row's redundancy 0)", len(zero), "-", 0,
                 Verdict("none" if not zero else f"{len(zero)}: a blunder there cannot show (see Points)",
                         not zero)))
    n_ex = len(doc["excluded"])
    rows.append(("points left out (not determined by the observations)", n_ex, "-", 0,
                 Verdict("none" if n_ex == 0 else f"{n_ex}: see Points", n_ex == 0)))
    rows.append(("warnings", n_warnings, "-", 0, Verdict("none" if n_warnings == 0 else
                                                         f"{n_warnings}: see Warnings", n_warnings == 0)))
    return rows


def _key_rows(doc: dict, r: Rows) -> list:
    kinds = {}
    for o in r.obs:
        kinds[_what(o)] = kinds.get(_what(o), 0) + 1
    rows = [("σ0" + (" (estimated: variance factor unknown)" if doc["variance_factor"] == "unknown"
                     else " (ratio to the a-priori σ)"), _num(doc, "sigma0", digits=4)),
            ("degrees of freedom", doc["dof"]), ("datum defect", doc["defect"]),
            ("points adjusted / left out", f"{doc['n_points']} / {len(doc['excluded'])}"),
            ("observation rows", f"{doc['n_obs']} (" + ", ".join(f"{n} {k}" for k, n in kinds.items()) + ")"),
            ("test", f"{doc['tests']['test']}-test, α0 = {doc['tests']['alpha0']:.3g}"),
            ("input", f"{doc['input']} ({doc['format']}; general model)")]
    pid, axis = worst_point(doc["points"])
    if pid is not None:
        rows.append((f"worst point: {pid}, largest coordinate u ({'xyz'[axis]}) (µm)",
                     _num(doc, "points", pid, "cov_m2", axis, axis, scale=MICRO, digits=1, op="sqrt")))
        rows.append((f"worst point: {pid}, U = {K:g} u (µm)",
                     _num(doc, "points", pid, "cov_m2", axis, axis, scale=MICRO, digits=1, op="sqrt", k=K)))
    return rows


# ------------------------------------------------------------------------------------ frame, points
def frame_section(doc: dict) -> Section:
    sec = Section("Frame and datum", key="frame")
    fr = doc["frame"]
    sec.items([f"datum: {doc['datum']}", f"frame ({fr['kind']}): {fr['axes']}", f"scale: {fr['scale']}",
               f"σ a priori: {doc['sigma_source'].get('description', doc['sigma_source'].get('kind'))}"])
    if "azimuth_sense" in doc:
        sec.paragraph(f"Azimuths read {doc['azimuth_sense']['sense']} ({doc['azimuth_sense']['source']}).")
    if doc.get("notes"):
        sec.items([f"note: {n}" for n in doc["notes"]])
    return sec


def points_section(doc: dict, r: Rows) -> Section:
    sec = Section("Points", key="points")
    pts = doc["points"]
    ids = list(pts)
    if len(ids) > MAX_ROWS:
        var = [max(np.diag(np.asarray(pts[p]["cov_m2"], float))) for p in ids]
        ids = [ids[i] for i in sorted(np.argsort(-np.nan_to_num(np.array(var), nan=np.inf))[:MAX_ROWS])]
    zero = set(_zero_points(doc, r))
    rows = [(p, pts[p]["status"], " ".join(pts[p]["roles"]),
             *(_num(doc, "points", p, "xyz_m", i, digits=6) for i in range(3)),
             *(_num(doc, "points", p, "cov_m2", i, i, scale=MICRO, digits=1, op="sqrt") for i in range(3)),
             *(_num(doc, "points", p, "cov_m2", i, i, scale=MICRO, digits=1, op="sqrt", k=K) for i in range(3)),
             _num(doc, "points", p, "semi_axes_95_m", 2, scale=MICRO, digits=1),
             Verdict("none: every row r = 0", False) if p in zero else Verdict("-"))
            for p in ids]
    more = "" if len(ids) == len(pts) else f" ({len(ids)} of {len(pts)}: the largest u shown)"
    sec.table(("point", "status", "roles", "x (m)", "y (m)", "z (m)", "u_x (µm)", "u_y (µm)", "u_z (µm)",
               "U_x (µm)", "U_y (µm)", "U_z (µm)", "95 % largest semi-axis (µm)", "control"), rows,
              caption=f"Points: coordinates, u (k = 1) and U (k = {K:g}); control none: the point follows its "
                      f"observations exactly (e.g. one polar reading){more}", name="points")
    if doc["excluded"]:
        sec.table(("point", "reason", "observation rows removed", "round"),
                  [(e["id"], e["reason"], e["n_obs"], e.get("round", "-")) for e in doc["excluded"]],
                  caption="Points left out: the observations do not determine them", name="left-out")
    return sec


def parameters_section(doc: dict) -> Section:
    sec = Section("Instrument and set-up parameters", key="parameters")
    rows = []
    for name, v in doc["parameters"].items():
        kind, owner = name.split(":", 1)
        if v["unit"] == "rad":
            val, u_unit = _num(doc, "parameters", name, "value", digits=9, sign=True), "µrad"
            unit = "rad"
        else:
            val = _num(doc, "parameters", name, "value", scale=MICRO, digits=2, sign=True)
            unit = u_unit = "µm" if v["unit"] == "m" else "µm/m"
        rows.append((owner, _KIND_WORDS.get(kind, kind), val, unit,
                     _num(doc, "parameters", name, "std", scale=MICRO, digits=2),
                     _num(doc, "parameters", name, "std", scale=MICRO, digits=2, k=K), u_unit))
    if rows:
        sec.table(("instrument / set-up", "parameter", "value", "unit", "u", f"U, k = {K:g}", "unit of u"), rows,
                  caption="Each head's additive constant (and scale) and each set-up's orientation, with u (k = 1)",
                  name="parameters")
    else:
        sec.paragraph("No unknown besides the coordinates.")
    return sec


# ----------------------------------------------------------------------------------- reliability
def reliability_section(doc: dict, r: Rows) -> Section:
    sec = Section("Reliability", key="reliability")
    obs, (r_min, limit) = r.obs, _limits()
    poor = _poor(r)
    if poor:
        rows = []
        for k in poor[:MAX_ROWS]:
            o = obs[k]
            why = [w for w, bad in ((f"r < {r_min:g}", o["redundancy"] < r_min),
                                    ("r = 0: no MDB", o["mdb_sigma"] is None),
                                    (f"MDB > {limit:g} σ", o["mdb_sigma"] is not None and o["mdb_sigma"] > limit))
                   if bad]
            rows.append((o["label"] or "-", _what(o), _ends(o), r.num(k, "redundancy"),
                         r.num(k, "mdb", scale=MICRO, digits=1), _UNIT[o["unit"]],
                         r.num(k, "mdb_sigma", digits=1), r.num(k, "shift_max_m", scale=MICRO, digits=1),
                         o["shift_point"] or "-", Verdict(" and ".join(why), False)))
        sec.table(("row", "kind", "points", "redundancy", "MDB", "unit", "MDB / σ", "largest shift (µm)",
                   "at point", "poorly controlled because"), rows,
                  caption=f"Poorly controlled observation rows ({len(poor)}{', first ' + str(MAX_ROWS) if len(poor) > MAX_ROWS else ''})",
                  name="poor-observations")
    else:
        sec.paragraph(f"Every observation row is controlled (redundancy >= {r_min:g}, MDB <= {limit:g} σ).",
                      cls="ok")
    zero = _zero_points(doc, r)
    if zero:
        sec.paragraph("Points kept without control (every observation row referencing them has redundancy 0; "
                      "their coordinates follow the observations exactly): " + ", ".join(zero) + ".", cls="warn")
    er = doc["external_reliability"]
    if er["largest"]:
        sec.table(("row", "kind", "points", "redundancy", "MDB / σ", "shift (µm)", "at point"),
                  [(o.get("label") or "-", _what(o), _ends(o),
                    _num(doc, "external_reliability", "largest", i, "redundancy"),
                    _num(doc, "external_reliability", "largest", i, "mdb_sigma", digits=1),
                    _num(doc, "external_reliability", "largest", i, "shift_max_m", scale=MICRO, digits=1),
                    o.get("shift_point") or "-") for i, o in enumerate(er["largest"])],
                  caption=f"External reliability: the rows whose undetected MDB moves a point most "
                          f"({er['n_uncontrolled']} uncontrolled row(s) without an MDB)", name="external")
    return sec


def residuals_section(doc: dict, r: Rows) -> Section:
    sec = Section("Residuals by kind", key="residuals")
    obs, rows = r.obs, []
    for (kind, comp), idx in _groups(obs).items():
        big = _largest(obs, idx, "residual")
        low = min(idx, key=lambda k: obs[k]["redundancy"])
        w = _largest(obs, idx, "statistic", controlled_only=True)
        o = obs[big]
        rows.append((_what(o), len(idx), _UNIT[o["unit"]],
                     r.num(big, "residual", scale=MICRO, digits=2, sign=True),
                     o["label"] or _ends(o), r.num(low, "redundancy"),
                     r.num(w, "statistic", digits=2, sign=True) if w is not None else "-",
                     _num(doc, "tests", "critical", digits=2),
                     _test_verdict(doc, obs[w]["statistic"]) if w is not None else Verdict("no row controlled", None)))
    sec.table(("kind", "rows", "unit", "largest |residual|", "at", "smallest redundancy",
               f"largest {_test_name(doc)}", "critical", "verdict"), rows,
              caption="Residuals (measured − adjusted) by observation kind", name="residuals-by-kind")
    return sec


def tests_section(doc: dict, r: Rows) -> Section:
    sec = Section("Tests and data snooping", key="tests")
    t = doc["tests"]
    sec.paragraph("Test procedure: " + t["rule"] + ".")
    sec.table(("test", "α0 per row", "critical", "λ0", "rows above the critical value"),
              [(t["test"], _num(doc, "tests", "alpha0", digits=7), _num(doc, "tests", "critical"),
                _num(doc, "tests", "lambda0", digits=2), t["n_failed"])], caption="Row tests", name="row-tests")
    obs = r.obs
    stat = np.array([abs(o["statistic"]) for o in obs], float)
    order = [int(k) for k in np.argsort(-stat, kind="stable")[:LARGEST_ROWS]]
    from multilat.network.adjust.statistics import R_ZERO

    sec.table(("row", "kind", "points", "σ", "residual", "unit", "redundancy", _test_name(doc).strip("|"),
               "verdict"),
              [(obs[k]["label"] or "-", _what(obs[k]), _ends(obs[k]),
                r.num(k, "sigma", scale=MICRO, digits=2),
                r.num(k, "residual", scale=MICRO, digits=2, sign=True), _UNIT[obs[k]["unit"]],
                r.num(k, "redundancy"), r.num(k, "statistic", digits=2, sign=True),
                _test_verdict(doc, obs[k]["statistic"]) if obs[k]["redundancy"] > R_ZERO
                else Verdict("r = 0: not testable", None)) for k in order],
              caption=f"The {len(order)} rows with the largest {_test_name(doc)}", name="largest-tests")
    if doc["outliers"]:
        sec.table(("order", "row", "kind", "points", "statistic", "critical", "rows", "points left out with it",
                   "index"),
                  [(o["order"], o["label"] or "-", o["kind"].replace("_", " "), _ends(o),
                    _num(doc, "outliers", i, "statistic", digits=2, sign=True),
                    _num(doc, "outliers", i, "critical", digits=2), o["n_rows"],
                    ", ".join(o["points_left_out"]) or "-", o["index"]) for i, o in enumerate(doc["outliers"])],
                  caption="Rows rejected by data snooping, in order", name="outliers")
    elif doc["snooping"]:
        sec.paragraph("No observation row rejected by data snooping.", cls="ok")
    else:
        sec.paragraph("Data snooping was not done (--no-snooping).")
    if doc["unlocated"]:
        sec.paragraph("Not rejected: " + "; ".join(f"{u['label'] or u['kind']} {_ends(u)}" for u in doc["unlocated"])
                      + f": {doc['unlocated_reason']}", cls="warn")
    if t.get("snooping_note"):
        sec.paragraph(t["snooping_note"])
    return sec


def variance_section(doc: dict) -> Section:
    sec = Section("Variance components", key="variance")
    v = doc["variance_components"]
    sec.table(("group", "variance factor", "u", "σ scale", "redundancy", "differs from 1"),
              [(c["group"], _num(doc, "variance_components", "components", i, "variance_factor"),
                _num(doc, "variance_components", "components", i, "variance_factor_std"),
                _num(doc, "variance_components", "components", i, "sigma_scale"),
                _num(doc, "variance_components", "components", i, "redundancy", digits=1),
                Verdict("yes" if c["differs_from_1"] else "no", not c["differs_from_1"]))
               for i, c in enumerate(v["components"])],
              caption=f"Förstner's estimate by {v['grouping']} ({v['iterations']} iterations; test against 1 at "
                      f"α = {v['alpha']:g})", name="variance-components")
    return sec
