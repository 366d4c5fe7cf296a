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

The per-instrument additive constant: JAG3D gives every observation group one zero-point offset
(``SlopeDistanceGroup``) and, with the import option "separate groups by station", makes one group
per station; the writer therefore lists the distances station by station and, when the offsets
are to be estimated, says in the file's header to enable each group's zero-point offset. Fixed
offsets are subtracted (as for the other formats) and recorded as ``# multilat-offsets-m: ..``,
which the reader adds back.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
import re

import numpy as np

from multilat.errors import MultilatError
from multilat.io import write_text_atomic
from multilat.network.data import Observations, Points
from multilat.network.interop.common import (SIGMA_DECIMALS, Network, apply_offsets, build_network,
                                              check_ids, fmt_m, read_text, restore_offsets)

__all__ = ["jag3d_texts", "write_jag3d", "read_jag3d"]

_OFFSETS_TAG = "# multilat-offsets-m:"


def jag3d_texts(obs: Observations, points: Points | None, *, offsets=None) -> tuple[str, str]:
    """(points file text, slope-distances file text). ``offsets``: None/"estimate" (JAG3D
    estimates one zero-point offset per group = per station) or fixed values (subtracted)."""
    check_ids(obs, points, "jag3d", forbid=";")
    missing = [i for i in obs.station_ids + obs.target_ids if points is None or points.get(i) is None]
    if missing:
        raise MultilatError(f"jag3d: point {missing[0]!r} has no coordinates; JAG3D's point groups "
                            "need every point (give --points covering every point)")
    estimate = offsets is None or (isinstance(offsets, str) and offsets == "estimate")
    head = ["# multilat network: slope distances for JAG3D's flat-file import (metres)",
            "# import with the option 'separate groups by station': one group per station = one "
            "instrument"]
    if estimate:
        head.append("# enable the additional parameter 'zero point offset' in every group: "
                    "multilat's per-station additive offset")
        corrected = obs
    else:
        corrected, notes = apply_offsets(obs, offsets, "JAG3D")
        o = [offsets[s] if isinstance(offsets, Mapping) else float(offsets) for s in obs.station_ids]
        head.append(_OFFSETS_TAG + " " + " ".join(f"{s}={fmt_m(v, 10)}"
                                                  for s, v in zip(obs.station_ids, o)))
        head += ["# " + n + " (keep the zero point offsets fixed at 0)" for n in notes]
    lines = list(head)
    for si in range(obs.n_stations):
        for k in np.flatnonzero(obs.station_index == si):
            sig = corrected.sigma_m[k]
            if not sig < 1.0:
                raise MultilatError(f"jag3d: σ of {obs.label(k)} is {sig} m: JAG3D reads a value "
                                    ">= 1 there as a distance, not a σ")
            lines.append(f"{obs.station_ids[si]} {obs.target_ids[obs.target_index[k]]} "
                         f"{fmt_m(corrected.distance_m[k])} {fmt_m(sig, SIGMA_DECIMALS)}")
    pts = ["# multilat points: NAME Y X Z = multilat x y z (east, north, up), metres"]
    if points is not None:
        for i, xyz in zip(points.ids, points.xyz_m):
            pts.append(f"{i} {fmt_m(xyz[0])} {fmt_m(xyz[1])} {fmt_m(xyz[2])}")
    return "\n".join(pts) + "\n", "\n".join(lines) + "\n"


def write_jag3d(points_path, obs_path, obs: Observations, points: Points | None, **kw) -> None:
    """Write the two import files (each atomically)."""
    p, o = jag3d_texts(obs, points, **kw)
    write_text_atomic(points_path, p)
    write_text_atomic(obs_path, o)


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
    """Read JAG3D flat files: points (``NAME Y X Z [σ..]``) and slope distances. ``sigma_m``: σ
    for distances that have none in the file (else an error naming the line)."""
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
    rows, offsets = [], None
    for n, line in enumerate(read_text(obs_path).splitlines(), 1):
        s = line.strip()
        if s.startswith(_OFFSETS_TAG):
            offsets = {}
            for item in s[len(_OFFSETS_TAG):].split():
                key, sep, val = item.partition("=")
                v = _number(obs_path, n, val, f"offset {key!r}") if sep else math.nan
                if not key or not math.isfinite(v):
                    raise MultilatError(f"{obs_path}:{n}: offsets item {item!r} is not ID=metres")
                offsets[key] = v
            continue
        if not s or s.startswith("#"):
            continue
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
        rows.append((n, a, b, d, sig))
    rows = restore_offsets(obs_path, rows, offsets, notes)
    return build_network(obs_path, rows, declared, coords, (), notes, "JAG3D points")
