"""Network file formats: observations, reference lengths and points CSVs (read), results (write).

Observations CSV (one row per measured distance)::

    station,target,distance_m[,sigma_m][,head][,azimuth_rad,elevation_rad]

``head`` (optional): the measurement head on the station (default: the station id); one head per
station, any number of stations per head (offsets and scales belong to heads).

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
from multilat.io import ELEVATION_RANGE, read_csv_table, write_csv_atomic, write_table_atomic
from multilat.network.model.data import Observations, Points, ReferenceLengths
from multilat.network.io.screening import screen_observations

__all__ = ["read_observations", "read_reference_lengths", "read_points", "write_result_tables", "result_tables", "write_observations"]

OBS_REQUIRED = ("station", "target", "distance_m")
OBS_OPTIONAL = ("sigma_m", "head", "azimuth_rad", "elevation_rad", "zenith_rad", "sigma_azimuth_rad",
                "sigma_elevation_rad")
#: The checks of each numeric column of an observations file (:func:`multilat.inputs.number`),
#: applied to each row as it is read.
OBS_NUMBERS = {"distance_m": dict(positive=True), "sigma_m": dict(positive=True),
               "azimuth_rad": dict(required=False, within=(-2 * np.pi, 2 * np.pi, "±2π")),
               "elevation_rad": dict(required=False, within=ELEVATION_RANGE),
               "zenith_rad": dict(required=False, within=(0.0, np.pi, "[0, π]")),
               "sigma_azimuth_rad": dict(required=False, positive=True),
               "sigma_elevation_rad": dict(required=False, positive=True)}
REF_NUMBERS = {"length_m": dict(positive=True), "u_m": dict(nonnegative=True, required=False)}
POINT_STD = ("sx_m", "sy_m", "sz_m")
POINT_NUMBERS = {"x_m": {}, "y_m": {}, "z_m": {}, **{c: dict(required=False) for c in POINT_STD}}


def _head_column(tab, st):
    """The head of each row (the station where the cell is empty), or None without a head column;
    a station with two heads is refused at the row."""
    if not tab.has("head"):
        return None
    hd = [h if h else s_ for h, s_ in zip(tab.column("head"), st)]
    first: dict[str, int] = {}
    for k, (s_, h) in enumerate(zip(st, hd)):
        k0 = first.setdefault(s_, k)
        if hd[k0] != h:
            raise tab.error(k, f"station {s_!r} has head {h!r} here but {hd[k0]!r} at line "
                               f"{tab.line_numbers[k0]} (one head per station)")
    return hd


def _angle_columns(tab, path):
    """``(azimuth, elevation, σ azimuth, σ elevation)`` (rad; None where not given): elevation from
    ``elevation_rad`` or ``zenith_rad``, both angles or neither, a σ only beside its angle."""
    az = el = saz = sel = None
    if tab.has("elevation_rad") and tab.has("zenith_rad"):
        raise MultilatError(f"{path}: give elevation_rad or zenith_rad (zenith = π/2 − elevation), not both")
    has_el = tab.has("elevation_rad") or tab.has("zenith_rad")
    if tab.has("azimuth_rad") != has_el:
        raise MultilatError(f"{path}: give both azimuth_rad and elevation_rad (or zenith_rad) columns, or neither")
    if tab.has("azimuth_rad"):
        az = tab.floats("azimuth_rad", **OBS_NUMBERS["azimuth_rad"])
        if tab.has("zenith_rad"):
            el = np.pi / 2 - tab.floats("zenith_rad", **OBS_NUMBERS["zenith_rad"])
        else:
            el = tab.floats("elevation_rad", **OBS_NUMBERS["elevation_rad"])
    for name in ("sigma_azimuth_rad", "sigma_elevation_rad"):
        if tab.has(name):
            if az is None:
                raise MultilatError(f"{path}: column {name} without the angle columns (azimuth_rad, "
                                    "elevation_rad or zenith_rad)")
            v = tab.floats(name, **OBS_NUMBERS[name])
            ang = az if name == "sigma_azimuth_rad" else el
            miss = np.flatnonzero(np.isfinite(v) & ~np.isfinite(ang))
            if miss.size:
                raise tab.error(int(miss[0]), f"column '{name}': a σ for an empty angle")
            if name == "sigma_azimuth_rad":
                saz = v
            else:
                sel = v
    return az, el, saz, sel


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
        instrument (default preset ``"seed2020"``) for the row's head: the ``head`` column (which
        the instrument must know: its own block, ``head_map`` or ``[heads.default]``; else
        ``FILE:LINE: unknown head``), or without that column the station id when the instrument
        resolves it (else head ``"A"``).
    sigma_source : dict, optional
        Filled with where σ came from (:mod:`multilat.network.model.sigma_source`).

    Returns
    -------
    Observations
    """
    if _large_file(path):
        from multilat.network.io.fastio import plain_observations

        fast = plain_observations(path, sigma_m)       # None unless plain: then the checks below
        if fast is not None:
            _record(sigma_source, "column", path) if sigma_m is None else _record(sigma_source, "option", sigma_m)
            return fast
    tab = read_csv_table(path, required=OBS_REQUIRED, optional=OBS_OPTIONAL, numbers=OBS_NUMBERS,
                         kind="observations")
    st = tab.ids("station")
    tg = tab.ids("target")
    d = tab.floats("distance_m", **OBS_NUMBERS["distance_m"])
    hd = _head_column(tab, st)
    both = set(st) & set(tg)
    if both:
        v = sorted(both)[0]
        k = st.index(v)
        raise tab.error(k, f"id {v!r} is used both as a station and as a target")
    az, el, saz, sel = _angle_columns(tab, path)
    if tab.has("sigma_m"):
        sig = tab.floats("sigma_m", **OBS_NUMBERS["sigma_m"])
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
        sig = _model_sigma(d, st if hd is None else hd, instrument,
                           where=None if hd is None else tab.error)
        _record(sigma_source, "model", st, instrument, *(() if hd is None else (dict(zip(st, hd)),)))
    if az is not None and saz is None and sel is None and instrument is not None:
        saz, sel = _tracker_angle_sigma(d, st if hd is None else hd, az, el, instrument)
        if saz is not None and sigma_source is not None:
            sigma_source["angles"] = "laser trackers' transverse MPE × std_per_mpe over the range (instrument)"
    lev = ()
    if instrument is not None and az is not None:
        from multilat import instrument as _instr

        inst = _instr.load_instrument(instrument) if isinstance(instrument, (str, os.PathLike)) else instrument
        trk = getattr(inst, "trackers", {}) or {}
        names = st if hd is None else hd
        lev = tuple(dict.fromkeys(s_ for s_, h in zip(st, names) if h in trk and trk[h].levelled))
    obs = Observations.from_labels(st, tg, d, sig, azimuth_rad=az, elevation_rad=el, head=hd,
                                   sigma_azimuth_rad=saz, sigma_elevation_rad=sel, levelled=lev)
    screen_observations(obs, source=str(tab.path), line_numbers=tab.line_numbers)
    return obs


#: Regular files at least this large go through the vectorised reader first (:mod:`.fastio`), which
#: takes the plain subset of the format and leaves any other file to the checks here.
FAST_READ_ABOVE_BYTES = 1 << 20


def _large_file(path) -> bool:
    try:
        p = Path(path)
        return p.is_file() and p.stat().st_size >= FAST_READ_ABOVE_BYTES
    except OSError:
        return False


def _record(out, kind, *args):
    if out is not None:
        from multilat.network.model import sigma_source as ss

        out.update({"column": ss.file_column, "option": ss.option, "model": ss.distance_model}[kind](*args))


def _tracker_angle_sigma(d, heads, az, el, instrument):
    """The angles' σ of the rows read by a laser tracker of ``instrument`` (its transverse MPE over
    the range, :meth:`multilat.tracker.TrackerSpec.angle_sigma_rad`), when the file gives the angles but
    no σ columns; (None, None) when no row is a tracker's. Other rows' angles stay initial values only."""
    from multilat import instrument as instr

    inst = instr.load_instrument(instrument) if isinstance(instrument, (str, os.PathLike)) else instrument
    trk = getattr(inst, "trackers", {}) or {}
    heads = np.asarray(heads, dtype=object)
    if not any(h in trk for h in dict.fromkeys(heads)):
        return None, None
    saz = np.full(d.shape, np.nan)
    for hid in dict.fromkeys(heads):
        if hid in trk:
            m = (heads == hid) & np.isfinite(az) & np.isfinite(el)
            saz[m] = trk[hid].spec().angle_sigma_rad(d[m])
    return saz, saz.copy()


def _model_sigma(d, heads, instrument, *, where=None):
    """Each distance's sigma from the instrument's distance model for its head. ``heads`` (m,) are
    the head column (``where`` = the table's row error: an unknown head is ``FILE:LINE``) or, without
    one, the station ids (a station the instrument does not resolve falls back to head ``A``)."""
    try:
        from multilat import budget, instrument as instr
    except ImportError:
        raise MultilatError("the observations have no sigma_m column: give --sigma-um (the distance "
                            "model is not available)") from None
    inst = instr.load_instrument("seed2020" if instrument is None else instrument) \
        if isinstance(instrument, (str, os.PathLike, type(None))) else instrument
    out = np.empty_like(d)
    heads = np.asarray(heads, dtype=object)
    for hid in dict.fromkeys(heads):
        m = heads == hid
        head = hid
        if getattr(inst, "is_tracker", lambda _: False)(head):     # a laser tracker: its MPE form
            out[m] = inst.trackers[head].spec().distance_sigma_m(d[m])
            continue
        if not inst.has_head(head):
            if where is not None:
                k = int(np.flatnonzero(m)[0])
                try:
                    inst.head(head)
                except MultilatError as exc:
                    raise where(k, f"column 'head': {exc}") from None
            head = "A"
        out[m] = budget.distance_std_m(inst, d[m], head=head)
    return out


def read_reference_lengths(path: str | os.PathLike) -> ReferenceLengths:
    """Read ``target_a,target_b,length_m[,u_m]`` (u_m: standard uncertainty, metres)."""
    tab = read_csv_table(path, required=("target_a", "target_b", "length_m"), optional=("u_m",),
                         numbers=REF_NUMBERS)
    a = tab.ids("target_a")
    b = tab.ids("target_b")
    L = tab.floats("length_m", **REF_NUMBERS["length_m"])
    u = tab.floats("u_m", **REF_NUMBERS["u_m"]) if tab.has("u_m") else np.full(L.shape, np.nan)
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
    """Read ``point,x_m,y_m,z_m[,sx_m,sy_m,sz_m]`` (approximate or control coordinates, metres).

    The optional standard uncertainties make a row a **weighted** control point under the control
    datum (all three > 0 on the row); a row with them empty is hard control. A value <= 0, or a row
    with only some of them, is ``FILE:LINE: ...``.
    """
    tab = read_csv_table(path, required=("point", "x_m", "y_m", "z_m"), optional=POINT_STD,
                         numbers=POINT_NUMBERS)
    ids = tab.ids("point")
    seen = {}
    for k, i in enumerate(ids):
        if i in seen:
            raise tab.error(k, f"duplicate point {i!r} (first at line {tab.line_numbers[seen[i]]})")
        seen[i] = k
    xyz = np.column_stack([tab.floats(c) for c in ("x_m", "y_m", "z_m")])
    std = None
    if any(tab.has(c) for c in POINT_STD):
        if not all(tab.has(c) for c in POINT_STD):
            raise MultilatError(f"{tab.path}: give all of sx_m, sy_m, sz_m columns, or none")
        std = np.column_stack([tab.floats(c, required=False) for c in POINT_STD])
        for k in range(len(ids)):
            given = ~np.isnan(std[k])
            if given.any() and not given.all():
                raise tab.error(k, f"point {ids[k]!r}: give sx_m, sy_m and sz_m (weighted control) or none "
                                   "(hard control)")
            bad = np.flatnonzero(given & ~(std[k] > 0))
            if bad.size:
                c = POINT_STD[int(bad[0])]
                raise tab.error(k, f"column '{c}': a control point's standard uncertainty must be > 0, "
                                   f"got {float(std[k, bad[0]])!r}")
    return Points(tuple(ids), xyz, std)


def result_tables(result, *, references=None) -> dict[str, dict]:
    """The tables of an adjustment, each a dict of columns (arrays, ``(labels, index)``, or lists for
    the small ones): ``stations``, ``targets``, ``observations`` (every observation's row:
    :func:`multilat.network.io.result_rows.observation_columns`) and, with ``references``,
    ``reference_lengths`` (an empty reference σ is None). One definition for every table format."""
    (s_ax, _), (t_ax, _) = result.ellipsoids()
    su = np.sqrt(np.clip(np.diagonal(result.station_cov_m2, axis1=1, axis2=2), 0, None))
    sx = result.station_xyz_m
    tables = {"stations": {
        "station": list(result.station_ids), "x_m": sx[:, 0].tolist(), "y_m": sx[:, 1].tolist(),
        "z_m": sx[:, 2].tolist(), "offset_m": np.asarray(result.offset_m, float).tolist(),
        "x_std_m": su[:, 0].tolist(), "y_std_m": su[:, 1].tolist(), "z_std_m": su[:, 2].tolist(),
        "offset_std_m": np.asarray(result.offset_std_m, float).tolist(),
        "offset_estimated": [bool(x) for x in result.offset_estimated],
        "semi_axis_1_95_m": [float(a[2]) for a in s_ax], "semi_axis_2_95_m": [float(a[1]) for a in s_ax],
        "semi_axis_3_95_m": [float(a[0]) for a in s_ax], "head": list(result.obs.head_of_station)}}
    # per-target and per-observation tables: from the columns (millions of rows)
    tx, tu = result.target_xyz_m, np.sqrt(np.clip(np.diagonal(result.target_cov_m2, axis1=1, axis2=2), 0, None))
    tables["targets"] = {"target": (result.target_ids, np.arange(len(result.target_ids))),
                         "x_m": tx[:, 0], "y_m": tx[:, 1], "z_m": tx[:, 2], "x_std_m": tu[:, 0],
                         "y_std_m": tu[:, 1], "z_std_m": tu[:, 2], "semi_axis_1_95_m": t_ax[:, 2],
                         "semi_axis_2_95_m": t_ax[:, 1], "semi_axis_3_95_m": t_ax[:, 0]}
    from multilat.network.io.result_rows import observation_columns

    tables["observations"] = observation_columns(result)
    if references is not None:
        cmp = result.compare_references(references)
        tables["reference_lengths"] = {
            "target_a": [c.target_a for c in cmp], "target_b": [c.target_b for c in cmp],
            "length_m": [float(c.length_m) for c in cmp], "length_std_m": [float(c.u_m) for c in cmp],
            "reference_m": [float(c.reference_m) for c in cmp],
            "reference_std_m": [None if c.reference_u_m is None else float(c.reference_u_m) for c in cmp],
            "difference_m": [float(c.difference_m) for c in cmp]}
    return tables


def write_result_tables(result, out_dir: str | os.PathLike, *, references=None, fmt: str = "csv") -> list[Path]:
    """Write the tables of :func:`result_tables` into ``out_dir`` as ``stations.csv``, ``targets.csv``,
    ``observations.csv`` (and ``reference_lengths.csv``), or ``.parquet`` with ``fmt="parquet"``,
    each file atomically; ``fmt="auto"``: the observations table as Parquet when pyarrow is
    installed (CSV otherwise), the others as CSV. Returns the paths written."""
    out = Path(out_dir)
    return [write_table_atomic(out / name, cols, table_format(name, fmt))
            for name, cols in result_tables(result, references=references).items()]


def table_format(name: str, fmt: str) -> str:
    """The file format of table ``name`` under ``--tables fmt``: ``fmt`` itself, or for "auto" the
    observations table as parquet when pyarrow is installed (else csv) and the other tables as csv."""
    if fmt != "auto":
        return fmt
    import importlib.util

    return "parquet" if name == "observations" and importlib.util.find_spec("pyarrow") is not None else "csv"


def write_observations(path: str | os.PathLike, obs: Observations) -> None:
    """Write ``obs`` as the observations CSV that :func:`read_observations` reads (whole or not at all):
    ``station,target,distance_m,sigma_m``, then ``head`` when stations share heads, the angle columns
    when the observations carry angles, and their σ columns when any angle is an observation (empty
    cells where a value is absent). Levelled stations are not a column: give them to
    ``adjust --levelled``."""
    def cells(v):
        return ["" if not np.isfinite(x) else float(x) for x in np.asarray(v, float)]

    header = ["station", "target", "distance_m", "sigma_m"]
    cols = [[obs.station_ids[i] for i in obs.station_index], [obs.target_ids[j] for j in obs.target_index],
            cells(obs.distance_m), cells(obs.sigma_m)]
    if obs.station_heads is not None:
        header.append("head")
        cols.append([obs.station_heads[i] for i in obs.station_index])
    if obs.azimuth_rad is not None:
        header += ["azimuth_rad", "elevation_rad"]
        cols += [cells(obs.azimuth_rad), cells(obs.elevation_rad)]
    if obs.has_angle_observations:
        nan = np.full(obs.n_obs, np.nan)
        header += ["sigma_azimuth_rad", "sigma_elevation_rad"]
        cols += [cells(nan if obs.sigma_azimuth_rad is None else obs.sigma_azimuth_rad),
                 cells(nan if obs.sigma_elevation_rad is None else obs.sigma_elevation_rad)]
    write_csv_atomic(path, header, zip(*cols))
