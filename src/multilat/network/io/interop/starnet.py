"""Star*Net (MicroSurvey STAR*NET) data files (``.dat``): written and read for a 3D network of
slope distances, with the directions and zenith angles of levelled stations.

Format (STAR*NET reference manual ch. 5 "Preparing Input Data", its "DM" code; MicroSurvey help desk
"Summary of STAR*NET Input Data Types and Inline Options"): one record per line, ``#`` starts a
comment, ``'`` a description; inline options start with ``.`` and may be abbreviated. Written::

    .UNITS Meters
    .ORDER EN
    .3D
    .DELTA OFF                         (slope distances)
    C A  0.50460000 0.94120000 0.49200000  * * *     ('*' free, '!' fixed)
    D A-1  0.77560520 0.0000047000                   (From-To  slope distance  std error)
    DB AT1                                           (a levelled station's direction set: one orientation)
    DM P1 146-00-09.064076 3.02822109 104-37-04.683822 1.13 0.0000054542 1.13
    DE                                               (direction, slope distance, zenith; std errors, " and m)

Directions are clockwise (``-azimuth``), zenith angles ``90° - elevation``, d-m-s; a direction
without zenith angle is a ``DN`` line (its distance a ``D`` line), a zenith angle without direction
a ``V`` line. ``.ORDER EN`` puts easting before northing on ``C`` lines: multilat's x, y, z (east,
north, up). The reader also takes ``.ORDER NE`` (Star*Net's default), ``.UNITS FeetUS/FeetInt``
(any other linear unit, e.g. ``Furlongs``, is refused by name; angles are read in ``DMS`` only),
``.MULTIPLIER``, ``.SEP``, ``.DATA OFF/ON`` and ``.END`` (the rest of the file is not read); ``C``
lines with three numeric σ are read as approximate coordinates (their σ ignored, a note). Other
data types (``A``, ``B``, ``M``, ``BM``, ``DV``, ``L``, ``G``, ``T``, ``SS``, ``E``, ``P``, ...), 2D
and levelling modes, ``.DELTA ON`` (horizontal distances), non-zero HI/HT and inline options that
would change distances in ways multilat does not model are refused with the line and type named.

A ``.dat`` file has no additive constant per instrument: fixed offsets (and estimated scales) are
divided out, ``(d - o) / (1 + k)``, and recorded with the heads as the comments
``# multilat-offsets-m: S1=..``, ``# multilat-heads: S1=T1 ..``, ``# multilat-scales: T1=..``, which
the reader restores (docs/interop.md); offsets to be estimated are refused.
Star*Net needs a datum (fixed or weighted control): give the points to hold fixed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.inputs import finite_number
from multilat.io import write_text_atomic
from multilat.network.model.data import Observations, Points
from multilat.network.io.interop.angles import angle_sigmas, dms, join_angles, parse_dms
from multilat.network.io.interop.common import (SIGMA_DECIMALS, ModelTags, Network, apply_offsets, build_network,
                                              check_ids, fmt_m, model_lines, read_text, refuse_weighted_points,
                                              restore_model)

__all__ = ["starnet_text", "write_starnet", "read_starnet"]

_US_FOOT = 1200.0 / 3937.0
#: data codes multilat does not read, with what they are (refused, named)
_CODES = {"A": "horizontal angles", "B": "bearings/azimuths",
          "M": "all measurements to another station", "BM": "bearing and measurements",
          "DV": "distance and vertical", "L": "levelling",
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
    sa, se = angle_sigmas(obs, "starnet", "Star*Net")
    for si in range(obs.n_stations):
        out += _station_lines(obs, corrected, si, sa, se)
    return "\n".join(out) + "\n"


def _sec(s_rad: float) -> str:
    return f"{math.degrees(float(s_rad)) * 3600:.9f}"        # arc seconds, 1e-9" = 4.8e-15 rad


def _station_lines(obs, corrected, si, sa, se) -> list[str]:
    """One station's lines: a direction set ``DB``..``DE`` of a levelled station (``DM`` direction,
    slope distance and zenith angle; ``DN`` a direction alone), ``V`` zenith angles without a
    direction, ``D`` the other distances. Directions are clockwise: ``-azimuth`` (the set's
    orientation is the station's heading); zenith = 90° - elevation; angle σ in arc seconds."""
    sid = obs.station_ids[si]
    ks = np.flatnonzero(obs.station_index == si)
    d, sd = corrected.distance_m, corrected.sigma_m
    tid = [obs.target_ids[obs.target_index[k]] for k in ks]
    dist = {k: f"{fmt_m(d[k])}" for k in ks}
    sdd = {k: f"{fmt_m(sd[k], SIGMA_DECIMALS)}" for k in ks}
    dset, rest = [], []
    for k, t in zip(ks, tid):
        has_a, has_e = np.isfinite(sa[k]), np.isfinite(se[k])
        z = dms(math.pi / 2 - obs.elevation_rad[k]) if has_e else ""
        if has_a and has_e:
            dset.append(f"DM {t} {dms(-obs.azimuth_rad[k])} {dist[k]} {z} {_sec(sa[k])} {sdd[k]} {_sec(se[k])}")
            continue
        if has_a:
            dset.append(f"DN {t} {dms(-obs.azimuth_rad[k])} {_sec(sa[k])}")
        elif has_e:
            rest.append(f"V {sid}-{t} {z} {_sec(se[k])}")
        rest.append(f"D {sid}-{t} {dist[k]} {sdd[k]}")
    return ([f"DB {sid}", *dset, "DE"] if dset else []) + rest


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
    gons: bool = False


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
            elif a in _ANGULAR_UNITS:
                st.gons = a != "DMS"
            else:
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
    """Read a Star*Net ``.dat``: ``C`` (coordinates) and ``D`` (slope distances) lines, direction sets
    (``DB``, ``DN``, ``DM``, ``DE``: a levelled station's directions, with slope distance and zenith
    angle on ``DM``) and ``V`` zenith angles. ``sigma_m``: σ for distances without a standard error
    (or with ``&``, the default); angles need theirs."""
    st = _Options()
    declared, coords, fixed, rows, notes, tags = {}, {}, [], [], [], ModelTags()
    arows, sets, weighted, open_set = [], {}, 0, None
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
        if code == "C":
            weighted += _c_line(path, n, tok, st, declared, coords, fixed)
        elif code == "D":
            if open_set is not None:
                raise MultilatError(f"{path}:{n}: a D line inside the direction set of {open_set!r} (close it with DE)")
            rows.append(_d_line(path, n, tok, st, sigma_m))
        elif code in ("DB", "DN", "DM", "DE", "V"):
            open_set = _angle_line(path, n, tok, st, sigma_m, open_set, sets, rows, arows)
        else:
            what = _CODES.get(code)
            raise MultilatError(f"{path}:{n}: {code!r} lines" + (f" ({what})" if what else "")
                                + " are not supported: multilat reads C, D, V lines and direction sets "
                                "(DB/DN/DM/DE) of a 3D network")
    if open_set is not None:
        raise MultilatError(f"{path}:{sets[open_set]}: the direction set of {open_set!r} has no DE")
    if weighted:
        notes.append(f"{weighted} C line(s) with numeric σ read as approximate coordinates (σ ignored)")
    rows, heads = restore_model(path, rows, tags, notes)
    network = build_network(path, rows, declared, coords, fixed, notes, "Star*Net (C line)", heads)
    return join_angles(path, network, arows) if arows else network


def _c_line(path, n, tok, st, declared, coords, fixed) -> int:
    """Read a ``C`` line; 1 when it carries numeric σ (read as approximate coordinates), else 0."""
    if len(tok) < 5:
        raise MultilatError(f"{path}:{n}: C line needs Station and three coordinates (3D)")
    pid = tok[1]
    if pid in declared:
        raise MultilatError(f"{path}:{n}: point {pid!r} given twice (first at line {declared[pid]})")
    declared[pid] = n
    f = st.unit * st.mult
    c = [_num(path, n, t, "coordinate") * f for t in tok[2:5]]
    coords[pid] = (c[0], c[1], c[2]) if st.order_en else (c[1], c[0], c[2])
    flags = tok[5:]
    if flags and all(t == "!" for t in flags):
        fixed.append(pid)
    elif any(t == "!" for t in flags):
        raise MultilatError(f"{path}:{n}: point {pid!r} is partly fixed ({' '.join(flags)}): "
                            "multilat fixes x, y and z together")
    return int(any(t not in ("*", "&", "!") for t in flags))


def _hi_ht(path, n, rest) -> list[str]:
    """``rest`` without its HI/HT entries, each of which must be zero."""
    for t in (t for t in rest if "/" in t):
        hi, _, ht = t.partition("/")
        if _num(path, n, hi, "HI") or _num(path, n, ht, "HT"):
            raise MultilatError(f"{path}:{n}: HI/HT {t} is not supported (instrument and "
                                "target heights are not in multilat's model)")
    return [t for t in rest if "/" not in t]


def _sigma(path, n, tok, what, default):
    """A standard error: a number (times ``default``'s unit factor for distances), or ``&``/absent
    for ``default`` (None: refused); ``!``/``*`` (fixed/free) refused."""
    if tok is None or tok == "&":
        if default is None:
            raise MultilatError(f"{path}:{n}: {what} has no standard error ("
                                + ("give --sigma-um)" if what.startswith("distance") else "give one on the line)"))
        return default
    if tok in ("!", "*"):
        raise MultilatError(f"{path}:{n}: {what} marked {tok!r} (fixed/free) is not supported: give a "
                            "standard error")
    return _num(path, n, tok, "standard error")


def _d_line(path, n, tok, st, sigma_m):
    if st.delta:
        raise MultilatError(f"{path}:{n}: D line under .DELTA ON is a horizontal distance: "
                            "not supported (multilat reads slope distances)")
    if len(tok) < 3 or tok[1].count(st.sep) != 1:
        raise MultilatError(f"{path}:{n}: D line needs From{st.sep}To and a distance")
    a, b = tok[1].split(st.sep)
    f = st.unit * st.mult
    std = _hi_ht(path, n, tok[3:])
    if len(std) > 1:
        raise MultilatError(f"{path}:{n}: D line: unexpected fields {' '.join(std[1:])!r}")
    sig = _sigma(path, n, std[0] if std else None, f"distance {a}->{b}", None if sigma_m is None else sigma_m / f)
    return (n, a, b, _num(path, n, tok[2], "distance") * f, sig * f)


def _angle(path, n, st, text):
    if st.gons:
        raise MultilatError(f"{path}:{n}: angles under .UNITS Gons are not read: write them in DMS (d-m-s)")
    return parse_dms(f"{path}:{n}", text)


def _angle_line(path, n, tok, st, sigma_m, open_set, sets, rows, arows):
    """A direction-set line (``DB``, ``DN``, ``DM``, ``DE``) or a ``V`` zenith angle; returns the
    station of the set now open (None when closed). One set per station (one orientation)."""
    code = tok[0].upper()
    if st.delta and code in ("DM", "V"):
        raise MultilatError(f"{path}:{n}: {code} line under .DELTA ON holds a horizontal distance or an "
                            "elevation difference: not supported (multilat reads slope distances and zenith angles)")
    if code == "DB":
        if open_set is not None or len(tok) != 2:
            raise MultilatError(f"{path}:{n}: DB needs one station" + (f" and the set of {open_set!r} closed first"
                                                                     if open_set is not None else ""))
        if tok[1] in sets:
            raise MultilatError(f"{path}:{n}: a second direction set of station {tok[1]!r} (the first at line "
                                f"{sets[tok[1]]}): two orientation unknowns; multilat has one per station")
        sets[tok[1]] = n
        return tok[1]
    if code == "DE":
        if open_set is None:
            raise MultilatError(f"{path}:{n}: DE without a DB")
        return None
    if code == "V":
        if open_set is not None or len(tok) < 3 or tok[1].count(st.sep) != 1:
            raise MultilatError(f"{path}:{n}: V line needs From{st.sep}To and a zenith angle (outside a direction set)")
        a, b = tok[1].split(st.sep)
        std = _hi_ht(path, n, tok[3:])
        arows.append((n, a, b, "elevation", math.pi / 2 - _angle(path, n, st, tok[2]),
                      math.radians(_sigma(path, n, std[0] if std else None, f"zenith angle {a}->{b}", None) / 3600)))
        return None
    if open_set is None:
        raise MultilatError(f"{path}:{n}: {code} outside a direction set (DB ... DE)")
    fields = _hi_ht(path, n, tok[1:])
    want = (2, 3) if code == "DN" else (4, 7)
    if len(fields) not in want:
        raise MultilatError(f"{path}:{n}: {code} needs " + ("To Direction [StdErr]" if code == "DN" else
                            "To Direction SlopeDist Zenith [3 StdErrs]") + f", got {len(fields)} fields")
    a, b = open_set, fields[0]
    nval = 2 if code == "DN" else 4
    se = fields[nval:] or [None] * (nval - 1)
    arows.append((n, a, b, "azimuth", _wrap(-_angle(path, n, st, fields[1])),
                  math.radians(_sigma(path, n, se[0], f"direction {a}->{b}", None) / 3600)))
    if code == "DM":
        f = st.unit * st.mult
        sig = _sigma(path, n, se[1], f"distance {a}->{b}", None if sigma_m is None else sigma_m / f) * f
        rows.append((n, a, b, _num(path, n, fields[2], "distance") * f, sig))
        arows.append((n, a, b, "elevation", math.pi / 2 - _angle(path, n, st, fields[3]),
                      math.radians(_sigma(path, n, se[2], f"zenith angle {a}->{b}", None) / 3600)))
    return open_set


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi
