"""Self-calibrating multilateration: one least-squares adjustment for station coordinates, target
coordinates and station offsets (and optionally scales) from distances alone, with statistics.

Entry point :func:`adjust`; the result is an :class:`AdjustmentResult` (frozen dataclass).
Model and costs: :mod:`multilat.network.model`; datum: :mod:`multilat.network.datum`;
statistics: :mod:`multilat.network.statistics`; solvability: :mod:`multilat.network.solvability`.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from multilat.errors import MultilatError
from multilat.network import statistics as st
from multilat.network.covariance import NetworkCovariance
from multilat.network.data import Observations, Points, ReferenceLengths
from multilat.network.datum import (Datum, apply_rigid, frame_321, helmert_basis, parse_datum,
                                    rigid_fit)
from multilat.network.model import (COSTS, Q, back_substitute, reduced_normal_equations,
                                    residuals_and_jacobian)
from multilat.network.solvability import (CONDITION_LIMIT, check_structure, diagnose_degeneracy,
                                          flat_geometry)

__all__ = ["adjust", "AdjustmentResult", "Outlier", "InterpointDistance", "Start"]


@dataclass(frozen=True)
class Start:
    """Initial values (any object with these three attributes is accepted by :func:`adjust`)."""

    station_xyz_m: np.ndarray
    target_xyz_m: np.ndarray
    offset_m: np.ndarray


@dataclass(frozen=True)
class Outlier:
    """An observation rejected by data snooping: ``w`` its normalised residual when rejected,
    ``residual_m`` observed minus computed in the final adjustment (without it)."""

    station: str
    target: str
    w: float
    residual_m: float
    mdb_m: float


@dataclass(frozen=True)
class InterpointDistance:
    """Distance between two points of the adjusted network and its standard uncertainty, compared to
    a reference length when given (``difference_m = length_m - reference_m``)."""

    target_a: str
    target_b: str
    length_m: float
    u_m: float
    reference_m: float | None = None
    reference_u_m: float | None = None
    difference_m: float | None = None


@dataclass(frozen=True, eq=False)
class AdjustmentResult:
    """Result of :func:`adjust`. Arrays are in the order of ``obs.station_ids`` / ``obs.target_ids``.

    Attributes
    ----------
    obs : Observations  all observations given (including rejected ones)
    used : ndarray of bool (m,)  False for observations rejected by data snooping
    datum : Datum
    cost : str  "distance" or "squared"
    station_xyz_m : (s, 3) ; target_xyz_m : (t, 3)   adjusted coordinates in the datum frame, m
    offset_m : (s,)  additive instrument offsets, m ; offset_estimated : (s,) bool
    scale : (s,)  scale per station (0 when not estimated) ; scale_estimated : (s,) bool
    station_cov_m2 : (s, 3, 3) ; target_cov_m2 : (t, 3, 3)   point covariances in the datum, m²
    global_cov : (5s, 5s)  covariance of [x, y, z, offset, scale] per station (datum)
    offset_std_m : (s,) ; scale_std : (s,)
    residuals_m : (m,)  observed minus computed (``"squared"``: still in metres, d_obs - d_model)
    redundancy : (m,)  redundancy numbers (0 for rejected observations)
    w : (m,)  Baarda's normalised residuals (0 for rejected or uncontrolled observations)
    mdb_m : (m,)  minimal detectable biases (alpha, power), m
    sigma0 : float  a-posteriori standard deviation of unit weight (distance cost: dimensionless)
    dof : int
    global_test : statistics.GlobalTest
    outliers : tuple of Outlier  rejected by data snooping, in order of rejection
    unlocated : tuple of Outlier  a w-test failure that was not rejected: either it cannot be
        located (these observations' w-tests are perfectly correlated, e.g. the 4 distances to a
        target seen by only 4 stations) or rejecting it would leave the network unsolvable or a
        point without redundancy; empty when snooping ended normally
    unlocated_reason : str  why ``unlocated`` was not rejected (one phrase; "" when empty)
    snooping : bool  whether data snooping was run (not for the ``"squared"`` cost, nor when off)
    alpha, power : float  w-test significance and power used for the MDBs
    iterations : int ; condition : float (unit-diagonal reduced normal matrix)
    covariance : NetworkCovariance  any block of the full covariance in the datum
    """

    obs: Observations
    used: np.ndarray
    datum: Datum
    cost: str
    station_xyz_m: np.ndarray
    target_xyz_m: np.ndarray
    offset_m: np.ndarray
    offset_estimated: np.ndarray
    scale: np.ndarray
    scale_estimated: np.ndarray
    station_cov_m2: np.ndarray
    target_cov_m2: np.ndarray
    global_cov: np.ndarray
    offset_std_m: np.ndarray
    scale_std: np.ndarray
    residuals_m: np.ndarray
    redundancy: np.ndarray
    w: np.ndarray
    mdb_m: np.ndarray
    sigma0: float
    dof: int
    global_test: st.GlobalTest
    outliers: tuple
    unlocated: tuple
    alpha: float
    power: float
    iterations: int
    condition: float
    covariance: NetworkCovariance = field(repr=False)
    unlocated_reason: str = ""
    snooping: bool = True

    @property
    def sigma0_unit(self) -> str:
        """Unit of ``sigma0``: ``"1"`` for the weighted distance cost (a ratio to the a-priori
        uncertainties), ``"m^2"`` for the unweighted squared-distance cost (eq. 6)."""
        return "1" if self.cost == "distance" else "m^2"

    # ------------------------------------------------------------ derived quantities
    @property
    def station_ids(self):
        return self.obs.station_ids

    @property
    def target_ids(self):
        return self.obs.target_ids

    def point_index(self, ident: str) -> tuple[str, int]:
        """``("station", i)`` or ``("target", j)`` of a point id."""
        if ident in self.obs.station_ids:
            return "station", self.obs.station_ids.index(ident)
        if ident in self.obs.target_ids:
            return "target", self.obs.target_ids.index(ident)
        raise MultilatError(f"unknown point id {ident!r}")

    def xyz(self, ident: str) -> np.ndarray:
        kind, i = self.point_index(ident)
        return (self.station_xyz_m if kind == "station" else self.target_xyz_m)[i]

    def _param_rows(self, ident: str) -> np.ndarray:
        kind, i = self.point_index(ident)
        if kind == "station":
            return Q * i + np.arange(3)
        return Q * self.obs.n_stations + 3 * i + np.arange(3)

    def points_covariance(self, ids) -> np.ndarray:
        """Joint covariance (3p, 3p) of the points ``ids`` (stations or targets), m²."""
        rows = np.concatenate([self._param_rows(i) for i in ids])
        return self.covariance.block(rows)

    def interpoint_distance(self, a: str, b: str) -> InterpointDistance:
        """Distance between points ``a`` and ``b`` with its standard uncertainty (datum-free)."""
        d = self.xyz(a) - self.xyz(b)
        L = float(np.linalg.norm(d))
        g = np.concatenate([d / L, -d / L])
        C = self.points_covariance([a, b])
        return InterpointDistance(a, b, L, float(np.sqrt(max(g @ C @ g, 0.0))))

    def compare_references(self, refs: ReferenceLengths) -> list[InterpointDistance]:
        """Interpoint distances beside the reference lengths (seed 000 Tables V-VI)."""
        known = self.obs.station_ids + self.obs.target_ids
        refs.check_ids(known)
        out = []
        for a, b, L, u in zip(refs.target_a, refs.target_b, refs.length_m, refs.u_m):
            ip = self.interpoint_distance(a, b)
            out.append(InterpointDistance(a, b, ip.length_m, ip.u_m, float(L),
                                          None if np.isnan(u) else float(u), ip.length_m - float(L)))
        return out

    def ellipsoids(self, *, level: float = 0.95):
        """Confidence ellipsoids of stations and targets: ``(semi_axes_m, axes)`` each a pair of
        arrays ((s, 3), (s, 3, 3)) and ((t, 3), (t, 3, 3)); see :func:`statistics.confidence_ellipsoid`."""
        return (st.confidence_ellipsoid(self.station_cov_m2, level=level),
                st.confidence_ellipsoid(self.target_cov_m2, level=level))

    def offset_correlations(self) -> np.ndarray:
        """Correlation of each station's offset with its own x, y, z and offset (s, 4):
        ``corr[i] = (rho(o_i, x_i), rho(o_i, y_i), rho(o_i, z_i), 1)`` (NaN where not estimated)."""
        s = self.obs.n_stations
        C = self.global_cov
        out = np.full((s, 4), np.nan)
        for i in range(s):
            o = Q * i + 3
            if C[o, o] <= 0:
                continue
            for c in range(4):
                v = C[Q * i + c, Q * i + c]
                if v > 0:
                    out[i, c] = C[o, Q * i + c] / np.sqrt(C[o, o] * v)
        return out

    def correlation_matrix(self) -> np.ndarray:
        """Correlations among all station parameters (5s, 5s) (NaN rows for fixed parameters)."""
        d = np.sqrt(np.clip(np.diag(self.global_cov), 0, None))
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.global_cov / np.outer(d, d)


# ====================================================================== solver internals
def _as_start(initial, obs: Observations) -> Start:
    try:
        sx = np.array(initial.station_xyz_m, dtype=float)
        tx = np.array(initial.target_xyz_m, dtype=float)
        off = np.array(initial.offset_m, dtype=float)
    except AttributeError:
        raise MultilatError("initial values need station_xyz_m, target_xyz_m and offset_m") from None
    if sx.shape != (obs.n_stations, 3) or tx.shape != (obs.n_targets, 3) or off.shape != (obs.n_stations,):
        raise MultilatError(f"initial values: expected shapes ({obs.n_stations}, 3), ({obs.n_targets}, 3), "
                            f"({obs.n_stations},), got {sx.shape}, {tx.shape}, {off.shape}")
    if not (np.all(np.isfinite(sx)) and np.all(np.isfinite(tx)) and np.all(np.isfinite(off))):
        raise MultilatError("initial values must be finite")
    return Start(sx, tx, off)


def _initial(obs: Observations, initial, points: Points | None, rng) -> Start:
    """Initial values: given; or all from ``points``; or from distances (fitted onto ``points``)."""
    if initial is not None:
        return _as_start(initial, obs)
    if points is not None:
        have = [points.get(i) is not None for i in obs.station_ids + obs.target_ids]
        if all(have):
            return Start(np.array([points.get(i) for i in obs.station_ids]),
                         np.array([points.get(i) for i in obs.target_ids]), np.zeros(obs.n_stations))
    try:
        from multilat.network.initial import initial_values
    except ImportError:
        raise MultilatError("no initial values: give approximate coordinates of every point (--points) "
                            "until multilat.network.initial is available") from None
    iv = _as_start(initial_values(obs, rng=rng), obs)
    if points is not None:
        ids = [i for i in obs.station_ids + obs.target_ids if points.get(i) is not None]
        if len(ids) >= 3:
            allx = np.vstack([iv.station_xyz_m, iv.target_xyz_m])
            allids = obs.station_ids + obs.target_ids
            src = np.array([allx[allids.index(i)] for i in ids])
            try:
                R, t = rigid_fit(src, np.array([points.get(i) for i in ids]))
            except MultilatError:
                R, t = np.eye(3), np.zeros(3)
            iv = Start(apply_rigid(R, t, iv.station_xyz_m), apply_rigid(R, t, iv.target_xyz_m), iv.offset_m)
    return iv


def _pick_321_stations(sx) -> tuple[int, int, int]:
    """Three stations spanning the largest triangle (for the internal minimal constraint)."""
    s = sx.shape[0]
    best, bi = -1.0, (0, 1, 2)
    combos = itertools.combinations(range(s), 3) if s <= 40 else [
        (0, int(np.argmax(np.linalg.norm(sx - sx[0], axis=1))), None)]
    for c in combos:
        if c[2] is None:
            a, b = c[0], c[1]
            area = np.linalg.norm(np.cross(sx[b] - sx[a], sx - sx[a]), axis=1)
            k = int(np.argmax(area))
            c = (a, b, k)
        a, b, k = c
        area = np.linalg.norm(np.cross(sx[b] - sx[a], sx[k] - sx[a]))
        if area > best:
            best, bi = area, (a, b, k)
    return bi


@dataclass
class _Problem:
    obs: Observations
    cost: str
    global_free: np.ndarray      # (s, 5) bool
    target_free: np.ndarray      # (t,) bool
    weights_sqrt: np.ndarray     # (m,) 1/sigma (distance) or 1 (squared)


def _evaluate(pb: _Problem, sx, tx, off, sc):
    o = pb.obs
    r, Js, Jt = residuals_and_jacobian(o.distance_m, sx, tx, off, sc, o.station_index, o.target_index,
                                       cost=pb.cost)
    w = pb.weights_sqrt
    r_w = r * w
    Js_w = Js * w[:, None] * pb.global_free[o.station_index]
    Jt_w = Jt * w[:, None] * pb.target_free[o.target_index][:, None]
    return r_w, Js_w, Jt_w


def _cost(pb, sx, tx, off, sc):
    o = pb.obs
    r, _, _ = residuals_and_jacobian(o.distance_m, sx, tx, off, sc, o.station_index, o.target_index,
                                     cost=pb.cost)
    return float(np.sum((r * pb.weights_sqrt) ** 2))


def _param_names(obs):
    names = []
    for sid in obs.station_ids:
        names += [f"x of {sid}", f"y of {sid}", f"z of {sid}", f"offset of {sid}", f"scale of {sid}"]
    return names


def _solve_reduced(N, b, free, obs, sx, tx):
    """Solve the free part of ``N dg = b`` after a conditioning check; returns (dg, Qgg, cond)."""
    Nf = N[np.ix_(free, free)]
    d = np.sqrt(np.diag(Nf))
    if np.any(~np.isfinite(d)) or np.any(d <= 0):
        k = int(np.flatnonzero(~(d > 0))[0]) if np.any(~(d > 0)) else 0
        name = np.array(_param_names(obs))[free][k]
        raise MultilatError(f"near-degenerate geometry: {name} is not determined by the observations")
    Ns = Nf / np.outer(d, d)
    ev, V = np.linalg.eigh(Ns)
    cond = float(ev[-1] / ev[0]) if ev[0] > 0 else np.inf
    if not cond < CONDITION_LIMIT:
        nv = np.zeros(free.size)
        nv[free] = V[:, 0] / d
        raise MultilatError(diagnose_degeneracy(sx, tx, obs.station_ids, obs.target_ids, nv,
                                                _param_names(obs), condition=cond,
                                                sigma_m=float(np.median(obs.sigma_m)),
                                                n_obs=obs.n_obs))
    # solve in the scaled form via the eigen-decomposition (well conditioned here)
    Qs = (V / ev) @ V.T
    Qf = Qs / np.outer(d, d)
    dgf = Qf @ b[free]
    dg = np.zeros(free.size)
    dg[free] = dgf
    Qgg = np.zeros((free.size, free.size))
    Qgg[np.ix_(free, free)] = Qf
    return dg, Qgg, cond


def _check_target_blocks(Ntt, target_free, obs):
    ev = np.linalg.eigvalsh(Ntt[target_free])
    bad = ev[:, 0] <= 1e-10 * ev[:, 2]
    if np.any(bad):
        j = int(np.flatnonzero(target_free)[np.flatnonzero(bad)[0]])
        raise MultilatError(f"near-degenerate geometry: target {obs.target_ids[j]!r} is not determined "
                            "(its stations are (nearly) on one line through it)")


def _gauss_newton(pb: _Problem, sx, tx, off, sc, *, max_iter, tol_m, chunk_targets):
    """Levenberg-Marquardt on the Schur-reduced normal equations. Returns parameters and count."""
    o = pb.obs
    free = pb.global_free.ravel()
    lam = 0.0
    cost = _cost(pb, sx, tx, off, sc)
    scale_len = float(np.max(np.abs(o.distance_m)))
    for it in range(1, max_iter + 1):
        r_w, Js_w, Jt_w = _evaluate(pb, sx, tx, off, sc)
        while True:
            sys_ = reduced_normal_equations(r_w, Js_w, Jt_w, o.station_index, o.target_index,
                                            o.n_stations, o.n_targets, target_free=pb.target_free,
                                            damping=lam, chunk_targets=chunk_targets)
            _check_target_blocks(sys_.Ntt, pb.target_free, o)
            dg, _, _ = _solve_reduced(sys_.N, sys_.b, free, o, sx, tx)
            dt = back_substitute(sys_, dg, Js_w, Jt_w, o.station_index, o.target_index)
            dgs = dg.reshape(-1, Q)
            nsx, ntx = sx + dgs[:, :3], tx + dt
            noff, nsc = off + dgs[:, 3], sc + dgs[:, 4]
            new_cost = _cost(pb, nsx, ntx, noff, nsc)
            step = max(float(np.max(np.abs(dgs[:, :4]))), float(np.max(np.abs(dt), initial=0.0)),
                       float(np.max(np.abs(dgs[:, 4]))) * scale_len)
            # at the minimum the cost changes only by rounding and the step is rounding noise
            # amplified by the condition number: stop there instead of chasing it
            flat = (abs(cost - new_cost) <= 1e-12 * max(cost, 1e-300) and step < 1e-7 * scale_len)
            if step < tol_m or flat:
                if new_cost <= cost:
                    sx, tx, off, sc = nsx, ntx, noff, nsc
                return sx, tx, off, sc, it
            if np.isfinite(new_cost) and new_cost <= cost:
                lam = 0.0 if lam < 1e-6 else lam / 10.0
                break
            lam = 1e-4 if lam == 0 else lam * 10.0
            if lam > 1e8:
                _raise_if_flat(o, sx, tx, "no convergence")
                raise MultilatError("the adjustment did not converge (no decrease of the cost); "
                                    "check initial values and the observations")
        sx, tx, off, sc, cost = nsx, ntx, noff, nsc, new_cost
    _raise_if_flat(o, sx, tx, f"no convergence in {max_iter} iterations")
    raise MultilatError(f"the adjustment did not converge in {max_iter} iterations "
                        f"(last step {step:.3g} m); check initial values, the geometry and the distances for gross errors")


def _raise_if_flat(obs, sx, tx, when: str) -> None:
    """Raise the one-line 'near-degenerate geometry (when): cause' if the points are (nearly)
    coplanar stations or collinear targets by :func:`solvability.flat_geometry`."""
    cause = flat_geometry(sx, tx, sigma_m=float(np.median(obs.sigma_m)), n_obs=obs.n_obs)
    if cause:
        raise MultilatError(f"near-degenerate geometry ({when}): {cause}")


def _fixed_offsets(offsets, obs: Observations):
    """(offset_free (s,) bool, fixed values (s,)) from the ``offsets`` option."""
    s = obs.n_stations
    free = np.ones(s, bool)
    val = np.zeros(s)
    if offsets is None or (isinstance(offsets, str) and offsets == "estimate"):
        return free, val
    if isinstance(offsets, Mapping):
        for k, v in offsets.items():
            if k not in obs.station_ids:
                raise MultilatError(f"offsets: unknown station id {k!r}")
            i = obs.station_ids.index(k)
            if not np.isfinite(v):
                raise MultilatError(f"offsets: value for {k!r} must be finite")
            free[i], val[i] = False, float(v)
        return free, val
    try:
        v = float(offsets)
    except (TypeError, ValueError):
        raise MultilatError(f"offsets must be None/'estimate', a number or a mapping, got {offsets!r}") from None
    if not np.isfinite(v):
        raise MultilatError("offsets must be finite")
    return np.zeros(s, bool), np.full(s, v)


def _scale_flags(scales, obs):
    s = obs.n_stations
    if scales is False or scales is None:
        return np.zeros(s, bool)
    if scales is True:
        return np.ones(s, bool)
    out = np.zeros(s, bool)
    for k in scales:
        if k not in obs.station_ids:
            raise MultilatError(f"scales: unknown station id {k!r}")
        out[obs.station_ids.index(k)] = True
    return out


# ====================================================================== public
def adjust(obs: Observations, *, datum: Datum | str | None = "free", initial=None,
           points: Points | None = None, cost: str = "distance", offsets=None, scales=False,
           alpha: float = 0.001, power: float = 0.80, alpha_global: float = 0.05,
           snooping: bool = True, max_rejections: int | None = None, max_iter: int = 100,
           tol_m: float = 1e-10, chunk_targets: int = 20000, rng=None) -> AdjustmentResult:
    """Adjust a self-calibrating multilateration network.

    Unknowns: station coordinates, target coordinates, one additive offset per station (estimated
    unless fixed) and optionally one scale per station; model ``d = (1 + k_i)|H_i - T_j| + o_i``.
    Solved by Gauss-Newton with Levenberg-Marquardt damping on the normal equations reduced by the
    Schur complement over the 3x3 target blocks (cost linear in the number of targets).

    Parameters
    ----------
    obs : Observations
        Distances with a-priori uncertainties ``sigma_m``.
    datum : Datum or str
        ``"free"`` (inner constraints over all points; ``"free:P1,P2,.."`` over chosen points),
        ``"321:A,B,C"`` (A at origin, B on +x, C in xy-plane), or ``"control"`` /
        ``"control:P1,.."`` (the given ``points`` held fixed). See :mod:`multilat.network.datum`.
    initial : object with ``station_xyz_m`` (s, 3), ``target_xyz_m`` (t, 3), ``offset_m`` (s,), optional
        Initial values. Default: ``points`` when they cover every point, else
        :func:`multilat.network.initial.initial_values` from the distances (rigidly fitted onto
        ``points`` when >= 3 are given).
    points : Points, optional
        Approximate coordinates (their frame is the frame of the ``free`` datum) or control. Ids
        that are in no observation are ignored with a ``UserWarning`` naming them.
    cost : "distance" or "squared"
        ``"distance"``: residuals in metres weighted by ``1/sigma``; ``"squared"``: the paper's
        eq. (6), unweighted squared-distance differences (covariance scaled by the a-posteriori
        variance; no global test or data snooping, which need known weights).
    offsets : None, "estimate", float or mapping station -> metres
        Estimate all offsets (default), fix all to one value, or fix the named ones.
    scales : bool or iterable of station ids
        Estimate a scale per station (all, or the named ones). Default: none.
    alpha : float
        Significance of Baarda's w-test (two-sided) for data snooping; also the MDBs' alpha.
    power : float
        Power of the test for the minimal detectable biases (Baarda: 0.80).
    alpha_global : float
        Significance of the global χ² test (one-sided, upper).
    snooping : bool
        Iteratively reject the observation with the largest ``|w|`` above the critical value and
        re-adjust, while the network stays solvable (at most ``max_rejections``).
    max_iter, tol_m : int, float
        Iteration limit and convergence threshold on the largest step (metres).
    chunk_targets : int
        Targets per chunk in the normal-equation assembly.
    rng : numpy Generator, int or None
        Passed to ``initial_values`` (if used).

    Returns
    -------
    AdjustmentResult

    Raises
    ------
    MultilatError
        Unsolvable network (disconnected, too few observations, degenerate geometry: coplanar
        stations and collinear targets are tested on the initial coordinates), control coordinates
        inconsistent with the distances (``datum="control"``, tested before data snooping), bad
        options, or no convergence — one line naming the cause.
    """
    if not isinstance(obs, Observations):
        raise MultilatError("adjust: obs must be an Observations")
    if cost not in COSTS:
        raise MultilatError(f"cost must be one of {', '.join(COSTS)}, got {cost!r}")
    for name, v in (("alpha", alpha), ("power", power), ("alpha_global", alpha_global)):
        if not (0 < v < 1):
            raise MultilatError(f"{name} must be in (0, 1), got {v!r}")
    datum = parse_datum(datum)
    off_free, off_val = _fixed_offsets(offsets, obs)
    sc_free = _scale_flags(scales, obs)
    if datum.kind == "control" and points is None:
        raise MultilatError("datum control needs control coordinates (points)")
    if points is not None:
        known = set(obs.station_ids) | set(obs.target_ids)
        stray = [i for i in points.ids if i not in known]
        if stray:
            warnings.warn(f"points: {len(stray)} id(s) not in the observations, ignored: "
                          f"{', '.join(stray[:8])}{'...' if len(stray) > 8 else ''}",
                          UserWarning, stacklevel=2)
    _structure(obs, datum, points, off_free, sc_free, warn=False)   # before any initial values
    start = _initial(obs, initial, points, rng)
    # coplanar stations / collinear targets make the problem singular: say so before solving
    _raise_if_flat(obs, start.station_xyz_m, start.target_xyz_m, "initial coordinates")
    start = Start(start.station_xyz_m, start.target_xyz_m,
                  np.where(off_free, start.offset_m, off_val))
    do_snoop = snooping and cost == "distance"
    used = np.ones(obs.n_obs, bool)
    rejected: list[tuple[int, float]] = []
    limit = obs.n_obs if max_rejections is None else int(max_rejections)
    crit = st.w_critical(alpha)
    warn = True
    guess = start
    unlocated: tuple = ()
    reason = ""
    first = True
    while True:
        sub = obs if used.all() else obs.subset(used)
        core = _adjust_once(sub, datum, guess, start, obs, used, points, cost, off_free, off_val,
                            sc_free, max_iter, tol_m, chunk_targets, warn=warn)
        if first and datum.kind == "control" and cost == "distance":
            # a failed global test under control may be the control coordinates, not the distances:
            # test them (against the free network) before data snooping blames the distances
            _check_control(obs, core, start, points, off_free, off_val, sc_free, alpha_global,
                           max_iter, tol_m, chunk_targets, datum)
        first = False
        # the next adjustment (after a rejection) starts from this solution
        gs, gt_, go = guess.station_xyz_m.copy(), guess.target_xyz_m.copy(), guess.offset_m.copy()
        gs[core["smap"]], gt_[core["tmap"]], go[core["smap"]] = core["sx"], core["tx"], core["off"]
        guess = Start(gs, gt_, go)
        warn = False
        if not do_snoop or len(rejected) >= limit:
            break
        w_sub = st.w_statistics(core["residual_w"], np.ones_like(core["residual_w"]), core["redundancy"])
        order = np.argsort(-np.abs(w_sub))
        k_sub = int(order[0])
        if not abs(w_sub[k_sub]) > crit:
            break
        k = int(np.flatnonzero(used)[k_sub])
        # is the fault locatable? another observation whose w-test is perfectly (|rho| > 1 - 1e-6)
        # correlated with this one would show the same |w|: the data cannot tell which is wrong
        red_sub = core["redundancy"]
        hrow = core["cov"].hat_row(k_sub)
        with np.errstate(divide="ignore", invalid="ignore"):
            rho = -hrow / np.sqrt(red_sub[k_sub] * red_sub)
        rho[k_sub] = 0.0
        twins = np.flatnonzero(np.abs(np.nan_to_num(rho)) > 1.0 - 1e-6)
        if twins.size:
            unlocated = tuple(int(np.flatnonzero(used)[q]) for q in np.concatenate([[k_sub], twins]))
            reason = "perfectly correlated w-tests: the data cannot tell which observation is wrong"
            break
        trial = used.copy()
        trial[k] = False
        why = _last_redundancy(obs, used, trial, k, datum, points)
        if why:
            unlocated, reason = (k,), why
            break
        try:
            _structure(obs.subset(trial), datum, points, off_free[_station_map(obs, trial)],
                       sc_free[_station_map(obs, trial)], warn=False)
        except MultilatError as exc:
            # rejecting it would make the network unsolvable: keep it, report it as not rejected
            unlocated, reason = (k,), f"rejecting it would leave the network unsolvable ({exc})"
            break
        rejected.append((k, float(w_sub[k_sub])))
        used = trial
    return _build_result(obs, used, rejected, unlocated, core, datum, cost, alpha, power, alpha_global,
                         reason=reason, snooped=do_snoop)


def _last_redundancy(obs, used, trial, k, datum, points) -> str:
    """Why rejecting observation ``k`` must not happen (it takes a point's last redundancy), or ""."""
    j = int(obs.target_index[k])
    tid = obs.target_ids[j]
    before = int(np.sum(obs.target_index[used] == j))
    after = int(np.sum(obs.target_index[trial] == j))
    fixed = datum.kind == "control" and tid in _control_ids(obs.subset(used), datum, points)
    need = 1 if fixed else 4          # a control target: any distance checks it; a free one: 3 + 1
    if before >= need > after:
        what = "control point" if fixed else "target"
        return (f"rejecting it would leave {what} {tid!r} with {after} observation(s), without "
                "redundancy")
    return ""


def _check_control(obs, core, start, points, off_free, off_val, sc_free, alpha_global, max_iter,
                   tol_m, chunk_targets, datum) -> None:
    """Raise if the control coordinates are inconsistent with the distances.

    The adjustment with the control held fixed has ``Omega_c = v^T P v`` on ``dof_c``; the free
    network of the same distances ``Omega_f`` on ``dof_f``. With a-priori weights, consistent
    control gives ``Omega_c - Omega_f ~ chi2(dof_c - dof_f)`` independent of the distances' own
    misfit (a blunder inflates both). Only run when the global test under control fails.
    """
    gt = st.global_test(core["vtpv"], core["dof"], alpha=alpha_global)
    if gt.passed is None or gt.passed:
        return
    used = np.ones(obs.n_obs, bool)
    ctrl = sorted(_control_ids(obs, datum, points))
    guess = Start(core["sx"], core["tx"], core["off"])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            free = _adjust_once(obs, parse_datum("free"), guess, guess, obs, used, None, "distance",
                                off_free, off_val, sc_free, max_iter, tol_m, chunk_targets, warn=False)
    except MultilatError:
        return            # not solvable without the control: nothing to compare; snooping goes on
    k = core["dof"] - free["dof"]
    if k <= 0:
        return
    stat = core["vtpv"] - free["vtpv"]
    from scipy import stats

    crit = float(stats.chi2.ppf(1.0 - alpha_global, k))
    if not stat > crit:
        return
    ids = obs.station_ids + obs.target_ids
    xyz = dict(zip(ids, np.vstack([free["sx"], free["tx"]])))
    src = np.array([xyz[i] for i in ctrl])
    dst = np.array([points.get(i) for i in ctrl])
    R, t = rigid_fit(src, dst)
    mis = np.linalg.norm(apply_rigid(R, t, src) - dst, axis=1)
    w = int(np.argmax(mis))
    raise MultilatError(
        f"control coordinates inconsistent with the distances (σ0 = {core['sigma0']:.3g} with the "
        f"control held fixed, {free['sigma0']:.3g} free; global test {gt.statistic:.1f} > "
        f"{gt.critical:.1f}; control test χ² = {stat:.1f} > {crit:.1f} on {k} dof; largest misfit "
        f"{ctrl[w]!r} {mis[w] * 1e3:.2f} mm after a rigid fit): check the control points or use "
        "--datum free")


def _station_map(obs, used):
    """Indices (into obs.station_ids) of the stations present in obs.subset(used), in its order."""
    return np.flatnonzero(np.bincount(obs.station_index[used], minlength=obs.n_stations) > 0)


def _target_map(obs, used):
    return np.flatnonzero(np.bincount(obs.target_index[used], minlength=obs.n_targets) > 0)


def _structure(sub, datum, points, off_free, sc_free, *, warn):
    fixed_t = np.zeros(sub.n_targets, bool)
    fixed_sc = 0
    defect = 6
    if datum.kind == "control":
        ctrl = _control_ids(sub, datum, points)
        fixed_t = np.array([t in ctrl for t in sub.target_ids])
        fixed_sc = 3 * sum(s in ctrl for s in sub.station_ids)
        defect = 0
    return check_structure(sub, offset_free=off_free, scale_free=sc_free, fixed_targets=fixed_t,
                           fixed_station_coords=fixed_sc, datum_defect=defect, warn=warn)


def _control_ids(sub, datum, points):
    given = [i for i in sub.station_ids + sub.target_ids if points.get(i) is not None]
    ids = given if datum.points is None else list(datum.points)
    for i in ids:
        if i not in sub.station_ids + sub.target_ids:
            raise MultilatError(f"datum control: unknown point id {i!r}")
        if points.get(i) is None:
            raise MultilatError(f"datum control: no coordinates given for {i!r}")
    if len(ids) < 3:
        raise MultilatError(f"datum control needs at least 3 control points, got {len(ids)}")
    sv = np.linalg.svd(np.array([points.get(i) for i in ids]) - np.mean([points.get(i) for i in ids], 0),
                       compute_uv=False)
    if sv[1] <= 1e-9 * sv[0]:
        raise MultilatError("datum control: the control points are collinear")
    return set(ids)


def _adjust_once(sub, datum, start, ref_start, obs, used, points, cost, off_free_all, off_val_all,
                 sc_free_all, max_iter, tol_m, chunk_targets, *, warn):
    """One adjustment of the observations ``sub`` (a subset of ``obs``) from ``start``;
    ``ref_start`` gives the reference coordinates of the free datum. Returns a dict of arrays in
    ``sub``'s order plus the maps back."""
    smap, tmap = _station_map(obs, used), _target_map(obs, used)
    off_free, off_val, sc_free = off_free_all[smap], off_val_all[smap], sc_free_all[smap]
    _structure(sub, datum, points, off_free, sc_free, warn=warn)
    s, t = sub.n_stations, sub.n_targets
    sx0 = start.station_xyz_m[smap].copy()
    tx0 = start.target_xyz_m[tmap].copy()
    off0 = np.where(off_free, start.offset_m[smap], off_val)
    sc0 = np.zeros(s)
    gfree = np.ones((s, Q), bool)
    gfree[:, 3] = off_free
    gfree[:, 4] = sc_free
    tfree = np.ones(t, bool)
    all_ids = sub.station_ids + sub.target_ids
    if datum.kind == "control":
        ctrl = _control_ids(sub, datum, points)
        # bring the initial values into the control frame first (rigid fit on the control points)
        cur = dict(zip(all_ids, np.vstack([sx0, tx0])))
        cids = sorted(ctrl)
        Rc, tc = rigid_fit(np.array([cur[i] for i in cids]), np.array([points.get(i) for i in cids]))
        sx0, tx0 = apply_rigid(Rc, tc, sx0), apply_rigid(Rc, tc, tx0)
        for i, sid in enumerate(sub.station_ids):
            if sid in ctrl:
                sx0[i] = points.get(sid)
                gfree[i, :3] = False
        for j, tid in enumerate(sub.target_ids):
            if tid in ctrl:
                tx0[j] = points.get(tid)
                tfree[j] = False
        R0, t0 = np.eye(3), np.zeros(3)
    else:
        if datum.kind == "321":
            for p in datum.points:
                if p not in all_ids:
                    raise MultilatError(f"datum 321: unknown point id {p!r}")
        a, b, c = _pick_321_stations(sx0)
        R0, t0 = frame_321(sx0[a], sx0[b], sx0[c])
        sx0, tx0 = apply_rigid(R0, t0, sx0), apply_rigid(R0, t0, tx0)
        gfree[a, :3] = False
        gfree[b, 1:3] = False
        gfree[c, 2] = False
    wsq = 1.0 / sub.sigma_m if cost == "distance" else np.ones(sub.n_obs)
    pb = _Problem(sub, cost, gfree, tfree, wsq)
    sx, tx, off, sc, iters = _gauss_newton(pb, sx0, tx0, off0, sc0, max_iter=max_iter, tol_m=tol_m,
                                           chunk_targets=chunk_targets)
    # final normal equations at the solution
    r_w, Js_w, Jt_w = _evaluate(pb, sx, tx, off, sc)
    sys_ = reduced_normal_equations(r_w, Js_w, Jt_w, sub.station_index, sub.target_index, s, t,
                                    target_free=tfree, chunk_targets=chunk_targets)
    _check_target_blocks(sys_.Ntt, tfree, sub)
    _, Qgg, cond = _solve_reduced(sys_.N, sys_.b, gfree.ravel(), sub, sx, tx)
    n_free = int(gfree.sum()) + 3 * int(tfree.sum())
    dof = sub.n_obs - n_free
    vtpv = float(r_w @ r_w)
    sigma0 = float(np.sqrt(vtpv / dof)) if dof > 0 else float("nan")
    factor = 1.0 if cost == "distance" else (sigma0 ** 2 if dof > 0 else float("nan"))
    # move to the requested datum
    if datum.kind == "control":
        R, tr, G, E = np.eye(3), np.zeros(3), None, None
    else:
        if datum.kind == "321":
            xyz = {i: p for i, p in zip(all_ids, np.vstack([sx, tx]))}
            R, tr = frame_321(xyz[datum.points[0]], xyz[datum.points[1]], xyz[datum.points[2]])
        else:
            ids = all_ids if datum.points is None else datum.points
            for p in ids:
                if p not in all_ids:
                    raise MultilatError(f"datum free: unknown point id {p!r}")
            ref = {i: p for i, p in zip(all_ids, np.vstack([ref_start.station_xyz_m[smap],
                                                             ref_start.target_xyz_m[tmap]]))}
            if points is not None:
                ref.update({i: points.get(i) for i in ids if points.get(i) is not None})
            cur = {i: p for i, p in zip(all_ids, np.vstack([sx, tx]))}
            R, tr = rigid_fit(np.array([cur[i] for i in ids]), np.array([ref[i] for i in ids]))
        sx, tx = apply_rigid(R, tr, sx), apply_rigid(R, tr, tx)
        G, E = _datum_matrices(datum, sub, sx, tx)
    cov = NetworkCovariance(Qgg, sys_.Ntt_inv, Js_w, Jt_w, sub.station_index, sub.target_index,
                            factor=factor, R=R, G=G, E=E)
    h = cov.hat_diagonal(chunk_targets)
    red = np.clip(1.0 - h, 0.0, 1.0)
    return dict(smap=smap, tmap=tmap, sx=sx, tx=tx, off=off, sc=sc, off_free=off_free, sc_free=sc_free,
                chunk_targets=chunk_targets, residual_w=r_w, redundancy=red, sigma0=sigma0, dof=dof,
                vtpv=vtpv, iterations=iters, cond=cond, cov=cov)


def _datum_matrices(datum, sub, sx, tx):
    """G (n, 6) rigid motions of all coordinates, E (n, 6) the datum's constraint matrix."""
    s, t = sub.n_stations, sub.n_targets
    n = Q * s + 3 * t
    rows = np.concatenate([(Q * np.arange(s)[:, None] + np.arange(3)).ravel(),
                           Q * s + np.arange(3 * t)])
    Gp = helmert_basis(np.vstack([sx, tx]))
    G = np.zeros((n, 6))
    G[rows] = Gp
    pos = {pid: k for k, pid in enumerate(sub.station_ids + sub.target_ids)}

    def prow(pid, c):
        return rows[3 * pos[pid] + c]

    E = np.zeros((n, 6))
    if datum.kind == "321":
        a, b, c = datum.points
        for col, (pid, comp) in enumerate([(a, 0), (a, 1), (a, 2), (b, 1), (b, 2), (c, 2)]):
            E[prow(pid, comp), col] = 1.0
    else:
        if datum.points is None:
            E[rows] = G[rows]
        else:
            for pid in datum.points:
                for comp in range(3):
                    r = prow(pid, comp)
                    E[r] = G[r]
    return G, E


def _build_result(obs, used, rejected, unlocated, core, datum, cost, alpha, power, alpha_global, *,
                  reason="", snooped=True):
    s, t, m = obs.n_stations, obs.n_targets, obs.n_obs
    smap, tmap = core["smap"], core["tmap"]
    sx = np.full((s, 3), np.nan)
    tx = np.full((t, 3), np.nan)
    off = np.full(s, np.nan)
    sc = np.zeros(s)
    sx[smap], tx[tmap], off[smap], sc[smap] = core["sx"], core["tx"], core["off"], core["sc"]
    if len(smap) != s or len(tmap) != t:
        lost = [obs.station_ids[i] for i in range(s) if i not in smap] + \
               [obs.target_ids[j] for j in range(t) if j not in tmap]
        raise MultilatError(f"data snooping removed every observation of {', '.join(lost)}")
    cov = core["cov"]
    gcov = cov.global_block()
    scov = np.stack([gcov[Q * i:Q * i + 3, Q * i:Q * i + 3] for i in range(s)])
    tcov = cov.target_blocks(core["chunk_targets"])
    off_est = np.zeros(s, bool)
    sc_est = np.zeros(s, bool)
    off_est[smap], sc_est[smap] = core["off_free"], core["sc_free"]
    # residuals of all observations (rejected ones against the final solution)
    r_all = obs.distance_m - ((1 + sc[obs.station_index]) *
                              np.linalg.norm(sx[obs.station_index] - tx[obs.target_index], axis=1)
                              + off[obs.station_index])
    red = np.zeros(m)
    red[used] = core["redundancy"]
    if cost == "distance":
        w = st.w_statistics(r_all, obs.sigma_m, red)
        w[~used] = 0.0
        mdb = st.minimal_detectable_bias_m(obs.sigma_m, red, alpha=alpha, power=power)
        gt = st.global_test(core["vtpv"], core["dof"], alpha=alpha_global)
    else:
        w = np.zeros(m)
        mdb = np.full(m, np.nan)
        gt = st.GlobalTest(None, None, None, None, alpha_global, core["dof"])
    outliers = tuple(Outlier(obs.station_ids[obs.station_index[k]], obs.target_ids[obs.target_index[k]],
                             wk, float(r_all[k]), float(mdb[k]) if np.isfinite(mdb[k]) else float("nan"))
                     for k, wk in rejected)
    unloc = tuple(Outlier(obs.station_ids[obs.station_index[k]], obs.target_ids[obs.target_index[k]],
                          float(w[k]), float(r_all[k]), float(mdb[k]) if np.isfinite(mdb[k]) else float("nan"))
                  for k in unlocated)
    cov = core["cov"]
    gd = np.diag(gcov).reshape(s, Q)
    return AdjustmentResult(
        obs=obs, used=used, datum=datum, cost=cost, station_xyz_m=sx, target_xyz_m=tx, offset_m=off,
        offset_estimated=off_est, scale=sc, scale_estimated=sc_est, station_cov_m2=scov,
        target_cov_m2=tcov, global_cov=gcov, offset_std_m=np.sqrt(np.clip(gd[:, 3], 0, None)),
        scale_std=np.sqrt(np.clip(gd[:, 4], 0, None)), residuals_m=r_all, redundancy=red, w=w,
        mdb_m=mdb, sigma0=core["sigma0"], dof=core["dof"], global_test=gt, outliers=outliers,
        unlocated=unloc, unlocated_reason=reason if unloc else "", snooping=bool(snooped),
        alpha=alpha, power=power, iterations=core["iterations"], condition=core["cond"], covariance=cov)
