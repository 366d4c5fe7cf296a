"""Internal and external reliability of a network adjustment, and which observations and targets it
controls poorly.

Internal reliability: the redundancy number ``r_k`` and the minimal detectable bias
``MDB_k = sigma_k sqrt(lambda0 / r_k)`` (:mod:`.statistics`). External reliability: what an
undetected bias of that size does to the coordinates,

    Δx_k = C Aᵀ P e_k MDB_k            (C the covariance in the datum, e_k the k-th unit vector)

reported as the largest shift of any station or target (its norm, and which point), and Baarda's
bias-to-noise ratio ``λ̄_k = sqrt(lambda0 (1 - r_k) / r_k)`` (the bound on the effect on any function
of the unknowns in units of its own standard deviation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.network import statistics as st
from multilat.network.model import Q

__all__ = ["Reliability", "external_shifts", "reliability", "MAX_EXTERNAL_OBS"]

MAX_EXTERNAL_OBS = 20000     # the coordinate shifts cost O(m) per observation: computed up to this many


@dataclass(frozen=True, eq=False)
class Reliability:
    """Reliability of the used observations of an adjustment (arrays over all observations; NaN for
    rejected ones).

    redundancy, mdb_m, mdb_sigma (MDB / σ_k), bnr (λ̄_k), shift_max_m (largest point shift caused by
    MDB_k; NaN when not computed), shift_point (the point's id, "" when not computed); poor_obs:
    indices of observations with ``r < r_min`` or ``MDB > mdb_limit_sigma σ``, worst first;
    poor_targets: tuple of dicts per target owning such an observation (id, n_obs, min redundancy,
    max MDB in m and in σ, max shift in m); ``shifts_computed`` False above ``MAX_EXTERNAL_OBS``.
    """

    redundancy: np.ndarray
    mdb_m: np.ndarray
    mdb_sigma: np.ndarray
    bnr: np.ndarray
    shift_max_m: np.ndarray
    shift_point: tuple
    r_min: float
    mdb_limit_sigma: float
    poor_obs: tuple
    poor_targets: tuple
    shifts_computed: bool


def external_shifts(cov, obs, used, sx_ids, tx_ids, bias_m, *, batch: int = 256):
    """Largest point shift ``max_p |Δx_p|`` caused by a bias ``bias_m[k]`` in each used observation.

    ``cov``: the adjustment's :class:`~.covariance.NetworkCovariance` (its whitened Jacobian rows are
    the used observations' ``A_k / sigma_k``); ``bias_m`` over the used observations. The a-priori
    covariance is used (``cov.factor`` divided out; a low-rank ``extra`` term, the uncertainty of a
    reference length, is not part of the least-squares response and is left out).
    Checked against re-adjusting with the bias added (tests/test_reliability.py). Returns
    ``(shift_m (mu,), point id per observation)``.
    """
    s, t, n = cov.s, cov.t, cov.n
    mu = cov.Js_w.shape[0]
    ids = list(sx_ids) + list(tx_ids)
    out = np.empty(mu)
    where = np.empty(mu, dtype=np.intp)
    R = cov.R
    for lo in range(0, mu, batch):
        ks = np.arange(lo, min(lo + batch, mu))
        V = np.zeros((n, ks.size))
        c = np.arange(ks.size)
        si, ti = cov.si[ks], cov.ti[ks]
        a_s = cov.Js_w[ks].copy()
        a_s[:, :3] = a_s[:, :3] @ R.T              # into the final frame
        for q in range(Q):
            V[Q * si + q, c] = a_s[:, q]
        a_t = cov.Jt_w[ks] @ R.T
        for q in range(3):
            V[Q * s + 3 * ti + q, c] = a_t[:, q]
        # S C a: the internal (minimal-constraint) response, rotated, then S-transformed on the left
        # only (the Jacobian rows have the internally fixed columns zeroed, so Sᵀ a != a)
        D = cov._rot_times(V)
        if cov.G is not None:
            D = D - cov.G @ (cov.H @ D)
        D /= cov.factor
        pts = np.concatenate([D[:Q * s].reshape(s, Q, -1)[:, :3], D[Q * s:].reshape(t, 3, -1)], axis=0)
        norm = np.linalg.norm(pts, axis=1)           # (points, batch)
        j = np.argmax(norm, axis=0)
        # the response is to a whitened unit bias: scale by bias / sigma (whitening: a_k = A_k / sigma_k)
        out[ks] = norm[j, c] * bias_m[ks]
        where[ks] = j
    return out, tuple(ids[j] for j in where)


def reliability(res_obs, used, redundancy, sigma_m, cov, station_ids, target_ids, *, alpha: float,
                power: float, r_min: float = 0.1, mdb_limit_sigma: float = 10.0,
                sigma_scale: float = 1.0) -> Reliability:
    """Internal and external reliability of the used observations (``redundancy`` over all
    observations, 0 for rejected ones). ``sigma_scale``: σ̂0 when the variance factor is estimated
    (the MDBs then use σ̂0 σ_k)."""
    m = res_obs.n_obs
    sig = np.asarray(sigma_m, float) * sigma_scale
    red = np.asarray(redundancy, float)
    mdb = st.minimal_detectable_bias_m(sig, red, alpha=alpha, power=power)
    bnr = st.bias_to_noise_ratio(red, alpha=alpha, power=power)
    mdb_sig = mdb / np.asarray(sigma_m, float)
    for a in (mdb, bnr, mdb_sig):
        a[~used] = np.nan
    shift = np.full(m, np.nan)
    point = [""] * m
    computed = int(used.sum()) <= MAX_EXTERNAL_OBS
    if computed:
        idx = np.flatnonzero(used)
        b = mdb[idx] / sig[idx]                     # the bias in units of its σ: the whitened response
        b = np.where(np.isfinite(b), b, np.nan)
        # shift_m = |C a_k| * MDB_k / sigma_k, a_k already divided by sigma_k; sig scaled back to a-priori
        sh, pt = external_shifts(cov, res_obs, used, station_ids, target_ids,
                                 np.nan_to_num(b, nan=0.0) * sigma_scale)
        sh[~np.isfinite(b)] = np.inf
        shift[idx] = sh
        for k, p in zip(idx, pt):
            point[k] = p
    poor = used & ((red < r_min) | (mdb_sig > mdb_limit_sigma))
    pk = np.flatnonzero(poor)
    pk = pk[np.argsort(-np.nan_to_num(mdb_sig[pk], posinf=1e300))]
    targets = []
    ti = res_obs.target_index
    u_idx = np.flatnonzero(used)
    by_t = u_idx[np.argsort(ti[u_idx], kind="stable")]           # used observations grouped by target
    bounds = np.searchsorted(ti[by_t], np.arange(res_obs.n_targets + 1))
    for j in dict.fromkeys(int(ti[k]) for k in pk):
        mine = by_t[bounds[j]:bounds[j + 1]]
        targets.append({"id": target_ids[j], "n_obs": int(mine.size),
                        "redundancy_min": float(red[mine].min()),
                        "mdb_max_m": float(np.max(mdb[mine])), "mdb_max_sigma": float(np.max(mdb_sig[mine])),
                        "shift_max_m": float(np.max(shift[mine])) if computed else None})
    return Reliability(red, mdb, mdb_sig, bnr, shift, tuple(point), float(r_min), float(mdb_limit_sigma),
                       tuple(int(k) for k in pk), tuple(targets), computed)
