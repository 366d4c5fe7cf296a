"""Repeated readings of one (station, target) pair: kept, or averaged into one observation.

A campaign often reads each distance several times (the paper's Table V: the mean of 9 readings).
The adjustment takes the readings as separate observations; :func:`average_repeats` replaces the
readings of each pair by their weighted mean

    d̄ = Σ w_k d_k / Σ w_k,   w_k = 1 / sigma_k²,   sigma(d̄) = (Σ w_k)^-1/2,

which gives the same least-squares solution (the weighted sum of squared residuals of the readings is
that of the means plus a constant, the within-pair scatter), and reports the scatter of each pair.
The averaging is linear, ``d̄ = A d`` with ``A`` (p x m); ``A C Aᵀ`` is the covariance of the means
for a full covariance ``C`` of the readings (shared sensors), and the Monte Carlo of
:mod:`multilat.network.montecarlo.propagate` draws the readings' errors and averages them with the same ``A``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Averaged", "average_repeats"]


@dataclass(frozen=True, eq=False)
class Averaged:
    """The means of repeated readings.

    Attributes
    ----------
    obs : Observations
        One observation per (station, target) pair, in order of first reading; ``sigma_m`` of the mean.
    matrix : ndarray (p, m)
        ``obs.distance_m = matrix @ readings.distance_m`` (rows: the readings' normalised weights).
    count : ndarray of int (p,)
        Readings per pair.
    std_m : ndarray (p,)
        Sample standard deviation of the readings of each pair (NaN for a single reading).
    """

    obs: object
    matrix: np.ndarray
    count: np.ndarray
    std_m: np.ndarray

    def scatter_json(self) -> list[dict]:
        """Per pair ``{station, target, n, mean_m, std_m}`` (std null for one reading)."""
        o = self.obs
        return [{"station": o.station_ids[o.station_index[k]], "target": o.target_ids[o.target_index[k]],
                 "n": int(self.count[k]), "mean_m": float(o.distance_m[k]),
                 "std_m": None if not np.isfinite(self.std_m[k]) else float(self.std_m[k])}
                for k in range(o.n_obs)]


def average_repeats(obs) -> Averaged:
    """Weighted means of the repeated readings of each pair (module docstring).

    ``obs`` is :class:`multilat.network.model.data.Observations`; pointing angles are averaged (NaN-aware)
    with the same weights. Pairs read once are kept as they are.
    """
    from multilat.errors import MultilatError
    from multilat.network.model.data import Observations

    if obs.has_angle_observations:
        raise MultilatError("--average-repeats: the angle observations (sigma_azimuth_rad/sigma_elevation_rad) "
                            "are not averaged; keep the repeated readings as separate observations")
    si = np.asarray(obs.station_index, np.int64)
    ti = np.asarray(obs.target_index, np.int64)
    key = si * obs.n_targets + ti
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")          # pairs in order of first reading
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    grp = rank[inv.ravel()]
    p, m = order.size, obs.n_obs
    w = 1.0 / np.asarray(obs.sigma_m, float) ** 2
    wsum = np.bincount(grp, weights=w, minlength=p)
    a = np.zeros((p, m))
    a[grp, np.arange(m)] = w / wsum[grp]
    d = a @ obs.distance_m
    count = np.bincount(grp, minlength=p)
    dev = obs.distance_m - (np.bincount(grp, weights=obs.distance_m, minlength=p) / count)[grp]
    with np.errstate(divide="ignore", invalid="ignore"):
        std = np.where(count > 1, np.sqrt(np.bincount(grp, weights=dev * dev, minlength=p)
                                           / np.maximum(count - 1, 1)), np.nan)

    def mean_angle(v):
        if v is None:
            return None
        v = np.asarray(v, float)
        ok = np.isfinite(v)
        num = np.bincount(grp, weights=np.where(ok, v * w, 0.0), minlength=p)
        den = np.bincount(grp, weights=np.where(ok, w, 0.0), minlength=p)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)

    f = first[order]
    out = Observations(obs.station_ids, obs.target_ids, obs.station_index[f], obs.target_index[f], d,
                       1.0 / np.sqrt(wsum), azimuth_rad=mean_angle(obs.azimuth_rad),
                       elevation_rad=mean_angle(obs.elevation_rad), station_heads=obs.station_heads)
    return Averaged(out, a, count, std)
