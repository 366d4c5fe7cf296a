"""Batched Gauss-Newton: every trial of a Monte Carlo solved together on one network structure.

A Monte Carlo over a self-calibrating multilateration network (stations ``s``, targets ``t``,
observations ``m`` with a fixed pattern ``station_index[k], target_index[k]``) re-solves the same
least-squares problem thousands of times with distances that differ by micrometres. This module
advances all trials of a chunk together:

* the model is the distance model of the adjustment,
  ``d_k = |H_i - T_j| + o_i`` (station ``i = station_index[k]``, target ``j = target_index[k]``,
  additive offset ``o_i``), weighted by ``w_k = 1 / sigma_k**2``;
* each trial starts from the **nominal solution** (the noise-free network or the adjustment of the
  measured distances), which is valid because the perturbations are micrometres;
* the normal equations are reduced by the Schur complement over the 3x3 target blocks (closed-form
  batched 3x3 inverses), leaving a ``4s x 4s`` station/offset system per trial;
* two methods, both converging to the same fixed point, the exact weighted normal equations
  ``J(x)^T W r(x) = 0`` of every trial:

  ``"gauss-newton"`` — a full Gauss-Newton step per trial and iteration: Jacobian, Schur complement
  and Cholesky factorisation recomputed per trial (numpy stacked linalg).

  ``"frozen"`` (default) — Gauss-Newton with the normal matrix frozen at the nominal solution and
  the *exact* gradient of each trial at each iteration (a chord / simplified-Newton method). The
  fixed point is the same as Gauss-Newton's (the gradient is exact); the contraction factor per
  iteration is about ``cond * |dx| / distance`` — 0.01 to 0.1 for the paper's small volume, whose
  offsets and station coordinates move by ~0.1 mm per trial — so 4 to 6 iterations reach a 0.1 nm
  step. Trials that do not converge fall back to full Gauss-Newton. The frozen Schur complement is
  factorised once, so an
  iteration is a handful of array operations over ``(n, m)`` plus one ``(n, 4s) @ (4s, 4s)``
  product. A numba kernel does the same arithmetic in one pass when numba is installed
  (``engine="numba"``); ``engine="numpy"`` is the plain reference path the tests compare with.

* convergence is tracked per trial (largest coordinate/offset step below ``tol_m``). A trial that
  does not converge within ``max_iter`` iterations, or produces a non-finite value, is flagged in
  :attr:`BatchSolution.converged` — callers drop and count it, never keep it silently.

The datum (distances leave translation and rotation free) is applied to every trial in the same
way by :class:`Datum`: the solved network is moved rigidly so that its datum points coincide with
the nominal ones — a least-squares (Kabsch) fit over the chosen points for ``TrialDatum.inner`` (to first
order the inner-constraint, minimum-trace datum of the free-network adjustment), or the 3-2-1
definition on three stations for ``TrialDatum.three_two_one``. :meth:`BatchedNetwork.linear_covariance`
returns the first-order covariance in exactly that datum, for the MC-vs-linear validation: the
adjustment's covariance (:class:`multilat.network.adjust.covariance.NetworkCovariance`) of the nominal
network, never read by the trials.

Parameter vector layout (used by the covariance and by :func:`flatten`):
``[station xyz (3s, station-major), station offsets (s), target xyz (3t, target-major)]``, metres
(:meth:`multilat.network.model.parameter_layout.ParameterLayout.batched`); the frozen station system's is
``station_system`` (``x, y, z, offset`` per station).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.datum import ABOUT_Z_COLUMNS, helmert_basis
from multilat.network.montecarlo.trial_datum import TrialDatum
from multilat.network.model.distance import inv3, line_of_sight, range_m
from multilat.network.model.parameter_layout import XYZ, ParameterLayout, gather

__all__ = [
    "TrialDatum",
    "BatchedNetwork",
    "BatchSolution",
    "flatten",
    "numba_available",
]


# ----------------------------------------------------------------------------------------------
# small vectorised helpers

def flatten(station_xyz_m, offset_m, target_xyz_m) -> np.ndarray:
    """Parameter vectors in the module's layout.

    Parameters
    ----------
    station_xyz_m : ndarray, shape (..., s, 3)
    offset_m : ndarray, shape (..., s)
    target_xyz_m : ndarray, shape (..., t, 3)

    Returns
    -------
    ndarray, shape (..., 4s + 3t)
    """
    h = np.asarray(station_xyz_m, float)
    o = np.asarray(offset_m, float)
    tg = np.asarray(target_xyz_m, float)
    lay = ParameterLayout.batched(h.shape[-2], tg.shape[-2])
    out = np.empty(h.shape[:-2] + (lay.n,))
    out[..., lay.station_block(XYZ)] = h
    out[..., lay.station_columns("offset")] = o
    out[..., lay.target_block()] = tg
    return out


# ----------------------------------------------------------------------------------------------
# results

@dataclass(frozen=True)
class BatchSolution:
    """Solutions of ``n`` trials (already moved into the datum).

    Attributes
    ----------
    station_xyz_m : ndarray, shape (n, s, 3)
    offset_m : ndarray, shape (n, s)
    target_xyz_m : ndarray, shape (n, t, 3)
    converged : ndarray of bool, shape (n,)
        False for a trial whose last step exceeded ``tol_m`` after ``max_iter`` iterations or that
        produced a non-finite value. Such trials must be dropped and counted by the caller.
    iterations : ndarray of int, shape (n,)
        Iterations until the trial's step fell below ``tol_m`` (``max_iter`` if it never did).
    last_step_m : ndarray, shape (n,)
        Largest absolute coordinate/offset change of the last iteration, metres.
    sigma0 : ndarray, shape (n,)
        A-posteriori standard deviation of unit weight of each trial.
    retried : ndarray of bool, shape (n,), or None
        Trials re-solved by full Gauss-Newton after the frozen method did not converge.
    """

    station_xyz_m: np.ndarray
    offset_m: np.ndarray
    target_xyz_m: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    last_step_m: np.ndarray
    sigma0: np.ndarray
    retried: np.ndarray | None = None

    @property
    def n_failed(self) -> int:
        return int(np.count_nonzero(~self.converged))


# ----------------------------------------------------------------------------------------------
# the solver

def numba_available() -> bool:
    from multilat._numba import HAVE_NUMBA       # imported on first use: numba takes ~0.2 s to load

    return HAVE_NUMBA


class NetworkSizes:
    """``n_stations``, ``n_targets``, ``n_obs`` of a batched network (station_xyz_m, target_xyz_m,
    station_index): shared by :class:`BatchedNetwork` and the general
    :class:`multilat.network.montecarlo.batched_coupled.CoupledBatchedNetwork`."""

    @property
    def n_stations(self) -> int:
        return len(self.station_xyz_m)

    @property
    def n_targets(self) -> int:
        return len(self.target_xyz_m)

    @property
    def n_obs(self) -> int:
        return len(self.station_index)

    @property
    def reported_layout(self) -> ParameterLayout:
        """The reported parameter vector's columns ``[3s, s, 3t]`` (:func:`flatten`, the linear covariance)."""
        return ParameterLayout.batched(self.n_stations, self.n_targets)

    # -- linear propagation: the adjustment's covariance --------------------------------------
    def datum_rows(self):
        """``(G, E)`` of this network's datum in the adjustment layout (rigid motions of all points and
        the trials' datum conditions, :meth:`TrialDatum.constraint_matrix`), or ``(None, None)`` when the
        network has none (a control datum)."""
        if self.datum is None:
            return None, None
        adj = ParameterLayout.adjustment(self.n_stations, self.n_targets)
        e = self.datum.constraint_matrix(self.station_xyz_m, self.target_xyz_m)
        g = helmert_basis(np.concatenate([self.station_xyz_m, self.target_xyz_m]))
        if self.datum.about_z:
            g = g[:, ABOUT_Z_COLUMNS]
        etg = e.T @ self.reported_layout.datum_rows(g)
        if abs(np.linalg.det(etg)) < 1e-14 * np.linalg.norm(etg) ** etg.shape[0]:
            raise MultilatError("the datum does not fix translation and rotation (degenerate points)")
        return adj.datum_rows(g), adj.datum_rows(self.reported_layout.point_rows(e))

    @cached_property
    def nominal_covariance(self):
        """The adjustment's covariance (:class:`multilat.network.adjust.covariance.NetworkCovariance`) of
        this network at its nominal solution: the one given (``covariance=``, the adjustment the
        network was built from), else :meth:`_build_covariance`."""
        cov = self.covariance
        if cov is None:
            return self._build_covariance()
        if (cov.s, cov.t) != (self.n_stations, self.n_targets) or not (
                np.array_equal(cov.si, self.station_index) and np.array_equal(cov.ti, self.target_index)):
            raise MultilatError("covariance: not this network's (its stations, targets or observations differ)")
        return cov

    def linear_covariance(self, *, sigma_m: np.ndarray | None = None,
                          cov_m2: np.ndarray | None = None) -> np.ndarray:
        """First-order (GUM) covariance of the reported parameters (:func:`flatten`'s layout) in this
        network's datum, (p, p), m²: the adjustment's covariance of the nominal network
        (:attr:`nominal_covariance`), through the one sandwich of
        :meth:`multilat.network.adjust.covariance.NetworkCovariance.linear_covariance` when the distances'
        actual uncertainties ``sigma_m`` (or their full covariance ``cov_m2``, correlated readings)
        differ from the weights' (``self.sigma_m``). Scale bars, control and angles keep their own
        variances (each trial draws them with them)."""
        cols = self.reported_layout.index_in(ParameterLayout.adjustment(self.n_stations, self.n_targets))
        return self.nominal_covariance.linear_covariance(cols, weight_sigma_m=self.sigma_m, sigma_m=sigma_m,
                                                         cov_m2=cov_m2)


@dataclass(frozen=True)
class BatchedNetwork(NetworkSizes):
    """A fixed network structure linearised at its nominal solution, ready to solve batches.

    Parameters
    ----------
    station_index, target_index : ndarray of int, shape (m,)
        Observation pattern.
    sigma_m : ndarray, shape (m,)
        Standard uncertainty of each distance (weights ``1 / sigma**2``), metres.
    station_xyz_m : ndarray, shape (s, 3)
        Nominal station coordinates (starting point of every trial, and the datum reference).
    offset_m : ndarray, shape (s,)
        Nominal additive offsets.
    target_xyz_m : ndarray, shape (t, 3)
        Nominal target coordinates.
    datum : Datum
        Applied to every trial (default: inner over all points).
    covariance : NetworkCovariance, optional
        The adjustment's covariance of this network (the adjustment it was built from): the linear
        covariance's source (:attr:`nominal_covariance`); None: built from the nominal values.
    """

    station_index: np.ndarray
    target_index: np.ndarray
    sigma_m: np.ndarray
    station_xyz_m: np.ndarray
    offset_m: np.ndarray
    target_xyz_m: np.ndarray
    datum: "TrialDatum" = field(default_factory=lambda: TrialDatum.inner())
    #: the adjustment's covariance of this network (:attr:`nominal_covariance`), or None: built here
    covariance: object = field(default=None, repr=False, compare=False)
    # precomputed (filled in __post_init__)
    _pre: dict = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        si = np.asarray(self.station_index, np.int64)
        ti = np.asarray(self.target_index, np.int64)
        sig = np.asarray(self.sigma_m, float)
        h0 = np.asarray(self.station_xyz_m, float)
        o0 = np.asarray(self.offset_m, float)
        t0 = np.asarray(self.target_xyz_m, float)
        if h0.ndim != 2 or h0.shape[1] != 3 or t0.ndim != 2 or t0.shape[1] != 3:
            raise MultilatError("station_xyz_m and target_xyz_m must have shape (s, 3) and (t, 3)")
        s, t, m = len(h0), len(t0), len(si)
        if o0.shape != (s,):
            raise MultilatError(f"offset_m must have shape ({s},), got {o0.shape}")
        if ti.shape != (m,) or sig.shape != (m,):
            raise MultilatError("station_index, target_index and sigma_m must have the same length")
        if m == 0 or si.min() < 0 or si.max() >= s or ti.min() < 0 or ti.max() >= t:
            raise MultilatError("observation indices out of range")
        if not np.all(np.isfinite(sig)) or np.any(sig <= 0):
            raise MultilatError("sigma_m must be finite and > 0")
        if m * (s + t) > 50_000_000:
            raise MultilatError(f"network too large for the batched Monte Carlo solver ({m} observations, "
                                f"{t} targets); it is meant for networks of up to a few thousand observations")
        for name, v in (("station_xyz_m", h0), ("offset_m", o0), ("target_xyz_m", t0)):
            if not np.all(np.isfinite(v)):
                raise MultilatError(f"{name} must be finite")
        for k, v in (("station_index", si), ("target_index", ti), ("sigma_m", sig),
                     ("station_xyz_m", h0), ("offset_m", o0), ("target_xyz_m", t0)):
            object.__setattr__(self, k, v)
        object.__setattr__(self, "_pre", self._precompute())

    # -- sizes: NetworkSizes ------------------------------------------------------------------
    @property
    def n_params(self) -> int:
        return self.reported_layout.n

    @property
    def dof(self) -> int:
        """Degrees of freedom: observations minus parameters plus the 6 datum defects."""
        return self.n_obs - self.n_params + 6

    def nominal_distance_m(self) -> np.ndarray:
        """Model distances at the nominal solution, shape (m,)."""
        d = self.station_xyz_m[self.station_index] - self.target_xyz_m[self.target_index]
        return range_m(d) + self.offset_m[self.station_index]

    # -- precomputation --------------------------------------------------------------------
    def _precompute(self) -> dict:
        si, ti = self.station_index, self.target_index
        s, t, m = self.n_stations, self.n_targets, self.n_obs
        w = 1.0 / self.sigma_m**2
        with np.errstate(divide="ignore", invalid="ignore"):
            rho, u0 = line_of_sight(self.station_xyz_m[si] - self.target_xyz_m[ti])
        if np.any(rho <= 0):
            raise MultilatError("a station coincides with a target at the nominal solution")
        # incidence matrices for scatter sums (dense for small networks)
        a_s = np.zeros((m, s))
        a_s[np.arange(m), si] = 1.0
        a_t = np.zeros((m, t))
        a_t[np.arange(m), ti] = 1.0
        ntt = _target_blocks(u0[None], w, a_t)[0]                        # (t, 3, 3)
        det = np.linalg.det(ntt)
        scale = np.trace(ntt, axis1=1, axis2=2)
        bad = np.nonzero(det <= 1e-12 * scale**3)[0]
        if len(bad):
            raise MultilatError(f"target {int(bad[0])} is not determined by its observations "
                                "(fewer than 3 stations or collinear lines of sight)")
        ninv0 = inv3(ntt)
        system = ParameterLayout.station_system(s)                       # [x, y, z, offset] per station
        cols = system.station_block()
        e_pen = system.datum_rows(helmert_basis(self.station_xyz_m))
        s0 = _schur(u0[None], w, si, ti, ninv0[None], cols, a_s, a_t)[0]
        pen_scale = np.trace(s0) / system.n / max(np.trace(e_pen.T @ e_pen) / 6, 1e-300)
        pen = pen_scale * (e_pen @ e_pen.T)
        try:
            chol = np.linalg.cholesky(s0 + pen)
        except np.linalg.LinAlgError:
            raise MultilatError("the station/offset system is singular (degenerate geometry: "
                                "coplanar/collinear stations or too few targets)") from None
        s0inv = np.linalg.inv(s0 + pen)
        return dict(w=w, u0=u0, a_s=a_s, a_t=a_t, ninv0=ninv0, s0inv=s0inv, pen=pen, chol=chol, cols=cols)

    # -- linear propagation (NetworkSizes.linear_covariance) ---------------------------------
    def _build_covariance(self):
        """The adjustment's covariance of this network at its nominal solution (no adjustment given)."""
        from multilat.network.adjust.covariance import distance_covariance

        G, E = self.datum_rows()
        return distance_covariance(self.station_xyz_m, self.target_xyz_m, self.offset_m, np.zeros(self.n_stations),
                                   self.station_index, self.target_index, self.sigma_m, G=G, E=E)

    # -- batched solving -------------------------------------------------------------------
    def solve(self, distance_m: np.ndarray, *, method: str = "frozen", engine: str = "auto",
              tol_m: float = 1e-10, max_iter: int = 10, fallback: bool = True) -> BatchSolution:
        """Solve ``n`` trials with distances ``distance_m`` (shape (n, m)), all from the nominal solution.

        Parameters
        ----------
        distance_m : ndarray, shape (n, m)
            Measured (simulated) distances of each trial, metres, in the observation order.
        method : {"frozen", "gauss-newton"}
            See the module docstring; both converge to the same solution.
        engine : {"auto", "numpy", "numba"}
            ``"auto"`` uses numba for the frozen method when installed.
        tol_m : float
            A trial has converged when its largest parameter step is below this, metres.
        max_iter : int
            Iteration limit; trials still moving after it are flagged, not kept.
        fallback : bool
            With the frozen method, trials that have not converged after ``max_iter`` iterations
            (far from the nominal solution, where the frozen matrix contracts slowly) are solved again
            from the nominal solution by full Gauss-Newton (at least 20 iterations); only those that
            still fail are flagged.

        Returns
        -------
        BatchSolution (in this network's datum)
        """
        d = np.ascontiguousarray(distance_m, dtype=float)
        if d.ndim == 1:
            d = d[None]
        if d.ndim != 2 or d.shape[1] != self.n_obs:
            raise MultilatError(f"distance_m must have shape (n, {self.n_obs}), got {np.shape(distance_m)}")
        if method not in ("frozen", "gauss-newton"):
            raise MultilatError(f"method must be 'frozen' or 'gauss-newton', got {method!r}")
        if engine not in ("auto", "numpy", "numba"):
            raise MultilatError(f"engine must be auto, numpy or numba, got {engine!r}")
        if engine == "auto":
            engine = "numba" if (method == "frozen" and numba_available()) else "numpy"
        if engine == "numba" and method != "frozen":
            raise MultilatError("the numba engine implements the frozen method only")
        h, o, tg, iters, last, vtpv = self._iterate(d, method, engine, tol_m, max_iter)
        retried = np.zeros(len(d), bool)
        if method == "frozen" and fallback:
            bad = np.nonzero(~(last < tol_m))[0]
            if len(bad):   # far from the nominal solution: full Gauss-Newton for those trials
                h2, o2, t2, it2, l2, v2 = self._iterate(d[bad], "gauss-newton", "numpy", tol_m,
                                                        max(max_iter, 20))
                h[bad], o[bad], tg[bad], last[bad], vtpv[bad] = h2, o2, t2, l2, v2
                iters[bad] = iters[bad] + it2
                retried[bad] = True
        n = len(d)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            sigma0 = np.sqrt(vtpv / self.dof) if self.dof > 0 else np.full(n, np.nan)
            hd, td = self.datum.apply(h, tg, self.station_xyz_m, self.target_xyz_m,
                                      engine="numba" if engine == "numba" else "numpy")
        finite = (np.isfinite(hd).all(axis=(1, 2)) & np.isfinite(td).all(axis=(1, 2))
                  & np.isfinite(o).all(axis=1))
        converged = (last < tol_m) & finite
        return BatchSolution(hd, o, td, converged, iters, last, sigma0, retried)

    def _iterate(self, d, method, engine, tol_m, max_iter):
        """Iterate all trials from the nominal solution; raw (not datum-moved) parameters."""
        n = d.shape[0]
        s, t = self.n_stations, self.n_targets
        h = np.broadcast_to(self.station_xyz_m, (n, s, 3)).copy()
        o = np.broadcast_to(self.offset_m, (n, s)).copy()
        tg = np.broadcast_to(self.target_xyz_m, (n, t, 3)).copy()
        if engine == "numba":
            from multilat.network.montecarlo import _batched_numba as nb
            p = self._pre
            iters, last, vtpv = nb.solve_frozen(d, h, o, tg, self.station_index, self.target_index,
                                                p["w"], p["u0"], p["ninv0"], p["s0inv"], p["cols"], tol_m,
                                                max_iter)
            return h, o, tg, iters, last, vtpv
        iters = np.full(n, max_iter, np.int64)
        last = np.full(n, np.inf)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            for it in range(max_iter):
                dh, do, dt = self._step(d, h, o, tg, method)
                h += dh
                o += do
                tg += dt
                step = np.maximum(np.abs(dh).reshape(n, -1).max(axis=1),
                                  np.maximum(np.abs(do).max(axis=1), np.abs(dt).reshape(n, -1).max(axis=1)))
                step = np.where(np.isfinite(step), step, np.inf)
                newly = (step < tol_m) & (iters == max_iter)
                iters[newly] = it + 1
                last = step
                if np.all(step < tol_m):
                    break
            r = d - self._model(h, o, tg)
            vtpv = np.einsum("nm,m->n", r * r, self._pre["w"])
        return h, o, tg, iters, last, vtpv

    def _model(self, h, o, tg):
        diff = h[:, self.station_index] - tg[:, self.target_index]
        return range_m(diff) + o[:, self.station_index]

    def _step(self, d, h, o, tg, method):
        """One step (dh (n,s,3), do (n,s), dt (n,t,3)) of the chosen method (numpy path)."""
        p = self._pre
        si, ti, w, a_s, a_t = self.station_index, self.target_index, p["w"], p["a_s"], p["a_t"]
        n, cols = h.shape[0], p["cols"]
        rho, u = line_of_sight(h[:, si] - tg[:, ti])                  # (n, m), (n, m, 3)
        e = w * (d - rho - o[:, si])                                  # w r, (n, m)
        eu = e[..., None] * u
        g_h = np.einsum("nmc,ms->nsc", eu, a_s)                       # (n, s, 3)
        g_o = e @ a_s                                                 # (n, s)
        g_t = -np.einsum("nmc,mt->ntc", eu, a_t)                      # (n, t, 3)
        if method == "frozen":
            ub = np.broadcast_to(p["u0"], u.shape)
            ninv = p["ninv0"][None]
            sinv = p["s0inv"][None]
        else:
            ub = u
            ninv = inv3(_target_blocks(u, w, a_t))
            sm = _schur(u, w, si, ti, ninv, cols, a_s, a_t) + p["pen"]
            sinv = None
        y_t = np.einsum("ntab,ntb->nta", np.broadcast_to(ninv, (n,) + ninv.shape[1:]), g_t)
        sk = w * np.einsum("nmc,nmc->nm", ub, y_t[:, ti])
        gp = np.empty((n, cols.size))
        gp[:, cols[:, :3]] = g_h + np.einsum("nm,nmc,ms->nsc", sk, ub, a_s)
        gp[:, cols[:, 3]] = g_o + sk @ a_s
        if sinv is not None:
            dxp = gp @ sinv[0].T
        else:
            dxp = np.linalg.solve(sm, gp[..., None])[..., 0]
        dxp = gather(dxp, cols)                                       # (n, s, 4)
        dh, do = dxp[..., :3], dxp[..., 3]
        q = w * (np.einsum("nmc,nmc->nm", ub, dh[:, si]) + do[:, si])
        rhs = g_t + np.einsum("nm,nmc,mt->ntc", q, ub, a_t)
        dt = np.einsum("ntab,ntb->nta", np.broadcast_to(ninv, (n,) + ninv.shape[1:]), rhs)
        return dh, do, dt


def _target_blocks(u, w, a_t):
    """Target normal blocks ``sum_k w u u^T`` per target, shape (n, t, 3, 3)."""
    uu = np.einsum("nmi,nmj->nmij", u, u) * w[:, None, None]
    return np.einsum("nmij,mt->ntij", uu, a_t)


def _schur(u, w, si, ti, ninv, cols, a_s, a_t):
    """Schur complement ``N_pp - N_pt N_tt^-1 N_tp`` per trial, shape (n, 4s, 4s) (no datum), on the
    station system's columns ``cols`` (s, 4).

    Station/offset rows of observation k: ``a_k = [u_k, 1]``; ``N_pt`` block (i, j) is
    ``-sum w a u^T``. The reduction for two observations k, l of the same target j is
    ``w_k w_l (u_k^T Ninv_j u_l) a_k a_l^T`` into station block (i_k, i_l).
    """
    n, m, s = u.shape[0], u.shape[1], cols.shape[0]
    a = np.concatenate([u, np.ones((n, m, 1))], axis=2)            # (n, m, 4)
    npp = np.einsum("nmi,nmj,m,ms->nsij", a, a, w, a_s)            # diagonal station blocks
    out = np.zeros((n, s, s, 4, 4))
    idx = np.arange(s)
    out[:, idx, idx] = npp
    # pairs of observations on the same target
    kk, ll = np.nonzero(ti[:, None] == ti[None, :])
    v = np.einsum("nkab,nkb->nka", np.broadcast_to(ninv, (n,) + ninv.shape[1:])[:, ti], u)  # Ninv_j u_k
    c = np.einsum("nka,nka->nk", v[:, kk], u[:, ll]) * (w[kk] * w[ll])
    blk = np.einsum("nk,nki,nkj->nkij", c, a[:, kk], a[:, ll])      # (n, P, 4, 4)
    pair_block = si[kk] * s + si[ll]
    inc = np.zeros((len(kk), s * s))
    inc[np.arange(len(kk)), pair_block] = 1.0
    red = np.einsum("nkij,kb->nbij", blk, inc).reshape(n, s, s, 4, 4)
    out -= red
    full = np.zeros((n, cols.size, cols.size))
    full[:, cols[:, :, None, None], cols[None, None]] = out.transpose(0, 1, 3, 2, 4)
    return full
