"""Angle observations in the interchange formats: the levelled-station check of the writers, the
join of read angles to the distance rows, and degrees-minutes-seconds text.

Every format here (gama-local, JAG3D, Star*Net) models a horizontal direction as the bearing to the
target minus one orientation unknown per set and a zenith angle from the vertical: a **levelled**
instrument, multilat's ``levelled`` station (heading κ only). multilat's azimuth is counter-clockwise
from the instrument's x axis; a clockwise direction (JAG3D, Star*Net, Gama ``left-handed``) is its
negative, up to the orientation.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.data import Observations
from multilat.network.io.interop.common import Network

__all__ = ["angle_sigmas", "join_angles", "dms", "parse_dms", "refuse_tilted_result"]


def angle_sigmas(obs: Observations, fmt: str, tool: str) -> tuple[np.ndarray, np.ndarray]:
    """The σ of the azimuths and elevations that are observations (NaN elsewhere); an angle on a
    station that is not levelled is refused: ``tool``'s directions and zenith angles are read
    from a levelled instrument (one orientation unknown per station, the vertical known)."""
    nan = np.full(obs.n_obs, np.nan)
    sa = nan if obs.sigma_azimuth_rad is None else np.asarray(obs.sigma_azimuth_rad, float)
    se = nan if obs.sigma_elevation_rad is None else np.asarray(obs.sigma_elevation_rad, float)
    has = np.isfinite(sa) | np.isfinite(se)
    for k in np.flatnonzero(has):
        sid = obs.station_ids[obs.station_index[k]]
        if sid not in obs.levelled:
            raise MultilatError(f"{fmt}: station {sid!r} reads angles (observation {obs.label(int(k))}) but is "
                                f"not levelled: {tool}'s directions and zenith angles need a levelled "
                                f"instrument, and its tilt (ω, φ) has no counterpart in {tool} (declare it "
                                f"with --levelled {sid} only if it was levelled when it measured, or drop "
                                "its angle columns)")
    return sa, se


def _general_setups(par: dict) -> dict:
    """The set-ups' orientation in a general result's ``parameters`` (``omega:U``, ``phi:U``,
    ``kappa:U``) in the distance path's shape: ``{U: {parameters, orientation_rad,
    orientation_std_rad}}``."""
    out: dict = {}
    for key, v in par.items():
        name, _, setup = key.partition(":")
        if name in ("omega", "phi", "kappa"):
            st = out.setdefault(setup, {"parameters": [], "orientation_rad": [], "orientation_std_rad": []})
            st["parameters"].append(name)
            st["orientation_rad"].append(float(v["value"]))
            st["orientation_std_rad"].append(float(v["std"]))
    return out


def refuse_tilted_result(obs: Observations, directory, fmt: str) -> None:
    """Refuse (one line) a station exported as levelled whose adjustment in ``directory`` (the
    ``--out`` of ``multilat adjust``) estimated its tilt ω, φ: the format would hold it level, a
    different model from the one adjusted (nothing written)."""
    import json

    from multilat.io import decode_text, read_input_bytes

    path = Path(directory) / "result.json"
    if not obs.levelled or not path.is_file():
        return
    try:
        doc = json.loads(decode_text(read_input_bytes(path), path))
        stations = doc.get("stations") or _general_setups(doc.get("parameters") or {})
        tilted = {}
        for sid in obs.levelled:
            st = stations.get(sid) or {}
            par, ang, std = (list(st.get(k) or ()) for k in ("parameters", "orientation_rad", "orientation_std_rad"))
            free = [i for i, n in enumerate(par) if n in ("omega", "phi") and i < len(std) and std[i] > 0]
            if free:
                tilted[sid] = ", ".join(f"{par[i]} = {ang[i] * 1e6:.1f} ± {std[i] * 1e6:.1f} µrad" for i in free)
    except (ValueError, AttributeError, TypeError, IndexError) as exc:
        raise MultilatError(f"{path}: not the result of `multilat adjust` ({exc})") from None
    if tilted:                          # ω, φ with a standard deviation: unknowns of that adjustment
        sid, tilt = next(iter(tilted.items()))
        raise MultilatError(f"{fmt}: station {sid!r} is exported levelled (--levelled) but its adjustment in "
                            f"{path} estimated its tilt ({tilt}): {fmt} would hold it level, another model; "
                            f"adjust with --levelled {sid} first, or export it unlevelled")


def join_angles(path, network: Network, arows) -> Network:
    """The network's observations with the angles ``(line, station, target, "azimuth"|"elevation",
    value_rad, sigma_rad)`` joined to the slope distances of their rows; every station with angles
    is levelled. ``path`` None: the rows' ``line`` is already ``FILE:LINE``."""
    def at(line):
        return f"{path}:{line}" if path is not None else str(line)

    obs = network.obs
    row = {obs.label(k): k for k in range(obs.n_obs)}
    n = obs.n_obs
    val = {"azimuth": np.full(n, np.nan), "elevation": np.full(n, np.nan)}
    sig = {"azimuth": np.full(n, np.nan), "elevation": np.full(n, np.nan)}
    seen = {}
    for line, s, t, kind, v, sg in arows:
        k = row.get(f"{s}->{t}")
        if k is None:
            raise MultilatError(f"{at(line)}: {'direction' if kind == 'azimuth' else 'zenith angle'} {s}->{t} "
                                "has no slope distance: multilat's observation rows are distances with "
                                "optional angles")
        if (k, kind) in seen:
            raise MultilatError(f"{at(line)}: a second {kind} {s}->{t} (the first at line {seen[(k, kind)]})")
        seen[(k, kind)] = line
        val[kind][k], sig[kind][k] = v, sg
    # an azimuth without an elevation (or the reverse) on a row: the other stays an empty cell
    levelled = tuple(dict.fromkeys(s for _, s, _, _, _, _ in arows))
    angles = Observations(obs.station_ids, obs.target_ids, obs.station_index, obs.target_index, obs.distance_m,
                          obs.sigma_m, val["azimuth"], val["elevation"], obs.station_heads, sig["azimuth"],
                          sig["elevation"], levelled)
    note = (f"{int(np.isfinite(sig['azimuth']).sum())} directions and {int(np.isfinite(sig['elevation']).sum())} "
            f"zenith angles read as azimuths and elevations; levelled stations: {', '.join(levelled)}")
    return Network(angles, network.points, network.fixed, network.notes + (note,))


#: micro-arcseconds per degree: the resolution of :func:`dms` (1e-6" = 4.8e-12 rad)
_UAS_PER_DEG = 3600 * 10**6


def dms(a_rad: float) -> str:
    """``ddd-mm-ss.ssssss`` of an angle in [0, 360) degrees (rounded to 1e-6 arc seconds)."""
    uas = round(math.degrees(a_rad) * _UAS_PER_DEG) % (360 * _UAS_PER_DEG)
    d, rest = divmod(uas, _UAS_PER_DEG)
    m, rest = divmod(rest, 60 * 10**6)
    s, frac = divmod(rest, 10**6)
    return f"{d}-{m:02d}-{s:02d}.{frac:06d}"


_DMS = re.compile(r"^(\d+)-(\d{1,2})-(\d{1,2}(?:\.\d*)?)$")


def parse_dms(where: str, text: str) -> float:
    """Radians of ``d-m-s`` text (minutes and seconds < 60); anything else is an error ``where``."""
    m = _DMS.match(text)
    if not m or int(m.group(2)) >= 60 or float(m.group(3)) >= 60:
        raise MultilatError(f"{where}: angle {text!r} is not d-m-s (degrees-minutes-seconds, e.g. 12-34-56.789)")
    return math.radians(int(m.group(1)) + int(m.group(2)) / 60 + float(m.group(3)) / 3600)
