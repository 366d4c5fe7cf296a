"""The JSON document of a general-network adjustment (``multilat adjust NET.xml --json``), and the
words for its datum, point roles and status. The keys are documented in ``docs/general-network.md``
("The JSON document").
"""

from __future__ import annotations

import numpy as np

from multilat.network.model.points import FIXED, FREE, WEIGHTED
from multilat.rows_text import JsonRows
from multilat.network.model.frame_words import INVARIANT

__all__ = ["to_json", "roles", "status_words", "datum_words", "observation_rows", "row_record", "external_reliability",
           "SETUP_KINDS", "poorly_controlled", "zero_redundancy_points", "row_ends", "constant_words",
           "TABLE_KEYS", "observation_table", "list_observations", "LISTINGS", "ObservationRows"]

#: kinds whose ``from`` point carries an instrument set-up (the others: levelling, vectors)
SETUP_KINDS = ("slope_distance", "direction", "zenith_angle", "horizontal_distance", "horizontal_angle",
               "tracker_angles")
_UNIT = {True: "rad", False: "m"}


def roles(network) -> list[list[str]]:
    """Per point its roles, in this order: ``station`` (an instrument set up on it), ``target``
    (sighted from a set-up), ``levelling`` (an end of a height difference), ``vector`` (an end of a
    coordinate difference), ``observed`` (observed coordinates), ``control`` (a fixed or weighted
    coordinate), ``datum`` (a datum point of a free network)."""
    pts = network.points
    order = ("station", "target", "levelling", "vector", "observed", "control", "datum")
    has = np.zeros((pts.n, len(order)), bool)          # per point, per role of ``order``
    for b in network.blocks:
        if b.kind in SETUP_KINDS:
            has[np.asarray(b.index["from"], np.intp), 0] = True
            for k in ("to", "bs", "fs"):
                has[np.asarray(b.index.get(k, ()), np.intp), 1] = True
        elif b.kind in ("height_difference", "coordinate_difference"):
            for k in ("from", "to"):
                has[np.asarray(b.index[k], np.intp), 2 if b.kind == "height_difference" else 3] = True
        elif b.kind == "observed_coordinates":
            has[np.asarray(b.index["point"], np.intp), 4] = True
    has[:, 5] = np.any(np.asarray(pts.status) != FREE, axis=1)
    has[:, 6] = np.asarray(pts.constrained, bool)
    words: dict = {}                                   # the few distinct combinations, each once
    return [list(words.setdefault(row, tuple(r for r, h in zip(order, row) if h))) for row in map(tuple, has.tolist())]


def status_words(status_row) -> str:
    """``free``, ``fixed``, ``weighted`` (all three alike) or ``partly fixed`` (mixed)."""
    s = set(int(v) for v in status_row)
    if len(s) == 1:
        return {FREE: "free", FIXED: "fixed", WEIGHTED: "weighted"}[s.pop()]
    return "partly fixed" if FIXED in s else "partly weighted"


def _names(ids, limit=6):
    ids = list(ids)
    return ", ".join(ids[:limit]) + (f" and {len(ids) - limit} more" if len(ids) > limit else "")


def datum_words(points, result) -> str:
    """The datum in one sentence, from the points' status and the adjustment's defect."""
    d = result.determinability
    if d.constraints is not None:
        dp = [p for p, c in zip(points.ids, points.constrained) if c] or list(points.ids)
        return (f"free network (datum defect {result.defect}): inner constraints, minimum trace over the "
                f"free coordinates of {len(dp)} datum point(s) ({_names(dp)})")
    fixed = [p for p, s in zip(points.ids, points.status) if np.all(s == FIXED)]
    partly = [p for p, s in zip(points.ids, points.status) if np.any(s == FIXED) and not np.all(s == FIXED)]
    weighted = [p for p, s in zip(points.ids, points.status) if np.any(s == WEIGHTED)]
    parts = []
    if fixed:
        parts.append(f"{len(fixed)} fixed point(s) ({_names(fixed)})")
    if partly:
        parts.append(f"{len(partly)} partly fixed ({_names(partly)})")
    if weighted:
        parts.append(f"{len(weighted)} weighted ({_names(weighted)})")
    return "given by " + "; ".join(parts) if parts else "no datum points (datum defect 0)"


def observation_rows(system, stats) -> list[dict]:
    """One dict per row of the adjusted system (the ``observations`` table of the JSON)."""
    return list(ObservationRows(system, stats))


class ObservationRows(JsonRows):
    """Every row of the adjusted system as :func:`to_json`'s ``observations``, without building them:
    as a sequence it gives :func:`_row`'s dicts one at a time; :func:`observation_table` reads its
    columns from ``stats`` and the blocks (arrays), so ``--json`` builds a dict only for the rows it
    lists. Written to JSON (:func:`multilat.io.write_json`) as the list of those dicts."""

    def __init__(self, system, stats):
        self.system, self.stats, self.columns, self._labels = system, stats, {}, {}
        self.n = int(sum(b.n_rows for b in system.blocks))
        self._stops = np.array([sl.stop for sl in system.rows], np.int64)

    def _row(self, i: int) -> dict:
        q = int(np.searchsorted(self._stops, i, side="right"))
        sl, b = self.system.rows[q], self.system.blocks[q]
        return _row(b, i - sl.start, i, self.system.network.points.ids, self.stats)

    def __iter__(self):
        ids = self.system.network.points.ids
        return (_row(b, k, sl.start + k, ids, self.stats)
                for b, sl in zip(self.system.blocks, self.system.rows) for k in range(b.n_rows))

    def write(self, orjson, write, indent: int | None, chunk: int = 0) -> None:
        """The rows' dicts as orjson writes a list nested at column ``indent`` (None: compact)."""
        text = orjson.dumps(self.to_python(), option=orjson.OPT_INDENT_2 if indent is not None else 0)
        write(text.replace(b"\n", b"\n" + b" " * indent) if indent else text)

    def columns_of(self) -> dict:
        """:data:`TABLE_KEYS` as lists (None for an empty cell), the values of :func:`_row`'s dicts."""
        st, ids = self.stats, np.asarray(self.system.network.points.ids, object)
        cols = {key: np.full(self.n, None, object) for key in TABLE_KEYS}
        for b, sl in zip(self.system.blocks, self.system.rows):
            c = {"kind": b.kind, "label": (np.asarray(b.labels, str).astype(object) if len(b.labels) == b.n_rows
                                           else "")}
            c.update({key: ids[np.asarray(b.index[key], np.intp)] for key in ("from", "to", "bs", "fs", "point")
                      if key in b.index})
            if "axis" in b.index:
                c["axis"] = np.array(list("xyz"), object)[np.asarray(b.index["axis"], np.intp)]
            if "component" in b.index:
                c["component"] = np.array(["azimuth", "elevation"], object)[np.asarray(b.index["component"], np.intp)]
            if "set" in b.index:
                c["set"] = np.asarray(b.names["set"], object)[np.asarray(b.index["set"], np.intp)]
            c["value"] = np.asarray(b.value, float)
            for key, v in c.items():
                cols[key][sl] = v
        cols["unit"] = np.where(np.asarray(st.angular, bool), "rad", "m").astype(object)
        for key in ("sigma", "residual", "redundancy", "w", "statistic"):
            cols[key] = np.asarray(getattr(st, key), float)
        cols["passed"] = np.asarray(st.passed, bool)
        for key in ("mdb", "mdb_sigma", "bias_to_noise", "shift_max_m"):
            v = np.asarray(getattr(st, key), float)
            cols[key] = v.astype(object)
            cols[key][~np.isfinite(v)] = None
        cols["shift_point"] = np.asarray(st.shift_point, str).astype(object)
        return {key: v.tolist() for key, v in cols.items()}


def row_record(system, stats, i: int) -> dict:
    """The ``observations`` entry of row ``i`` of ``system`` (one row: data snooping's records)."""
    q = int(np.searchsorted([sl.stop for sl in system.rows], i, side="right"))
    return _row(system.blocks[q], i - system.rows[q].start, i, system.network.points.ids, stats)


def _row(b, k: int, i: int, ids, stats) -> dict:
    """Row ``k`` of block ``b``, row ``i`` of the system."""
    row = {"kind": b.kind}
    for key in ("from", "to", "bs", "fs", "point"):
        if key in b.index:
            row[key] = ids[int(b.index[key][k])]
    if "axis" in b.index:
        row["axis"] = "xyz"[int(b.index["axis"][k])]
    if "component" in b.index:
        row["component"] = ("azimuth", "elevation")[int(b.index["component"][k])]
    if "set" in b.index:
        row["set"] = b.names["set"][int(b.index["set"][k])]
    label = str(b.labels[k]) if len(b.labels) == b.n_rows else ""
    row.update(label=label, unit=_UNIT[bool(stats.angular[i])], value=float(b.value[k]),
               sigma=float(stats.sigma[i]), residual=float(stats.residual[i]),
               redundancy=float(stats.redundancy[i]), w=float(stats.w[i]),
               statistic=float(stats.statistic[i]), passed=bool(stats.passed[i]),
               mdb=_finite(stats.mdb[i]), mdb_sigma=_finite(stats.mdb_sigma[i]),
               bias_to_noise=_finite(stats.bias_to_noise[i]), shift_max_m=_finite(stats.shift_max_m[i]),
               shift_point=str(stats.shift_point[i]))
    return row


def _finite(v):
    return float(v) if np.isfinite(v) else None


def _plain(d: dict) -> dict:
    """A record with numpy scalars as Python numbers and non-finite numbers as None."""
    out = {}
    for k, v in d.items():
        if isinstance(v, (bool, np.bool_)):
            out[k] = bool(v)
        elif isinstance(v, (int, np.integer)):
            out[k] = int(v)
        elif isinstance(v, (float, np.floating)):
            out[k] = _finite(v)
        elif isinstance(v, list):
            out[k] = [_finite(x) if isinstance(x, (float, np.floating)) else x for x in v]
        else:
            out[k] = v
    return out


#: rows listed in ``external_reliability.largest`` (the full list: each row's ``shift_max_m``)
WORST_SHIFTS = 10


def external_reliability(system, stats, n: int = WORST_SHIFTS) -> dict:
    """The rows whose MDB moves a point most (``∇x = Q Jᵀ P ∇l``), largest first, and the largest
    shift of all; uncontrolled rows (r = 0, no MDB) are counted apart."""
    sh = np.asarray(stats.shift_max_m, float)
    computed = bool(np.any(~np.isnan(sh))) or sh.size == 0
    fin = np.flatnonzero(np.isfinite(sh))
    order = fin[np.argsort(-sh[fin], kind="stable")][:n]
    keys = ("label", "kind", "from", "to", "bs", "fs", "point", "axis", "component", "redundancy", "mdb",
            "mdb_sigma", "bias_to_noise", "shift_max_m", "shift_point")
    rows = [{k: v for k, v in row_record(system, stats, int(i)).items() if k in keys} for i in order]
    return {"computed": computed, "n_uncontrolled": int(np.count_nonzero(np.isinf(sh))),
            "shift_max_m": _finite(sh[order[0]]) if order.size else None, "largest": rows}


def to_json(adjustment, stats, *, source: str, snooping=None, variance=None) -> dict:
    """The document (without its schema stamp): points map, observations table, statistics; with
    ``snooping`` (a :class:`~.snooping.Snooping`) its rejections, and ``variance`` (the
    :class:`~.variance.GeneralVarianceComponents`) the estimated factors."""

    net, res = adjustment.network, adjustment.result
    pts = net.points
    rl = roles(net)
    cov = np.asarray(stats.cov_m2)
    std = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0, None)).tolist()
    words: dict = {}                                   # per distinct status row: its words, once
    for row in set(map(tuple, np.asarray(pts.status).tolist())):
        words[row] = (status_words(row), [{FREE: "free", FIXED: "fixed", WEIGHTED: "weighted"}[s] for s in row])
    points = {}
    for p, xyz, sd, c, semi, r, st in zip(pts.ids, res.xyz_m.tolist(), std, cov.tolist(),
                                          stats.semi_axes_95_m.tolist(), rl, map(tuple, pts.status.tolist())):
        points[p] = {"xyz_m": xyz, "xyz_std_m": sd, "cov_m2": c, "semi_axes_95_m": semi, "roles": r,
                     "status": words[st][0], "status_xyz": list(words[st][1])}
    gt = stats.global_test
    scale = res.sigma0 ** 2 if stats.variance_factor == "unknown" and np.isfinite(res.sigma0) else 1.0
    others = {}
    qdiag = res.cofactor_diagonal()
    for k, name in enumerate(res.free_names):
        if name[:2] not in ("x:", "y:", "z:"):
            kind = name.split(":", 1)[0]
            others[name] = {"value": float(res.parameters[res.names.index(name)]),
                            "std": float(np.sqrt(max(qdiag[k], 0.0) * scale)),
                            "unit": {"offset": "m", "scale": "1"}.get(kind, "rad")}
    failing = [k for k in range(len(stats.passed)) if not stats.passed[k]]
    return {
        "input": source,
        "format": "gama-local",
        "datum": datum_words(pts, res),
        "frame": general_frame_words(pts, res),              # the adjust JSON's vocabulary
        "defect": res.defect,
        "n_points": pts.n,
        "n_obs": int(sum(b.n_rows for b in adjustment.system.blocks)),
        "excluded": [dict(e) for e in adjustment.excluded],
        "points": points,
        "parameters": others,
        "sigma0": res.sigma0,
        "dof": res.dof,
        "vtpv": stats.vtpv,
        "variance_factor": stats.variance_factor,
        "global_test": {"statistic": gt.statistic, "critical": gt.critical, "passed": gt.passed, "alpha": gt.alpha,
                        "dof": gt.dof, "power": gt.power, "lambda0": gt.lambda0,
                        "decides": stats.variance_factor == "known", "method": stats.test_method},
        "tests": {"test": stats.test, "alpha0": stats.alpha0, "critical": stats.critical,
                  "lambda0": stats.lambda0, "n_failed": len(failing), "snooping": bool(snooping and snooping.snooping),
                  "rule": stats.rule, "steps": [_plain(s) for s in snooping.steps] if snooping else [],
                  "snooping_note": snooping.note if snooping else ""},
        "snooping": bool(snooping and snooping.snooping),
        "outliers": [_plain(r) for r in snooping.rejected] if snooping else [],
        "unlocated": [_plain(r) for r in snooping.unlocated] if snooping else [],
        "unlocated_reason": snooping.unlocated_reason if snooping else "",
        "external_reliability": external_reliability(adjustment.system, stats),
        "backend": res.backend,
        "not_computed": list(res.not_computed),
        "variance_components": variance.to_json() if variance is not None else None,
        "sigma_source": {"kind": "file", "file": source,
                         "description": "a-priori σ of the gama-local input: each observation's stdev=, else the "
                                        "<points-observations> defaults (distance-stdev, direction-stdev, "
                                        "angle-stdev, zenith-angle-stdev), <cov-mat> of vectors, coordinates "
                                        "and height-difference blocks"},
        "observations": ObservationRows(adjustment.system, stats),
        "iterations": [{"step_max": s, "vtpv": v} for s, v in res.iterations],
        "notes": list(net.notes),
    }


def general_frame_words(points, result) -> dict:
    """The same ``{"kind", "axes", "scale"}`` for the general network layer
    (:mod:`multilat.network.adjust.general`): ``points`` its points (ids, status, constrained), ``result``
    its adjustment (determinability, defect, free parameter names). A free network (inner
    constraints) is in the frame of the approximate coordinates given for its datum points; a network
    with fixed or weighted coordinates in the frame of those coordinates."""
    scaled = [n.split(":", 1)[1] for n in result.free_names if n.startswith("scale:")]
    scale = (f"scale factors estimated for {', '.join(scaled)}; the scale from the other observations and "
             "the given coordinates" if scaled else
             "the observed distances (and vectors), no scale factor")
    if result.determinability.constraints is not None:
        dp = [p for p, c in zip(points.ids, points.constrained) if c] or list(points.ids)
        return {"kind": "free", "axes": (
            f"the frame (origin and axes) is that of the approximate coordinates given for the datum points "
            f"({_names(dp)}): the solution fits them with the minimum trace over their free coordinates "
            f"(datum defect {result.defect}). " + INVARIANT), "scale": scale}
    return {"kind": "control", "axes": f"the frame of the given coordinates (datum {datum_words(points, result)})",
            "scale": scale}


def row_ends(row: dict) -> list[str]:
    """The points an ``observations`` row references (``from``, ``to``, ``bs``, ``fs``, ``point``)."""
    return [row[e] for e in ("from", "to", "point", "bs", "fs") if e in row]


def poorly_controlled(rows, *, r_min: float | None = None, mdb_limit_sigma: float | None = None) -> list[int]:
    """Indices of the ``observations`` rows that are poorly controlled: redundancy below ``r_min`` or
    MDB above ``mdb_limit_sigma`` σ (the distance path's rule and defaults,
    :data:`multilat.network.adjust.distance.reliability.R_MIN`, ``MDB_LIMIT_SIGMA``); an uncontrolled row (r = 0,
    no MDB) is one. A blunder there would not show in its test."""
    rows = list(rows)
    red = np.array([o["redundancy"] for o in rows], float).reshape(len(rows))
    mdb_sigma = np.array([o["mdb_sigma"] for o in rows], float).reshape(len(rows))
    return np.flatnonzero(_poor_mask(red, mdb_sigma, r_min=r_min, mdb_limit_sigma=mdb_limit_sigma)).tolist()


def _poor_mask(redundancy, mdb_sigma, *, r_min: float | None = None, mdb_limit_sigma: float | None = None):
    """:func:`poorly_controlled`'s rule on arrays (``mdb_sigma`` nan where a row has no MDB)."""
    from multilat.network.adjust.distance.reliability import MDB_LIMIT_SIGMA, R_MIN

    r_min = R_MIN if r_min is None else r_min
    limit = MDB_LIMIT_SIGMA if mdb_limit_sigma is None else mdb_limit_sigma
    with np.errstate(invalid="ignore"):
        return (redundancy < r_min) | ~np.isfinite(mdb_sigma) | (mdb_sigma > limit)


def zero_redundancy_points(rows, points: dict) -> list[str]:
    """The free points kept without any control: every ``observations`` row that references them has
    redundancy 0 (:data:`multilat.network.adjust.statistics.R_ZERO`; e.g. a point placed by one polar
    reading: distance, azimuth, elevation for its three coordinates). Their coordinates follow the
    observations exactly; a blunder there cannot show. ``points``: the JSON's ``points`` map."""
    from multilat.network.adjust.statistics import R_ZERO

    seen: dict = {}
    for o in rows:
        for p in row_ends(o):
            seen[p] = seen.get(p, True) and o["redundancy"] <= R_ZERO
    return [p for p, zero in seen.items() if zero and points.get(p, {}).get("status") != "fixed"]


def constant_words(parameters: dict) -> list[str]:
    """Each head's additive constant and scale (the JSON's ``parameters``, in m and 1) in the words of
    the summary, in µm and µm/m as every small quantity of the report: ``"T1 +124.1 µm (u 9.2 µm)"``."""
    out = []
    for name, v in parameters.items():
        kind, owner = name.split(":", 1)
        if kind in ("offset", "scale"):
            unit = "µm" if kind == "offset" else "µm/m"
            out.append(f"{owner} {v['value'] * 1e6:+.1f} {unit} (u {v['std'] * 1e6:.1f} {unit})")
    return out


#: the row keys of the ``observations`` table (schema ``multilat.adjust-general/3``), after ``index``
#: and before the flags (:data:`multilat.network.io.result_rows.FLAGS`); absent keys are empty cells
TABLE_KEYS = ("kind", "from", "to", "bs", "fs", "point", "axis", "component", "set", "label", "unit", "value",
              "sigma", "residual", "redundancy", "w", "statistic", "passed", "mdb", "mdb_sigma", "bias_to_noise",
              "shift_max_m", "shift_point")
#: what the document lists: the rows that matter, or every row (``--observations``)
LISTINGS = ("flagged", "all")


def observation_table(doc: dict) -> dict:
    """The ``observations`` table of a general adjustment's document (every row of ``doc["observations"]``
    as :func:`to_json` writes it, then one row per rejection of data snooping, from ``doc["outliers"]``):
    ``index``, :data:`TABLE_KEYS` (lists, None for an empty cell) and the flags of the distance path
    (:data:`multilat.network.io.result_rows.FLAGS`, bool arrays) by its rule: ``rejected`` (by data
    snooping; its residual at the final solution, None for a correlated block rejected whole, whose
    rows' residuals are the outlier's list), ``w_failed`` (the test at the end fails) and
    ``poorly_controlled`` (:func:`poorly_controlled`)."""
    obs = doc["observations"]
    if isinstance(obs, ObservationRows):          # to_json's rows: the columns from the arrays
        adjusted = obs.columns_of()
    else:
        adjusted = {key: [o.get(key) for o in obs] for key in TABLE_KEYS}
    n_adj = len(adjusted["kind"])
    out = [{**o, "residual": o["residual"] if isinstance(o["residual"], (int, float)) else None}
           for o in doc["outliers"]]
    n = n_adj + len(out)
    cols: dict = {"index": np.arange(n, dtype=np.int64)}
    for key in TABLE_KEYS:
        cols[key] = adjusted[key] + [o.get(key) for o in out]
    red = np.array(adjusted["redundancy"], float).reshape(n_adj)
    mdb_sigma = np.array(adjusted["mdb_sigma"], float).reshape(n_adj)      # None (no MDB): nan
    poor = np.zeros(n, bool)
    poor[:n_adj] = _poor_mask(red, mdb_sigma)
    failed = np.zeros(n, bool)
    failed[:n_adj] = ~np.array(adjusted["passed"], bool).reshape(n_adj)
    cols.update(rejected=np.arange(n) >= n_adj, w_failed=failed, poorly_controlled=poor)
    return cols


def list_observations(doc: dict, listing: str = "flagged") -> dict:
    """``doc`` (:func:`to_json`'s, every row listed) as schema ``multilat.adjust-general/3`` lists it:
    ``observations`` only the rows that matter (``listing="flagged"``: rejected, failing w-tests,
    poorly controlled; the rule and keys of the distance path's ``multilat.adjust/2``) or every row
    (``"all"``), each with its ``index`` in the table and its flags, and ``observation_counts``
    (:func:`multilat.network.io.result_rows.observation_counts`; ``n_excluded``: the rows of the points
    left out). A new dict; ``doc`` is not changed."""
    from multilat.errors import MultilatError
    from multilat.network.io import result_rows as rr

    if listing not in LISTINGS:
        raise MultilatError(f"observations listing must be 'flagged' or 'all', got {listing!r}")
    cols = observation_table(doc)
    keep = np.arange(len(cols["index"])) if listing == "all" else rr.flagged(cols)
    rows = []
    for k in keep.tolist():
        row = {"index": k, **{key: cols[key][k] for key in TABLE_KEYS if cols[key][k] is not None
                              or key in ("residual", "mdb", "mdb_sigma", "bias_to_noise", "shift_max_m")}}
        row.update({f: bool(cols[f][k]) for f in rr.FLAGS})
        rows.append(row)
    n_excl = sum(int(e["n_obs"]) for e in doc["excluded"])
    return {**doc, "observations": rows,
            "observation_counts": rr.observation_counts(cols, len(rows), listing, n_excl)}
