"""Batched Monte Carlo solver for what the plain batched solver cannot hold: heads that occupy several
stations, scale bars, weighted (and hard) control points and per-head scales.

:class:`multilat.network.batched.BatchedNetwork` is specialised (one offset per station, distances
only, compiled kernels). This module solves every trial of a block together for the general problem
that :func:`multilat.network.adjust.adjust` solves, with the same model:

* distances ``d_k = (1 + k_h) |H_i - T_j| + o_h`` (station ``i``, target ``j``, ``h`` the head of
  station ``i``: offsets and scales belong to heads), weights ``1 / sigma_k**2``;
* scale bars ``L_b = |X_a - X_b|`` between any two points, weights ``1 / u_b**2``;
* weighted control ``c = X_pc`` (one row per coordinate), weights ``1 / s_pc**2``; hard control
  points (no uncertainty) and fixed offsets/scales are held at their nominal values.

Each trial starts from the nominal solution (the adjustment of the measured values) and iterates a
chord method: the exact gradient ``J(x)^T W r(x)`` of the trial, the normal matrix frozen at the
nominal solution (regularised by the datum conditions for a free or 3-2-1 datum). Its fixed point is
the trial's least-squares minimum (the gradient is exact); trials that have not converged after
``max_iter`` chord steps are re-solved one by one by full Gauss-Newton, and flagged only if that
fails too. The datum is applied to every trial as in the batched solver
(:class:`multilat.network.trial_datum.TrialDatum`: rigid fit onto the nominal points or 3-2-1); under
a control datum the control observations place the network and nothing is moved.

Unknowns (the ``P`` space): ``[station xyz (3s), head offsets (h), head scales (h), target xyz (3t)]``;
results are returned in the batched layout ``[station xyz (3s), offset per station (s), target xyz
(3t)]`` (a head's offset repeated on each of its stations) so that :mod:`multilat.network.propagate`
summarises both solvers the same way. Scales are estimated in every trial but not reported.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from multilat.errors import MultilatError
from multilat.network.batched import BatchSolution, NetworkSizes
from multilat.network.datum import helmert_basis

__all__ = ["CoupledBatchedNetwork"]


@dataclass(frozen=True, eq=False)
class CoupledBatchedNetwork(NetworkSizes):
    """A network of heads, distances, scale bars and control, linearised at its nominal solution.

    Parameters
    ----------
    station_index, target_index : ndarray of int, shape (m,)
    sigma_m : ndarray, shape (m,)
        Distances' standard uncertainties (weights), metres.
    head_index : ndarray of int, shape (s,)
        Head of each station (``0..h-1``).
    station_xyz_m (s, 3), offset_m (s,), scale (s,), target_xyz_m (t, 3) : nominal solution
        (per-station offsets and scales; stations of one head must carry equal values).
    station_held (s,), target_held (t,) : bool
        Hard control points (held at their nominal coordinates).
    offset_free (h,), scale_free (h,) : bool
        Which head offsets and scales are estimated.
    bar_a, bar_b : ndarray of int, shape (nb,)
        Scale bars' end points, indices into the stacked ``[stations; targets]``.
    bar_length_m, bar_sigma_m : ndarray, shape (nb,)
    control_point, control_axis : ndarray of int, shape (nc,)
        Weighted control coordinates: point index (stacked) and axis (0, 1, 2).
    control_value_m, control_sigma_m : ndarray, shape (nc,)
    datum : TrialDatum or None
        None under a control datum (the control observations place the network).
    """

    station_index: np.ndarray
    target_index: np.ndarray
    sigma_m: np.ndarray
    head_index: np.ndarray
    station_xyz_m: np.ndarray
    offset_m: np.ndarray
    scale: np.ndarray
    target_xyz_m: np.ndarray
    station_held: np.ndarray
    target_held: np.ndarray
    offset_free: np.ndarray
    scale_free: np.ndarray
    bar_a: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    bar_b: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    bar_length_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    bar_sigma_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    control_point: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    control_axis: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    control_value_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    control_sigma_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    datum: object = None
    _pre: dict = field(default=None, repr=False)

    def __post_init__(self):
        i64 = ("station_index", "target_index", "head_index", "bar_a", "bar_b", "control_point", "control_axis")
        for k in i64:
            object.__setattr__(self, k, np.asarray(getattr(self, k), np.int64).ravel())
        for k in ("sigma_m", "offset_m", "scale", "bar_length_m", "bar_sigma_m", "control_value_m",
                  "control_sigma_m"):
            object.__setattr__(self, k, np.asarray(getattr(self, k), float).ravel())
        for k in ("station_xyz_m", "target_xyz_m"):
            object.__setattr__(self, k, np.asarray(getattr(self, k), float).reshape(-1, 3))
        for k in ("station_held", "target_held", "offset_free", "scale_free"):
            object.__setattr__(self, k, np.asarray(getattr(self, k), bool).ravel())
        s, t, m = self.n_stations, self.n_targets, self.n_obs
        h = self.n_heads
        if self.target_index.shape != (m,) or self.sigma_m.shape != (m,) or self.head_index.shape != (s,):
            raise MultilatError("station_index, target_index, sigma_m (m,) and head_index (s,) disagree")
        if m == 0 or self.station_index.max() >= s or self.target_index.max() >= t:
            raise MultilatError("observation indices out of range")
        if self.offset_free.shape != (h,) or self.scale_free.shape != (h,):
            raise MultilatError("offset_free and scale_free need one entry per head")
        sig = self.coupling_sigma_m
        if not (np.all(np.isfinite(self.sigma_m)) and np.all(self.sigma_m > 0)
                and np.all(np.isfinite(sig)) and np.all(sig > 0)):
            raise MultilatError("every sigma (distances, scale bars, control) must be finite and > 0")
        if m * (s + t) > 50_000_000:
            raise MultilatError(f"network too large for the batched Monte Carlo solver ({m} observations, "
                                f"{t} targets)")
        object.__setattr__(self, "_pre", self._precompute())

    #: how propagate's JSON names this solver (``solver``)
    solver_name = "batched-coupled"

    # -- sizes (n_stations, n_targets, n_obs: NetworkSizes) ----------------------------------------
    @property
    def n_heads(self) -> int:
        return int(self.head_index.max()) + 1 if self.head_index.size else 0

    @property
    def n_params(self) -> int:
        """Parameters in the reported (batched) layout ``[3s, s, 3t]``."""
        return 4 * self.n_stations + 3 * self.n_targets

    @property
    def n_couplings(self) -> int:
        return len(self.bar_a) + len(self.control_point)

    @property
    def coupling_sigma_m(self) -> np.ndarray:
        return np.concatenate([self.bar_sigma_m, self.control_sigma_m])

    @property
    def coupling_value_m(self) -> np.ndarray:
        """The couplings' observed values (bar lengths, control coordinates), metres."""
        return np.concatenate([self.bar_length_m, self.control_value_m])

    @property
    def dof(self) -> int:
        return self.n_obs + self.n_couplings - int(self._pre["free"].sum()) + (0 if self.datum is None else 6)

    def nominal_distance_m(self) -> np.ndarray:
        x = self._pre["x0"][None]
        return self._model(x)[0]

    # -- layout ----------------------------------------------------------------------------------
    def _split(self, x):
        s, h, t = self.n_stations, self.n_heads, self.n_targets
        n = x.shape[0]
        return (x[:, :3 * s].reshape(n, s, 3), x[:, 3 * s:3 * s + h], x[:, 3 * s + h:3 * s + 2 * h],
                x[:, 3 * s + 2 * h:].reshape(n, t, 3))

    def _x0(self) -> np.ndarray:
        hi = self.head_index
        first = np.unique(hi, return_index=True)[1]
        o_h, k_h = self.offset_m[first], self.scale[first]
        if not (np.allclose(self.offset_m, o_h[hi], rtol=0, atol=1e-12)
                and np.allclose(self.scale, k_h[hi], rtol=0, atol=1e-15)):
            raise MultilatError("stations of one head must have the same nominal offset and scale")
        return np.concatenate([self.station_xyz_m.ravel(), o_h, k_h, self.target_xyz_m.ravel()])

    def _layout_map(self) -> np.ndarray:
        """``M`` (4s + 3t, P): the reported layout from the P space."""
        s, h, t = self.n_stations, self.n_heads, self.n_targets
        M = np.zeros((4 * s + 3 * t, 3 * s + 2 * h + 3 * t))
        M[np.arange(3 * s), np.arange(3 * s)] = 1.0
        M[3 * s + np.arange(s), 3 * s + self.head_index] = 1.0
        M[4 * s + np.arange(3 * t), 3 * s + 2 * h + np.arange(3 * t)] = 1.0
        return M

    # -- model -----------------------------------------------------------------------------------
    def _model(self, x):
        H, o, k, T = self._split(x)
        si, ti = self.station_index, self.target_index
        hs = self.head_index[si]
        diff = H[:, si] - T[:, ti]
        rho = np.sqrt(np.einsum("nmi,nmi->nm", diff, diff))
        return (1.0 + k[:, hs]) * rho + o[:, hs]

    def _points(self, x):
        H, _, _, T = self._split(x)
        return np.concatenate([H, T], axis=1)

    def _coupling_model(self, x):
        X = self._points(x)
        dv = X[:, self.bar_a] - X[:, self.bar_b]
        L = np.sqrt(np.einsum("nbi,nbi->nb", dv, dv))
        return np.concatenate([L, X[:, self.control_point, self.control_axis]], axis=1)

    def _jacobian(self, x1) -> np.ndarray:
        """Jacobian of all model values (distances, then couplings) at one point x1 (P,), (m + q, P)."""
        s, h, t, m = self.n_stations, self.n_heads, self.n_targets, self.n_obs
        P = x1.size
        H, o, k, T = (a[0] for a in self._split(x1[None]))
        si, ti = self.station_index, self.target_index
        hs = self.head_index[si]
        diff = H[si] - T[ti]
        rho = np.linalg.norm(diff, axis=1)
        u = diff / rho[:, None]
        J = np.zeros((m + self.n_couplings, P))
        r = np.arange(m)
        for c in range(3):
            J[r, 3 * si + c] = (1.0 + k[hs]) * u[:, c]
            J[r, 3 * s + 2 * h + 3 * ti + c] = -(1.0 + k[hs]) * u[:, c]
        J[r, 3 * s + hs] = 1.0
        J[r, 3 * s + h + hs] = rho
        X = np.concatenate([H, T])
        col = np.concatenate([3 * np.arange(s), 3 * s + 2 * h + 3 * np.arange(t)])   # point -> first column
        nb = len(self.bar_a)
        if nb:
            dv = X[self.bar_a] - X[self.bar_b]
            ub = dv / np.linalg.norm(dv, axis=1)[:, None]
            rb = m + np.arange(nb)
            for c in range(3):
                J[rb, col[self.bar_a] + c] += ub[:, c]
                J[rb, col[self.bar_b] + c] -= ub[:, c]
        if len(self.control_point):
            J[m + nb + np.arange(len(self.control_point)), col[self.control_point] + self.control_axis] = 1.0
        return J

    # -- precomputation --------------------------------------------------------------------------
    def _precompute(self) -> dict:
        s, h, t, m = self.n_stations, self.n_heads, self.n_targets, self.n_obs
        x0 = self._x0()
        P = x0.size
        free = np.concatenate([np.repeat(~self.station_held, 3), self.offset_free, self.scale_free,
                               np.repeat(~self.target_held, 3)])
        w_all = 1.0 / np.concatenate([self.sigma_m, self.coupling_sigma_m]) ** 2
        J0 = self._jacobian(x0)
        N = J0.T @ (w_all[:, None] * J0)
        E = G = None
        pen = np.zeros((P, P))
        if self.datum is not None:
            EL = self.datum.constraint_matrix(self.station_xyz_m, self.target_xyz_m)
            E = np.zeros((P, 6))
            E[:3 * s] = EL[:3 * s]
            E[3 * s + 2 * h:] = EL[4 * s:]
            gp = helmert_basis(np.concatenate([self.station_xyz_m, self.target_xyz_m]))
            G = np.zeros((P, 6))
            G[:3 * s] = gp[:3 * s]
            G[3 * s + 2 * h:] = gp[3 * s:]
            ef = E[free]
            c = np.trace(N[np.ix_(free, free)]) / free.sum() / max(np.trace(ef.T @ ef) / 6, 1e-300)
            pen = c * (E @ E.T)
        Nf = (N + pen)[np.ix_(free, free)]
        try:
            np.linalg.cholesky(Nf)
        except np.linalg.LinAlgError:
            raise MultilatError("the Monte Carlo's normal matrix is singular (the datum or the "
                                "observations do not determine every parameter)") from None
        Ninv = np.zeros((P, P))
        Ninv[np.ix_(free, free)] = np.linalg.inv(Nf)
        # incidence matrices for the scatter sums of the gradient
        a_s = np.zeros((m, s))
        a_s[np.arange(m), self.station_index] = 1.0
        a_t = np.zeros((m, t))
        a_t[np.arange(m), self.target_index] = 1.0
        a_h = np.zeros((m, h))
        a_h[np.arange(m), self.head_index[self.station_index]] = 1.0
        b_pm = np.zeros((len(self.bar_a), s + t))
        b_pm[np.arange(len(self.bar_a)), self.bar_a] += 1.0
        b_pm[np.arange(len(self.bar_a)), self.bar_b] -= 1.0
        c_in = np.zeros((len(self.control_point), 3 * (s + t)))
        c_in[np.arange(len(self.control_point)), 3 * self.control_point + self.control_axis] = 1.0
        return dict(x0=x0, free=free, w_all=w_all, J0=J0, N=N, pen=pen, Ninv=Ninv, E=E, G=G,
                    a_s=a_s, a_t=a_t, a_h=a_h, b_pm=b_pm, c_in=c_in,
                    scale_len=float(np.max(np.abs(self.nominal_distance_m_raw(x0)))))

    def nominal_distance_m_raw(self, x0) -> np.ndarray:
        return self._model(x0[None])[0]

    # -- gradient --------------------------------------------------------------------------------
    def _gradient(self, x, d, c):
        """Gradient ``J^T W r`` (n, P) and ``r^T W r`` (n,) of every trial."""
        p = self._pre
        s, t, m = self.n_stations, self.n_targets, self.n_obs
        n = x.shape[0]
        H, o, k, T = self._split(x)
        si, ti = self.station_index, self.target_index
        hs = self.head_index[si]
        w = p["w_all"]
        diff = H[:, si] - T[:, ti]
        rho = np.sqrt(np.einsum("nmi,nmi->nm", diff, diff))
        u = diff / rho[..., None]
        r = d - (1.0 + k[:, hs]) * rho - o[:, hs]
        e = w[:m] * r
        vtpv = np.einsum("nm,nm->n", e, r)
        eu = (e * (1.0 + k[:, hs]))[..., None] * u
        eut = eu.transpose(0, 2, 1)                                               # (n, 3, m)
        gX = np.concatenate([eut @ p["a_s"], -(eut @ p["a_t"])], axis=2).transpose(0, 2, 1)   # (n, s + t, 3)
        g_o = e @ p["a_h"]
        g_k = (e * rho) @ p["a_h"]
        nb = len(self.bar_a)
        if self.n_couplings:
            X = np.concatenate([H, T], axis=1)
            rc = c - self._coupling_model(x)
            ec = w[m:] * rc
            vtpv = vtpv + np.einsum("nq,nq->n", ec, rc)
            if nb:
                dv = X[:, self.bar_a] - X[:, self.bar_b]
                ub = dv / np.sqrt(np.einsum("nbi,nbi->nb", dv, dv))[..., None]
                gX = gX + np.einsum("nbc,bp->npc", ec[:, :nb, None] * ub, p["b_pm"])
            if len(self.control_point):
                gX = gX + (ec[:, nb:] @ p["c_in"]).reshape(n, s + t, 3)
        g = np.concatenate([gX[:, :s].reshape(n, 3 * s), g_o, g_k, gX[:, s:].reshape(n, 3 * t)], axis=1)
        return g * p["free"], vtpv

    def _step_size(self, dx):
        s, h = self.n_stations, self.n_heads
        a = np.abs(dx)
        a[:, 3 * s + h:3 * s + 2 * h] *= self._pre["scale_len"]
        return a.max(axis=1)

    # -- solving ---------------------------------------------------------------------------------
    def solve(self, distance_m: np.ndarray, *, couplings: np.ndarray | None = None, tol_m: float = 1e-10,
              max_iter: int = 10, fallback: bool = True) -> BatchSolution:
        """Solve ``n`` trials: distances (n, m) and the couplings' observed values (n, q) (default:
        their nominal values). Returns the solutions in the datum, offsets per station."""
        d = np.ascontiguousarray(distance_m, dtype=float)
        if d.ndim == 1:
            d = d[None]
        n = d.shape[0]
        if d.shape[1] != self.n_obs:
            raise MultilatError(f"distance_m must have shape (n, {self.n_obs}), got {np.shape(distance_m)}")
        q = self.n_couplings
        c = (np.broadcast_to(self.coupling_value_m, (n, q)) if couplings is None
             else np.asarray(couplings, float).reshape(n, q))
        p = self._pre
        x = np.broadcast_to(p["x0"], (n, p["x0"].size)).copy()
        iters = np.full(n, max_iter, np.int64)
        last = np.full(n, np.inf)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            for it in range(max_iter):
                g, _ = self._gradient(x, d, c)
                dx = g @ p["Ninv"]
                x += dx
                step = self._step_size(dx)
                step = np.where(np.isfinite(step), step, np.inf)
                iters[(step < tol_m) & (iters == max_iter)] = it + 1
                last = step
                if np.all(step < tol_m):
                    break
        retried = np.zeros(n, bool)
        if fallback:
            for i in np.nonzero(~(last < tol_m))[0]:
                x[i], last[i], k = self._gauss_newton(d[i], c[i], tol_m, max(max_iter, 20))
                iters[i] += k
                retried[i] = True
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            _, vtpv = self._gradient(x, d, c)
            sigma0 = np.sqrt(vtpv / self.dof) if self.dof > 0 else np.full(n, np.nan)
            H, o, _, T = self._split(x)
            if self.datum is not None:
                H, T = self.datum.apply(H, T, self.station_xyz_m, self.target_xyz_m)
        off = o[:, self.head_index]
        finite = np.isfinite(H).all(axis=(1, 2)) & np.isfinite(T).all(axis=(1, 2)) & np.isfinite(off).all(axis=1)
        return BatchSolution(H, off, T, (last < tol_m) & finite, iters, last, sigma0, retried)

    def _gauss_newton(self, d1, c1, tol_m, max_iter):
        """Full Gauss-Newton for one trial from the nominal solution: (x, last step, iterations)."""
        p = self._pre
        free = p["free"]
        x = p["x0"].copy()
        w = p["w_all"]
        step = np.inf
        for it in range(1, max_iter + 1):
            J = self._jacobian(x)
            g, _ = self._gradient(x[None], d1[None], c1[None])
            N = (J.T @ (w[:, None] * J) + p["pen"])[np.ix_(free, free)]
            dx = np.zeros_like(x)
            try:
                dx[free] = np.linalg.solve(N, g[0][free])
            except np.linalg.LinAlgError:
                return x, np.inf, it
            x = x + dx
            step = float(self._step_size(dx[None])[0])
            if not np.isfinite(step):
                return x, np.inf, it
            if step < tol_m:
                return x, step, it
        return x, step, max_iter

    # -- linear propagation ------------------------------------------------------------------------
    def linear_covariance(self, *, sigma_m: np.ndarray | None = None,
                          cov_m2: np.ndarray | None = None) -> np.ndarray:
        """First-order covariance in the reported layout (4s + 3t, 4s + 3t), m², in this datum.

        ``Q = S N^+ J^T W C W J N^+ S^T`` with the distances' covariance ``C`` (``sigma_m`` or the
        full ``cov_m2``; default the weights' sigmas) beside the couplings' own variances (each trial
        draws them with their uncertainties), ``S`` the S-transformation onto the datum (none under
        control), mapped to the per-station offsets of the layout.
        """
        p = self._pre
        J, w = p["J0"], p["w_all"]
        P = J.shape[1]
        q = p["Ninv"]
        if sigma_m is not None or cov_m2 is not None:
            m = self.n_obs
            C = np.zeros((len(w), len(w)))
            if cov_m2 is not None:
                C[:m, :m] = np.asarray(cov_m2, float)
            else:
                C[np.arange(m), np.arange(m)] = np.asarray(sigma_m, float) ** 2
            C[np.arange(m, len(w)), np.arange(m, len(w))] = self.coupling_sigma_m ** 2
            jw = (J * w[:, None]).T
            q = q @ (jw @ C @ jw.T) @ q
        if self.datum is not None:
            E, G = p["E"], p["G"]
            etg = E.T @ G
            S = np.eye(P) - G @ np.linalg.solve(etg, E.T)
            q = S @ q @ S.T
        M = self._layout_map()
        return M @ q @ M.T
