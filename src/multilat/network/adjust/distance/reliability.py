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

from multilat.network.adjust import statistics as st
from multilat.network.model.distance import Q

__all__ = ["Reliability", "external_shifts", "largest_point_shift", "reliability", "MAX_EXTERNAL_OBS", "R_MIN",
           "MDB_LIMIT_SIGMA"]

#: an observation is poorly controlled when its redundancy number is below R_MIN or its MDB above
#: MDB_LIMIT_SIGMA times its σ (the adjustment's defaults; the design's warning uses the same)
R_MIN = 0.1
MDB_LIMIT_SIGMA = 10.0

# the coordinate shifts are computed up to this many used observations (since issue 29 they cost
# O(m s²) plus a bounded search, not O(m) each; the cap keeps the large documents as they were)
MAX_EXTERNAL_OBS = 20000


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


def external_shifts(cov, obs, used, sx_ids, tx_ids, bias_m, *, batch: int = 2048):
    """Largest point shift ``max_p |Δx_p|`` caused by a bias ``bias_m[k]`` in each used observation.

    ``cov``: the adjustment's :class:`~.covariance.NetworkCovariance` (its whitened Jacobian rows are
    the used observations' ``A_k / sigma_k``); ``bias_m`` over the used observations. The a-priori
    covariance is used (``cov.factor`` divided out; a low-rank ``extra`` term, the uncertainty of a
    reference length, is not part of the least-squares response and is left out).
    Checked against re-adjusting with the bias added (tests/test_reliability.py) and against one
    covariance product per observation (tests/test_reliability_fast.py). Returns
    ``(shift_m (mu,), point id per observation)``; ties go to the first point (stations, then targets).

    Independent targets: block algebra through the Schur form (:func:`_shifts_blocked`), O(m s²)
    plus the other targets' shifts, pruned by a bound. Coupled targets (scale bars, angles): the
    dense product in batches (those networks are small; their covariance is dense already).
    """
    from multilat.network.adjust.covariance import CoupledCovariance

    ids = list(sx_ids) + list(tx_ids)
    mu = cov.Js_w.shape[0]
    if isinstance(cov, CoupledCovariance):
        norm_max, where = _shifts_dense(cov, batch=256)
    else:
        norm_max, where = np.empty(mu), np.empty(mu, dtype=np.intp)
        ctx = _BlockContext(cov)
        for lo in range(0, mu, batch):
            ks = np.arange(lo, min(lo + batch, mu))
            norm_max[ks], where[ks] = ctx.shifts(ks)
    # the response is to a whitened unit bias: scale by bias / sigma (whitening: a_k = A_k / sigma_k)
    return norm_max * bias_m, tuple(ids[j] for j in where)


def _shifts_dense(cov, *, batch: int):
    """Largest point response ``|S C a_k|`` and its point, from the covariance product of the whole
    design row (coupled targets)."""
    s, t, n = cov.s, cov.t, cov.n
    mu = cov.Js_w.shape[0]
    out, where = np.empty(mu), np.empty(mu, dtype=np.intp)
    for lo in range(0, mu, batch):
        ks = np.arange(lo, min(lo + batch, mu))
        V = np.zeros((n, ks.size))
        c = np.arange(ks.size)
        si, ti = cov.si[ks], cov.ti[ks]
        for q in range(Q):
            V[Q * si + q, c] = cov.Js_w[ks, q]
        for q in range(3):
            V[Q * s + 3 * ti + q, c] = cov.Jt_w[ks, q]
        # S C a: the internal response, rotated, then S-transformed on the left only (the Jacobian
        # rows have the internally fixed columns zeroed, so Sᵀ a != a)
        D = cov._rotate_rows(cov._times(V), cov.R) / cov.factor
        if cov.G is not None:
            D = D - cov.G @ (cov.H @ D)
        pts = np.concatenate([D[:Q * s].reshape(s, Q, -1)[:, :3], D[Q * s:].reshape(t, 3, -1)], axis=0)
        out[ks], where[ks] = largest_point_shift(pts)
    return out, where


def largest_point_shift(shifts):
    """``shifts`` (points, 3, k): the coordinate shifts of every point caused by each of k biases.
    Returns the largest point shift ``max_p |Δx_p|`` (k,) and its point's index (k,) (ties: the
    first point). Shared by the distance path and the general layer
    (:mod:`multilat.network.adjust.general.reliability`)."""
    norm = np.linalg.norm(shifts, axis=1)           # (points, k)
    j = np.argmax(norm, axis=0)
    return norm[j, np.arange(norm.shape[1])], j


class _BlockContext:
    """What every observation's response shares (independent targets), in the final frame::

        u_k = Q_gg (E_i a_k - L_jᵀ b_k)                   station part (internal), one multi-RHS product
        h_k = H Δ_k = H_u u_k + H_j R M_j b_k             the S-transform's coefficients (d,)
        Δ_j' = T_j' [u_k; h_k] (+ R M_j b_k for j' = j),  T_j' = [-R L_j', -G_j']

    ``L_j`` the target's Schur coupling (:meth:`~.covariance.NetworkCovariance.target_coupling`).
    The largest other-target shift is searched in order of the bound ``|T_j' z| <= ||T_j'||_2 |z|``
    and stops when the bound falls below the best shift found: exact, and usually only the own
    target and the stations are evaluated.
    """

    CHUNK = 512          # targets per step of the search
    MARGIN = 1e-9        # relative slack on the bound (rounding of the evaluated norms)

    def __init__(self, cov):
        s, t = cov.s, cov.t
        self.cov, self.s, self.t = cov, s, t
        R = cov.R
        self.L = cov.target_coupling()                                        # (t, 3, 5s)
        Rb = np.eye(Q * s)
        for i in range(s):
            Rb[Q * i:Q * i + 3, Q * i:Q * i + 3] = R
        self.Rb = Rb
        RL = -np.einsum("ij,tjc->tic", R, self.L)                             # (t, 3, 5s)
        if cov.G is None:
            self.Hu = None
            T = RL
        else:
            Ht = cov.H[:, Q * s:].reshape(-1, t, 3)                           # (d, t, 3)
            self.Ht = np.ascontiguousarray(Ht.transpose(1, 0, 2))             # (t, d, 3)
            self.Hu = cov.H[:, :Q * s] @ Rb + np.einsum("dti,tic->dc", Ht, RL)
            Gt = cov.G[Q * s:].reshape(t, 3, -1)
            self.Gs = cov.G[:Q * s].reshape(s, Q, -1)[:, :3]                  # (s, 3, d)
            self.Gt = Gt
            T = np.concatenate([RL, -Gt], axis=2)
        self.T = T                                                            # (t, 3, p)
        bound = np.sqrt(np.maximum(np.linalg.eigvalsh(np.einsum("tip,tjp->tij", T, T))[:, -1], 0.0))
        self.order = np.argsort(-bound, kind="stable")
        self.bound = bound[self.order]
        self.Ts = T[self.order].reshape(-1, T.shape[2])                       # (3t, p), sorted

    def shifts(self, ks):
        """Largest point response and its point index for the observations ``ks``."""
        cov, s = self.cov, self.s
        si, ti = cov.si[ks], cov.ti[ks]
        a, b = cov.Js_w[ks], cov.Jt_w[ks]
        c = np.arange(ks.size)
        acc = -np.einsum("kic,ki->kc", self.L[ti], b)
        acc.reshape(-1, s, Q)[c, si] += a
        u = acc @ cov.Qgg.T                                                   # (k, 5s)
        own = np.einsum("ij,kj->ki", cov.R, np.einsum("kij,kj->ki", cov.Minv[ti], b))   # R M_j b
        st_xyz = (u @ self.Rb.T).reshape(-1, s, Q)[:, :, :3]                  # (k, s, 3)
        if self.Hu is None:
            z = u
        else:
            h = u @ self.Hu.T + np.einsum("kdi,ki->kd", self.Ht[ti], own)
            st_xyz = st_xyz - np.einsum("sid,kd->ksi", self.Gs, h)
            z = np.concatenate([u, h], axis=1)
        sn = np.linalg.norm(st_xyz, axis=2)                                   # (k, s)
        where = np.argmax(sn, axis=1)
        best = sn[c, where]
        on = np.linalg.norm(np.einsum("kip,kp->ki", self.T[ti], z) + own, axis=1)
        better = on > best
        best = np.where(better, on, best)
        where = np.where(better, s + ti, where)
        return self._others(z, ti, best, where)

    def _others(self, z, ti, best, where):
        """The other targets' shifts ``|T_j' z|``, largest bound first, while they can still win."""
        s, t = self.s, self.t
        zn = np.linalg.norm(z, axis=1)
        for lo in range(0, t, self.CHUNK):
            act = np.flatnonzero((self.bound[lo] * zn * (1 + self.MARGIN) >= best) & (self.bound[lo] > 0))
            if act.size == 0:
                break
            hi = min(lo + self.CHUNK, t)
            tj = self.order[lo:hi]
            val = np.linalg.norm((self.Ts[3 * lo:3 * hi] @ z[act].T).reshape(hi - lo, 3, -1), axis=1)
            val[tj[:, None] == ti[act][None, :]] = -np.inf                   # the own target: done
            vmax = val.max(axis=0)
            idx = np.where(val == vmax, (s + tj)[:, None], np.iinfo(np.intp).max).min(axis=0)
            win = (vmax > best[act]) | ((vmax == best[act]) & (idx < where[act]))
            best[act[win]], where[act[win]] = vmax[win], idx[win]
        return best, where


def reliability(res_obs, used, redundancy, sigma_m, cov, station_ids, target_ids, *, alpha: float,
                power: float, r_min: float = R_MIN, mdb_limit_sigma: float = MDB_LIMIT_SIGMA,
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
