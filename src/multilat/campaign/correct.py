"""Raw readings -> corrected geometric distances with their uncertainty (the campaign pipeline).

For each raw reading ``i`` (seed 000 §2, §3.2, §3.3):

1. the air along the beam (:mod:`multilat.campaign.environment`): temperature, pressure, humidity,
   CO2 interpolated at the reading's time and averaged over the beam's heights;
2. the air **group** index ``n_i`` (:func:`multilat.air.group_index`, Ciddor or Bönsch-Potulski) at
   the instrument's wavelength;
3. the distance in air: ``D_i = L_i / n_i`` for an optical path ``L_i`` (vacuum, n = 1), or eq. (1)
   :func:`multilat.adm.distance_from_phase` with ``n_i`` for a phase reading;
4. the transit offsets by eq. (2), inverted: first the head's ``Toh`` with ``elevation_rad``
   (:func:`multilat.gimbal.transit_offset_correction`), then the target's ``Tot`` with
   ``target_elevation_rad`` (:func:`multilat.gimbal.target_transit_offset_correction`, eq. 5's sign
   convention of Table IV's ``Tot``), with the Tables III-IV values of the instrument config. Both
   angles are from the horizontal. Without ``target_elevation_rad`` the line of sight
   (``-elevation_rad``) is used; without any angle the corrections are skipped (noted);
5. the uncertainty: ``cov = J Σ_e Jᵀ + diag(u_model²)`` where ``J = ∂D/∂e`` is the exact sensitivity
   of every distance to every sensor's calibration error ``e`` (``Σ_e`` diagonal from the
   instrument's sensor uncertainties) and ``u_model`` the distance model's standard uncertainty at
   that length (:func:`multilat.budget.distance_std_m`: telemetric + head + target with corrected
   transit offsets, Tables I, III, IV). The air part is correlated between all observations a sensor
   serves; the model part is taken independent between observations (as in the paper's budget).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from multilat.campaign.environment import (QUANTITIES, EnvironmentLog, beam_environment,
                                           environment_from_rows, read_environment)
from multilat.campaign.raw import RawObservations, read_raw
from multilat.errors import MultilatError

__all__ = ["CorrectedObservations", "correct_raw", "correct_file", "observations_from_raw",
           "is_raw_file", "write_observations", "write_covariance", "sensor_std_from_instrument", "read_heights",
           "FD_STEPS"]

from multilat.campaign.raw import is_raw_file  # noqa: E402  (re-exported for `multilat adjust`)

#: central-difference steps for ∂n/∂q (T °C, P hPa, RH %, CO2 ppm); n is smooth, so the
#: truncation error (~h²) is far below 1e-6 relative.
FD_STEPS = {"temperature_c": 0.01, "pressure_hpa": 0.1, "humidity_pct": 0.1, "co2_ppm": 1.0}


@dataclass(frozen=True)
class CorrectedObservations:
    """Corrected distances (``m`` observations) with their uncertainty and every intermediate.

    Attributes
    ----------
    station_ids, target_ids : tuple of str, length m
    distance_m : ndarray (m,)
        Geometric distance, air and transit offsets corrected, metres.
    sigma_m : ndarray (m,)
        Standard uncertainty, ``sqrt(diag(covariance_m2))``.
    sigma_air_m, sigma_model_m : ndarray (m,)
        The environment-sensor part and the distance-model part of ``sigma_m``.
    covariance_m2 : ndarray (m, m)
        Full covariance of the corrected distances, m².
    air_jacobian_m : ndarray (m, p)
        ``∂ distance_i / ∂ e_j`` for the sensor calibration errors ``e`` labelled by
        ``air_parameters`` (``"sensor:quantity"``), metres per unit of the quantity.
    air_parameters : tuple of str, length p
    air_parameter_std : ndarray (p,)
        Standard uncertainty of each sensor error (°C, hPa, %RH, ppm).
    group_index : ndarray (m,)
    vacuum_path_m : ndarray (m,)
        The reading as a vacuum distance ``L`` (n = 1).
    index_correction_m : ndarray (m,)
        ``D_air - L`` (negative: the air lengthens the optical path).
    head_transit_correction_m, target_transit_correction_m : ndarray (m,)
        Corrections added by eq. (2) (zeros when the angle column is absent).
    environment : dict ``{quantity: ndarray (m,)}``
        Beam-averaged air values used.
    gradient_c_per_m : ndarray (m,)
        Fitted vertical temperature gradient (NaN with one sensor height).
    time_s : ndarray (m,) or None
    azimuth_rad, elevation_rad : ndarray (m,) or None
        Passed through to the observation file.
    formula : str
    extrapolated : ndarray (m,) bool
    notes : tuple of str
        What was done or skipped (missing angle columns, extrapolation, ...).
    """

    station_ids: tuple[str, ...]
    target_ids: tuple[str, ...]
    distance_m: np.ndarray
    sigma_m: np.ndarray
    sigma_air_m: np.ndarray
    sigma_model_m: np.ndarray
    covariance_m2: np.ndarray
    air_jacobian_m: np.ndarray
    air_parameters: tuple[str, ...]
    air_parameter_std: np.ndarray
    group_index: np.ndarray
    vacuum_path_m: np.ndarray
    index_correction_m: np.ndarray
    head_transit_correction_m: np.ndarray
    target_transit_correction_m: np.ndarray
    environment: dict
    gradient_c_per_m: np.ndarray
    time_s: np.ndarray | None
    azimuth_rad: np.ndarray | None
    elevation_rad: np.ndarray | None
    formula: str
    extrapolated: np.ndarray
    notes: tuple[str, ...]
    head_ids: tuple[str, ...] | None = None

    @property
    def correlation(self) -> np.ndarray:
        """Correlation matrix (m, m) of the corrected distances."""
        s = np.sqrt(np.diag(self.covariance_m2))
        return self.covariance_m2 / np.outer(s, s)

    def to_observations(self):
        """The corrected distances as :class:`multilat.network.model.data.Observations` (for ``adjust``)."""
        from multilat.network.model.data import Observations

        return _make_observations(Observations, self)


def _make_observations(Observations, c: CorrectedObservations):
    both = c.azimuth_rad is not None and c.elevation_rad is not None
    return Observations.from_labels(c.station_ids, c.target_ids, c.distance_m, c.sigma_m,
                                    azimuth_rad=c.azimuth_rad if both else None,
                                    elevation_rad=c.elevation_rad if both else None, head=c.head_ids)


# ------------------------------------------------------------------------------------------------
# instrument adaptors (the instrument config is the distance-model helper's; read it in one place)
# ------------------------------------------------------------------------------------------------

def _load_instrument(instrument):
    from multilat import instrument as _inst

    if isinstance(instrument, (str, os.PathLike)):
        return _inst.load_instrument(instrument)
    return instrument


def sensor_std_from_instrument(inst) -> dict:
    """Standard uncertainties of the environment sensors ``{quantity: u}`` (°C, hPa, %RH, ppm)."""
    env = inst.environment
    return {"temperature_c": float(env.u_temperature_c), "pressure_hpa": float(env.u_pressure_hpa),
            "humidity_pct": float(env.u_humidity_pct), "co2_ppm": float(env.u_co2_ppm)}


def _head_toh_m(inst, head: str):
    return float(inst.head(head).toh_m)


def _target_tot_m(inst):
    return float(inst.target.tot_m)


def _head_names(inst) -> tuple[str, ...]:
    return tuple(inst.heads)


def _wavelength_m(inst) -> float:
    return float(inst.adm.wavelength_nm) * 1e-9


# ------------------------------------------------------------------------------------------------

def read_heights(path: str | os.PathLike) -> dict:
    """Heights of stations and targets ``{id: z_m}`` from a points file.

    Accepts ``id,height_m`` or a points file ``id,x_m,y_m,z_m`` (z is taken as the height in the
    environment sensors' vertical frame).
    """
    from multilat.io import read_csv_table

    t = read_csv_table(path, required=("id",), optional=("height_m", "x_m", "y_m", "z_m"),
                       warn_unknown=False)
    col = "height_m" if t.has("height_m") else "z_m" if t.has("z_m") else None
    if col is None:
        raise MultilatError(f"{t.path}: heights file needs a height_m or z_m column")
    z = t.floats(col)
    ids = t.ids("id")
    out: dict = {}
    for i, k in enumerate(ids):
        if k in out:
            raise MultilatError(f"{t.path}:{t.line_numbers[i]}: duplicate id {k!r}")
        out[k] = float(z[i])
    return out


def _mid_heights(raw: RawObservations, heights: Mapping[str, float] | None) -> np.ndarray | None:
    m = raw.size
    zs = raw.station_height_m.copy() if raw.station_height_m is not None else np.full(m, np.nan)
    zt = raw.target_height_m.copy() if raw.target_height_m is not None else np.full(m, np.nan)
    if heights:
        for i in range(m):
            if np.isnan(zs[i]) and raw.station_ids[i] in heights:
                zs[i] = heights[raw.station_ids[i]]
            if np.isnan(zt[i]) and raw.target_ids[i] in heights:
                zt[i] = heights[raw.target_ids[i]]
    return 0.5 * (zs + zt)


def _group_index(env: dict, formula: str, wavelength_m: float, **delta) -> np.ndarray:
    from multilat import air

    v = {q: env[q] + delta.get(q, 0.0) for q in QUANTITIES}
    return air.group_index(v["temperature_c"], v["pressure_hpa"] * 100.0,
                           humidity_pct=np.clip(v["humidity_pct"], 0.0, 100.0),
                           co2_ppm=v["co2_ppm"], wavelength_m=wavelength_m, formula=formula)


def _beam_air(raw: RawObservations, environment: EnvironmentLog | None, *, heights, extrapolate: bool,
              max_gap_s, notes: list[str]):
    """The air along each beam, from the log or from the raw rows' own columns (one sensor; a note
    added to ``notes``): ``(env, weights, sensor ids, gradient °C/m, extrapolated)``."""
    m = raw.size
    if environment is not None and raw.environment is not None:
        raise MultilatError(f"{raw.path}: has per-row environment columns and an environment log was "
                            f"given; use one or the other")
    if environment is not None:
        be = beam_environment(environment, raw.time_s, mid_height_m=_mid_heights(raw, heights),
                              extrapolate=extrapolate, where=raw.where, size=m, max_gap_s=max_gap_s)
        env, weights, sensors = be.values, be.weights, be.sensor_ids
        grad, extrap = be.gradient_c_per_m, be.extrapolated
    elif raw.environment is not None:
        env = environment_from_rows(raw.environment)
        weights = np.ones((m, 1, len(QUANTITIES)))
        sensors = ("row-sensor",)
        grad, extrap = np.full(m, np.nan), np.zeros(m, dtype=bool)
        notes.append("environment from the raw rows (one sensor, errors fully correlated)")
    else:
        raise MultilatError(f"{raw.path}: no environment: give an environment log (--environment) or "
                            f"temperature_c,pressure_hpa,humidity_pct columns")
    return env, weights, sensors, grad, extrap


def _transit_corrections(raw: RawObservations, inst, d_air, notes: list[str]):
    """Eq. (2): the head and target transit offsets applied to the distances in air ``d_air``;
    readings without the elevation they need are named in ``notes``. Returns ``(d, head
    correction, target correction)`` (m)."""
    from multilat import gimbal

    m = raw.size
    d = d_air.copy()
    head_corr = np.zeros(m)
    tgt_corr = np.zeros(m)
    heads = _head_names(inst)
    row_heads = raw.heads
    what = "station" if raw.head_ids is None else "head"
    for i, s in enumerate(row_heads):
        if not inst.has_head(s):
            raise MultilatError(f"{raw.where(i)}: {what} {s!r} is not a head of the instrument "
                                f"{inst.name!r} (heads: {', '.join(heads)}; give a head column, or a "
                                "[heads.default] block in the instrument)")
    if raw.elevation_rad is not None:
        toh = np.array([_head_toh_m(inst, s) for s in row_heads])
        d_h = np.asarray(gimbal.transit_offset_correction(d, toh, raw.elevation_rad), dtype=float)
        head_corr = d_h - d
        d = d_h
    else:
        notes.append("no elevation_rad column: head transit offsets not corrected")
    tel = raw.target_elevation_rad
    if tel is None and raw.elevation_rad is not None:
        # the straight line of sight seen from the target has elevation -phi (seed2020's
        # correction_elevation = "line_of_sight"); eq. (2)'s cosine makes the sign irrelevant
        tel = -raw.elevation_rad
        notes.append("no target_elevation_rad column: target transit offset corrected with the line of "
                     "sight (-elevation_rad)")
    if tel is not None:
        d_t = np.asarray(gimbal.target_transit_offset_correction(d, np.full(m, _target_tot_m(inst)), tel),
                         dtype=float)
        tgt_corr = d_t - d
        d = d_t
    else:
        notes.append("no elevation columns: target transit offset not corrected")
    return d, head_corr, tgt_corr


def _sensor_std(inst, sensor_std: Mapping[str, float] | None) -> dict[str, float]:
    """The sensors' standard uncertainties: the instrument's, or all of ``sensor_std``."""
    u = dict(sensor_std_from_instrument(inst)) if sensor_std is None else {}
    if sensor_std is not None:
        for q in QUANTITIES:
            if q not in sensor_std:
                raise MultilatError(f"sensor_std lacks key {q!r}")
            u[q] = float(sensor_std[q])
    return u


def _air_jacobian(env, formula: str, lam, d_air, n, weights, sensors, u: Mapping[str, float]):
    """The exact sensitivity of each distance to each sensor's calibration error (central
    differences of the group index): ``(jacobian m per unit, labels "sensor:quantity", their
    standard uncertainties)``."""
    m = len(d_air)
    S = len(sensors)
    jac = np.empty((m, S * len(QUANTITIES)))
    labels, ustd = [], []
    for k, q in enumerate(QUANTITIES):
        h = FD_STEPS[q]
        dn = (_group_index(env, formula, lam, **{q: h}) - _group_index(env, formula, lam, **{q: -h})) / (2 * h)
        dd_dq = -d_air / n * dn                                  # (m,) m per unit of q
        jac[:, k::len(QUANTITIES)] = dd_dq[:, None] * weights[:, :, k]
    for s in sensors:
        for q in QUANTITIES:
            labels.append(f"{s}:{q}")
            ustd.append(u[q])
    return jac, labels, np.array(ustd)


def correct_raw(raw: RawObservations, *, environment: EnvironmentLog | None = None,
                instrument="seed2020", formula: str = "ciddor",
                heights: Mapping[str, float] | None = None, extrapolate: bool = False,
                max_gap_s: float | None = None,
                sensor_std: Mapping[str, float] | None = None) -> CorrectedObservations:
    """Correct raw readings into geometric distances with their covariance (module docstring).

    Parameters
    ----------
    raw : RawObservations
    environment : EnvironmentLog, optional
        Sensor log; without it the raw rows' own environment columns are used (one sensor, the
        same for every row, so its errors are fully correlated between rows).
    instrument : str, path or instrument object
        Preset name (``"seed2020"``) or TOML path for :func:`multilat.instrument.load_instrument`.
    formula : {"ciddor", "edlen"}
        Group index formula (``"edlen"``: Bönsch-Potulski 1998).
    heights : mapping id -> height (m), optional
        Station/target heights in the sensors' frame, where the raw file has no height columns.
    extrapolate : bool
        Allow readings outside the log's time span (linear extrapolation, warned) or in a sensor's
        gap longer than ``max_gap_s`` (interpolated across, warned).
    max_gap_s : float, optional
        Longest gap of a sensor's log bridged by interpolation (s); default 3 x its median logging
        interval (:func:`multilat.campaign.environment.beam_environment`).
    sensor_std : mapping quantity -> standard uncertainty, optional
        Overrides the instrument's sensor uncertainties (keys of :data:`QUANTITIES`).

    Returns
    -------
    CorrectedObservations
    """
    from multilat import adm, budget

    if formula not in ("ciddor", "edlen"):
        raise MultilatError(f"formula must be 'ciddor' or 'edlen', got {formula!r}")
    inst = _load_instrument(instrument)
    m = raw.size
    notes: list[str] = []

    # 1. the air along each beam
    env, weights, sensors, grad, extrap = _beam_air(raw, environment, heights=heights, extrapolate=extrapolate,
                                                    max_gap_s=max_gap_s, notes=notes)

    # 2. group index, 3. distance in air
    lam = _wavelength_m(inst)
    n = _group_index(env, formula, lam)
    phase_rows = ~np.isnan(raw.phase_rad)
    d_air = raw.optical_path_m / n
    if phase_rows.any():
        d_air[phase_rows] = adm.distance_from_phase(raw.phase_rad[phase_rows], raw.k[phase_rows],
                                                    raw.frequency_hz[phase_rows], n[phase_rows])

    # 4. transit offsets, eq. (2)
    d, head_corr, tgt_corr = _transit_corrections(raw, inst, d_air, notes)
    if extrap.any():
        notes.append(f"{int(extrap.sum())} observation(s) with extrapolated environment")

    # 5. uncertainty: exact sensitivity to each sensor's calibration error
    jac, labels, ustd_arr = _air_jacobian(env, formula, lam, d_air, n, weights, sensors,
                                          _sensor_std(inst, sensor_std))
    cov_air = (jac * ustd_arr**2) @ jac.T
    sig_model = np.empty(m)
    row_heads = raw.heads
    st = np.array(row_heads, dtype=object)
    for s in dict.fromkeys(row_heads):
        rows = st == s
        sig_model[rows] = budget.distance_std_m(inst, d[rows], head=s)
    cov = cov_air + np.diag(sig_model**2)
    sig_air = np.sqrt(np.clip(np.diag(cov_air), 0.0, None))
    return CorrectedObservations(
        station_ids=raw.station_ids, target_ids=raw.target_ids, distance_m=d,
        sigma_m=np.sqrt(np.diag(cov)), sigma_air_m=sig_air, sigma_model_m=sig_model,
        covariance_m2=cov, air_jacobian_m=jac, air_parameters=tuple(labels), air_parameter_std=ustd_arr,
        group_index=n, vacuum_path_m=raw.optical_path_m.copy(), index_correction_m=d_air - raw.optical_path_m,
        head_transit_correction_m=head_corr, target_transit_correction_m=tgt_corr,
        environment={q: np.asarray(env[q]) for q in QUANTITIES}, gradient_c_per_m=grad,
        time_s=raw.time_s, azimuth_rad=raw.azimuth_rad, elevation_rad=raw.elevation_rad,
        formula=formula, extrapolated=extrap, notes=tuple(notes), head_ids=raw.head_ids)


def correct_file(path: str | os.PathLike, *, environment: str | os.PathLike | EnvironmentLog | None = None,
                 instrument="seed2020", formula: str = "ciddor",
                 heights: str | os.PathLike | Mapping[str, float] | None = None,
                 extrapolate: bool = False, max_gap_s: float | None = None) -> CorrectedObservations:
    """:func:`correct_raw` on files: a raw file, an optional environment log and heights file."""
    raw = read_raw(path)
    log = environment if environment is None or isinstance(environment, EnvironmentLog) \
        else read_environment(environment)
    hts = read_heights(heights) if isinstance(heights, (str, os.PathLike)) else heights
    return correct_raw(raw, environment=log, instrument=instrument, formula=formula, heights=hts,
                       extrapolate=extrapolate, max_gap_s=max_gap_s)


def observations_from_raw(path: str | os.PathLike, *, environment=None, instrument="seed2020",
                          formula: str = "ciddor", heights=None, extrapolate: bool = False,
                          max_gap_s: float | None = None):
    """Raw file -> :class:`multilat.network.model.data.Observations` with corrected distances and sigma_m.

    The entry point for ``multilat adjust RAW.csv --environment ENV.csv`` (see :func:`is_raw_file`).
    """
    return correct_file(path, environment=environment, instrument=instrument, formula=formula,
                        heights=heights, extrapolate=extrapolate,
                        max_gap_s=max_gap_s).to_observations()


def write_observations(path: str | os.PathLike, c: CorrectedObservations) -> None:
    """Write ``station,target,distance_m,sigma_m[,azimuth_rad,elevation_rad]`` atomically (the file
    ``multilat adjust`` reads). Angles are written when the raw file had both."""
    from multilat.io import write_csv_atomic

    header = ["station", "target", "distance_m", "sigma_m"]
    cols = [c.station_ids, c.target_ids, c.distance_m, c.sigma_m]
    if c.azimuth_rad is not None and c.elevation_rad is not None:
        header += ["azimuth_rad", "elevation_rad"]
        cols += [c.azimuth_rad, c.elevation_rad]
    write_csv_atomic(path, header, zip(*cols))


def write_covariance(path: str | os.PathLike, c: CorrectedObservations) -> None:
    """Write the full covariance (m², m x m) atomically: a header ``row,<label 1>,...`` with labels
    ``station:target:n`` (n the 1-based observation number) and one row per observation."""
    from multilat.io import write_csv_atomic

    labels = [f"{s}:{t}:{i + 1}" for i, (s, t) in enumerate(zip(c.station_ids, c.target_ids))]
    write_csv_atomic(path, ["row", *labels],
                     ([labels[i], *c.covariance_m2[i].tolist()] for i in range(len(labels))))
