"""The environment along each beam: sensor log, interpolation in time, vertical gradient in height.

Model (``docs/campaign.md`` gives the reasoning)
------------------------------------------------
- Each sensor ``s`` (fixed height ``z_s``) reports temperature, pressure, humidity (and CO2) at its
  own times. At an observation time ``t`` every sensor's reading is interpolated **linearly in
  time** between its two neighbouring readings. A time outside a sensor's span is refused, or with
  ``extrapolate=True`` extrapolated linearly from the two end readings (with a warning).
- **Several heights**: the temperature profile at time ``t`` is the least-squares line
  ``T(z) = T0 + g z`` through the sensors' interpolated temperatures. Averaged along a straight
  beam from height ``z_a`` to ``z_b`` a linear profile gives exactly its value at the mid-height
  ``(z_a + z_b)/2``; so the beam temperature is ``T(z_mid) = sum_s w_s T_s`` with the weights
  ``w = [1, z_mid] (AᵀA)⁻¹ Aᵀ``, ``A = [1, z_s]`` (they sum to 1). Pressure, humidity and CO2
  are averaged over the sensors (their vertical variation, ~0.12 hPa/m for pressure, i.e.
  0.03 µm/m per metre, is below the sensors' uncertainty).
- **One height** (one sensor, or several side by side): the mean of the sensors; beam heights are
  not needed.
- **Sensor uncertainty**: each sensor's reading of quantity ``q`` carries an unknown calibration
  error ``e_{s,q}``, constant over the campaign, independent between sensors and quantities, of
  standard uncertainty ``u_q`` (from the instrument config). Interpolation weights in time sum to 1,
  so the error passes unchanged to the interpolated reading, and then with weight ``w_s`` (or
  ``1/S``) to the beam value: the sensitivity matrix ``∂(beam value)/∂e`` is exact and shared by
  every observation a sensor serves, which makes the correlation explicit.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass

import numpy as np

from multilat.campaign.raw import ENV_COLUMNS, ENV_RANGES, check_environment_ranges, format_time, parse_time
from multilat.errors import MultilatError
from multilat.io import read_csv_table

__all__ = ["EnvironmentLog", "read_environment", "environment_from_rows", "BeamEnvironment",
           "beam_environment", "QUANTITIES"]

#: The quantities a sensor reports (CO2 optional in files; 450 ppm when absent).
QUANTITIES = ENV_COLUMNS
DEFAULT_CO2_PPM = 450.0


@dataclass(frozen=True)
class EnvironmentLog:
    """Sensor readings over time.

    Attributes
    ----------
    path : str
    sensor_ids : tuple of str, length S
    height_m : ndarray (S,)
        Sensor heights (NaN when the log gives none, allowed only for a single height).
    times_s : tuple of S ndarrays (k_s,)
        Reading times of each sensor, POSIX seconds, strictly increasing.
    readings : tuple of S dicts ``{quantity: ndarray (k_s,)}``
        Keys :data:`QUANTITIES` (``co2_ppm`` filled with 450 ppm when the log has no CO2 column).
    has_co2 : bool
    """

    path: str
    sensor_ids: tuple[str, ...]
    height_m: np.ndarray
    times_s: tuple
    readings: tuple
    has_co2: bool

    @property
    def span_s(self) -> tuple[float, float]:
        return (min(float(t[0]) for t in self.times_s), max(float(t[-1]) for t in self.times_s))

    @property
    def several_heights(self) -> bool:
        h = self.height_m[np.isfinite(self.height_m)]
        return h.size > 0 and float(np.ptp(h)) > 0.0


def read_environment(path: str | os.PathLike) -> EnvironmentLog:
    """Read an environment log ``time,sensor,height_m,temperature_c,pressure_hpa,humidity_pct[,co2_ppm]``.

    Rows may come in any order; each sensor must keep one height (which may be empty only when
    there is a single sensor), and no sensor may have two readings at the same time. Errors name
    ``FILE:LINE``.
    """
    t = read_csv_table(path, required=("time", "sensor", "height_m", "temperature_c", "pressure_hpa",
                                       "humidity_pct"), optional=("co2_ppm",))
    where = lambda i: f"{t.path}:{t.line_numbers[i]}"  # noqa: E731
    times = np.empty(len(t.rows))
    for i, s in enumerate(t.column("time")):
        try:
            times[i] = parse_time(s)
        except ValueError:
            raise MultilatError(f"{where(i)}: column 'time': not an ISO 8601 time: {s!r}") from None
    heights = t.floats("height_m", required=False)
    vals = {c: t.floats(c) for c in QUANTITIES if t.has(c)}
    check_environment_ranges(vals, where)
    sensors = t.column("sensor")
    ids: list[str] = []
    for i, s in enumerate(sensors):
        if not s:
            raise MultilatError(f"{where(i)}: empty sensor id")
        if s not in ids:
            ids.append(s)
    h_out, t_out, r_out = [], [], []
    sensors_arr = np.array(sensors, dtype=object)
    for s in ids:
        rows = np.flatnonzero(sensors_arr == s)
        hs = heights[rows]
        if np.any(np.isnan(hs)) and not np.all(np.isnan(hs)):
            i = int(rows[np.flatnonzero(np.isnan(hs))[0]])
            raise MultilatError(f"{where(i)}: sensor {s!r}: height_m missing here but given elsewhere")
        if not np.all(np.isnan(hs)) and np.any(hs != hs[0]):
            i = int(rows[np.flatnonzero(hs != hs[0])[0]])
            raise MultilatError(f"{where(i)}: sensor {s!r} changes height ({hs[0]:g} m before)")
        order = rows[np.argsort(times[rows], kind="stable")]
        ts = times[order]
        dup = np.flatnonzero(np.diff(ts) == 0)
        if dup.size:
            i = int(order[dup[0] + 1])
            raise MultilatError(f"{where(i)}: sensor {s!r} has two readings at {format_time(ts[dup[0]])}")
        rd = {c: vals[c][order] for c in vals}
        if "co2_ppm" not in rd:
            rd["co2_ppm"] = np.full(order.size, DEFAULT_CO2_PPM)
        if len(ids) > 1 and np.isnan(hs[0]):
            raise MultilatError(f"{where(int(rows[0]))}: sensor {s!r} has no height_m; with several sensors "
                                f"every sensor needs its height (equal heights to average them)")
        h_out.append(hs[0])
        t_out.append(ts)
        r_out.append(rd)
    return EnvironmentLog(path=t.path, sensor_ids=tuple(ids), height_m=np.array(h_out, dtype=float),
                          times_s=tuple(t_out), readings=tuple(r_out), has_co2=t.has("co2_ppm"))


def environment_from_rows(env: dict, *, label: str = "per-row") -> dict:
    """Per-row environment columns of a raw file -> ``{quantity: ndarray (m,)}`` (CO2 defaulted)."""
    out = {c: np.asarray(env[c], dtype=float) for c in env}
    if "co2_ppm" not in out:
        out["co2_ppm"] = np.full(out["temperature_c"].shape, DEFAULT_CO2_PPM)
    return out


@dataclass(frozen=True)
class BeamEnvironment:
    """The air along each beam and its sensitivity to the sensors' calibration errors.

    Attributes
    ----------
    values : dict ``{quantity: ndarray (m,)}``
        Beam-averaged temperature (°C), pressure (hPa), humidity (%RH), CO2 (ppm).
    sensor_ids : tuple of str, length S
    weights : ndarray (m, S, 4)
        ``∂ values[q][i] / ∂ e_{s,q}``: the weight of sensor ``s`` in observation ``i``'s value of
        quantity ``q`` (order of :data:`QUANTITIES`); rows sum to 1 over ``s``.
    gradient_c_per_m : ndarray (m,)
        Fitted vertical temperature gradient at each observation's time (NaN with one height).
    mid_height_m : ndarray (m,)
        Mid-height of each beam (NaN when not used).
    sensor_values : dict ``{quantity: ndarray (m, S)}``
        Each sensor's reading interpolated at each observation's time.
    extrapolated : ndarray (m,) bool
    """

    values: dict
    sensor_ids: tuple[str, ...]
    weights: np.ndarray
    gradient_c_per_m: np.ndarray
    mid_height_m: np.ndarray
    sensor_values: dict
    extrapolated: np.ndarray


def _interp_series(ts: np.ndarray, ys: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Linear interpolation of (ts, ys) at t, extrapolated linearly beyond the ends (1 reading: constant)."""
    if ts.size == 1:
        return np.full(t.shape, ys[0])
    out = np.interp(t, ts, ys)
    lo, hi = t < ts[0], t > ts[-1]
    if lo.any():
        out[lo] = ys[0] + (t[lo] - ts[0]) * (ys[1] - ys[0]) / (ts[1] - ts[0])
    if hi.any():
        out[hi] = ys[-1] + (t[hi] - ts[-1]) * (ys[-1] - ys[-2]) / (ts[-1] - ts[-2])
    return out


def _check_extrapolated(sensor_values: dict, log: EnvironmentLog, time_s, where) -> None:
    """Refuse a reading extrapolated (``--extrapolate``) outside the air formula's range
    (:data:`multilat.campaign.raw.ENV_RANGES`, the ranges of :mod:`multilat.air`: humidity 0-100 %RH,
    CO2 0-2000 ppm, ...). The readings themselves are checked when the log is read and interpolation
    stays between them; only extrapolation leaves the range, where the values were clipped silently
    (a humidity of 107 % used as 100 %). One line naming the observation, the sensor and the value."""
    for q, vals in sensor_values.items():
        lo, hi = ENV_RANGES[q]
        bad = np.argwhere((vals < lo) | (vals > hi))
        if bad.size:
            i, s = (int(x) for x in bad[0])
            raise MultilatError(
                f"{where(i)}: {q} of sensor {log.sensor_ids[s]!r} extrapolated to {vals[i, s]:g} at "
                f"{format_time(time_s[i])}, outside the air formula's range [{lo:g}, {hi:g}] "
                f"({int(((vals < lo) | (vals > hi)).any(axis=1).sum())} observation(s)); the log "
                f"{log.path} does not cover these times: extend it or drop those observations")


GAP_FACTOR = 3.0  # default longest bridged gap: this many times a sensor's median logging interval


def beam_environment(log: EnvironmentLog, time_s, *, mid_height_m=None, extrapolate: bool = False,
                     where=None, size: int | None = None, max_gap_s: float | None = None) -> BeamEnvironment:
    """Interpolate ``log`` at each observation's time and average it along each beam.

    Parameters
    ----------
    log : EnvironmentLog
    time_s : ndarray (m,) or None
        Observation times (POSIX s). None is allowed only when every sensor has a single reading
        (then ``size`` gives ``m``).
    mid_height_m : ndarray (m,) or None
        Mid-height of each beam, ``(z_station + z_target)/2``, in the sensors' vertical frame;
        required when the sensors are at several heights.
    extrapolate : bool
        Allow times outside a sensor's span (linear extrapolation, with a warning) and inside a gap
        of its log longer than ``max_gap_s`` (interpolation across the gap, with a warning).
    max_gap_s : float, optional
        Longest gap between two readings of one sensor across which an observation is interpolated
        (seconds); default ``GAP_FACTOR`` (3) times that sensor's median logging interval, so a
        regular log is never refused but a sensor that stopped reporting for a while is: its last
        reading would be a stale value. ``inf`` bridges every gap.
    where : callable(i) -> str, optional
        Names row ``i`` in messages (default ``"observation i"``).

    Returns
    -------
    BeamEnvironment
    """
    where = where or (lambda i: f"observation {i + 1}")
    if max_gap_s is not None and not max_gap_s > 0:
        raise MultilatError(f"max_gap_s must be > 0 (seconds), got {max_gap_s!r}")
    S = len(log.sensor_ids)
    no_time = time_s is None
    if no_time:
        if any(ts.size > 1 for ts in log.times_s):
            raise MultilatError(f"{where(0)}: the observations have no time column, needed to "
                                f"interpolate the environment log {log.path}")
        if size is None:
            raise MultilatError("beam_environment: give time_s or size")
        time_s = np.array([float(ts[0]) for ts in log.times_s[:1]] * int(size))
    else:
        time_s = np.asarray(time_s, dtype=float)
    m = time_s.size
    extrap = np.zeros(m, dtype=bool)
    sensor_values = {q: np.empty((m, S)) for q in QUANTITIES}
    for s, (sid, ts, rd) in enumerate(zip(log.sensor_ids, log.times_s, log.readings)):
        out = (time_s < ts[0]) | (time_s > ts[-1])
        if out.any() and not no_time:
            i = int(np.flatnonzero(out)[0])
            span = f"{format_time(ts[0])} to {format_time(ts[-1])}"
            if not extrapolate:
                raise MultilatError(f"{where(i)}: time {format_time(time_s[i])} has no reading of sensor "
                                    f"{sid!r} around it (its readings span {span}); "
                                    f"use --extrapolate to extrapolate")
            extrap |= out
        if ts.size > 1 and not no_time:
            dt = np.diff(ts)
            limit = GAP_FACTOR * float(np.median(dt)) if max_gap_s is None else float(max_gap_s)
            k = np.searchsorted(ts, time_s, side="right") - 1        # reading at or before each time
            inside = (k >= 0) & (k < ts.size - 1)
            gap = np.zeros(m)
            gap[inside] = dt[k[inside]]
            long_gap = inside & (gap > limit) & (time_s != ts[np.clip(k, 0, ts.size - 1)])
            if long_gap.any():
                i = int(np.flatnonzero(long_gap)[0])
                msg = (f"{where(i)}: time {format_time(time_s[i])} falls in a {gap[i] / 60:.1f} min gap of "
                       f"sensor {sid!r} (readings {format_time(ts[k[i]])} and {format_time(ts[k[i] + 1])}; "
                       f"longest bridged gap {limit / 60:.1f} min)")
                if not extrapolate:
                    raise MultilatError(msg + "; use --max-gap-s or --extrapolate to interpolate across it")
                warnings.warn(msg + ": interpolated across it", UserWarning, stacklevel=2)
                extrap |= long_gap
        for q in QUANTITIES:
            sensor_values[q][:, s] = _interp_series(ts, rd[q], time_s)
    if extrap.any():
        i = int(np.flatnonzero(extrap)[0])
        warnings.warn(f"{int(extrap.sum())} observation(s) outside the environment log's span or in a "
                      f"long gap of a sensor (first: {where(i)}): environment extrapolated or interpolated "
                      "across the gap", UserWarning, stacklevel=2)
    _check_extrapolated(sensor_values, log, time_s, where)

    weights = np.empty((m, S, len(QUANTITIES)))
    mean_w = np.full(S, 1.0 / S)
    weights[:] = mean_w[None, :, None]
    grad = np.full(m, np.nan)
    mids = np.full(m, np.nan)
    if log.several_heights:
        if mid_height_m is None:
            raise MultilatError(f"{where(0)}: the environment sensors are at several heights; "
                                f"station and target heights are needed (station_height_m/"
                                f"target_height_m columns or a heights file)")
        mids = np.asarray(mid_height_m, dtype=float)
        bad = np.flatnonzero(~np.isfinite(mids))
        if bad.size:
            raise MultilatError(f"{where(int(bad[0]))}: station or target height missing (needed: the "
                                f"environment sensors are at several heights)")
        if np.any(~np.isfinite(log.height_m)):
            raise MultilatError(f"{log.path}: some sensors have no height_m")
        A = np.column_stack([np.ones(S), log.height_m])
        pinv = np.linalg.solve(A.T @ A, A.T)           # (2, S)
        w_t = np.column_stack([np.ones(m), mids]) @ pinv   # (m, S)
        weights[:, :, 0] = w_t
        grad = sensor_values["temperature_c"] @ pinv[1]
    values = {q: np.einsum("ms,ms->m", sensor_values[q], weights[:, :, k])
              for k, q in enumerate(QUANTITIES)}
    return BeamEnvironment(values=values, sensor_ids=log.sensor_ids, weights=weights,
                           gradient_c_per_m=grad, mid_height_m=mids, sensor_values=sensor_values,
                           extrapolated=extrap)
