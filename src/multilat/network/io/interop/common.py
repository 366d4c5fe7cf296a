"""What the interchange formats share: the network bundle they carry, the per-instrument offsets
that most of them cannot carry (applied as a correction or refused), id checks, number formats,
and a small line-numbered XML tree (``FILE:LINE:`` errors for GNU Gama's XML).

The model of :mod:`multilat.network` is ``d_ij = |H_i - T_j| + o_i`` with one additive offset
``o_i`` per station (seed 000 §4.3). A format without a per-instrument additive constant receives
``d_ij - o_i`` with the offsets fixed at given values (``offsets`` a mapping station -> metres,
e.g. the adjusted offsets of a multilat run); when the offsets are to be estimated the export is
refused with a one-line reason (:func:`apply_offsets`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

import numpy as np

from multilat.errors import MultilatError
from multilat.inputs import hidden_character
from multilat.io import decode_text, read_input_bytes
from multilat.network.model.data import Observations, Points

__all__ = ["Network", "apply_offsets", "station_values", "model_lines", "ModelTags", "restore_model",
           "refuse_weighted_points", "check_ids", "fmt_m", "read_text", "XmlNode", "parse_xml",
           "DISTANCE_DECIMALS", "SIGMA_DECIMALS", "read_result_dir"]

#: decimals of metres written for coordinates and distances (1e-8 m = 0.01 µm)
DISTANCE_DECIMALS = 8
#: decimals of metres written for standard uncertainties (1e-10 m)
SIGMA_DECIMALS = 10


@dataclass(frozen=True, eq=False)
class Network:
    """What a file read by an importer holds.

    obs : Observations   distances (as they stand in the file) with their a-priori σ
    points : Points      the points that have three coordinates in the file (may be empty)
    fixed : tuple of str the points the file holds fixed (control), in file order
    notes : tuple of str what the reader applied or ignored, one line each
    restored : bool      the file's multilat lines (heads, offsets, scales) were applied: ``obs``
                         is multilat's model again, not the file's corrected distances
    """

    obs: Observations
    points: Points
    fixed: tuple = ()
    notes: tuple = field(default=())
    restored: bool = False


def read_text(path) -> str:
    """The UTF-8 text of an input file (one-line errors naming the file), refused by ``FILE:LINE``
    when it holds an invisible formatting character (:func:`refuse_hidden`)."""
    return refuse_hidden(decode_text(read_input_bytes(path), Path(path)), path)


def refuse_hidden(text: str, path) -> str:
    """``text``, or ``FILE:LINE: ... U+202E (...)`` for its first invisible formatting character
    (bidi overrides, zero-width characters: :func:`multilat.inputs.hidden_character`), which would
    reach ids, terminal output and reports unseen. A leading byte-order mark is allowed."""
    what = hidden_character(text.removeprefix("\ufeff"))
    if what is None:
        return text
    body = text.removeprefix("\ufeff")
    ch = chr(int(what[2:].split(" ")[0], 16))
    line = body.count("\n", 0, body.index(ch)) + 1
    raise MultilatError(f"{path}:{line}: holds the invisible formatting character {what}: ids and values must "
                        "be plain text")


def fmt_m(v: float, decimals: int = DISTANCE_DECIMALS) -> str:
    """Fixed-point text of ``v`` (no exponent: every format here reads it)."""
    s = f"{float(v):.{decimals}f}"
    return "0." + "0" * decimals if s.lstrip("-") == "0." + "0" * decimals else s


_BAD_ID = re.compile(r"[\s\"'<>&#]")


def check_ids(obs: Observations, points: Points | None, fmt: str, *, forbid: str = "") -> None:
    """Refuse ids that the format cannot write (blanks, quotes, comment or markup characters, and
    the characters in ``forbid``), naming the first."""
    ids = list(obs.station_ids) + list(obs.target_ids) + (list(points.ids) if points else [])
    for i in ids:
        if _BAD_ID.search(i) or any(c in i for c in forbid):
            raise MultilatError(f"{fmt}: point id {i!r} cannot be written in this format (blanks, "
                                f"quotes, '#', '<', '>', '&'{', ' + repr(forbid) if forbid else ''} "
                                "are not allowed in ids); rename it")


def apply_offsets(obs: Observations, offsets, fmt: str, scales=None) -> tuple[Observations, list[str]]:
    """Distances without the per-head additive offsets (and scales), for a format that cannot carry them.

    ``offsets``: a number (the same for every head), or a mapping whose keys are head ids (every
    head) or station ids (every station; the stations of one head must agree: one head, one offset).
    ``None`` or ``"estimate"`` (the offsets are unknowns) is refused: the format has no additive
    constant per instrument. ``scales``: None or a mapping head id -> scale k of the model
    ``d = (1 + k)|H - T| + o`` (a head not named has k = 0). The distances written are
    ``(d - o) / (1 + k)``; the σ stay as given. Returns the corrected observations and one note
    line per station."""
    if offsets is None or (isinstance(offsets, str) and offsets == "estimate"):
        what = f"the offsets of heads {', '.join(obs.head_ids)}" if obs.station_heads is not None else "the offsets"
        raise MultilatError(f"{fmt} has no additive constant per instrument, so {what} cannot "
                            "be estimated there: give them fixed (--offsets-um A=..,B=.. or "
                            "--result DIR of `multilat adjust --out`) to export the distances "
                            "corrected by them")
    o = station_values(obs, offsets, fmt, "offset")
    k = station_values(obs, scales or {}, fmt, "scale", default=0.0)
    if not (np.all(np.isfinite(o)) and np.all(np.isfinite(k)) and np.all(k > -1)):
        raise MultilatError(f"{fmt}: offsets and scales must be finite (scales > -1)")
    d = (obs.distance_m - o[obs.station_index]) / (1.0 + k[obs.station_index])
    if np.any(d <= 0):
        j = int(np.flatnonzero(d <= 0)[0])
        raise MultilatError(f"{fmt}: distance {obs.label(j)} minus its head's offset is not > 0")
    heads = obs.head_of_station
    notes = [f"station {s} (head {heads[i]}): offset {o[i] * 1e6:.4f} um subtracted from its distances"
             + (f", then divided by 1 + scale {k[i]:.10g}" if k[i] else "")
             for i, s in enumerate(obs.station_ids)]
    return obs.with_distances(d), notes


def station_values(obs: Observations, values, fmt: str, what: str, *, default=None) -> np.ndarray:
    """One value per station from ``values``: a number, or a mapping by head id or station id.

    Every station must be covered (through its own id or its head's) unless ``default`` is given; a
    key that is neither a station nor a head, and two stations of one head with different values,
    are refused in one line naming them."""
    heads = obs.head_of_station
    if not isinstance(values, Mapping):
        return np.full(obs.n_stations, float(values))
    unknown = [key for key in values if key not in obs.station_ids and key not in heads]
    if unknown:
        raise MultilatError(f"{fmt}: {what} given for {unknown[0]!r}, which is neither a station nor a head")
    out = np.empty(obs.n_stations)
    first: dict = {}
    for i, (s, h) in enumerate(zip(obs.station_ids, heads)):
        v = values.get(s, values.get(h, default))
        if v is None:
            raise MultilatError(f"{fmt}: no fixed {what} for head {h!r} (station {s!r}); give every head's")
        out[i] = float(v)
        j = first.setdefault(h, i)
        if out[j] != out[i]:
            raise MultilatError(f"{fmt}: head {h!r} has two {what}s, {out[j]!r} (station {obs.station_ids[j]}) "
                                f"and {out[i]!r} (station {s}): one head has one {what}")
    return out


#: the lines (comments or description lines) by which a writer records what the format cannot hold
OFFSETS_TAG = "multilat-offsets-m:"
HEADS_TAG = "multilat-heads:"
SCALES_TAG = "multilat-scales:"


def model_lines(obs: Observations, offsets=None, scales=None, fmt: str = "") -> list[str]:
    """The convention lines of a file (without a comment prefix): ``multilat-offsets-m: S=m ..``
    (per station, when fixed offsets were subtracted), ``multilat-heads: S=H ..`` (when stations
    share heads or heads have their own names) and ``multilat-scales: H=k ..`` (heads with a fixed
    scale other than 0 divided out). The readers restore all three (:func:`restore_model`)."""
    out = []
    if offsets is not None and not (isinstance(offsets, str) and offsets == "estimate"):
        o = station_values(obs, offsets, fmt, "offset")
        out.append(OFFSETS_TAG + " " + " ".join(f"{s}={fmt_m(v, 10)}" for s, v in zip(obs.station_ids, o)))
    if obs.station_heads is not None:
        out.append(HEADS_TAG + " " + " ".join(f"{s}={h}" for s, h in zip(obs.station_ids, obs.station_heads)))
    ks = {h: float(v) for h, v in (scales or {}).items() if float(v) != 0.0}
    if ks:
        out.append(SCALES_TAG + " " + " ".join(f"{h}={v!r}" for h, v in ks.items()))
    return out


def parse_tag(where: str, text: str, tag: str, numbers: bool = True) -> dict:
    """The ``ID=value`` items after ``tag`` (floats when ``numbers``), one-line errors ``where``."""
    out = {}
    for item in text.split():
        key, sep, val = item.partition("=")
        try:
            v = float(val) if numbers else val
        except ValueError:
            v = None
        if not sep or not key or not val or v is None or (numbers and not math.isfinite(v)):
            raise MultilatError(f"{where}: {tag} item {item!r} is not ID={'number' if numbers else 'ID'}")
        if key in out:
            raise MultilatError(f"{where}: {tag} names {key!r} twice")
        out[key] = v
    return out


@dataclass
class ModelTags:
    """The convention lines found in a file: offsets by station, heads by station, scales by head
    (each None when absent), with where each was found (for errors)."""

    offsets: dict | None = None
    heads: dict | None = None
    scales: dict | None = None
    where: dict = field(default_factory=dict)

    def read(self, where: str, line: str) -> bool:
        """Take ``line`` (comment marks stripped) if it is one of the tags; True when it was."""
        for tag, attr, num in ((OFFSETS_TAG, "offsets", True), (HEADS_TAG, "heads", False),
                               (SCALES_TAG, "scales", True)):
            if line.startswith(tag):
                if getattr(self, attr) is not None:
                    raise MultilatError(f"{where}: a second {tag} line (the first at {self.where[attr]})")
                setattr(self, attr, parse_tag(where, line[len(tag):], tag, num))
                self.where[attr] = where
                return True
        return False


def restore_model(path, rows, tags: ModelTags, notes: list) -> tuple[list, dict | None]:
    """Undo a writer's corrections on the rows ``(line, station, target, d, sigma)``: ``d = (1 + k) d'
    + o`` with the head's scale k and the station's offset o; returns the rows and the head of each
    station (None without a heads line). Every station named must have distances; with a heads line
    every station needs a head, and the offsets (scales) of one head's stations must agree."""
    stations = list(dict.fromkeys(r[1] for r in rows))
    heads = tags.heads
    for attr, keys in (("offsets", stations), ("heads", stations)):
        d = getattr(tags, attr)
        bad = [s for s in (d or {}) if s not in keys]
        if bad:
            raise MultilatError(f"{tags.where[attr]}: the {attr} line names {bad[0]!r}, a station with no "
                                "distances")
    if heads is not None:
        missing = [s for s in stations if s not in heads]
        if missing:
            raise MultilatError(f"{tags.where['heads']}: the heads line gives no head for station {missing[0]!r}")
        clash = [h for h in heads.values() if h in stations and heads[h] != h]
        if clash:
            raise MultilatError(f"{tags.where['heads']}: head id {clash[0]!r} is also a station of another head")
    head_of = heads or {s: s for s in stations}
    scales = tags.scales or {}
    bad = [h for h in scales if h not in set(head_of.values())]
    if bad:
        raise MultilatError(f"{tags.where['scales']}: the scales line names {bad[0]!r}, which is no head")
    offsets = tags.offsets
    if offsets is not None:
        first: dict = {}
        for s in stations:
            h = head_of[s]
            other = first.setdefault(h, s)
            if offsets.get(s, 0.0) != offsets.get(other, 0.0):
                raise MultilatError(f"{tags.where['offsets']}: head {h!r} has two offsets ({other} "
                                    f"{offsets.get(other, 0.0)!r}, {s} {offsets.get(s, 0.0)!r}): one head has one offset")
        notes.append("per-station offsets restored from the file: "
                     + ", ".join(f"{k} {v * 1e6:.4f} µm" for k, v in offsets.items()))
    if scales:
        notes.append("fixed scales restored from the file (the source divided them out): "
                     + ", ".join(f"{h} {k:.10g}" for h, k in scales.items())
                     + "; adjust with --scales to estimate them again")
    if heads is not None:
        n_h = len(set(heads.values()))
        notes.append(f"{n_h} head{'s' if n_h > 1 else ''} over {len(stations)} stations restored from the file: "
                     + ", ".join(f"{h} ({' '.join(s for s in stations if heads[s] == h)})"
                                 for h in dict.fromkeys(heads[s] for s in stations)))
    o = offsets or {}
    rows = [(ln, a, b, d * (1.0 + scales.get(head_of[a], 0.0)) + o.get(a, 0.0), sg) for ln, a, b, d, sg in rows]
    return rows, heads


def refuse_weighted_points(points: Points | None, fmt: str) -> None:
    """Refuse a points file with standard uncertainties (weighted control): the export writes
    approximate coordinates (or hard control with ``--fix``), never silently drops a σ."""
    std = getattr(points, "std_m", None) if points is not None else None
    if std is None:
        return
    rows = np.flatnonzero(np.isfinite(np.asarray(std, float)).any(axis=1))
    if rows.size:
        raise MultilatError(f"{fmt}: point {points.ids[int(rows[0])]!r} has standard uncertainties (weighted "
                            "control, sx_m/sy_m/sz_m): not exported; give approximate coordinates without them, "
                            "or hold the point with --fix")


# ----------------------------------------------------------------------------- XML
@dataclass
class XmlNode:
    """An element with its line: ``tag`` (namespace removed), ``attrib``, ``children``, ``text``."""

    tag: str
    attrib: dict
    line: int
    children: list = field(default_factory=list)
    text: str = ""

    def find(self, tag):
        return next((c for c in self.children if c.tag == tag), None)

    def findall(self, tag):
        return [c for c in self.children if c.tag == tag]

    def child_text(self, tag, default=None):
        c = self.find(tag)
        return default if c is None else c.text.strip()


def parse_xml(path) -> XmlNode:
    """Parse an XML file into :class:`XmlNode` (namespaces dropped); a malformed file is an error
    ``FILE:LINE: malformed XML (...)``. DTDs and entity declarations are refused."""
    data = read_input_bytes(path)
    refuse_hidden(data.decode("utf-8", errors="replace"), path)
    parser = expat.ParserCreate(namespace_separator="}")
    root: list[XmlNode] = []
    stack: list[XmlNode] = []

    def start(name, attrs):
        node = XmlNode(name.rsplit("}", 1)[-1], dict(attrs), parser.CurrentLineNumber)
        (stack[-1].children if stack else root).append(node)
        stack.append(node)

    def end(name):
        stack.pop()

    def chars(text):
        if stack:
            stack[-1].text += text

    def no_dtd(*args):
        raise MultilatError(f"{path}:{parser.CurrentLineNumber}: XML with a DTD or entity "
                            "declarations is not read")

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    parser.StartDoctypeDeclHandler = no_dtd
    parser.EntityDeclHandler = no_dtd
    try:
        parser.Parse(data, True)
    except expat.ExpatError as exc:
        raise MultilatError(f"{path}:{exc.lineno}: malformed XML ({expat.ErrorString(exc.code)})") from None
    if not root:
        raise MultilatError(f"{path}:1: malformed XML (no element)")
    return root[0]


def xml_float(path, node: XmlNode, name: str, *, positive: bool = False, required: bool = True):
    """Attribute ``name`` of ``node`` as a finite float (``FILE:LINE:`` errors)."""
    v = node.attrib.get(name)
    if v is None:
        if required:
            raise MultilatError(f"{path}:{node.line}: <{node.tag}> needs attribute {name}=")
        return None
    try:
        x = float(v)
    except ValueError:
        raise MultilatError(f"{path}:{node.line}: <{node.tag}> {name}={v!r} is not a number") from None
    if not math.isfinite(x) or (positive and x <= 0):
        raise MultilatError(f"{path}:{node.line}: <{node.tag}> {name}={v!r} must be finite"
                            + (" and > 0" if positive else ""))
    return x


def xml_escape(s: str) -> str:
    return s.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")


def build_network(path, rows, declared: dict, coords: dict, fixed, notes, fmt: str, heads: dict | None = None) -> Network:
    """Check and build a :class:`Network` from parsed rows ``(line, station, target, d_m, sigma_m)``.

    ``declared``: point id -> line where the file declares it (every observed point must be);
    ``coords``: id -> (x, y, z); ``heads``: station -> head (None: every station its own head).
    Errors name ``FILE:LINE`` (``path`` None: the rows' ``line`` is already ``FILE:LINE``)."""
    def at(line):
        return f"{path}:{line}" if path is not None else str(line)

    if not rows:
        raise MultilatError(f"{path}: no distance observations")
    seen: dict = {}
    stations = {r[1] for r in rows}
    for line, s, t, d, sig in rows:
        for p in (s, t):
            if p not in declared:
                raise MultilatError(f"{at(line)}: unknown point {p!r} in an observation (not "
                                    f"declared as a point in the {fmt} file)")
        if s == t:
            raise MultilatError(f"{at(line)}: distance from {s!r} to itself")
        if t in stations:
            raise MultilatError(f"{at(line)}: point {t!r} is a target here and a station "
                                "elsewhere; multilat's model has stations (instruments, with an "
                                "offset) and targets apart")
        if (s, t) in seen:
            raise MultilatError(f"{at(line)}: duplicate distance {s}->{t} (first at "
                                f"{at(seen[(s, t)])}); average repeated measurements into one")
        seen[(s, t)] = line
        if not (math.isfinite(d) and d > 0):
            raise MultilatError(f"{at(line)}: distance {s}->{t} must be finite and > 0")
        if not (math.isfinite(sig) and sig > 0):
            raise MultilatError(f"{at(line)}: standard deviation of {s}->{t} must be finite and > 0")
    obs = Observations.from_labels([r[1] for r in rows], [r[2] for r in rows],
                                   np.array([r[3] for r in rows]), np.array([r[4] for r in rows]),
                                   head=None if heads is None else [heads[r[1]] for r in rows])
    ids = [p for p in coords]
    pts = Points(tuple(ids), np.array([coords[p] for p in ids]).reshape(len(ids), 3))
    return Network(obs, pts, tuple(fixed), tuple(notes))


def read_result_dir(directory) -> tuple[Points, dict[str, float], dict[str, float]]:
    """Adjusted coordinates (stations and targets), station offsets and head scales from the
    ``--out`` directory of ``multilat adjust`` (``stations.csv``: station, x_m, y_m, z_m, offset_m;
    ``targets.csv``: target, x_m, y_m, z_m; other columns ignored; ``result.json``: the scale of
    each head whose scale is not 0, when the file is there)."""
    import json

    from multilat.io import read_csv_table

    d = Path(directory)
    if not d.is_dir():
        raise MultilatError(f"--result {directory}: not a directory (give the --out directory of "
                            "`multilat adjust`)")
    if not (d / "stations.csv").exists() and (d / "points.csv").is_file():
        return _read_general_result(d)
    st = read_csv_table(d / "stations.csv", required=("station", "x_m", "y_m", "z_m", "offset_m"),
                        warn_unknown=False)
    tg = read_csv_table(d / "targets.csv", required=("target", "x_m", "y_m", "z_m"), warn_unknown=False)
    ids = st.ids("station") + tg.ids("target")
    xyz = np.vstack([np.column_stack([t.floats(c) for c in ("x_m", "y_m", "z_m")]) for t in (st, tg)])
    offsets = dict(zip(st.ids("station"), st.floats("offset_m")))
    scales = {}
    if (d / "result.json").is_file():
        try:
            heads = json.loads(decode_text(read_input_bytes(d / "result.json"), d / "result.json")).get("heads") or {}
            scales = {h: float(v.get("scale", 0.0)) for h, v in heads.items() if float(v.get("scale", 0.0)) != 0.0}
        except (ValueError, AttributeError, TypeError) as exc:
            raise MultilatError(f"{d / 'result.json'}: not the result of `multilat adjust` ({exc})") from None
    return Points(tuple(ids), xyz), offsets, scales


def _read_general_result(d: Path) -> tuple[Points, dict[str, float], dict[str, float]]:
    """:func:`read_result_dir` of the ``--out`` of the general model (``adjust ... --model general``
    or ``adjust DIR``): ``points.csv`` (point, x_m, y_m, z_m) and, from ``result.json``'s
    ``parameters``, each instrument's estimated additive constant ``offset:H`` and scale ``scale:H``
    (keyed by head; a head without one was not estimated there and must be given)."""
    import json

    from multilat.io import read_csv_table

    pt = read_csv_table(d / "points.csv", required=("point", "x_m", "y_m", "z_m"), warn_unknown=False)
    xyz = np.column_stack([pt.floats(c) for c in ("x_m", "y_m", "z_m")])
    try:
        par = json.loads(decode_text(read_input_bytes(d / "result.json"), d / "result.json"))["parameters"] or {}
        offsets = {k.split(":", 1)[1]: float(v["value"]) for k, v in par.items() if k.startswith("offset:")}
        scales = {k.split(":", 1)[1]: float(v["value"]) for k, v in par.items() if k.startswith("scale:")}
    except (ValueError, KeyError, AttributeError, TypeError) as exc:
        raise MultilatError(f"{d / 'result.json'}: not the result of `multilat adjust` ({exc})") from None
    return Points(tuple(pt.ids("point")), xyz), offsets, {h: k for h, k in scales.items() if k != 0.0}
