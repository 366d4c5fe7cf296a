"""Raw instrument readings of a measurement campaign: the file format and its strict reader.

A raw file holds one row per distance reading, before any correction (see ``docs/campaign.md``)::

    station,target,time,optical_path_m,elevation_rad,target_elevation_rad
    A,P1,2020-03-10T09:00:00,4.123456789,0.0123,0.0101

Columns
-------
``station, target`` (required)
    Identifiers of the station (a position of a head) and the target.
``head`` (optional)
    The measurement head of the instrument that stood on the station (default: the station id),
    e.g. ``A``..``D`` for ``seed2020``, or any name when the instrument has a ``[heads.default]``
    block or maps the name to a head type. One station, one head; one head, any number of stations
    (its offset is then one unknown for all of them).
``optical_path_m``
    The distance computed *in vacuum* (group index ``n = 1``): ``L = (1/2)(Φ/2π + k) c/f``.
``phase_rad, frequency_hz[, k]``
    Eq. (1) of seed 000: ``Φ`` in ``[0, 2π)``, the modulation frequency ``f > 0`` and the integer
    number of synthetic half-wavelengths ``k >= 0``. An empty/missing ``k`` is resolved from
    ``approx_distance_m`` (a coarse distance in air, good to better than half the ambiguity
    ``c/(2 n f)``, i.e. 15 mm at 4895 MHz; :func:`multilat.adm.resolve_integer` with a nominal group
    index 1.00027); without it the row is an error.
    Every row needs either ``optical_path_m`` or ``phase_rad``/``frequency_hz`` (not both).
``time`` (optional)
    ISO 8601 (``2020-03-10T09:00:00``, ``...+01:00``, ``...Z``); a time without zone is UTC.
``elevation_rad, target_elevation_rad`` (optional)
    Elevation angles of the head and of the target, in the convention of
    :func:`multilat.gimbal.transit_offset_correction` (eq. 2); used for the transit-offset
    corrections. ``azimuth_rad`` (optional) is passed through to the observation file.
``temperature_c, pressure_hpa, humidity_pct[, co2_ppm]`` (optional, all or none)
    Per-row environment (one sensor), used when no environment log is given.
``station_height_m, target_height_m`` (optional)
    Heights of the beam ends in the environment sensors' vertical frame (needed with sensors at
    several heights, unless a heights file is given).
"""

from __future__ import annotations

import datetime as _dt
import math
import os
from dataclasses import dataclass

import numpy as np

from multilat import adm
from multilat.errors import MultilatError
from multilat.io import ELEVATION_RANGE, CsvTable, read_csv_table

__all__ = ["RawObservations", "read_raw", "is_raw_file", "parse_time", "format_time",
           "ENV_COLUMNS", "RAW_COLUMNS", "SPEED_OF_LIGHT_M_S"]

SPEED_OF_LIGHT_M_S = adm.C_M_PER_S
#: Air group index assumed when resolving ``k`` from a coarse distance in air (typical lab air at
#: 1550 nm; a 3e-5 departure moves a 100 m coarse distance by 3 mm, well inside half an ambiguity).
NOMINAL_GROUP_INDEX = 1.00027
ENV_COLUMNS = ("temperature_c", "pressure_hpa", "humidity_pct", "co2_ppm")
RAW_COLUMNS = ("station", "target", "head", "time", "optical_path_m", "phase_rad", "frequency_hz", "k",
               "approx_distance_m", "elevation_rad", "target_elevation_rad", "azimuth_rad",
               *ENV_COLUMNS, "station_height_m", "target_height_m")

# validity ranges of the environment readings (those of multilat.air, in the file's units)
ENV_RANGES = {"temperature_c": (-40.0, 100.0), "pressure_hpa": (100.0, 1400.0),
              "humidity_pct": (0.0, 100.0), "co2_ppm": (0.0, 2000.0)}


def parse_time(text: str) -> float:
    """ISO 8601 time -> POSIX seconds (float). A time without zone is taken as UTC.

    Raises :class:`ValueError` (callers add the row) when ``text`` does not parse.
    """
    s = text.strip()
    if not s:
        raise ValueError("empty time")
    t = _dt.datetime.fromisoformat(s)
    if t.tzinfo is None:
        t = t.replace(tzinfo=_dt.timezone.utc)
    return t.timestamp()


def format_time(seconds: float) -> str:
    """POSIX seconds -> ISO 8601 UTC text (``2020-03-10T09:00:00Z``), for messages and files."""
    t = _dt.datetime.fromtimestamp(float(seconds), tz=_dt.timezone.utc)
    txt = t.isoformat(timespec="milliseconds" if seconds % 1 else "seconds")
    return txt.replace("+00:00", "Z")


@dataclass(frozen=True)
class RawObservations:
    """Raw distance readings, one per row (``m`` rows). Absent values are NaN, absent columns None.

    Attributes
    ----------
    path : str
        Source (for messages); ``line_numbers[i]`` is the file line of row ``i``.
    station_ids, target_ids : tuple of str, length m
    optical_path_m : ndarray (m,)
        Vacuum distance ``L`` (n = 1), metres; for phase rows it is computed from eq. (1).
    phase_rad, frequency_hz, k : ndarray (m,)
        Eq. (1) inputs (NaN on optical-path rows); ``k`` resolved.
    time_s : ndarray (m,) or None
        POSIX seconds.
    elevation_rad, target_elevation_rad, azimuth_rad : ndarray (m,) or None
    environment : dict[str, ndarray (m,)] or None
        Per-row readings keyed by :data:`ENV_COLUMNS` (``co2_ppm`` may be absent).
    station_height_m, target_height_m : ndarray (m,) or None
    head_ids : tuple of str, length m, or None
        The head of each row (None: the station id).
    """

    path: str
    line_numbers: tuple[int, ...]
    station_ids: tuple[str, ...]
    target_ids: tuple[str, ...]
    optical_path_m: np.ndarray
    phase_rad: np.ndarray
    frequency_hz: np.ndarray
    k: np.ndarray
    time_s: np.ndarray | None
    elevation_rad: np.ndarray | None
    target_elevation_rad: np.ndarray | None
    azimuth_rad: np.ndarray | None
    environment: dict | None
    station_height_m: np.ndarray | None
    target_height_m: np.ndarray | None
    head_ids: tuple[str, ...] | None = None

    @property
    def size(self) -> int:
        return len(self.station_ids)

    @property
    def heads(self) -> tuple[str, ...]:
        """The head of each row (the station id where no head column was given)."""
        return self.station_ids if self.head_ids is None else self.head_ids

    def where(self, i: int) -> str:
        """``"FILE:LINE"`` of row ``i`` for error messages."""
        return f"{self.path}:{self.line_numbers[i]}"


def _header(path) -> tuple[str, ...] | None:
    from multilat.io import read_input_head

    try:
        text = read_input_head(path).decode("utf-8-sig", errors="replace")
    except MultilatError:
        return None          # the reader proper reports the problem
    for line in text.splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            return tuple(c.strip() for c in line.strip().split(","))
    return None


def is_raw_file(path: str | os.PathLike) -> bool:
    """True if ``path`` is a raw-reading file (header sniffing, no full parse).

    A raw file has ``station`` and ``target`` and ``optical_path_m`` or ``phase_rad``, and no
    ``distance_m`` (which marks an already corrected observation file).
    """
    h = _header(path)
    if h is None:
        return False
    cols = set(h)
    return ({"station", "target"} <= cols and ("optical_path_m" in cols or "phase_rad" in cols)
            and "distance_m" not in cols)


def _opt_floats(t: CsvTable, name: str, **kw) -> np.ndarray | None:
    return t.floats(name, **kw) if t.has(name) else None


#: numeric columns checked on each row as it is read (their range: below, with the whole file)
_RAW_NUMBERS = ("optical_path_m", "phase_rad", "frequency_hz", "k", "approx_distance_m")


def _resolve_paths(opt, phase, freq, kk, approx, where) -> None:
    """Check each row's reading and complete it in place: an optical path as given (> 0), or one
    from the phase, frequency and integer ``k`` (resolved from ``approx`` where ``k`` is missing).
    ``where(i)`` names row ``i`` in the errors."""
    m = len(opt)
    for i in range(m):
        if not np.isnan(opt[i]):
            if not np.isnan(phase[i]):
                raise MultilatError(f"{where(i)}: give optical_path_m or phase_rad, not both")
            if not opt[i] > 0:
                raise MultilatError(f"{where(i)}: column 'optical_path_m': must be > 0, got {float(opt[i])!r}")
            continue
        if np.isnan(phase[i]):
            raise MultilatError(f"{where(i)}: neither optical_path_m nor phase_rad given")
        if not 0.0 <= phase[i] < 2 * math.pi:
            raise MultilatError(f"{where(i)}: column 'phase_rad': must be in [0, 2π), got {float(phase[i])!r}")
        if np.isnan(freq[i]) or not freq[i] > 0:
            raise MultilatError(f"{where(i)}: column 'frequency_hz': must be > 0, got {float(freq[i])!r}")
        if np.isnan(kk[i]):
            if np.isnan(approx[i]):
                raise MultilatError(f"{where(i)}: k missing and no approx_distance_m to resolve it")
            if not approx[i] > 0:
                raise MultilatError(f"{where(i)}: column 'approx_distance_m': must be > 0")
            try:
                kk[i] = float(adm.resolve_integer(phase[i], approx[i], freq[i], NOMINAL_GROUP_INDEX))
            except MultilatError as exc:
                raise MultilatError(f"{where(i)}: {exc}") from None
        elif kk[i] < 0 or kk[i] != round(kk[i]):
            raise MultilatError(f"{where(i)}: column 'k': must be an integer >= 0, got {float(kk[i])!r}")
        opt[i] = float(adm.distance_from_phase(phase[i], int(kk[i]), freq[i], 1.0))
        if not opt[i] > 0:
            raise MultilatError(f"{where(i)}: phase and k give a zero distance")


def _row_times(t, where) -> np.ndarray:
    """The ``time`` column as seconds (ISO 8601, :func:`parse_time`)."""
    m = len(t.rows)
    col = t.column("time")
    time_s = np.empty(m)
    for i, s in enumerate(col):
        try:
            time_s[i] = parse_time(s)
        except ValueError:
            raise MultilatError(f"{where(i)}: column 'time': not an ISO 8601 time: {s!r}") from None
    return time_s


def read_raw(path: str | os.PathLike) -> RawObservations:
    """Read and validate a raw-reading file (format in the module docstring).

    Every bad cell raises :class:`MultilatError` ``"FILE:LINE: ..."`` naming the row: a phase
    outside ``[0, 2π)``, a frequency ``<= 0``, a non-integer or negative ``k``, a ``k`` that cannot
    be resolved, a time that does not parse, an environment reading outside its range (humidity
    over 100 %), a row with both or neither of optical path and phase.
    """
    t = read_csv_table(path, required=("station", "target"), optional=RAW_COLUMNS, kind="observations",
                       numbers={c: dict(required=False) for c in _RAW_NUMBERS})
    m = len(t.rows)
    where = lambda i: f"{t.path}:{t.line_numbers[i]}"  # noqa: E731
    stations = tuple(t.column("station"))
    targets = tuple(t.column("target"))
    for i in range(m):
        if not stations[i] or not targets[i]:
            raise MultilatError(f"{where(i)}: empty station or target id")
    heads = None
    if t.has("head"):
        heads = tuple(h if h else s_ for h, s_ in zip(t.column("head"), stations))
        first: dict[str, int] = {}
        for i, (s_, h) in enumerate(zip(stations, heads)):
            k = first.setdefault(s_, i)
            if heads[k] != h:
                raise MultilatError(f"{where(i)}: station {s_!r} has head {h!r} here but {heads[k]!r} at "
                                    f"line {t.line_numbers[k]} (one head per station)")

    has_opt, has_phase = t.has("optical_path_m"), t.has("phase_rad")
    if not (has_opt or has_phase):
        raise MultilatError(f"{t.path}: header needs optical_path_m or phase_rad,frequency_hz")
    if has_phase and not t.has("frequency_hz"):
        raise MultilatError(f"{t.path}: column phase_rad needs a frequency_hz column")
    nan = np.full(m, np.nan)
    opt = t.floats("optical_path_m", required=False) if has_opt else nan.copy()
    phase = t.floats("phase_rad", required=False) if has_phase else nan.copy()
    freq = t.floats("frequency_hz", required=False) if has_phase else nan.copy()
    kk = t.floats("k", required=False) if t.has("k") else nan.copy()
    approx = t.floats("approx_distance_m", required=False) if t.has("approx_distance_m") else nan.copy()

    _resolve_paths(opt, phase, freq, kk, approx, where)

    time_s = _row_times(t, where) if t.has("time") else None

    env = None
    present = [c for c in ENV_COLUMNS if t.has(c)]
    if present:
        need = ENV_COLUMNS[:3]
        missing = [c for c in need if c not in present]
        if missing:
            raise MultilatError(f"{t.path}: per-row environment needs {', '.join(need)}; "
                                f"missing {', '.join(missing)}")
        env = {c: t.floats(c) for c in present}
        check_environment_ranges(env, where)

    return RawObservations(
        path=t.path, line_numbers=t.line_numbers, station_ids=stations, target_ids=targets,
        optical_path_m=opt, phase_rad=phase, frequency_hz=freq, k=kk, time_s=time_s,
        elevation_rad=_opt_floats(t, "elevation_rad", within=ELEVATION_RANGE),
        target_elevation_rad=_opt_floats(t, "target_elevation_rad", within=ELEVATION_RANGE),
        azimuth_rad=_opt_floats(t, "azimuth_rad"),
        environment=env,
        station_height_m=_opt_floats(t, "station_height_m"),
        target_height_m=_opt_floats(t, "target_height_m"), head_ids=heads)


def check_environment_ranges(env: dict, where) -> None:
    """Raise ``"<where(i)>: column 'x': ..."`` for the first reading outside :data:`ENV_RANGES`."""
    for c, arr in env.items():
        lo, hi = ENV_RANGES[c]
        bad = np.flatnonzero((arr < lo) | (arr > hi))
        if bad.size:
            i = int(bad[0])
            raise MultilatError(f"{where(i)}: column '{c}': {float(arr[i]):g} outside [{lo:g}, {hi:g}]")
