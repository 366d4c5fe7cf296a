"""Batched Monte Carlo solver for what the plain batched solver cannot hold: heads that occupy several
stations, scale bars, weighted (and hard) control points and per-head scales.

:class:`multilat.network.montecarlo.batched.BatchedNetwork` is specialised (one offset per station, distances
only, compiled kernels). This module solves every trial of a block together for the general problem
that :func:`multilat.network.adjust.distance.adjust.adjust` solves, with the same model:

* distances ``d_k = (1 + k_h) |H_i - T_j| + o_h`` (station ``i``, target ``j``, ``h`` the head of
  station ``i``: offsets and scales belong to heads), weights ``1 / sigma_k**2``;
* scale bars ``L_b = |X_a - X_b|`` between any two points, weights ``1 / u_b**2``;
* weighted control ``c = X_pc`` (one row per coordinate), weights ``1 / s_pc**2``; hard control
  points (no uncertainty) and fixed offsets/scales are held at their nominal values;
* angle observations (azimuth, elevation; :mod:`multilat.network.model.angle_rows`) of stations with an
  orientation ``(ω, φ, κ)``, weights ``1 / σ²``; the orientations are unknowns of every trial (not
  reported: the rigid datum fit of the coordinates does not need them, since the datum conditions
  have no orientation rows).

Each trial starts from the nominal solution (the adjustment of the measured values) and iterates a
chord method: the exact gradient ``J(x)^T W r(x)`` of the trial, the normal matrix frozen at the
nominal solution (regularised by the datum conditions for a free or 3-2-1 datum). Its fixed point is
the trial's least-squares minimum (the gradient is exact); trials that have not converged after
``max_iter`` chord steps are re-solved one by one by full Gauss-Newton, and flagged only if that
fails too. The datum is applied to every trial as in the batched solver
(:class:`multilat.network.montecarlo.trial_datum.TrialDatum`: rigid fit onto the nominal points or 3-2-1); under
a control datum the control observations place the network and nothing is moved.

Unknowns (the ``P`` space): ``[station xyz (3s), head offsets (h), head scales (h), target xyz (3t),
orientations (3 per oriented station)]``; the "extra" observations of a trial are the bars' lengths,
the control coordinates and the angles (``extra_value``, ``extra_sigma``: metres or radians);
results are returned in the batched layout ``[station xyz (3s), offset per station (s), target xyz
(3t)]`` (a head's offset repeated on each of its stations) so that :mod:`multilat.network.montecarlo.propagate`
summarises both solvers the same way. Scales are estimated in every trial but not reported. Both
layouts are :class:`multilat.network.model.parameter_layout.ParameterLayout`'s (``coupled``, ``batched``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from multilat.errors import MultilatError
from multilat.network.montecarlo.batched import BatchSolution, NetworkSizes
from multilat.network.model.distance import line_of_sight, range_m
from multilat.network.model.parameter_layout import XYZ, ParameterLayout, gather

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
    covariance : NetworkCovariance or None
        The adjustment's covariance of this network (:attr:`nominal_covariance`, the linear
        covariance's source); needed with scale bars, control or angles.
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
    angle_station: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    angle_target: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    angle_kind: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    angle_value_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))
    angle_sigma_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))
    orientation_rad: np.ndarray = None      # (s, 3) nominal orientations (rows of oriented stations used)
    orientation_levelled: np.ndarray = None  # (s,) bool: levelled stations (ω, φ held at 0, κ estimated)
    datum: object = None
    #: the adjustment's covariance of this network (:attr:`nominal_covariance`), or None: built here
    covariance: object = field(default=None, repr=False)
    _pre: dict = field(default=None, repr=False)

    def __post_init__(self):
        i64 = ("station_index", "target_index", "head_index", "bar_a", "bar_b", "control_point", "control_axis",
               "angle_station", "angle_target", "angle_kind")
        for k in i64:
            object.__setattr__(self, k, np.asarray(getattr(self, k), np.int64).ravel())
        for k in ("sigma_m", "offset_m", "scale", "bar_length_m", "bar_sigma_m", "control_value_m",
                  "control_sigma_m", "angle_value_rad", "angle_sigma_rad"):
            object.__setattr__(self, k, np.asarray(getattr(self, k), float).ravel())
        for k in ("station_xyz_m", "target_xyz_m"):
            object.__setattr__(self, k, np.asarray(getattr(self, k), float).reshape(-1, 3))
        ori = np.zeros((len(self.station_xyz_m), 3)) if self.orientation_rad is None else self.orientation_rad
        object.__setattr__(self, "orientation_rad", np.asarray(ori, float).reshape(-1, 3))
        lev = np.zeros(len(self.station_xyz_m), bool) if self.orientation_levelled is None else self.orientation_levelled
        object.__setattr__(self, "orientation_levelled", np.asarray(lev, bool).reshape(-1))
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
        sig = self.extra_sigma
        if not (np.all(np.isfinite(self.sigma_m)) and np.all(self.sigma_m > 0)
                and np.all(np.isfinite(sig)) and np.all(sig > 0)):
            raise MultilatError("every sigma (distances, scale bars, control, angles) must be finite and > 0")
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

    @cached_property
    def unknown_layout(self) -> ParameterLayout:
        """The unknowns' columns: ``[station xyz, head offsets, head scales, target xyz, orientations]``."""
        return ParameterLayout.coupled(self.n_stations, self.n_targets, self.head_index, int(self.oriented.sum()))

    @property
    def n_params(self) -> int:
        """Parameters in the reported (batched) layout ``[3s, s, 3t]``."""
        return self.reported_layout.n

    @property
    def oriented(self) -> np.ndarray:
        """(s,) stations with angle observations (an orientation each)."""
        out = np.zeros(self.n_stations, bool)
        out[self.angle_station] = True
        return out

    @property
    def n_orientation(self) -> int:
        return 3 * int(self.oriented.sum())

    @property
    def n_extra(self) -> int:
        """Observations beside the distances: scale bars, control coordinates, angles."""
        return len(self.bar_a) + len(self.control_point) + len(self.angle_station)

    @property
    def extra_sigma(self) -> np.ndarray:
        """Standard uncertainties of the extra observations (m for bars and control, rad for angles)."""
        return np.concatenate([self.bar_sigma_m, self.control_sigma_m, self.angle_sigma_rad])

    @property
    def extra_value(self) -> np.ndarray:
        """The extra observations' measured values (bar lengths, control coordinates, angles)."""
        return np.concatenate([self.bar_length_m, self.control_value_m, self.angle_value_rad])

    @property
    def dof(self) -> int:
        return self.n_obs + self.n_extra - int(self._pre["free"].sum()) + (0 if self.datum is None else
                                                                            self.datum.n_defect)

    def nominal_distance_m(self) -> np.ndarray:
        x = self._pre["x0"][None]
        return self._model(x)[0]

    # -- layout ----------------------------------------------------------------------------------
    def _split(self, x):
        L = self.unknown_layout
        return (gather(x, L.station_block(XYZ)), gather(x, L.columns("head", "offset")),
                gather(x, L.columns("head", "scale")), gather(x, L.target_block()))

    def _orientations(self, x):
        """(n, s, 3) orientations of every trial (zeros for stations without angles)."""
        O = np.zeros((x.shape[0], self.n_stations, 3))
        O[:, self.oriented] = gather(x, self.unknown_layout.block("orientation"))
        return O

    def _x0(self) -> np.ndarray:
        hi = self.head_index
        first = np.unique(hi, return_index=True)[1]
        o_h, k_h = self.offset_m[first], self.scale[first]
        if not (np.allclose(self.offset_m, o_h[hi], rtol=0, atol=1e-12)
                and np.allclose(self.scale, k_h[hi], rtol=0, atol=1e-15)):
            raise MultilatError("stations of one head must have the same nominal offset and scale")
        L = self.unknown_layout
        x0 = np.empty(L.n)
        x0[L.station_block(XYZ)] = self.station_xyz_m
        x0[L.columns("head", "offset")] = o_h
        x0[L.columns("head", "scale")] = k_h
        x0[L.target_block()] = self.target_xyz_m
        x0[L.block("orientation")] = self.orientation_rad[self.oriented]
        return x0

    # -- model -----------------------------------------------------------------------------------
    def _model(self, x):
        H, o, k, T = self._split(x)
        si, ti = self.station_index, self.target_index
        hs = self.head_index[si]
        rho = range_m(H[:, si] - T[:, ti])
        return (1.0 + k[:, hs]) * rho + o[:, hs]

    def _points(self, x):
        H, _, _, T = self._split(x)
        return np.concatenate([H, T], axis=1)

    def _coupling_model(self, x):
        X = self._points(x)
        dv = X[:, self.bar_a] - X[:, self.bar_b]
        L = range_m(dv)
        return np.concatenate([L, X[:, self.control_point, self.control_axis]], axis=1)

    def _angle_parts(self, x):
        """Predicted angles (n, a) and their derivatives per trial: d/dT (n, a, 3) (= −d/dH) and
        d/d(ω, φ, κ) (n, a, 3), as :func:`multilat.network.model.angles.angle_jacobian` row by row."""
        from multilat.network.model.angles import rotation_derivatives, rotation_matrix

        H, _, _, T = self._split(x)
        O = self._orientations(x)[:, self.angle_station]                        # (n, a, 3)
        R = rotation_matrix(O)                                                    # (n, a, 3, 3)
        d = T[:, self.angle_target] - H[:, self.angle_station]                  # (n, a, 3)
        v = np.einsum("naji,naj->nai", R, d)
        vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
        h2 = vx * vx + vy * vy
        h = np.sqrt(h2)
        n2 = h2 + vz * vz
        az = self.angle_kind == 0
        pred = np.where(az, np.arctan2(vy, vx), np.arctan2(vz, h))
        dv = np.where(az[..., None], np.stack([-vy / h2, vx / h2, np.zeros_like(vx)], -1),
                      np.stack([-vz * vx / (h * n2), -vz * vy / (h * n2), h / n2], -1))
        dT = np.einsum("nak,najk->naj", dv, R)
        dR = rotation_derivatives(O)                                              # (n, a, 3, 3, 3)
        dO = np.einsum("nak,napjk,naj->nap", dv, dR, d)
        return pred, dT, dO

    def _jacobian(self, x1) -> np.ndarray:
        """Jacobian of all model values (distances, then couplings) at one point x1 (P,), (m + q, P)."""
        m, L = self.n_obs, self.unknown_layout
        H, o, k, T = (a[0] for a in self._split(x1[None]))
        si, ti = self.station_index, self.target_index
        hs = self.head_index[si]
        rho, u = line_of_sight(H[si] - T[ti])
        J = np.zeros((m + self.n_extra, L.n))
        r = np.arange(m)
        sb, tb, pc = L.station_block(XYZ), L.target_block(), L.point_columns()   # pc: stacked points
        J[r[:, None], sb[si]] = (1.0 + k[hs])[:, None] * u
        J[r[:, None], tb[ti]] = -((1.0 + k[hs])[:, None] * u)
        J[r, L.station_columns("offset")[si]] = 1.0
        J[r, L.station_columns("scale")[si]] = rho
        X = np.concatenate([H, T])
        nb = len(self.bar_a)
        if nb:
            _, ub = line_of_sight(X[self.bar_a] - X[self.bar_b])
            rb = (m + np.arange(nb))[:, None]
            J[rb, pc[self.bar_a]] += ub
            J[rb, pc[self.bar_b]] -= ub
        if len(self.control_point):
            J[m + nb + np.arange(len(self.control_point)), pc[self.control_point, self.control_axis]] = 1.0
        a = len(self.angle_station)
        if a:
            _, dT, dO = self._angle_parts(x1[None])
            ra = (m + nb + len(self.control_point) + np.arange(a))[:, None]
            slot = np.cumsum(self.oriented) - 1
            J[ra, sb[self.angle_station]] = -dT[0]
            J[ra, tb[self.angle_target]] = dT[0]
            J[ra, L.block("orientation")[slot[self.angle_station]]] = dO[0]
        return J

    # -- precomputation --------------------------------------------------------------------------
    def _precompute(self) -> dict:
        s, h, t, m = self.n_stations, self.n_heads, self.n_targets, self.n_obs
        x0 = self._x0()
        L = self.unknown_layout
        P = L.n
        from multilat.network.model.angle_rows import orientation_free_mask

        free = L.free_mask(station={f: ~self.station_held for f in XYZ},
                           head={"offset": self.offset_free, "scale": self.scale_free},
                           target={f: ~self.target_held for f in XYZ})
        free[L.block("orientation").ravel()] = orientation_free_mask(self.orientation_levelled[self.oriented])
        w_all = 1.0 / np.concatenate([self.sigma_m, self.extra_sigma]) ** 2
        J0 = self._jacobian(x0)
        N = J0.T @ (w_all[:, None] * J0)
        pen = np.zeros((P, P))
        if self.datum is not None:      # the chord matrix's datum: a penalty on the trials' conditions
            EL = self.datum.constraint_matrix(self.station_xyz_m, self.target_xyz_m)   # reported layout
            nd = EL.shape[1]
            E = L.datum_rows(self.reported_layout.point_rows(EL))
            ef = E[free]
            c = np.trace(N[np.ix_(free, free)]) / free.sum() / max(np.trace(ef.T @ ef) / nd, 1e-300)
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
        a = len(self.angle_station)
        ang_s = np.zeros((a, s + t))                       # angle row -> its station (stacked points)
        ang_s[np.arange(a), self.angle_station] = 1.0
        ang_t = np.zeros((a, s + t))                       # angle row -> its target
        ang_t[np.arange(a), s + self.angle_target] = 1.0
        ang_slot = np.zeros((a, int(self.oriented.sum())))   # angle row -> its station's orientation slot
        ang_slot[np.arange(a), (np.cumsum(self.oriented) - 1)[self.angle_station]] = 1.0
        c_in = np.zeros((len(self.control_point), s + t, 3))      # control row -> its point's coordinate
        c_in[np.arange(len(self.control_point)), self.control_point, self.control_axis] = 1.0
        return dict(x0=x0, free=free, w_all=w_all, pen=pen, Ninv=Ninv,
                    a_s=a_s, a_t=a_t, a_h=a_h, b_pm=b_pm, c_in=c_in, ang_s=ang_s, ang_t=ang_t, ang_slot=ang_slot,
                    scale_len=float(np.max(np.abs(self.nominal_distance_m_raw(x0)))))

    def nominal_distance_m_raw(self, x0) -> np.ndarray:
        return self._model(x0[None])[0]

    # -- gradient --------------------------------------------------------------------------------
    def _gradient(self, x, d, c):
        """Gradient ``J^T W r`` (n, P) and ``r^T W r`` (n,) of every trial."""
        p = self._pre
        s, t, m, L = self.n_stations, self.n_targets, self.n_obs, self.unknown_layout
        n = x.shape[0]
        H, o, k, T = self._split(x)
        si, ti = self.station_index, self.target_index
        hs = self.head_index[si]
        w = p["w_all"]
        rho, u = line_of_sight(H[:, si] - T[:, ti])
        r = d - (1.0 + k[:, hs]) * rho - o[:, hs]
        e = w[:m] * r
        vtpv = np.einsum("nm,nm->n", e, r)
        eu = (e * (1.0 + k[:, hs]))[..., None] * u
        eut = eu.transpose(0, 2, 1)                                               # (n, 3, m)
        gX = np.concatenate([eut @ p["a_s"], -(eut @ p["a_t"])], axis=2).transpose(0, 2, 1)   # (n, s + t, 3)
        g_o = e @ p["a_h"]
        g_k = (e * rho) @ p["a_h"]
        nb, nc, na = len(self.bar_a), len(self.control_point), len(self.angle_station)
        g_or = np.zeros((n,) + L.block("orientation").shape)
        if nb + nc:
            X = np.concatenate([H, T], axis=1)
            rc = c[:, :nb + nc] - self._coupling_model(x)
            ec = w[m:m + nb + nc] * rc
            vtpv = vtpv + np.einsum("nq,nq->n", ec, rc)
            if nb:
                _, ub = line_of_sight(X[:, self.bar_a] - X[:, self.bar_b])
                gX = gX + np.einsum("nbc,bp->npc", ec[:, :nb, None] * ub, p["b_pm"])
            if nc:
                gX = gX + (ec[:, nb:] @ p["c_in"].reshape(nc, -1)).reshape(n, s + t, 3)
        if na:
            pred, dT, dO = self._angle_parts(x)
            ra = c[:, nb + nc:] - pred
            ra = np.where(self.angle_kind == 0, (ra + np.pi) % (2.0 * np.pi) - np.pi, ra)   # wrapped azimuths
            ea = w[m + nb + nc:] * ra
            vtpv = vtpv + np.einsum("na,na->n", ea, ra)
            eT = ea[..., None] * dT                                                  # (n, a, 3)
            gX = gX + np.einsum("nac,ap->npc", eT, p["ang_t"]) - np.einsum("nac,ap->npc", eT, p["ang_s"])
            g_or = np.einsum("nac,ak->nkc", ea[..., None] * dO, p["ang_slot"])
        g = np.empty((n, L.n))
        g[:, L.point_columns()] = gX
        g[:, L.columns("head", "offset")] = g_o
        g[:, L.columns("head", "scale")] = g_k
        g[:, L.block("orientation")] = g_or
        return g * p["free"], vtpv

    def _step_size(self, dx):
        L = self.unknown_layout
        a = np.abs(dx)
        a[:, L.columns("head", "scale")] *= self._pre["scale_len"]
        a[:, L.block("orientation").ravel()] *= self._pre["scale_len"]          # orientations, rad x length
        return a.max(axis=1)

    # -- solving ---------------------------------------------------------------------------------
    def solve(self, distance_m: np.ndarray, *, extra: np.ndarray | None = None, tol_m: float = 1e-10,
              max_iter: int = 10, fallback: bool = True) -> BatchSolution:
        """Solve ``n`` trials: distances (n, m) and the extra observations' values (n, q: bar lengths,
        control coordinates, angles; default their measured values). Returns the solutions in the
        datum, offsets per station."""
        d = np.ascontiguousarray(distance_m, dtype=float)
        if d.ndim == 1:
            d = d[None]
        n = d.shape[0]
        if d.shape[1] != self.n_obs:
            raise MultilatError(f"distance_m must have shape (n, {self.n_obs}), got {np.shape(distance_m)}")
        q = self.n_extra
        c = (np.broadcast_to(self.extra_value, (n, q)) if extra is None
             else np.asarray(extra, float).reshape(n, q))
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

    # -- linear propagation (NetworkSizes.linear_covariance) ---------------------------------------
    def _build_covariance(self):
        """The adjustment's covariance of this network at its nominal solution when no adjustment was
        given: distances only (heads tied, held offsets, scales and points); the couplings' and angles'
        rows are the adjustment's own (:func:`multilat.network.montecarlo.propagate.problem_from_observations`
        passes its covariance)."""
        if self.n_extra:
            raise MultilatError("the linear covariance of a network with scale bars, weighted control or angles "
                                "is its adjustment's: build it with covariance=the adjustment's covariance "
                                "(propagate.problem_from_observations does)")
        from multilat.network.adjust.covariance import distance_covariance
        from multilat.network.model.parameter_layout import STATION_FIELDS

        sf = np.ones((self.n_stations, len(STATION_FIELDS)), bool)
        sf[:, :3] = ~self.station_held[:, None]
        sf[:, STATION_FIELDS.index("offset")] = self.offset_free[self.head_index]
        sf[:, STATION_FIELDS.index("scale")] = self.scale_free[self.head_index]
        G, E = self.datum_rows()
        return distance_covariance(self.station_xyz_m, self.target_xyz_m, self.offset_m, self.scale,
                                   self.station_index, self.target_index, self.sigma_m, station_free=sf,
                                   target_free=~self.target_held, head_index=self.head_index, G=G, E=E)
