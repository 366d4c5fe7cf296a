"""Star*Net (MicroSurvey STAR*NET) data files (``.dat``): written and read for a 3D network of
slope distances.

Format (STAR*NET reference manual ch. 5 "Preparing Input Data"; MicroSurvey help desk "Summary of
STAR*NET Input Data Types and Inline Options"): one record per line, ``#`` starts a comment,
``'`` a description; inline options start with ``.`` and may be abbreviated. Written::

    .UNITS Meters
    .ORDER EN
    .3D
    .DELTA OFF                         (slope distances)
    C A  0.50460000 0.94120000 0.49200000  * * *     ('*' free, '!' fixed)
    D A-1  0.77560520 0.0000047000                   (From-To  slope distance  std error)

``.ORDER EN`` puts easting before northing on ``C`` lines: multilat's x, y, z (east, north, up).
The reader also takes ``.ORDER NE`` (Star*Net's default), ``.UNITS FeetUS/FeetInt`` (any other
linear unit, e.g. ``Furlongs``, is refused by name; the angular ``DMS``/``Gons`` have no effect),
``.MULTIPLIER``, ``.SEP``, ``.DATA OFF/ON`` and ``.END`` (the rest of the file is not read); ``C`` lines with three numeric σ are read as
approximate coordinates (their σ ignored, a note). Other data types (``A``, ``V``, ``B``, ``M``,
``BM``, ``DV``, ``DB``/``DN``/``DM``/``DE``, ``L``, ``G``, ``T``, ``SS``, ``E``, ``P``, ...), 2D
and levelling modes, ``.DELTA ON`` (horizontal distances), non-zero HI/HT and inline options that
would change distances in ways multilat does not model are refused with the line and type named.

A ``.dat`` file has no additive constant per instrument: fixed offsets (and estimated scales) are
divided out, ``(d - o) / (1 + k)``, and recorded with the heads as the comments
``# multilat-offsets-m: S1=..``, ``# multilat-heads: S1=T1 ..``, ``# multilat-scales: T1=..``, which
the reader restores (docs/interop.md); offsets to be estimated are refused.
Star*Net needs a datum (fixed or weighted control): give the points to hold fixed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.inputs import finite_number
from multilat.io import write_text_atomic
from multilat.network.data import Observations, Points
from multilat.network.interop.common import (SIGMA_DECIMALS, ModelTags, Network, apply_offsets, build_network,
                                              check_ids, fmt_m, model_lines, read_text, refuse_weighted_points,
                                              restore_model)

__all__ = ["starnet_text", "write_starnet", "read_starnet"]

_US_FOOT = 1200.0 / 3937.0
#: data codes multilat does not read, with what they are (refused, named)
_CODES = {"A": "horizontal angles", "V": "vertical observations", "B": "bearings/azimuths",
          "M": "all measurements to another station", "BM": "bearing and measurements",
          "DV": "distance and vertical", "DB": "direction sets", "DN": "direction sets",
          "DM": "direction sets", "DE": "direction sets", "L": "levelling",
          "G": "GPS vectors", "G0": "GPS vectors", "G1": "GPS vectors", "G2": "GPS vectors",
          "G3": "GPS vectors", "G4": "GPS vectors", "T": "traverses", "TB": "traverses",
          "TE": "traverses", "SS": "sideshots", "E": "elevations", "EH": "elevations",
          "P": "geodetic positions", "PH": "geodetic positions", "CH": "coordinates with "
          "ellipsoid heights", "I": "instrument setups", "F": "fixed-direction lines"}
#: .UNITS words: linear units (metres per unit) and angular units (no effect on slope distances);
#: any other word is refused by name
_LINEAR_UNITS = {"M": 1.0, "METERS": 1.0, "METRES": 1.0, "METER": 1.0, "METRE": 1.0,
                 "FEETUS": _US_FOOT, "US": _US_FOOT, "USFEET": _US_FOOT,
                 "FEETINT": 0.3048, "INT": 0.3048, "FEET": 0.3048, "IFEET": 0.3048, "INTFEET": 0.3048}
_ANGULAR_UNITS = ("DMS", "GONS", "GON")
#: inline options read (full names; Star*Net accepts any unambiguous abbreviation)
_INLINE_READ = ("UNITS", "ORDER", "3D", "2D", "3REDUCE", "LEVEL", "DELTA", "SEPARATOR",
                "MULTIPLIER", "DATA", "END")
#: inline options with no effect on slope distances and coordinates (ignored)
_INLINE_HARMLESS = ("COPY", "ELLIPSE", "RELATIVE", "PTOLERANCE", "LONGITUDE", "REFRACTION",
                    "ELEVATION")


def starnet_text(obs: Observations, points: Points | None, *, offsets=None, fixed=(), scales=None) -> str:
    """The ``.dat`` text (see the module docstring). ``offsets``: fixed values (a number, or by
    head or station) subtracted from the distances (required: Star*Net has no per-instrument
    additive constant); ``scales``: fixed head scales divided out; ``fixed``: point ids written with
    ``! ! !``, the others ``* * *``. Heads, offsets and scales are recorded in comments."""
    check_ids(obs, points, "starnet", forbid="-")
    refuse_weighted_points(points, "starnet")
    corrected, notes = apply_offsets(obs, offsets, "Star*Net", scales)
    fixed = set(fixed)
    ids = list(obs.station_ids) + list(obs.target_ids)
    for f in fixed:
        if f not in ids:
            raise MultilatError(f"starnet: fixed point {f!r} is in no observation")
    out = ["# multilat network: slope distances for STAR*NET (3D), metres",
           *("# " + t for t in model_lines(obs, offsets, scales, "starnet")), *("# " + n for n in notes)]
    if not fixed:
        out.append("# no point is fixed: Star*Net needs a datum; fix or weight control before "
                   "adjusting")
    out += [".UNITS Meters", ".ORDER EN", ".3D", ".DELTA OFF", ""]
    if points is not None:
        for i in ids:
            xyz = points.get(i)
            if xyz is not None:
                flag = "! ! !" if i in fixed else "* * *"
                out.append(f"C {i} {fmt_m(xyz[0])} {fmt_m(xyz[1])} {fmt_m(xyz[2])} {flag}")
    for f in fixed:
        if points is None or points.get(f) is None:
            raise MultilatError(f"starnet: fixed point {f!r} has no coordinates")
    out.append("")
    for si in range(obs.n_stations):
        for k in np.flatnonzero(obs.station_index == si):
            out.append(f"D {obs.station_ids[si]}-{obs.target_ids[obs.target_index[k]]} "
                       f"{fmt_m(corrected.distance_m[k])} {fmt_m(corrected.sigma_m[k], SIGMA_DECIMALS)}")
    return "\n".join(out) + "\n"


def write_starnet(path, obs: Observations, points: Points | None, **kw) -> None:
    write_text_atomic(path, starnet_text(obs, points, **kw))


def _option(path, n, word):
    w = word[1:].upper()
    if not w:
        raise MultilatError(f"{path}:{n}: empty inline option '.'")
    hits = [o for o in _INLINE_READ + _INLINE_HARMLESS if o.startswith(w)]
    if len(hits) > 1 and w not in hits:
        raise MultilatError(f"{path}:{n}: inline option {word} is ambiguous ({', '.join(hits)})")
    if not hits:
        raise MultilatError(f"{path}:{n}: inline option {word} is not supported by multilat's "
                            "reader (it may change the distances)")
    return w if w in hits else hits[0]


def _num(path, n, tok, what):
    return finite_number(tok, f"{path}:{n}: {what}")


@dataclass
class _Options:
    """The inline options in force while reading (Star*Net's defaults)."""

    unit: float = 1.0
    mult: float = 1.0
    order_en: bool = False
    sep: str = "-"
    delta: bool = False
    data_on: bool = True


def _inline_option(path, n, tok, st: _Options) -> bool:
    """Apply the inline option of line ``n`` to ``st`` (refusing what the reader does not model);
    True at ``.END``."""
    opt = _option(path, n, tok[0])
    args = [a.upper() for a in tok[1:]]
    if opt == "DATA":
        st.data_on = not args or args[0] != "OFF"
    elif not st.data_on:
        return False
    elif opt == "END":
        return True
    elif opt == "UNITS":
        for a in args:
            if a in _LINEAR_UNITS:
                st.unit = _LINEAR_UNITS[a]
            elif a not in _ANGULAR_UNITS:
                raise MultilatError(f"{path}:{n}: .UNITS {a.title()} is not a unit multilat's reader knows "
                                    "(linear: Meters, FeetUS, FeetInt; angular, no effect on distances: DMS, Gons)")
    elif opt == "ORDER":
        for a in args:
            if a in ("EN", "NE"):
                st.order_en = a == "EN"
            elif a not in ("ATFROMTO", "FROMATTO"):
                raise MultilatError(f"{path}:{n}: .ORDER {a} is not an order multilat's reader knows (EN, NE; "
                                    "AtFromTo/FromAtTo, no effect on distances)")
    elif opt in ("2D", "3REDUCE", "LEVEL"):
        raise MultilatError(f"{path}:{n}: .{opt} mode is not supported: multilat reads 3D "
                            "slope distances (.3D)")
    elif opt == "DELTA":
        st.delta = bool(args) and args[0] == "ON"
    elif opt == "SEPARATOR":
        if len(tok) != 2 or len(tok[1]) != 1:
            raise MultilatError(f"{path}:{n}: .SEP needs one character")
        st.sep = tok[1]
    elif opt == "MULTIPLIER":
        st.mult = _num(path, n, tok[1], ".MULTIPLIER") if len(tok) > 1 else 1.0
    return False


def read_starnet(path, *, sigma_m: float | None = None) -> Network:
    """Read a Star*Net ``.dat``: ``C`` (coordinates) and ``D`` (slope distances) lines. ``sigma_m``:
    σ for ``D`` lines without a standard error (or with ``&``, the default)."""
    st = _Options()
    declared, coords, fixed, rows, notes, tags = {}, {}, [], [], [], ModelTags()
    weighted = 0
    for n, raw in enumerate(read_text(path).splitlines(), 1):
        if raw.strip().startswith("#") and tags.read(f"{path}:{n}", raw.strip()[1:].strip()):
            continue
        line = raw.split("#", 1)[0].split("'", 1)[0].strip()
        if not line:
            continue
        tok = line.split()
        if tok[0].startswith("."):
            if _inline_option(path, n, tok, st):
                break
            continue
        if not st.data_on:
            continue
        code = tok[0].upper()
        f = st.unit * st.mult
        if code == "C":
            if len(tok) < 5:
                raise MultilatError(f"{path}:{n}: C line needs Station and three coordinates (3D)")
            pid = tok[1]
            if pid in declared:
                raise MultilatError(f"{path}:{n}: point {pid!r} given twice (first at line "
                                    f"{declared[pid]})")
            declared[pid] = n
            c = [_num(path, n, t, "coordinate") * f for t in tok[2:5]]
            coords[pid] = (c[0], c[1], c[2]) if st.order_en else (c[1], c[0], c[2])
            flags = tok[5:]
            if flags and all(t == "!" for t in flags):
                fixed.append(pid)
            elif any(t == "!" for t in flags):
                raise MultilatError(f"{path}:{n}: point {pid!r} is partly fixed ({' '.join(flags)}): "
                                    "multilat fixes x, y and z together")
            elif any(t not in ("*", "&") for t in flags):
                weighted += 1
        elif code == "D":
            if st.delta:
                raise MultilatError(f"{path}:{n}: D line under .DELTA ON is a horizontal distance: "
                                    "not supported (multilat reads slope distances)")
            if len(tok) < 3 or tok[1].count(st.sep) != 1:
                raise MultilatError(f"{path}:{n}: D line needs From{st.sep}To and a distance")
            a, b = tok[1].split(st.sep)
            d = _num(path, n, tok[2], "distance") * f
            rest = tok[3:]
            hihts = [t for t in rest if "/" in t]
            for t in hihts:
                hi, _, ht = t.partition("/")
                if _num(path, n, hi, "HI") or _num(path, n, ht, "HT"):
                    raise MultilatError(f"{path}:{n}: HI/HT {t} is not supported (instrument and "
                                        "target heights are not in multilat's model)")
            std = [t for t in rest if "/" not in t]
            if len(std) > 1:
                raise MultilatError(f"{path}:{n}: D line: unexpected fields {' '.join(std[1:])!r}")
            if not std or std[0] == "&":
                if sigma_m is None:
                    raise MultilatError(f"{path}:{n}: distance {a}->{b} has no standard error "
                                        "(give --sigma-um)")
                sig = sigma_m
            elif std[0] in ("!", "*"):
                raise MultilatError(f"{path}:{n}: distance {a}->{b} marked {std[0]!r} (fixed/free) "
                                    "is not supported: give a standard error")
            else:
                sig = _num(path, n, std[0], "standard error") * f
            rows.append((n, a, b, d, sig))
        else:
            what = _CODES.get(code)
            raise MultilatError(f"{path}:{n}: {code!r} lines" + (f" ({what})" if what else "")
                                + " are not supported: multilat reads C and D lines (3D slope "
                                "distances) only")
    if weighted:
        notes.append(f"{weighted} C line(s) with numeric σ read as approximate coordinates (σ ignored)")
    rows, heads = restore_model(path, rows, tags, notes)
    return build_network(path, rows, declared, coords, fixed, notes, "Star*Net (C line)", heads)
