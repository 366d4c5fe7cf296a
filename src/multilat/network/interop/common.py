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
from multilat.network.data import Observations, Points

__all__ = ["Network", "apply_offsets", "restore_offsets", "check_ids", "fmt_m", "read_text", "XmlNode", "parse_xml",
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
    """

    obs: Observations
    points: Points
    fixed: tuple = ()
    notes: tuple = field(default=())


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


def apply_offsets(obs: Observations, offsets, fmt: str) -> tuple[Observations, list[str]]:
    """Distances without the per-station additive offsets, for a format that cannot carry them.

    ``offsets``: a mapping station id -> metres covering every station, or a number (the same for
    every station). ``None`` or ``"estimate"`` (the offsets are unknowns) is refused: the format
    has no additive constant per instrument. Returns the corrected observations and one note line
    per station."""
    if offsets is None or (isinstance(offsets, str) and offsets == "estimate"):
        raise MultilatError(f"{fmt} has no additive constant per instrument, so the offsets cannot "
                            "be estimated there: give them fixed (--offsets-um A=..,B=.. or "
                            "--result DIR of `multilat adjust --out`) to export the distances "
                            "corrected by them")
    if isinstance(offsets, Mapping):
        missing = [s for s in obs.station_ids if s not in offsets]
        if missing:
            raise MultilatError(f"{fmt}: no fixed offset for station {missing[0]!r}; give every "
                                "station's offset")
        unknown = [s for s in offsets if s not in obs.station_ids]
        if unknown:
            raise MultilatError(f"{fmt}: offset given for unknown station {unknown[0]!r}")
        o = np.array([float(offsets[s]) for s in obs.station_ids])
    else:
        o = np.full(obs.n_stations, float(offsets))
    if not np.all(np.isfinite(o)):
        raise MultilatError(f"{fmt}: offsets must be finite")
    d = obs.distance_m - o[obs.station_index]
    if np.any(d <= 0):
        k = int(np.flatnonzero(d <= 0)[0])
        raise MultilatError(f"{fmt}: distance {obs.label(k)} minus its station's offset is not > 0")
    notes = [f"station {s}: offset {o[i] * 1e6:.4f} um subtracted from its distances"
             for i, s in enumerate(obs.station_ids)]
    return obs.with_distances(d), notes


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


def restore_offsets(path, rows, offsets, notes: list) -> list:
    """Add back the per-station offsets a writer subtracted (named in the file's header) to the rows
    ``(line, station, target, distance_m, sigma_m)``; ``offsets`` None leaves them as read."""
    if offsets is None:
        return rows
    stations = {r[1] for r in rows}
    bad = [s for s in offsets if s not in stations]
    if bad:
        raise MultilatError(f"{path}: offsets line names {bad[0]!r}, a station with no distances")
    notes.append("per-station offsets restored from the header: "
                 + ", ".join(f"{k} {v * 1e6:.4f} um" for k, v in offsets.items()))
    return [(ln, a, b, d + offsets.get(a, 0.0), sg) for ln, a, b, d, sg in rows]


def build_network(path, rows, declared: dict, coords: dict, fixed, notes, fmt: str) -> Network:
    """Check and build a :class:`Network` from parsed rows ``(line, station, target, d_m, sigma_m)``.

    ``declared``: point id -> line where the file declares it (every observed point must be);
    ``coords``: id -> (x, y, z). Errors name ``FILE:LINE``."""
    if not rows:
        raise MultilatError(f"{path}: no distance observations")
    seen: dict = {}
    stations = {r[1] for r in rows}
    for line, s, t, d, sig in rows:
        for p in (s, t):
            if p not in declared:
                raise MultilatError(f"{path}:{line}: unknown point {p!r} in an observation (not "
                                    f"declared as a point in the {fmt} file)")
        if s == t:
            raise MultilatError(f"{path}:{line}: distance from {s!r} to itself")
        if t in stations:
            raise MultilatError(f"{path}:{line}: point {t!r} is a target here and a station "
                                "elsewhere; multilat's model has stations (instruments, with an "
                                "offset) and targets apart")
        if (s, t) in seen:
            raise MultilatError(f"{path}:{line}: duplicate distance {s}->{t} (first at line "
                                f"{seen[(s, t)]}); average repeated measurements into one")
        seen[(s, t)] = line
        if not (math.isfinite(d) and d > 0):
            raise MultilatError(f"{path}:{line}: distance {s}->{t} must be finite and > 0")
        if not (math.isfinite(sig) and sig > 0):
            raise MultilatError(f"{path}:{line}: standard deviation of {s}->{t} must be finite and > 0")
    obs = Observations.from_labels([r[1] for r in rows], [r[2] for r in rows],
                                   np.array([r[3] for r in rows]), np.array([r[4] for r in rows]))
    ids = [p for p in coords]
    pts = Points(tuple(ids), np.array([coords[p] for p in ids]).reshape(len(ids), 3))
    return Network(obs, pts, tuple(fixed), tuple(notes))


def read_result_dir(directory) -> tuple[Points, dict[str, float]]:
    """Adjusted coordinates (stations and targets) and station offsets from the ``--out``
    directory of ``multilat adjust`` (``stations.csv``: station, x_m, y_m, z_m, offset_m;
    ``targets.csv``: target, x_m, y_m, z_m; other columns ignored)."""
    from multilat.io import read_csv_table

    d = Path(directory)
    if not d.is_dir():
        raise MultilatError(f"--result {directory}: not a directory (give the --out directory of "
                            "`multilat adjust`)")
    st = read_csv_table(d / "stations.csv", required=("station", "x_m", "y_m", "z_m", "offset_m"),
                        warn_unknown=False)
    tg = read_csv_table(d / "targets.csv", required=("target", "x_m", "y_m", "z_m"), warn_unknown=False)
    ids = st.ids("station") + tg.ids("target")
    xyz = np.vstack([np.column_stack([t.floats(c) for c in ("x_m", "y_m", "z_m")]) for t in (st, tg)])
    offsets = dict(zip(st.ids("station"), st.floats("offset_m")))
    return Points(tuple(ids), xyz), offsets
