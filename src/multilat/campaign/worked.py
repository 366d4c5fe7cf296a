"""A simulated measurement campaign with a known environment (seed 000 §4.2 conditions).

The paper's large-volume campaign: 56 distances (14 target positions x 4 heads) in about 3.5 h;
the temperature, around 19 °C, rose by 0.6 °C; the pressure, around 1016.5 hPa, fell by 0.7 hPa;
the sensor at 2.4 m read 1 °C more than those at 0.3, 0.7 and 1.4 m. This module builds such a
campaign from a network geometry: the true environment, the sensor log (with or without sensor
calibration errors), the raw readings (optical paths, or phases), and the truth to compare with.

Truth model (documented in ``docs/campaign.md``)
-----------------------------------------------
- ``T(z, t) = T_start + ΔT t/τ + profile(z)``; ``profile`` is ``"paper"`` (flat up to the knee at
  1.4 m, then rising linearly to +1 °C at 2.4 m: sensors at 0.3-1.4 m agree, the 2.4 m one reads
  1 °C more) or ``"linear"`` (``g z``, the model the correction fits, for exact round trips).
  ``P(t) = P_start - ΔP t/τ``, uniform in height; humidity and CO2 constant.
- The optical path of a beam is ``L = n_g(air averaged along the beam) x (D_mech + K_s)``, with
  ``D_mech`` the distance the gimbals make the ADM see (true distance through the target's and the
  head's transit offsets, eq. 5 / eq. 2 forward) and ``K_s`` the head's additive constant (the
  network's per-station offset, a fibre/cable delay, so not scaled by the air). With
  ``exact_path=True`` (default) the group index is evaluated at the beam-averaged air, the
  pipeline's own model, so a correction with exactly known air must return the truth; with
  ``exact_path=False`` the index is integrated along the beam (Gauss-Legendre, 16 nodes), which
  differs by the index's curvature in temperature (nanometres).
- Heights: the network frame's ``z`` plus ``floor_offset_m`` (1 m by default; the large-volume
  configuration puts head A 1.10 m above the floor, an assumption of the network helpers, as the
  paper gives no heights above the floor).
"""

from __future__ import annotations

import datetime as _dt
import os
from dataclasses import dataclass, field, replace

import numpy as np

from multilat.campaign.environment import QUANTITIES, EnvironmentLog
from multilat.campaign.raw import RawObservations, format_time
from multilat.errors import MultilatError

__all__ = ["CampaignConditions", "PAPER_CONDITIONS", "SimulatedCampaign", "simulate_campaign",
           "large_volume_geometry", "write_raw_csv", "write_environment_csv", "write_heights_csv",
           "ignore_gradient", "gradient_study", "GradientStudy", "STUDY_METHODS",
           "START_TIME"]

START_TIME = _dt.datetime(2020, 3, 10, 9, 0, tzinfo=_dt.timezone.utc).timestamp()


@dataclass(frozen=True)
class CampaignConditions:
    """The environment of a campaign (defaults: seed 000 §4.2).

    Attributes
    ----------
    duration_s : float
        Campaign length (3.5 h).
    temperature_start_c, temperature_rise_c : float
        Air temperature at the lowest sensors at the start, and its rise over the campaign.
    pressure_start_hpa, pressure_drop_hpa : float
    humidity_pct, co2_ppm : float
        Constant (not given by the paper: 45 %RH and 450 ppm assumed).
    sensor_heights_m : tuple of float
        Heights of the sensors (0.3, 0.7, 1.4, 2.4 m).
    profile : {"paper", "linear"}
        Vertical temperature profile (module docstring).
    knee_height_m, top_excess_c : float
        ``"paper"`` profile: flat below the knee, ``top_excess_c`` more at the highest sensor.
    gradient_c_per_m : float
        ``"linear"`` profile: ``g``.
    log_interval_s : float
        Time between sensor readings; the log starts one interval before the first reading and
        ends one after the last.
    """

    duration_s: float = 3.5 * 3600.0
    temperature_start_c: float = 18.7
    temperature_rise_c: float = 0.6
    pressure_start_hpa: float = 1016.85
    pressure_drop_hpa: float = 0.7
    humidity_pct: float = 45.0
    co2_ppm: float = 450.0
    sensor_heights_m: tuple = (0.3, 0.7, 1.4, 2.4)
    profile: str = "paper"
    knee_height_m: float = 1.4
    top_excess_c: float = 1.0
    gradient_c_per_m: float = 0.5
    log_interval_s: float = 300.0

    def temperature_profile_c(self, z_m):
        """``profile(z)`` (°C), ndarray like ``z_m``."""
        z = np.asarray(z_m, dtype=float)
        if self.profile == "linear":
            return self.gradient_c_per_m * z
        slope = self.top_excess_c / (max(self.sensor_heights_m) - self.knee_height_m)
        return slope * np.clip(z - self.knee_height_m, 0.0, None)

    def _profile_integral(self, z):
        if self.profile == "linear":
            return 0.5 * self.gradient_c_per_m * z * z
        slope = self.top_excess_c / (max(self.sensor_heights_m) - self.knee_height_m)
        return 0.5 * slope * np.clip(z - self.knee_height_m, 0.0, None) ** 2

    def beam_profile_c(self, za_m, zb_m):
        """Mean of ``profile`` along straight beams from ``za`` to ``zb`` (exact), ndarray."""
        za, zb = np.broadcast_arrays(np.asarray(za_m, float), np.asarray(zb_m, float))
        dz = zb - za
        same = np.abs(dz) < 1e-9
        safe = np.where(same, 1.0, dz)
        mean = (self._profile_integral(zb) - self._profile_integral(za)) / safe
        return np.where(same, self.temperature_profile_c(0.5 * (za + zb)), mean)

    def base(self, t_rel_s):
        """Time-dependent part: ``(T(t) at profile 0, P(t))``; ``t_rel_s`` from the campaign start."""
        f = np.asarray(t_rel_s, dtype=float) / self.duration_s
        return (self.temperature_start_c + self.temperature_rise_c * f,
                self.pressure_start_hpa - self.pressure_drop_hpa * f)


PAPER_CONDITIONS = CampaignConditions()


@dataclass(frozen=True)
class SimulatedCampaign:
    """A simulated campaign: what the instrument and sensors recorded, and the truth.

    Attributes
    ----------
    raw : RawObservations
    log : EnvironmentLog
    true_distance_m : ndarray (m,)
        True head-target distances (between reference points, no offset).
    offset_m : ndarray (m,)
        The head's additive constant of each reading (``K_s``).
    observed_true_m : ndarray (m,)
        ``true_distance_m + offset_m``: what a perfect correction returns.
    true_environment : dict ``{quantity: ndarray (m,)}``
        Beam-averaged true air.
    heights : dict id -> height (m)
    sensor_error : dict ``{quantity: ndarray (S,)}``
        Calibration error of each sensor drawn for this campaign (zeros if none).
    model_error_m : ndarray (m,)
        Distance-model error drawn for each reading (zeros if none).
    conditions : CampaignConditions
    station_xyz_m, target_xyz_m : ndarray (s, 3), (t, 3)
    station_ids, target_ids : tuple of str (unique)
    """

    raw: RawObservations
    log: EnvironmentLog
    true_distance_m: np.ndarray
    offset_m: np.ndarray
    observed_true_m: np.ndarray
    true_environment: dict
    heights: dict
    sensor_error: dict
    model_error_m: np.ndarray
    conditions: CampaignConditions
    station_xyz_m: np.ndarray
    target_xyz_m: np.ndarray
    station_ids: tuple
    target_ids: tuple
    notes: tuple = field(default=())


def large_volume_geometry():
    """The large-volume configuration of the network helpers (seed 000 §4.2).

    Returns ``(station_ids, station_xyz_m (4, 3), target_ids, target_xyz_m (14, 3), offset_m (4,),
    floor_offset_m)``; heights above the floor are ``z + floor_offset_m`` (the network helpers'
    assumption: head A 1.10 m above the floor).
    """
    from multilat.network.synthetic import configs

    cfg = configs.large_volume()
    return (tuple(cfg.station_ids), np.asarray(cfg.station_xyz_m, float), tuple(cfg.target_ids),
            np.asarray(cfg.target_xyz_m, float), np.asarray(cfg.offset_m, float),
            -float(configs.LARGE_FLOOR_Z_M))


def _group_index(env, formula, wavelength_m):
    from multilat import air

    return air.group_index(env["temperature_c"], env["pressure_hpa"] * 100.0, humidity_pct=env["humidity_pct"],
                           co2_ppm=env["co2_ppm"], wavelength_m=wavelength_m, formula=formula)


def _beam_group_index(c, tb, pb, za, zb, true_env, formula: str, lam, *, exact_path: bool):
    """The group index averaged along each beam from height ``za`` to ``zb`` (16-point Gauss-Legendre
    over the true profile of ``c`` at base temperature ``tb`` and pressure ``pb``), or the index of
    the true environment ``true_env`` when ``exact_path``."""
    if exact_path:
        return _group_index(true_env, formula, lam)
    x, w = np.polynomial.legendre.leggauss(16)
    s = 0.5 * (x + 1.0)
    z = za[:, None] + (zb - za)[:, None] * s[None, :]
    env_q = {"temperature_c": tb[:, None] + c.temperature_profile_c(z),
             "pressure_hpa": np.broadcast_to(pb[:, None], z.shape),
             "humidity_pct": np.full(z.shape, c.humidity_pct), "co2_ppm": np.full(z.shape, c.co2_ppm)}
    return (_group_index(env_q, formula, lam) * (0.5 * w)[None, :]).sum(axis=1)


def _sensor_log(c, u, rng, *, sensor_errors: bool):
    """The simulated sensors' log under conditions ``c``, each sensor with one calibration error drawn
    from its standard uncertainty ``u`` (zero without ``sensor_errors``). Returns ``(log, errors)``."""
    S = len(c.sensor_heights_m)
    err = {q: (rng.normal(0.0, u[q], S) if sensor_errors else np.zeros(S)) for q in QUANTITIES}
    lt = np.arange(-c.log_interval_s, c.duration_s + 1.5 * c.log_interval_s, c.log_interval_s)
    ltb, lpb = c.base(lt)
    times, readings = [], []
    for k, h in enumerate(c.sensor_heights_m):
        times.append(START_TIME + lt)
        readings.append({"temperature_c": ltb + c.temperature_profile_c(h) + err["temperature_c"][k],
                         "pressure_hpa": lpb + err["pressure_hpa"][k],
                         "humidity_pct": np.full(lt.size, c.humidity_pct) + err["humidity_pct"][k],
                         "co2_ppm": np.full(lt.size, c.co2_ppm) + err["co2_ppm"][k]})
    log = EnvironmentLog(path="<simulated log>", sensor_ids=tuple(f"S{k + 1}" for k in range(S)),
                         height_m=np.array(c.sensor_heights_m, float), times_s=tuple(times),
                         readings=tuple(readings), has_co2=True)
    return log, err


def simulate_campaign(station_ids, station_xyz_m, target_ids, target_xyz_m, *, offset_m=None,
                      conditions: CampaignConditions = PAPER_CONDITIONS, instrument="seed2020",
                      formula: str = "ciddor", rng=None, sensor_errors: bool = False,
                      model_errors: bool = False, exact_path: bool = True, floor_offset_m: float = 1.0,
                      phase: bool = False, angles: bool = True) -> SimulatedCampaign:
    """Simulate every head measuring every target once, in order, over the campaign.

    Parameters
    ----------
    station_ids, target_ids : sequence of str
    station_xyz_m, target_xyz_m : ndarray (s, 3), (t, 3)
        Network frame, z up, metres.
    offset_m : ndarray (s,), optional
        Heads' additive constants (default zeros).
    conditions : CampaignConditions
    instrument : preset name, path or instrument object
        Supplies Toh (Table III), Tot (Table IV), the wavelength, the modulation frequency (for
        ``phase=True``), the sensor uncertainties and the distance-model errors.
    formula : {"ciddor", "edlen"}
    rng : numpy Generator, int or None
    sensor_errors : bool
        Draw a constant calibration error for every sensor and quantity, N(0, u_q).
    model_errors : bool
        Add one draw of the distance model's error per reading
        (:func:`multilat.budget.sample_distance_errors`, non-gaussian).
    exact_path : bool
        Module docstring.
    floor_offset_m : float
        Added to the network z to give heights in the sensors' frame.
    phase : bool
        Record phases and ``k`` (eq. 1) instead of optical paths.
    angles : bool
        Record ``elevation_rad``/``target_elevation_rad`` (else the transit offsets stay uncorrected).

    Returns
    -------
    SimulatedCampaign
    """
    from multilat import adm, gimbal
    from multilat.campaign.correct import _head_toh_m, _load_instrument, _target_tot_m, _wavelength_m
    from multilat.campaign.correct import sensor_std_from_instrument

    rng = np.random.default_rng(rng)
    inst = _load_instrument(instrument)
    st_ids, tg_ids = tuple(station_ids), tuple(target_ids)
    sxyz, txyz = np.asarray(station_xyz_m, float), np.asarray(target_xyz_m, float)
    if sxyz.shape != (len(st_ids), 3) or txyz.shape != (len(tg_ids), 3):
        raise MultilatError("station_xyz_m/target_xyz_m: expected shapes (s, 3) and (t, 3)")
    off = np.zeros(len(st_ids)) if offset_m is None else np.asarray(offset_m, float)
    c = conditions
    # reading order: target by target, each head in turn
    si = np.tile(np.arange(len(st_ids)), len(tg_ids))
    ti = np.repeat(np.arange(len(tg_ids)), len(st_ids))
    m = si.size
    t_rel = np.linspace(0.0, c.duration_s, m)
    time_s = START_TIME + t_rel
    vec = txyz[ti] - sxyz[si]
    dist = np.linalg.norm(vec, axis=1)
    elev = np.arcsin(vec[:, 2] / dist)
    heights = {s: float(sxyz[k, 2] + floor_offset_m) for k, s in enumerate(st_ids)}
    heights.update({t: float(txyz[k, 2] + floor_offset_m) for k, t in enumerate(tg_ids)})
    za = sxyz[si, 2] + floor_offset_m
    zb = txyz[ti, 2] + floor_offset_m

    # true air along each beam
    tb, pb = c.base(t_rel)
    true_env = {"temperature_c": tb + c.beam_profile_c(za, zb), "pressure_hpa": pb,
                "humidity_pct": np.full(m, c.humidity_pct), "co2_ppm": np.full(m, c.co2_ppm)}
    lam = _wavelength_m(inst)
    n = _beam_group_index(c, tb, pb, za, zb, true_env, formula, lam, exact_path=exact_path)

    # distance the ADM sees: target transit offset (eq. 5 convention), head transit offset (eq. 2)
    model_err = np.zeros(m)
    if model_errors:
        from multilat import budget

        for k, s in enumerate(st_ids):
            rows = si == k
            model_err[rows] = budget.sample_distance_errors(inst, dist[rows], rng=rng, head=s)
    tot = _target_tot_m(inst)
    toh = np.array([_head_toh_m(inst, s) for s in st_ids])[si]
    d_mech = gimbal.transit_offset_effect(dist + model_err, -tot, -elev)
    d_mech = gimbal.transit_offset_effect(d_mech, toh, elev)
    L = n * (d_mech + off[si])

    # sensor log
    log, err = _sensor_log(c, sensor_std_from_instrument(inst), rng, sensor_errors=sensor_errors)

    nan = np.full(m, np.nan)
    if phase:
        f = float(inst.adm.modulation_frequency_hz)
        ph, kk = adm.phase_from_distance(L, f, 1.0)
        raw_opt, raw_phase, raw_f, raw_k = L.copy(), ph, np.full(m, f), kk.astype(float)
    else:
        raw_opt, raw_phase, raw_f, raw_k = L.copy(), nan.copy(), nan.copy(), nan.copy()
    raw = RawObservations(
        path="<simulated raw>", line_numbers=tuple(range(2, m + 2)),
        station_ids=tuple(st_ids[k] for k in si), target_ids=tuple(tg_ids[k] for k in ti),
        optical_path_m=raw_opt, phase_rad=raw_phase, frequency_hz=raw_f, k=raw_k, time_s=time_s,
        elevation_rad=elev if angles else None, target_elevation_rad=-elev if angles else None,
        azimuth_rad=None, environment=None, station_height_m=za, target_height_m=zb)
    return SimulatedCampaign(raw=raw, log=log, true_distance_m=dist, offset_m=off[si],
                             observed_true_m=dist + off[si], true_environment=true_env, heights=heights,
                             sensor_error=err, model_error_m=model_err, conditions=c,
                             station_xyz_m=sxyz, target_xyz_m=txyz, station_ids=st_ids, target_ids=tg_ids)


def ignore_gradient(log: EnvironmentLog, *, below_m: float | None = None) -> EnvironmentLog:
    """The log as used when the vertical gradient is ignored: sensors (optionally only those below
    ``below_m``) averaged as if at one height."""
    keep = [k for k, h in enumerate(log.height_m) if below_m is None or h < below_m]
    if not keep:
        raise MultilatError(f"no sensor below {below_m} m")
    return replace(log, sensor_ids=tuple(log.sensor_ids[k] for k in keep),
                   height_m=np.full(len(keep), np.nan), times_s=tuple(log.times_s[k] for k in keep),
                   readings=tuple(log.readings[k] for k in keep))


def write_raw_csv(path: str | os.PathLike, camp: SimulatedCampaign, *, heights_in_file: bool = False) -> None:
    """Write the campaign's raw readings as a raw CSV (atomically)."""
    from multilat.io import write_csv_atomic

    r = camp.raw
    phase = not np.all(np.isnan(r.phase_rad))
    header = ["station", "target", "time"]
    header += ["phase_rad", "frequency_hz", "k"] if phase else ["optical_path_m"]
    if r.elevation_rad is not None:
        header += ["elevation_rad", "target_elevation_rad"]
    if heights_in_file:
        header += ["station_height_m", "target_height_m"]
    rows = []
    for i in range(r.size):
        row = [r.station_ids[i], r.target_ids[i], format_time(r.time_s[i])]
        row += [float(r.phase_rad[i]), float(r.frequency_hz[i]), int(r.k[i])] if phase \
            else [float(r.optical_path_m[i])]
        if r.elevation_rad is not None:
            row += [float(r.elevation_rad[i]), float(r.target_elevation_rad[i])]
        if heights_in_file:
            row += [float(r.station_height_m[i]), float(r.target_height_m[i])]
        rows.append(row)
    write_csv_atomic(path, header, rows)


def write_environment_csv(path: str | os.PathLike, log: EnvironmentLog) -> None:
    """Write an environment log CSV (atomically), rows ordered by time then sensor."""
    from multilat.io import write_csv_atomic

    rows = []
    for sid, h, ts, rd in zip(log.sensor_ids, log.height_m, log.times_s, log.readings):
        for k in range(ts.size):
            rows.append((ts[k], [format_time(ts[k]), sid, "" if not np.isfinite(h) else float(h),
                                 *(float(rd[q][k]) for q in QUANTITIES)]))
    rows.sort(key=lambda r: r[0])
    write_csv_atomic(path, ["time", "sensor", "height_m", *QUANTITIES], [r[1] for r in rows])


def write_heights_csv(path: str | os.PathLike, heights: dict) -> None:
    """Write ``id,height_m`` (atomically)."""
    from multilat.io import write_csv_atomic

    write_csv_atomic(path, ["id", "height_m"], [[k, float(v)] for k, v in heights.items()])


# ------------------------------------------------------------------------------------------------
# The gradient study: what ignoring the vertical gradient costs (seed 000 §4.2)
# ------------------------------------------------------------------------------------------------

#: The corrections compared, in order: name -> how the sensor log is used.
STUDY_METHODS = ("true air", "fitted gradient (4 sensors)", "lower sensors averaged (paper)",
                 "all sensors averaged")


@dataclass(frozen=True)
class GradientStudy:
    """Distances and coordinates of one simulated campaign corrected in several ways.

    Attributes
    ----------
    campaign : SimulatedCampaign
    methods : tuple of str
        :data:`STUDY_METHODS`.
    corrected : dict name -> CorrectedObservations
    distance_error_m : dict name -> ndarray (m,)
        Corrected minus true distance (offset included).
    beam_temperature_error_c : dict name -> ndarray (m,)
        Beam temperature used minus the true beam-averaged temperature.
    longest : int
        Index of the longest reading.
    sensitivity_per_c : float
        ``(1/n) ∂n/∂T`` at the campaign's mean air (m/m per °C, negative).
    paper_check_m : float
        ``|sensitivity| x 0.5 °C x longest distance`` (the paper's 5.4 µm).
    coordinate_rms_m : dict name -> float
        RMS 3D error of the adjusted targets after a best-fit rigid motion onto the truth
        (NaN when the adjustment was not run).
    interpoint_error_m : dict name -> ndarray (t*(t-1)/2,)
        Adjusted minus true target-to-target distances (datum-free).
    offset_error_m : dict name -> ndarray (s,)
        Adjusted minus true head offsets.
    """

    campaign: SimulatedCampaign
    methods: tuple
    corrected: dict
    distance_error_m: dict
    beam_temperature_error_c: dict
    longest: int
    sensitivity_per_c: float
    paper_check_m: float
    coordinate_rms_m: dict
    interpoint_error_m: dict
    offset_error_m: dict


def _rigid_rms(est, true):
    """RMS distance between ``est`` (n, 3) and ``true`` after the best rigid motion (Kabsch)."""
    ce, ct = est.mean(0), true.mean(0)
    h = (est - ce).T @ (true - ct)
    u, _, vt = np.linalg.svd(h)
    dmat = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
    rot = vt.T @ dmat @ u.T
    moved = (est - ce) @ rot.T + ct
    return float(np.sqrt(np.mean(np.sum((moved - true) ** 2, axis=1))))


def gradient_study(station_ids, station_xyz_m, target_ids, target_xyz_m, *, offset_m=None,
                   conditions: CampaignConditions = PAPER_CONDITIONS, instrument="seed2020",
                   formula: str = "ciddor", adjust: bool = True, rng=None, sensor_errors: bool = False,
                   model_errors: bool = False, floor_offset_m: float = 1.0) -> GradientStudy:
    """Simulate a campaign (path-integrated truth) and correct it with each of :data:`STUDY_METHODS`.

    With ``adjust=True`` each set of corrected distances goes through the self-calibrating network
    adjustment (:func:`multilat.network.adjust.distance.adjust.adjust`, free datum, truth as initial values, no data
    snooping) and the coordinates are compared with the truth.
    """
    from multilat import air
    from multilat.campaign.correct import _load_instrument, correct_raw

    inst = _load_instrument(instrument)
    camp = simulate_campaign(station_ids, station_xyz_m, target_ids, target_xyz_m, offset_m=offset_m,
                             conditions=conditions, instrument=inst, formula=formula, rng=rng,
                             sensor_errors=sensor_errors, model_errors=model_errors, exact_path=False,
                             floor_offset_m=floor_offset_m)
    logs = {STUDY_METHODS[0]: None, STUDY_METHODS[1]: camp.log,
            STUDY_METHODS[2]: ignore_gradient(camp.log, below_m=2.0), STUDY_METHODS[3]: ignore_gradient(camp.log)}
    corrected, derr, terr = {}, {}, {}
    for name, log in logs.items():
        if name == STUDY_METHODS[0]:
            res = _correct_with_true_air(camp, inst, formula)
        else:
            res = correct_raw(camp.raw, environment=log, instrument=inst, formula=formula)
        corrected[name] = res
        derr[name] = res.distance_m - camp.observed_true_m
        terr[name] = res.environment["temperature_c"] - camp.true_environment["temperature_c"]
    longest = int(np.argmax(camp.true_distance_m))
    env = camp.true_environment
    s_t = float(np.mean(air.sensitivities(np.mean(env["temperature_c"]), np.mean(env["pressure_hpa"]) * 100,
                                          humidity_pct=conditions.humidity_pct, co2_ppm=conditions.co2_ppm,
                                          formula=formula)["temperature_c"]))
    rms, ipe, offe = {}, {}, {}
    iu = np.triu_indices(len(camp.target_ids), 1)
    true_ip = np.linalg.norm(camp.target_xyz_m[:, None] - camp.target_xyz_m[None], axis=-1)[iu]
    true_off = np.zeros(len(camp.station_ids)) if offset_m is None else np.asarray(offset_m, float)
    for name, res in corrected.items():
        if not adjust:
            rms[name], ipe[name], offe[name] = float("nan"), np.full(true_ip.shape, np.nan), \
                np.full(true_off.shape, np.nan)
            continue
        from multilat.network.adjust.distance.adjust import adjust as _adjust

        obs = res.to_observations()
        init = _Initial(camp.station_xyz_m, camp.target_xyz_m, true_off)
        out = _adjust(obs, datum="free", initial=init, snooping=False,
                      variance_factor="unknown")   # a study of systematic errors: noise-free by design, σ0 not judged
        sidx = [obs.station_ids.index(s) for s in camp.station_ids]
        tidx = [obs.target_ids.index(t) for t in camp.target_ids]
        txyz = out.target_xyz_m[tidx]
        rms[name] = _rigid_rms(np.vstack([out.station_xyz_m[sidx], txyz]),
                               np.vstack([camp.station_xyz_m, camp.target_xyz_m]))
        ipe[name] = np.linalg.norm(txyz[:, None] - txyz[None], axis=-1)[iu] - true_ip
        offe[name] = out.offset_m[sidx] - true_off
    return GradientStudy(campaign=camp, methods=STUDY_METHODS, corrected=corrected, distance_error_m=derr,
                         beam_temperature_error_c=terr, longest=longest, sensitivity_per_c=s_t,
                         paper_check_m=abs(s_t) * 0.5 * float(camp.true_distance_m[longest]),
                         coordinate_rms_m=rms, interpoint_error_m=ipe, offset_error_m=offe)


@dataclass(frozen=True)
class _Initial:
    station_xyz_m: np.ndarray
    target_xyz_m: np.ndarray
    offset_m: np.ndarray


def _correct_with_true_air(camp: SimulatedCampaign, inst, formula):
    """The oracle: the raw file corrected with the true beam-averaged air (per-row environment)."""
    from multilat.campaign.correct import correct_raw

    env = {q: np.asarray(camp.true_environment[q], float) for q in QUANTITIES}
    return correct_raw(replace(camp.raw, environment=env), instrument=inst, formula=formula)
