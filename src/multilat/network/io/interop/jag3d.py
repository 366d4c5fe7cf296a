"""JAG3D (applied-geodesy/jag3d): its plain-text ("flat file") import of points and of slope
distances, written and read.

The formats are those of JAG3D's readers ``PointFlatFileReader`` with ``PointRow.scan3D`` and
``ObservationFlatFileReader`` with ``TerrestrialObservationRow.scan``
(``JAG3D/src/org/applied_geodesy/jag3d/ui/...``): lines starting with ``#`` are skipped, fields
are separated by blanks (points also by ``;``), lengths in JAG3D's length unit (metre by
default).

Points (3D)::

    NAME  Y  X  Z  [σY [σX [σZ]]]

JAG3D's ``Y`` is the first coordinate column (easting), ``X`` the second (northing), ``Z`` up:
multilat writes its x, y, z into those columns in that order (east, north, up: the same
right-handed axes) and reads them back the same way. Point σ are read and ignored (a note).

Slope distances, one of::

    FROM TO VALUE                 FROM TO VALUE SIGMA          (SIGMA < 1 m)
    FROM TO IH TH VALUE           FROM TO IH TH VALUE SIGMA

(JAG3D reads a fourth/sixth number >= 1 as a distance for its σ model, not as a σ; multilat then
needs a default σ, as for a line without one). Instrument and target heights must be 0.

The per-instrument additive constant and scale: JAG3D gives every observation group one zero-point
offset and one scale (``SlopeDistanceGroup``), and its flat-file reader
(``ObservationFlatFileReader``) makes **one group per file**, or, with the import option "separate
groups by station", a new group whenever the station changes. One group = one head, so:

* every station its own head: one file, listed station by station, imported with "separate groups
  by station";
* heads over several stations (a ``head`` column): one file per head, ``OUT-HEAD.txt``, each
  marked ``# multilat-head: T1`` and imported as one group (without that option).

With the offsets to be estimated the headers say to enable each group's zero-point offset (and the
scale of the heads whose scale the source adjustment estimated). Fixed offsets (and scales) are
divided out, ``(d - o) / (1 + k)``, and recorded as ``# multilat-offsets-m: ..`` /
``# multilat-scales: ..``; the reader restores them, and the heads from ``# multilat-head:``.

Angles of levelled stations: ``OUT-directions-S.txt`` per station (a ``DirectionGroup`` has one
``Orientation`` for all of its directions: the station's heading) and ``OUT-zenith-angles.txt``,
``FROM TO VALUE SIGMA`` in gon (JAG3D's reader passes value and σ of an angle through its angle
unit, gradian by default, and takes a σ < 1 as a σ); directions clockwise, ``-azimuth``; zenith
``100 gon - elevation``. The file type, which JAG3D's import dialog asks for, is recorded as
``# multilat-observations: directions`` / ``zenith angles`` (unmarked files: slope distances).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from multilat.errors import MultilatError
from multilat.io import write_text_atomic
from multilat.network.model.data import Observations, Points
from multilat.network.io.interop.angles import angle_sigmas, join_angles
from multilat.network.io.interop.common import (SIGMA_DECIMALS, ModelTags, Network, apply_offsets, build_network,
                                              OFFSETS_TAG, SCALES_TAG, check_ids, fmt_m, read_text,
                                              refuse_weighted_points, restore_model, station_values)

__all__ = ["jag3d_texts", "write_jag3d", "read_jag3d", "head_file", "jag3d_files"]

#: the comment naming the head (one JAG3D observation group) whose distances a file holds
HEAD_TAG = "multilat-head:"
_FILE_SAFE = re.compile(r"^[A-Za-z0-9._+-]+$")


def head_file(obs_path, head: str) -> Path:
    """The distances file of ``head``: ``OUT``'s name with ``-HEAD`` before the suffix."""
    p = Path(obs_path)
    return p.with_name(f"{p.stem}-{head}{p.suffix or '.txt'}")


def jag3d_texts(obs: Observations, points: Points | None, *, offsets=None, scales=None) -> tuple[str, dict]:
    """(points file text, {head id or None: slope-distances file text}).

    Every station its own head (no ``head`` column): one file (key None), to be imported with
    JAG3D's option "separate groups by station" (one group per station). Heads over several
    stations: one file per head, each to be imported as **one** group (JAG3D's flat-file reader
    makes one group per file unless that option is on), marked ``# multilat-head: T1``.
    ``offsets``: None/"estimate" (JAG3D estimates the group's zero-point offset) or fixed values
    (subtracted, recorded); ``scales``: the heads' scales of the source adjustment (fixed values
    divided out with fixed offsets; with offsets to be estimated, the header says to enable those
    groups' scale)."""
    check_ids(obs, points, "jag3d", forbid=";")
    refuse_weighted_points(points, "jag3d")
    missing = [i for i in obs.station_ids + obs.target_ids if points is None or points.get(i) is None]
    if missing:
        raise MultilatError(f"jag3d: point {missing[0]!r} has no coordinates; JAG3D's point groups "
                            "need every point (give --points covering every point)")
    by_head = obs.station_heads is not None
    bad = [h for h in obs.head_ids if by_head and not _FILE_SAFE.match(h)]
    if bad:
        raise MultilatError(f"jag3d: head id {bad[0]!r} cannot name a file (one file per head = one JAG3D "
                            "group): use letters, digits, '.', '_', '+', '-'")
    estimate = offsets is None or (isinstance(offsets, str) and offsets == "estimate")
    corrected, notes = (obs, []) if estimate else apply_offsets(obs, offsets, "JAG3D", scales)
    texts = {}
    for hi, head in enumerate(obs.head_ids if by_head else [None]):
        st = [i for i in range(obs.n_stations) if head is None or obs.head_index[i] == hi]
        texts[head] = "\n".join(_head_header(obs, head, st, estimate, scales, offsets, notes)
                                + _distance_lines(obs, corrected, st)) + "\n"
    for key, text in _angle_texts(obs).items():
        if key in texts:
            raise MultilatError(f"jag3d: head {key!r} and the angle file of that name would be one file: rename the head")
        texts[key] = text
    pts = ["# multilat points: NAME Y X Z = multilat x y z (east, north, up), metres"]
    if points is not None:
        for i, xyz in zip(points.ids, points.xyz_m):
            pts.append(f"{i} {fmt_m(xyz[0])} {fmt_m(xyz[1])} {fmt_m(xyz[2])}")
    return "\n".join(pts) + "\n", texts


#: the comment naming the observation type of a file (JAG3D's import dialog asks for it; the file
#: does not say): slope distances when absent
TYPE_TAG = "multilat-observations:"
_TYPES = ("slope distances", "directions", "zenith angles")


def _angle_texts(obs: Observations) -> dict:
    """The angle files: ``directions-S`` per levelled station (one JAG3D direction group = one
    orientation unknown = the station's heading) and ``zenith-angles`` (one group, refraction off).
    Values and σ in gon (JAG3D's default angle unit; its reader takes a σ < 1 as a σ); directions
    clockwise, ``-azimuth``; zenith = 100 gon - elevation."""
    sa, se = angle_sigmas(obs, "jag3d", "JAG3D")
    out, zen = {}, []
    for si, sid in enumerate(obs.station_ids):
        ks = [k for k in np.flatnonzero(obs.station_index == si)]
        rows = [f"{sid} {obs.target_ids[obs.target_index[k]]} {_gon((-obs.azimuth_rad[k]) % (2 * math.pi))} "
                f"{_gon(sa[k], 15)}" for k in ks if np.isfinite(sa[k])]
        zen += [f"{sid} {obs.target_ids[obs.target_index[k]]} {_gon(math.pi / 2 - obs.elevation_rad[k])} "
                f"{_gon(se[k], 15)}" for k in ks if np.isfinite(se[k])]
        if rows:
            if not _FILE_SAFE.match(sid):
                raise MultilatError(f"jag3d: station id {sid!r} cannot name its directions file: use letters, "
                                    "digits, '.', '_', '+', '-'")
            out[f"directions-{sid}"] = "\n".join([
                f"# multilat network: horizontal directions of the levelled station {sid} for JAG3D (gon)",
                f"# {TYPE_TAG} directions",
                "# import this file as ONE group of directions (one orientation = the station's heading); "
                "JAG3D's angle unit gon, directions clockwise", *rows]) + "\n"
    if zen:
        out["zenith-angles"] = "\n".join([
            "# multilat network: zenith angles of the levelled stations for JAG3D (gon)",
            f"# {TYPE_TAG} zenith angles",
            "# import this file as ONE group of zenith angles, refraction coefficient off; JAG3D's angle unit gon",
            *zen]) + "\n"
    return out


def _gon(a_rad: float, decimals: int = 12) -> str:
    return f"{float(a_rad) * 200.0 / math.pi:.{decimals}f}"      # 1e-12 gon = 1.6e-14 rad


def _head_header(obs, head, st, estimate, scales, offsets, notes) -> list[str]:
    """The comment lines of one distances file (``head`` None: every station its own head)."""
    names = " ".join(obs.station_ids[i] for i in st)
    if head is None:
        out = ["# multilat network: slope distances for JAG3D's flat-file import (metres)",
               "# import with the option 'separate groups by station': one group per station = one instrument"]
        heads = list(obs.head_ids)
    else:
        out = [f"# multilat network: slope distances of head {head} (stations {names}) for JAG3D's "
               "flat-file import (metres)",
               "# import this file as ONE group of slope distances, without 'separate groups by station': "
               f"one group = head {head}, one zero point offset and one scale for all of its stations",
               f"# {HEAD_TAG} {head}"]
        heads = [head]
    k_est = [h for h in heads if (scales or {}).get(h, 0.0) != 0.0]
    if estimate:
        out.append("# enable the additional parameter 'zero point offset' in "
                   + ("every group: multilat's per-station additive offset" if head is None else
                      f"the group: head {head}'s additive offset"))
        if k_est:
            out.append(f"# enable the additional parameter 'scale' for head(s) {' '.join(k_est)} (multilat "
                       "estimated their scale)")
        return out
    o = station_values(obs, offsets, "JAG3D", "offset")
    out.append(f"# {OFFSETS_TAG} " + " ".join(f"{obs.station_ids[i]}={fmt_m(o[i], 10)}" for i in st))
    if k_est:
        out.append(f"# {SCALES_TAG} " + " ".join(f"{h}={float(scales[h])!r}" for h in k_est))
    out += ["# " + notes[i] + " (keep the zero point offsets and scales fixed at 0)" for i in st]
    return out


def _distance_lines(obs, corrected, st) -> list[str]:
    lines = []
    for si in st:
        for k in np.flatnonzero(obs.station_index == si):
            sig = corrected.sigma_m[k]
            if not sig < 1.0:
                raise MultilatError(f"jag3d: σ of {obs.label(k)} is {sig} m: JAG3D reads a value "
                                    ">= 1 there as a distance, not a σ")
            lines.append(f"{obs.station_ids[si]} {obs.target_ids[obs.target_index[k]]} "
                         f"{fmt_m(corrected.distance_m[k])} {fmt_m(sig, SIGMA_DECIMALS)}")
    return lines


def jag3d_files(obs_path, obs: Observations) -> list[Path]:
    """The files :func:`write_jag3d` writes for ``obs`` besides the points file: the distances
    (``obs_path``, or one :func:`head_file` per head), the directions of each levelled station
    (``OUT-directions-S``) and the zenith angles (``OUT-zenith-angles``)."""
    keys = list(obs.head_ids) if obs.station_heads is not None else [None]
    for v, key in ((obs.sigma_azimuth_rad, "directions-"), (obs.sigma_elevation_rad, "zenith-angles")):
        has = np.zeros(obs.n_obs, bool) if v is None else np.isfinite(np.asarray(v, float))
        stations = dict.fromkeys(obs.station_ids[i] for i in obs.station_index[has])
        keys += [key + s for s in stations] if key.endswith("-") else ([key] if stations else [])
    return [Path(obs_path) if k is None else head_file(obs_path, k) for k in keys]


def write_jag3d(points_path, obs_path, obs: Observations, points: Points | None, **kw) -> list[Path]:
    """Write the points file and the observation files (each atomically; :func:`jag3d_files`).
    Returns the observation files."""
    p, texts = jag3d_texts(obs, points, **kw)
    paths = {h: Path(obs_path) if h is None else head_file(obs_path, h) for h in texts}
    write_text_atomic(points_path, p)
    for h, t in texts.items():
        write_text_atomic(paths[h], t)
    return list(paths.values())


def _number(path, n, tok, what, *, comma=False):
    """A finite number; ``comma``: a decimal comma is accepted (JAG3D's point reader replaces it;
    its observation reader, an English-locale scanner, does not)."""
    try:
        v = float(tok.replace(",", ".") if comma else tok)
    except ValueError:
        raise MultilatError(f"{path}:{n}: {what}: not a number: {tok!r}") from None
    if not math.isfinite(v):
        raise MultilatError(f"{path}:{n}: {what}: must be finite, got {tok!r}")
    return v


def read_jag3d(points_path, obs_path, *, sigma_m: float | None = None) -> Network:
    """Read JAG3D flat files: points (``NAME Y X Z [σ..]``) and observations (``obs_path``: one file
    or a sequence of files). A file is slope distances unless marked ``# multilat-observations:
    directions`` (one group: one station, one orientation) or ``zenith angles`` (gon). A distances
    file marked ``# multilat-head: T1`` holds head T1's distances (one JAG3D group); the stations of
    an unmarked file are their own heads. ``sigma_m``: σ for distances without one (else an error
    naming the line)."""
    coords, declared, notes = _read_points(points_path)
    paths = [obs_path] if isinstance(obs_path, (str, Path)) else list(obs_path)
    rows, arows, heads, where, dir_file = [], [], {}, {}, {}
    for path in paths:
        kind, f_rows, f_heads = _read_file(path, sigma_m, notes)
        if kind != "slope distances":
            _check_angle_file(path, kind, f_rows, dir_file)
            arows += [(f"{path}:{n}", *rest) for n, *rest in f_rows]
            continue
        for r in f_rows:
            h = (f_heads or {}).get(r[1], r[1])
            if heads.setdefault(r[1], h) != h:
                raise MultilatError(f"{path}:{r[0]}: station {r[1]!r} is on head {h!r} here and on head "
                                    f"{heads[r[1]]!r} in {where[r[1]]}: one station, one head")
            where.setdefault(r[1], path)
        rows += [(f"{path}:{n}", a, b, d, sg) for n, a, b, d, sg in f_rows]
    shared = any(h != s for s, h in heads.items())
    network = build_network(None, rows, declared, coords, (), notes, "JAG3D points", heads if shared else None)
    return join_angles(None, network, arows) if arows else network


def _check_angle_file(path, kind, rows, dir_file) -> None:
    """A directions file is one JAG3D group with one orientation: one station, in one file."""
    if kind != "directions":
        return
    stations = list(dict.fromkeys(r[1] for r in rows))
    if len(stations) > 1:
        line = next(r[0] for r in rows if r[1] == stations[1])
        raise MultilatError(f"{path}:{line}: directions from a second station {stations[1]!r} in one group (one "
                            "orientation): multilat has one orientation per station; one file per station")
    for s in stations:
        if s in dir_file:
            raise MultilatError(f"{path}: directions of station {s!r} in a second group (the first: {dir_file[s]}): "
                                "two orientation unknowns; multilat has one per station")
        dir_file[s] = path


def _read_points(points_path):
    coords, declared, notes = {}, {}, []
    point_sigmas = 0
    for n, line in enumerate(read_text(points_path).splitlines(), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        tok = re.split(r"[\s;]+", s)
        if len(tok) < 4 or len(tok) > 7:
            raise MultilatError(f"{points_path}:{n}: expected NAME Y X Z [σY [σX [σZ]]] (a 3D point), "
                                f"got {len(tok)} fields")
        name = tok[0]
        if name in declared:
            raise MultilatError(f"{points_path}:{n}: point {name!r} given twice (first at line "
                                f"{declared[name]})")
        declared[name] = n
        coords[name] = tuple(_number(points_path, n, t, c, comma=True) for t, c in zip(tok[1:4], "YXZ"))
        point_sigmas += len(tok) > 4
    if point_sigmas:
        notes.append(f"{point_sigmas} point σ ignored (multilat's points are approximate values or "
                     "fixed control)")
    return coords, declared, notes


def _read_file(obs_path, sigma_m, notes):
    """The observation type of one file, its rows and its heads: slope distances ``(line, from, to,
    d, σ)`` restored by the file's convention lines (heads: station -> head, or None), or angles
    ``(line, from, to, "azimuth"|"elevation", rad, σ rad)``."""
    rows, tags, head, kind = [], ModelTags(), None, "slope distances"
    for n, line in enumerate(read_text(obs_path).splitlines(), 1):
        s = line.strip()
        if s.startswith("#"):
            body = s[1:].strip()
            if body.startswith(HEAD_TAG):
                if head is not None or len(body[len(HEAD_TAG):].split()) != 1:
                    raise MultilatError(f"{obs_path}:{n}: one '{HEAD_TAG} ID' line per file (one file = one "
                                        "JAG3D group = one head)")
                head = body[len(HEAD_TAG):].strip()
            elif body.startswith(TYPE_TAG):
                kind = body[len(TYPE_TAG):].strip()
                if kind not in _TYPES or rows:
                    raise MultilatError(f"{obs_path}:{n}: {TYPE_TAG} {kind!r}: expected one of "
                                        f"{', '.join(_TYPES)}, before the first observation")
            else:
                tags.read(f"{obs_path}:{n}", body)
            continue
        if s:
            rows.append(_distance_row(obs_path, n, s, sigma_m) if kind == "slope distances" else
                        _angle_row(obs_path, n, s, kind))
    if kind != "slope distances":
        if head is not None or tags.where:
            raise MultilatError(f"{obs_path}: a file of {kind} has no head, offsets or scales lines")
        return kind, rows, None
    if head is not None:
        if tags.heads is not None:
            raise MultilatError(f"{tags.where['heads']}: a heads line beside '{HEAD_TAG} {head}'")
        tags.heads = {r[1]: head for r in rows}
        tags.where["heads"] = str(obs_path)
    return (kind, *restore_model(obs_path, rows, tags, notes))


def _angle_row(path, n, s, kind):
    """``FROM TO VALUE SIGMA`` in gon: a direction (clockwise, read as ``-azimuth``) or a zenith angle."""
    tok = s.split()
    if len(tok) != 4:
        raise MultilatError(f"{path}:{n}: expected FROM TO VALUE SIGMA ({kind}, gon; instrument heights are "
                            f"not in multilat's model), got {len(tok)} fields")
    v, sg = (_number(path, n, t, w) * math.pi / 200.0 for t, w in ((tok[2], "value"), (tok[3], "σ")))
    if not 0 < sg < math.pi / 200.0:
        raise MultilatError(f"{path}:{n}: σ {tok[3]} of {tok[0]}->{tok[1]} must be > 0 and < 1 gon (JAG3D reads "
                            "a larger number as a distance)")
    if kind == "directions":
        return (n, tok[0], tok[1], "azimuth", (-v + math.pi) % (2 * math.pi) - math.pi, sg)
    if not 0.0 <= v <= math.pi:
        raise MultilatError(f"{path}:{n}: zenith angle {tok[0]}->{tok[1]} is outside 0..200 gon")
    return (n, tok[0], tok[1], "elevation", math.pi / 2 - v, sg)


def _distance_row(obs_path, n, s, sigma_m):
    tok = s.split()
    if not 3 <= len(tok) <= 6:
        raise MultilatError(f"{obs_path}:{n}: expected FROM TO [IH TH] VALUE [SIGMA], got "
                            f"{len(tok)} fields")
    a, b = tok[0], tok[1]
    v = [_number(obs_path, n, t, "field " + str(i + 3)) for i, t in enumerate(tok[2:])]
    if len(v) >= 3:
        ih, th, d = v[0], v[1], v[2]
        if ih or th:
            raise MultilatError(f"{obs_path}:{n}: instrument/target heights {ih}/{th} are not "
                                "supported (not in multilat's model): give 0 0")
        extra = v[3] if len(v) == 4 else None
    else:
        d, extra = v[0], (v[1] if len(v) == 2 else None)
    sig = extra if extra is not None and extra < 1.0 else None
    if sig is None:
        if sigma_m is None:
            raise MultilatError(f"{obs_path}:{n}: distance {a}->{b} has no σ (give --sigma-um)")
        sig = sigma_m
    return (n, a, b, d, sig)
