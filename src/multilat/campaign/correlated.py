"""Coordinates' covariance when the corrected distances are correlated (shared environment sensors).

``multilat correct`` gives each corrected distance a full covariance ``C`` (m x m, m²): a sensor's
calibration error moves the air index of every observation that sensor serves, a common scale error.
The adjustment weights the distances by ``1/sigma_m²`` only (a diagonal weight is still an unbiased
estimator, and the paper's convention), so its reported covariance ``(AᵀWA)⁻`` ignores the
correlations. The estimate is ``x = G d`` to first order, with ``G`` the adjustment's linear map from
distances to parameters under its datum; the covariance it actually has is the sandwich

    Σ_x = G C Gᵀ.

``G`` is obtained here by central differences of the adjustment itself (each used distance moved by
±``step_m`` and the network re-adjusted from the solution, in the same datum, with the same fixed
offsets and scales): a second method, independent of the adjustment's analytic covariance, which it
reproduces for ``C = diag(sigma_m²)`` (tested). Costs ``2 m`` adjustments: meant for campaigns
(tens to a few hundred distances), not for 10⁶-row networks.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError

__all__ = ["CorrelatedCovariance", "adjustment_gain", "correlated_covariance", "correlated_json"]


@dataclass(frozen=True, eq=False)
class CorrelatedCovariance:
    """Covariance of the adjusted parameters under a full observation covariance.

    Attributes
    ----------
    station_ids, target_ids : tuple of str
    labels : tuple of str
        Parameter labels, ``"<station>.x|y|z|offset"`` then ``"<target>.x|y|z"``.
    cov_m2 : ndarray (n, n)
        ``G C Gᵀ`` in the adjustment's datum, m².
    station_cov_m2 : ndarray (s, 3, 3) ; target_cov_m2 : ndarray (t, 3, 3)
    offset_std_m : ndarray (s,)
    """

    station_ids: tuple
    target_ids: tuple
    labels: tuple
    cov_m2: np.ndarray
    station_cov_m2: np.ndarray
    target_cov_m2: np.ndarray
    offset_std_m: np.ndarray

    def interpoint_std_m(self, pairs: Sequence[tuple[str, str]], xyz_m: dict) -> np.ndarray:
        """Standard uncertainty of the distances between point pairs (ids of stations or targets),
        first order, with ``xyz_m`` the adjusted coordinates by id. Shape (len(pairs),), m."""
        index = {lab.rsplit(".", 1)[0]: i for i, lab in enumerate(self.labels) if lab.endswith(".x")}
        out = np.empty(len(pairs))
        for k, (a, b) in enumerate(pairs):
            for p in (a, b):
                if p not in index:
                    raise MultilatError(f"interpoint distance: unknown point id {p!r}")
            u = np.asarray(xyz_m[b], float) - np.asarray(xyz_m[a], float)
            u /= np.linalg.norm(u)
            j = np.zeros(len(self.labels))
            j[index[b]:index[b] + 3] += u
            j[index[a]:index[a] + 3] -= u
            out[k] = np.sqrt(max(float(j @ self.cov_m2 @ j), 0.0))
        return out


def _parameters(res) -> np.ndarray:
    return np.concatenate([np.column_stack([res.station_xyz_m, res.offset_m]).ravel(),
                           np.asarray(res.target_xyz_m).ravel()])


def adjustment_gain(result, *, step_m: float = 1e-6) -> np.ndarray:
    """``G = ∂x/∂d`` of an adjustment (n x m): parameters ``[x, y, z, offset]`` per station then
    ``[x, y, z]`` per target, in the result's datum, by central differences of :func:`adjust`.

    Parameters
    ----------
    result : multilat.network.adjust.distance.adjust.AdjustmentResult
    step_m : float
        Distance step (m); the adjustment is linear to ~step/distance, and its convergence
        tolerance (1e-10 m) is negligible beside ``step_m``.

    Returns
    -------
    ndarray (n, m); columns of rejected observations are zero.
    """
    from multilat.network.adjust.distance.adjust import adjust

    if not (np.isfinite(step_m) and step_m > 0):
        raise MultilatError(f"step_m must be finite and > 0, got {step_m!r}")
    obs = result.obs
    heads = result.heads()
    fixed = {hid: h["offset_m"] for hid, h in heads.items() if not h["offset_estimated"]}
    offsets = fixed or None          # heads not in the mapping keep their offset estimated
    scales = [hid for hid, h in heads.items() if h["scale_estimated"]]
    bars = None
    if result.scale_bars:              # scale bars were observations: they are in every re-adjustment
        from multilat.network.model.data import ReferenceLengths

        sb = result.scale_bars
        bars = ReferenceLengths(tuple(b["target_a"] for b in sb), tuple(b["target_b"] for b in sb),
                                [b["length_m"] for b in sb], [b["sigma_m"] for b in sb])
    used = np.asarray(result.used, bool)
    keep = obs if used.all() else _subset(obs, used)
    cols = np.flatnonzero(used)
    g = np.zeros((_parameters(result).size, obs.n_obs))
    for k_sub, k in enumerate(cols):
        sides = []
        for sign in (+1.0, -1.0):
            d = keep.distance_m.copy()
            d[k_sub] += sign * step_m
            r = adjust(dataclasses.replace(keep, distance_m=d), datum=result.datum, initial=result,
                       cost=result.cost, offsets=offsets, scales=scales or False, snooping=False,
                       scale_bars=bars)
            sides.append(_parameters(r))
        g[:, k] = (sides[0] - sides[1]) / (2 * step_m)
    return g


def _subset(obs, mask):
    from multilat.network.model.data import Observations

    def pick(a):
        return None if a is None else np.asarray(a)[mask]

    return Observations(obs.station_ids, obs.target_ids, obs.station_index[mask], obs.target_index[mask],
                        obs.distance_m[mask], obs.sigma_m[mask], azimuth_rad=pick(obs.azimuth_rad),
                        elevation_rad=pick(obs.elevation_rad), station_heads=obs.station_heads,
                        sigma_azimuth_rad=pick(obs.sigma_azimuth_rad),
                        sigma_elevation_rad=pick(obs.sigma_elevation_rad))


def correlated_covariance(result, obs_covariance_m2, *, step_m: float = 1e-6,
                          gain: np.ndarray | None = None) -> CorrelatedCovariance:
    """``G C Gᵀ``: the adjusted parameters' covariance with correlated distances.

    Parameters
    ----------
    result : multilat.network.adjust.distance.adjust.AdjustmentResult
        An adjustment of the distances (diagonal weights).
    obs_covariance_m2 : ndarray (m, m)
        Full covariance of ``result.obs.distance_m``, m² (e.g. ``CorrectedObservations.covariance_m2``).
    step_m : float
        See :func:`adjustment_gain`.
    gain : ndarray (n, m), optional
        A precomputed :func:`adjustment_gain` (to evaluate several covariances).
    """
    m = result.obs.n_obs
    c = np.asarray(obs_covariance_m2, float)
    if c.shape != (m, m):
        raise MultilatError(f"obs_covariance_m2 must be ({m}, {m}) like the observations, got {c.shape}")
    if not np.all(np.isfinite(c)) or not np.allclose(c, c.T, rtol=1e-10, atol=0.0):
        raise MultilatError("obs_covariance_m2 must be finite and symmetric")
    g = adjustment_gain(result, step_m=step_m) if gain is None else np.asarray(gain, float)
    cov = g @ c @ g.T
    s, t = len(result.station_ids), len(result.target_ids)
    labels = tuple(f"{sid}.{q}" for sid in result.station_ids for q in ("x", "y", "z", "offset")) + \
        tuple(f"{tid}.{q}" for tid in result.target_ids for q in ("x", "y", "z"))
    st = 4 * np.arange(s)[:, None] + np.arange(3)
    tg = 4 * s + 3 * np.arange(t)[:, None] + np.arange(3)
    return CorrelatedCovariance(
        station_ids=tuple(result.station_ids), target_ids=tuple(result.target_ids), labels=labels,
        cov_m2=cov, station_cov_m2=cov[st[:, :, None], st[:, None, :]],
        target_cov_m2=cov[tg[:, :, None], tg[:, None, :]],
        offset_std_m=np.sqrt(np.clip(np.diag(cov)[4 * np.arange(s) + 3], 0.0, None)))


def correlated_json(res, covariance_m2, refs=None) -> dict:
    """The parameters' covariance with the corrected distances' full covariance ``covariance_m2``
    (shared sensors): :func:`correlated_covariance` as the ``with_correlations`` JSON block of
    ``multilat adjust RAW``; ``refs`` adds the reference lengths' standard uncertainties."""
    cc = correlated_covariance(res, covariance_m2)
    tstd = np.sqrt(np.clip(np.diagonal(cc.target_cov_m2, axis1=1, axis2=2), 0, None))
    tstd0 = np.sqrt(np.clip(np.diagonal(res.target_cov_m2, axis1=1, axis2=2), 0, None))
    block = {
        "note": "covariance G C Gᵀ of the adjusted parameters with the full covariance C of the corrected "
                "distances (environment sensors shared between observations); the main keys use the "
                "diagonal weights' covariance",
        "stations": {sid: {"offset_std_m": float(cc.offset_std_m[i]), "cov_m2": cc.station_cov_m2[i]}
                     for i, sid in enumerate(cc.station_ids)},
        "targets": {tid: {"cov_m2": cc.target_cov_m2[j]} for j, tid in enumerate(cc.target_ids)},
        "target_std_max_m": float(tstd.max()),
        "target_std_diagonal_max_m": float(tstd0.max()),
    }
    if refs is not None:
        xyz = {**dict(zip(res.station_ids, res.station_xyz_m)), **dict(zip(res.target_ids, res.target_xyz_m))}
        pairs = list(zip(refs.target_a, refs.target_b))
        block["reference_lengths_u_m"] = dict(zip((f"{a}-{b}" for a, b in pairs),
                                                  cc.interpoint_std_m(pairs, xyz).tolist()))
    return block
