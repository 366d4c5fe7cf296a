"""The Monte Carlo problem of a real campaign: what ``multilat adjust`` reads, for ``multilat propagate``.

:func:`campaign_problem` reads an observations file or a raw-readings file exactly as ``adjust``
does (raw readings are corrected by :func:`multilat.campaign.correct.correct_file` with the
environment log, heights and formula), adjusts it for the nominal network, and attaches the readings
behind the observations (:class:`multilat.network.montecarlo.readings.Readings`):

* raw readings: the sensitivity ``J = ∂d/∂e`` of every corrected distance to every environment
  sensor's calibration error and those errors' standard uncertainties (the covariance
  ``J Σ_e Jᵀ + diag(u_model²)`` that ``adjust RAW`` propagates as ``G C Gᵀ``), so each Monte Carlo
  trial draws each sensor's error once and applies it to every reading it serves;
* repeated readings of a pair: kept as separate observations, or averaged (``average=True``,
  :func:`multilat.network.model.repeats.average_repeats`: weighted means, the scatter per pair reported)
  with every trial averaging its drawn readings the same way.

:func:`shifted_sensor_distances` redoes the whole correction with shifted sensor logs: the check of
the linear sensitivity (``tests/test_propagate_campaign.py``).
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from multilat.errors import MultilatError

__all__ = ["campaign_problem", "read_campaign", "shifted_sensor_distances"]


def read_campaign(path, *, sigma_m=None, instrument="seed2020", environment=None, heights=None,
                  formula: str = "ciddor", extrapolate: bool = False, max_gap_s=None,
                  sigma_source: dict | None = None, azimuth_sense: str | None = None):
    """Observations of ``path`` as ``adjust`` reads them: ``(obs, corrected)``, ``corrected`` the
    :class:`multilat.campaign.correct.CorrectedObservations` of a raw file (else None).

    One-line errors: raw options on an observation file, ``sigma_m`` on raw readings, a raw file
    without environment (from :func:`correct_raw`). ``sigma_source`` (a dict) is filled with where
    the distances' σ came from (:mod:`multilat.network.model.sigma_source`). ``azimuth_sense`` (``ccw``,
    ``cw`` or None: the instrument file's, else ``ccw``): the azimuths converted to counter-clockwise
    here, once, for every reader (:mod:`multilat.network.adjust.distance.azimuth_sense`).
    """
    from multilat.network.adjust.distance import azimuth_sense as _az

    sense, _ = _az.resolve(azimuth_sense, instrument)
    obs, corrected = _read_campaign(path, sigma_m=sigma_m, instrument=instrument, environment=environment,
                                    heights=heights, formula=formula, extrapolate=extrapolate,
                                    max_gap_s=max_gap_s, sigma_source=sigma_source)
    return _az.apply(obs, sense), corrected


def _read_campaign(path, *, sigma_m, instrument, environment, heights, formula, extrapolate, max_gap_s,
                   sigma_source):
    from multilat.campaign.raw import is_raw_file

    if is_raw_file(path):
        if sigma_m is not None:
            raise MultilatError("--sigma-um does not apply to raw readings: each corrected distance "
                                "gets its sigma_m from the distance model and the sensors")
        if formula not in ("ciddor", "edlen"):
            raise MultilatError(f"--formula must be ciddor or edlen, got {formula!r}")
        from multilat.campaign.correct import correct_file

        corrected = correct_file(path, environment=environment, instrument=instrument or "seed2020",
                                 formula=formula, heights=heights, extrapolate=extrapolate,
                                 max_gap_s=max_gap_s)
        if sigma_source is not None:
            sigma_source.update({"kind": "raw readings",
                                 "instrument": str(getattr(instrument, "name", instrument or "seed2020")),
                                 "note": "the distance model per reading and the air sensors"})
        return corrected.to_observations(), corrected
    if environment is not None or heights is not None or extrapolate or max_gap_s is not None:
        raise MultilatError(f"{path}: --environment/--heights/--extrapolate/--max-gap-s apply to raw "
                            "readings (optical_path_m or phase_rad), but this is an observation file "
                            "with distance_m")
    from multilat.network.io.files import read_observations

    return read_observations(path, sigma_m=sigma_m, instrument=instrument, sigma_source=sigma_source), None


def _has_repeats(obs) -> bool:
    key = np.asarray(obs.station_index, np.int64) * obs.n_targets + obs.target_index
    return np.unique(key).size < obs.n_obs


def campaign_problem(path, options=None, *, references=None, instrument="seed2020",
                     sigma_m=None, environment=None, heights=None, formula: str = "ciddor",
                     extrapolate: bool = False, max_gap_s=None, average: bool = False, pairs=None,
                     sigma_source: dict | None = None, points=None, pairs_option: str = "interpoint distance",
                     **option_fields):
    """The :class:`multilat.network.montecarlo.propagate.Problem` of a campaign file (module docstring).

    Parameters
    ----------
    path : observations CSV or raw-readings CSV
    options : NetworkOptions, optional
        The network model, as ``adjust`` takes it (datum, offsets, scales, levelled, scale bars, ...);
        its fields may also come as keywords (``datum=``, ``scales=``, ``levelled=``, ``scale_bars=``).
    references, pairs, pairs_option : as :func:`multilat.network.montecarlo.propagate.problem_from_observations`
    instrument : preset name, TOML path or Instrument
    sigma_m : float, optional
        Every distance's sigma (observation files without a sigma_m column).
    environment, heights, formula, extrapolate, max_gap_s :
        Raw readings only, as :func:`multilat.campaign.correct.correct_file`.
    average : bool
        Average the repeated readings of each pair (weighted means) instead of keeping them.
    sigma_source : dict, optional
        Filled with where the distances' σ came from (as ``adjust`` records it).
    points : Points, optional
        Approximate coordinates, or control under ``datum="control"`` (weighted rows drawn in every
        trial, hard rows held).

    Returns
    -------
    (Problem, corrected) — ``corrected`` the corrected raw readings (or None).
    """
    from multilat import instrument as _inst
    from multilat.network.montecarlo import propagate as pr
    from multilat.network.montecarlo.readings import Readings
    from multilat.network.model.repeats import average_repeats

    from multilat.network.adjust.distance.options import NetworkOptions

    inst = _inst.load_instrument(instrument) if isinstance(instrument, (str, os.PathLike)) else instrument
    opts = NetworkOptions.of(options, **option_fields)
    obs, corrected = read_campaign(path, sigma_m=sigma_m, instrument=inst, environment=environment,
                                   heights=heights, formula=formula, extrapolate=extrapolate,
                                   max_gap_s=max_gap_s, sigma_source=sigma_source,
                                   azimuth_sense=opts.azimuth_sense)
    if hasattr(references, "check_ids"):      # unknown ids named with the reference file (and its line)
        references.check_ids(tuple(obs.station_ids) + tuple(obs.target_ids))
    readings_obs = obs
    matrix = scatter = None
    if average:
        av = average_repeats(obs)
        obs, matrix, scatter = av.obs, av.matrix, av.scatter_json()
    obs = opts.prepare(obs, source=str(path))         # levelled stations; distance-only ones checked
    if corrected is not None:
        rd = Readings(np.asarray(readings_obs.station_index), np.asarray(corrected.distance_m, float),
                      np.asarray(corrected.sigma_model_m, float), air_jacobian_m=corrected.air_jacobian_m,
                      air_std=corrected.air_parameter_std, air_parameters=corrected.air_parameters,
                      matrix=matrix, scatter=scatter)
    elif average or _has_repeats(readings_obs):
        rd = Readings(np.asarray(readings_obs.station_index), np.asarray(readings_obs.distance_m, float),
                      np.asarray(readings_obs.sigma_m, float), matrix=matrix, scatter=scatter)
    else:
        rd = None                 # one independent error per observation: the plain path
    if opts.scale_bars and references is None:
        raise MultilatError("--scale-bars needs --references FILE (the bars' lengths with u_m)")
    prob = pr.problem_from_observations(obs, opts, references=references, instrument=inst, source=str(path),
                                        pairs=pairs, points=points, pairs_option=pairs_option)
    return dataclasses.replace(prob, readings=rd), corrected


def shifted_sensor_distances(raw_path, sensor_errors, *, environment, instrument="seed2020",
                             formula: str = "ciddor", heights=None, extrapolate: bool = False,
                             max_gap_s=None) -> np.ndarray:
    """Corrected distances (m,) with every sensor's readings shifted by its error: the full
    correction chain redone (no linearisation).

    ``sensor_errors`` maps ``"sensor:quantity"`` (the labels of ``air_parameters``) to the error
    added to all of that sensor's readings of that quantity (°C, hPa, %RH, ppm).
    """
    from multilat.campaign.correct import correct_raw, read_heights
    from multilat.campaign.environment import EnvironmentLog, read_environment
    from multilat.campaign.raw import read_raw

    raw = read_raw(raw_path)
    log = environment if isinstance(environment, EnvironmentLog) else read_environment(environment)
    readings = []
    for sid, rd in zip(log.sensor_ids, log.readings):
        readings.append({q: np.asarray(v, float) + float(sensor_errors.get(f"{sid}:{q}", 0.0))
                         for q, v in rd.items()})
    unknown = set(sensor_errors) - {f"{s}:{q}" for s, rd in zip(log.sensor_ids, log.readings) for q in rd}
    if unknown:
        raise MultilatError(f"unknown sensor error label {sorted(unknown)[0]!r}")
    log2 = dataclasses.replace(log, readings=tuple(readings))
    hts = read_heights(heights) if isinstance(heights, (str, os.PathLike)) else heights
    return correct_raw(raw, environment=log2, instrument=instrument, formula=formula, heights=hts,
                       extrapolate=extrapolate, max_gap_s=max_gap_s).distance_m
