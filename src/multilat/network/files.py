"""Network file formats: observations, reference lengths and points CSVs (read), results (write).

Observations CSV (one row per measured distance)::

    station,target,distance_m[,sigma_m][,azimuth_rad,elevation_rad]

Reference lengths CSV::  ``target_a,target_b,length_m[,u_m]``
Points CSV::             ``point,x_m,y_m,z_m``

Unknown columns give a warning; every bad cell or row is an error ``FILE:LINE: message``.
Result files are written whole or not at all (:mod:`multilat.io` atomic helpers).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from multilat.errors import MultilatError
from multilat.io import ELEVATION_RANGE, read_csv_table, write_csv_atomic
from multilat.network.data import Observations, Points, ReferenceLengths
from multilat.network.screening import screen_observations

__all__ = ["read_observations", "read_reference_lengths", "read_points", "write_result_csvs"]

OBS_REQUIRED = ("station", "target", "distance_m")
OBS_OPTIONAL = ("sigma_m", "azimuth_rad", "elevation_rad")


def _check_ids(tab, col):
    vals = tab.column(col)
    for k, v in enumerate(vals):
        if v == "":
            raise tab.error(k, f"column '{col}': empty id")
    return vals


def read_observations(path: str | os.PathLike, *, sigma_m: float | None = None,
                      instrument=None, sigma_source: dict | None = None) -> Observations:
    """Read an observations CSV.

    Parameters
    ----------
    path : path of the CSV
    sigma_m : float, optional
        A-priori standard uncertainty (metres) for every distance when the file has no ``sigma_m``
        column (ignored otherwise, with a warning).
    instrument : Instrument or preset name/path, optional
        When the file has no ``sigma_m`` column and ``sigma_m`` is not given, each distance's
        uncertainty comes from the distance model :func:`multilat.budget.distance_std_m` of this
        instrument (default preset ``"seed2020"``), with the station id as head name when the
        instrument has such a head (else head ``"A"``).
    sigma_source : dict, optional
        Filled with where σ came from (:mod:`multilat.network.sigma_source`).

    Returns
    -------
    Observations
    """
    tab = read_csv_table(path, required=OBS_REQUIRED, optional=OBS_OPTIONAL)
    st = _check_ids(tab, "station")
    tg = _check_ids(tab, "target")
    d = tab.floats("distance_m", positive=True)
    seen: dict[tuple[str, str], int] = {}
    for k, key in enumerate(zip(st, tg)):
        if key in seen:
            raise tab.error(k, f"duplicate observation {key[0]}->{key[1]} (first at line "
                               f"{tab.line_numbers[seen[key]]}); average repeated measurements into one row")
        seen[key] = k
    both = set(st) & set(tg)
    if both:
        v = sorted(both)[0]
        k = st.index(v)
        raise tab.error(k, f"id {v!r} is used both as a station and as a target")
    az = el = None
    if tab.has("azimuth_rad") != tab.has("elevation_rad"):
        raise MultilatError(f"{path}: give both azimuth_rad and elevation_rad columns, or neither")
    if tab.has("azimuth_rad"):
        az = tab.floats("azimuth_rad", required=False)
        el = tab.floats("elevation_rad", required=False, within=ELEVATION_RANGE)
    if tab.has("sigma_m"):
        sig = tab.floats("sigma_m", positive=True)
        _record(sigma_source, "column", path)
        if sigma_m is not None:
            import warnings
            warnings.warn(f"{path}: using the file's sigma_m column, ignoring the sigma option",
                          UserWarning, stacklevel=2)
    elif sigma_m is not None:
        if not (np.isfinite(sigma_m) and sigma_m > 0):
            raise MultilatError(f"sigma must be finite and > 0, got {sigma_m!r}")
        sig = np.full(d.shape, float(sigma_m))
        _record(sigma_source, "option", sigma_m)
    else:
        sig = _model_sigma(d, st, instrument)
        _record(sigma_source, "model", st, instrument)
    obs = Observations.from_labels(st, tg, d, sig, azimuth_rad=az, elevation_rad=el)
    screen_observations(obs, source=str(tab.path), line_numbers=tab.line_numbers)
    return obs


def _record(out, kind, *args):
    if out is not None:
        from multilat.network import sigma_source as ss

        out.update({"column": ss.file_column, "option": ss.option, "model": ss.distance_model}[kind](*args))


def _model_sigma(d, stations, instrument):
    try:
        from multilat import budget, instrument as instr
    except ImportError:
        raise MultilatError("the observations have no sigma_m column: give --sigma-um (the distance "
                            "model is not available)") from None
    inst = instr.load_instrument("seed2020" if instrument is None else instrument) \
        if isinstance(instrument, (str, os.PathLike, type(None))) else instrument
    out = np.empty_like(d)
    stations = np.asarray(stations)
    for sid in dict.fromkeys(stations):
        head = sid
        try:
            inst.head(head)
        except Exception:
            head = "A"
        m = stations == sid
        out[m] = budget.distance_std_m(inst, d[m], head=head)
    return out


def read_reference_lengths(path: str | os.PathLike) -> ReferenceLengths:
    """Read ``target_a,target_b,length_m[,u_m]`` (u_m: standard uncertainty, metres)."""
    tab = read_csv_table(path, required=("target_a", "target_b", "length_m"), optional=("u_m",))
    a = _check_ids(tab, "target_a")
    b = _check_ids(tab, "target_b")
    L = tab.floats("length_m", positive=True)
    u = tab.floats("u_m", nonnegative=True, required=False) if tab.has("u_m") else np.full(L.shape, np.nan)
    seen = {}
    for k, (x, y) in enumerate(zip(a, b)):
        if x == y:
            raise tab.error(k, f"reference length from {x!r} to itself")
        key = frozenset((x, y))
        if key in seen:
            raise tab.error(k, f"duplicate reference length {x}-{y} (first at line "
                               f"{tab.line_numbers[seen[key]]})")
        seen[key] = k
    return ReferenceLengths(tuple(a), tuple(b), L, u, path=str(tab.path), line_numbers=tab.line_numbers)


def read_points(path: str | os.PathLike) -> Points:
    """Read ``point,x_m,y_m,z_m`` (approximate or control coordinates, metres)."""
    tab = read_csv_table(path, required=("point", "x_m", "y_m", "z_m"))
    ids = _check_ids(tab, "point")
    seen = {}
    for k, i in enumerate(ids):
        if i in seen:
            raise tab.error(k, f"duplicate point {i!r} (first at line {tab.line_numbers[seen[i]]})")
        seen[i] = k
    xyz = np.column_stack([tab.floats(c) for c in ("x_m", "y_m", "z_m")])
    return Points(tuple(ids), xyz)


def write_result_csvs(result, out_dir: str | os.PathLike, *, references=None) -> list[Path]:
    """Write ``stations.csv``, ``targets.csv``, ``residuals.csv`` (and ``reference_lengths.csv``)
    into ``out_dir``, each file atomically. Returns the paths written."""
    out = Path(out_dir)
    written = []
    (s_ax, _), (t_ax, _) = result.ellipsoids()
    p = out / "stations.csv"
    write_csv_atomic(p, ["station", "x_m", "y_m", "z_m", "offset_m", "u_x_m", "u_y_m", "u_z_m",
                         "u_offset_m", "offset_estimated", "ell95_a_m", "ell95_b_m", "ell95_c_m"],
                     [[sid, *result.station_xyz_m[i], result.offset_m[i],
                       *np.sqrt(np.clip(np.diag(result.station_cov_m2[i]), 0, None)),
                       result.offset_std_m[i], bool(result.offset_estimated[i]), *s_ax[i][::-1]]
                      for i, sid in enumerate(result.station_ids)])
    written.append(p)
    p = out / "targets.csv"
    write_csv_atomic(p, ["target", "x_m", "y_m", "z_m", "u_x_m", "u_y_m", "u_z_m",
                         "ell95_a_m", "ell95_b_m", "ell95_c_m"],
                     [[tid, *result.target_xyz_m[j],
                       *np.sqrt(np.clip(np.diag(result.target_cov_m2[j]), 0, None)), *t_ax[j][::-1]]
                      for j, tid in enumerate(result.target_ids)])
    written.append(p)
    o = result.obs
    p = out / "residuals.csv"
    write_csv_atomic(p, ["station", "target", "distance_m", "sigma_m", "residual_m", "redundancy", "w",
                         "mdb_m", "used"],
                     [[o.station_ids[o.station_index[k]], o.target_ids[o.target_index[k]], o.distance_m[k],
                       o.sigma_m[k], result.residuals_m[k], result.redundancy[k], result.w[k],
                       result.mdb_m[k], bool(result.used[k])] for k in range(o.n_obs)])
    written.append(p)
    if references is not None:
        p = out / "reference_lengths.csv"
        write_csv_atomic(p, ["target_a", "target_b", "length_m", "u_m", "reference_m", "reference_u_m",
                             "difference_m"],
                         [[c.target_a, c.target_b, c.length_m, c.u_m, c.reference_m,
                           "" if c.reference_u_m is None else c.reference_u_m, c.difference_m]
                          for c in result.compare_references(references)])
        written.append(p)
    return written
