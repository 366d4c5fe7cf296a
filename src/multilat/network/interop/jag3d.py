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
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from multilat.errors import MultilatError
from multilat.io import write_text_atomic
from multilat.network.data import Observations, Points
from multilat.network.interop.common import (SIGMA_DECIMALS, ModelTags, Network, apply_offsets, build_network,
                                              OFFSETS_TAG, SCALES_TAG, check_ids, fmt_m, read_text,
                                              refuse_weighted_points, restore_model, station_values)

__all__ = ["jag3d_texts", "write_jag3d", "read_jag3d", "head_file"]

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
    pts = ["# multilat points: NAME Y X Z = multilat x y z (east, north, up), metres"]
    if points is not None:
        for i, xyz in zip(points.ids, points.xyz_m):
            pts.append(f"{i} {fmt_m(xyz[0])} {fmt_m(xyz[1])} {fmt_m(xyz[2])}")
    return "\n".join(pts) + "\n", texts


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


def write_jag3d(points_path, obs_path, obs: Observations, points: Points | None, **kw) -> list[Path]:
    """Write the points file and the distances file(s) (each atomically): ``obs_path``, or with
    heads over several stations one file per head (:func:`head_file`). Returns the distance files."""
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
    """Read JAG3D flat files: points (``NAME Y X Z [σ..]``) and slope distances (``obs_path``: one
    file or a sequence of files, e.g. one per head). ``sigma_m``: σ for distances that have none in
    the file (else an error naming the line). A file marked ``# multilat-head: T1`` holds the
    distances of head T1 (one JAG3D group); the stations of an unmarked file are their own heads."""
    coords, declared, notes = _read_points(points_path)
    paths = [obs_path] if isinstance(obs_path, (str, Path)) else list(obs_path)
    rows, heads, where = [], {}, {}
    for path in paths:
        f_rows, f_heads = _read_distances(path, sigma_m, notes)
        for r in f_rows:
            h = (f_heads or {}).get(r[1], r[1])
            if heads.setdefault(r[1], h) != h:
                raise MultilatError(f"{path}:{r[0]}: station {r[1]!r} is on head {h!r} here and on head "
                                    f"{heads[r[1]]!r} in {where[r[1]]}: one station, one head")
            where.setdefault(r[1], path)
        rows += [(f"{path}:{n}", a, b, d, sg) for n, a, b, d, sg in f_rows]
    shared = any(h != s for s, h in heads.items())
    return build_network(None, rows, declared, coords, (), notes, "JAG3D points", heads if shared else None)


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


def _read_distances(obs_path, sigma_m, notes):
    """The rows ``(line, from, to, d, σ)`` of one distances file, restored by its convention lines,
    and its heads (station -> head; None when the file names no head)."""
    rows, tags, head = [], ModelTags(), None
    for n, line in enumerate(read_text(obs_path).splitlines(), 1):
        s = line.strip()
        if s.startswith("#"):
            body = s[1:].strip()
            if body.startswith(HEAD_TAG):
                if head is not None or len(body[len(HEAD_TAG):].split()) != 1:
                    raise MultilatError(f"{obs_path}:{n}: one '{HEAD_TAG} ID' line per file (one file = one "
                                        "JAG3D group = one head)")
                head = body[len(HEAD_TAG):].strip()
            else:
                tags.read(f"{obs_path}:{n}", body)
            continue
        if not s:
            continue
        rows.append(_distance_row(obs_path, n, s, sigma_m))
    if head is not None:
        if tags.heads is not None:
            raise MultilatError(f"{tags.where['heads']}: a heads line beside '{HEAD_TAG} {head}'")
        tags.heads = {r[1]: head for r in rows}
        tags.where["heads"] = str(obs_path)
    return restore_model(obs_path, rows, tags, notes)


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
