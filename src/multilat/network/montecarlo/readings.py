"""The readings behind a network's observations, for the Monte Carlo of a real campaign.

A campaign's observations are not always independent draws of one distance each:

* **shared sensors** — a raw reading is corrected with the air of the environment sensors
  (:mod:`multilat.campaign.correct`); a sensor's calibration error ``e_j`` moves every distance it
  serves, ``δd_i = Σ_j J_ij e_j`` with ``J = ∂d/∂e`` (``air_jacobian_m``, the same matrix that gives
  ``multilat correct``'s and ``adjust RAW``'s covariance ``J Σ_e Jᵀ``). The sensitivity is linear: the
  group index is smooth, and for sensor errors of 0.1 °C / 0.1 hPa the second-order term is below
  1e-10 relative (``tests/test_propagate_campaign.py`` compares ``J e`` with the full correction
  redone with shifted sensor logs);
* **repeated readings** — several readings of one pair are kept as separate observations, or
  averaged (``matrix`` ``A``, :func:`multilat.network.model.repeats.average_repeats`).

One Monte Carlo trial draws every reading's own error once (distance model or gaussian with
``sigma_m``), every sensor's error once (gaussian with ``air_std``, applied through ``J`` to all the
readings it serves), and gives the observations ``A (ε + J e)`` (``A = I`` without averaging). The
covariance of the observations is ``A (diag(σ²) + J Σ_e Jᵀ) Aᵀ``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.fast_normal import _fast_std_normal

__all__ = ["Readings"]


@dataclass(frozen=True, eq=False)
class Readings:
    """Readings (``r``) behind ``p`` observations.

    Attributes
    ----------
    station_index : ndarray of int (r,)
        Station of each reading (index into the problem's station ids; its head gives the distance
        model).
    distance_m : ndarray (r,)
        The readings' distances (corrected), metres.
    sigma_m : ndarray (r,)
        Standard uncertainty of each reading's own, independent error (the distance-model part for
        raw readings; the file's ``sigma_m`` otherwise), for ``noise="gaussian"``.
    air_jacobian_m : ndarray (r, q) or None
        ``∂d_i/∂e_j`` for the sensor errors ``e`` (metres per °C, hPa, %RH, ppm).
    air_std : ndarray (q,) or None
        Standard uncertainty of each sensor error.
    air_parameters : tuple of str
        Labels ``"sensor:quantity"`` of the sensor errors.
    matrix : ndarray (p, r) or None
        Averaging of repeated readings (``observations = matrix @ readings``); None: one observation
        per reading.
    scatter : list of dict or None
        Per averaged pair ``{station, target, n, mean_m, std_m}``.
    """

    station_index: np.ndarray
    distance_m: np.ndarray
    sigma_m: np.ndarray
    air_jacobian_m: np.ndarray | None = None
    air_std: np.ndarray | None = None
    air_parameters: tuple = ()
    matrix: np.ndarray | None = None
    scatter: list | None = None

    def __post_init__(self):
        r = np.asarray(self.distance_m).shape[0]
        if np.asarray(self.sigma_m).shape != (r,) or np.asarray(self.station_index).shape != (r,):
            raise MultilatError("readings: station_index, distance_m and sigma_m must have one value per reading")
        if (self.air_jacobian_m is None) != (self.air_std is None):
            raise MultilatError("readings: give air_jacobian_m and air_std together")
        if self.air_jacobian_m is not None:
            q = np.asarray(self.air_std).shape[0]
            if np.asarray(self.air_jacobian_m).shape != (r, q):
                raise MultilatError(f"readings: air_jacobian_m must be ({r}, {q})")
        if self.matrix is not None and np.asarray(self.matrix).shape[1] != r:
            raise MultilatError(f"readings: the averaging matrix must have {r} columns")

    @property
    def n_readings(self) -> int:
        return int(np.asarray(self.distance_m).shape[0])

    @property
    def n_sensor_errors(self) -> int:
        return 0 if self.air_std is None else int(np.asarray(self.air_std).shape[0])

    def reading_std_m(self, noise: str, instrument=None, heads=()) -> np.ndarray:
        """Standard deviation of each reading's own error: ``sigma_m`` (gaussian) or the distance
        model's :func:`multilat.budget.distance_std_m` of the reading's head (model)."""
        if noise == "gaussian":
            return np.asarray(self.sigma_m, float)
        from multilat import budget

        out = np.empty(self.n_readings)
        for i, hd in enumerate(heads):
            sel = self.station_index == i
            if sel.any():
                out[sel] = budget.distance_std_m(instrument, self.distance_m[sel], head=hd)
        return out

    def covariance_m2(self, noise: str, instrument=None, heads=()) -> np.ndarray:
        """Covariance of the observations ``A (diag(σ²) + J Σ_e Jᵀ) Aᵀ`` (p, p), m²."""
        c = np.diag(self.reading_std_m(noise, instrument, heads) ** 2)
        if self.air_jacobian_m is not None:
            j = np.asarray(self.air_jacobian_m, float)
            c = c + (j * np.asarray(self.air_std, float) ** 2) @ j.T
        if self.matrix is not None:
            a = np.asarray(self.matrix, float)
            c = a @ c @ a.T
        return c

    def draw(self, n: int, rng: np.random.Generator, *, noise: str, error_model=None) -> np.ndarray:
        """Errors of the observations for ``n`` trials (n, p): each reading's own error, then each
        sensor's error once per trial through ``J``, then the averaging. Fixed order of draws."""
        r = self.n_readings
        if noise == "gaussian":     # numpy's draws, faster through numba (multilat.fast_normal)
            e = _fast_std_normal(rng, (n, r))
            e *= self.sigma_m
        else:   # the distance model, one row of ``error_model`` per station (multilat.distance_errors)
            from multilat.distance_errors import draw_errors

            e = draw_errors(error_model, self.station_index, self.distance_m, n, rng)
        if self.air_jacobian_m is not None:
            z = rng.standard_normal((n, self.n_sensor_errors)) * self.air_std
            e += z @ np.asarray(self.air_jacobian_m, float).T
        if self.matrix is not None:
            e = e @ np.asarray(self.matrix, float).T
        return e

    def to_json(self) -> dict:
        """The readings' summary for ``propagate``'s JSON (``readings`` block)."""
        sensors = sorted({p.split(":", 1)[0] for p in self.air_parameters})
        return {
            "n_readings": self.n_readings,
            "averaged": self.matrix is not None,
            "n_observations": self.n_readings if self.matrix is None else int(np.asarray(self.matrix).shape[0]),
            "sensors": sensors,
            "n_sensor_errors": self.n_sensor_errors,
            "air_sensitivity": None if self.air_jacobian_m is None else
            "linearised: d(distance)/d(sensor error) of the correction chain (campaign.correct), one draw "
            "of every sensor's error per trial applied to every reading it serves",
            "repeats": self.scatter,
        }
