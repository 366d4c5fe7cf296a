"""Large self-calibrating networks: sparse Gauss-Newton with the Schur complement over the targets.

A network of ``s`` stations (each with an additive offset) and ``t`` targets has ``4s + 3t``
unknowns; with ``t`` in the hundreds of thousands the normal matrix is far too big to form, but its
target part is block-diagonal (3x3 per target). Eliminating the targets leaves a dense
``4s x 4s`` station/offset system (the reduced camera system of bundle adjustment):

    S = N_pp - sum_j N_pj N_jj^-1 N_jp,      g' = g_p - sum_j N_pj N_jj^-1 g_j,

solved by Cholesky; the targets follow one by one, ``dT_j = N_jj^-1 (g_j - N_jp dp)``. All of it is
one pass over the observations grouped by target (numba kernels in :mod:`._sparse_kernels`), so time
and memory are linear in the number of targets.

Iterations: the first is a full Gauss-Newton step; later ones keep the normal matrix frozen and use
the exact gradient (a chord method with the same fixed point, the exact normal equations), which
costs a fifth of a full assembly. ``S`` is re-assembled while the step exceeds ``refresh_m`` (1 cm)
or when the steps shrink by less than a factor 10 (slow contraction). Convergence: largest parameter step below ``tol_m``.

Datum: free network with inner constraints over the stations — the solution is moved rigidly to
fit (least squares) the initial station coordinates, and the covariances are S-transformed onto
the same datum (minimum trace over the station coordinates). Offsets, interpoint distances and
``sigma0`` do not depend on the datum.

Covariances (``covariance=True``), re-assembled at the solution, scaled by the a-priori variance
factor (1, i.e. ``sigma_m`` taken as known): the full station/offset covariance ``(4s, 4s)`` in the
layout ``[station xyz (3s), offsets (s)]`` and a 3x3 covariance per target, with the formula in
:func:`._sparse_kernels.target_covariance`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network import _sparse_kernels as K
from multilat.network.batched import Datum, helmert_basis

__all__ = ["LargeSolution", "solve_large", "synthetic_network", "SyntheticNetwork"]


@dataclass(frozen=True)
class LargeSolution:
    """Result of :func:`solve_large`.

    Attributes
    ----------
    station_xyz_m : ndarray, shape (s, 3)
    offset_m : ndarray, shape (s,)
    target_xyz_m : ndarray, shape (t, 3)
    iterations : int
        Gauss-Newton iterations (full and frozen).
    full_assemblies : int
        How many of them re-assembled the Schur complement.
    converged : bool
    last_step_m : float
    sigma0 : float
        A-posteriori standard deviation of unit weight.
    dof : int
        Observations minus unknowns plus the 6 datum defects.
    station_cov_m2 : ndarray, shape (4s, 4s), or None
        Covariance of ``[station xyz (station-major), offsets]`` in the datum (inner over stations).
    target_cov_m2 : ndarray, shape (t, 3, 3), or None
        Covariance of each target in the same datum.
    timings_s : dict
        ``solve`` (sorting, iterations, datum) and ``covariance`` wall times, seconds.
    """

    station_xyz_m: np.ndarray
    offset_m: np.ndarray
    target_xyz_m: np.ndarray
    iterations: int
    full_assemblies: int
    converged: bool
    last_step_m: float
    sigma0: float
    dof: int
    station_cov_m2: np.ndarray | None
    target_cov_m2: np.ndarray | None
    timings_s: dict


def _nchunks() -> int:
    return max(1, 4 * K.get_num_threads())


def _penalty_basis(h):
    """Helmert basis of the stations about their centroid, in the (4s) [x, y, z, o] layout."""
    s = len(h)
    e = np.zeros((s, 4, 6))
    e[:, :3] = helmert_basis(h - h.mean(axis=0)).reshape(s, 3, 6)
    return e.reshape(4 * s, 6)


def solve_large(station_index, target_index, distance_m, sigma_m, station_xyz_m, offset_m,
                target_xyz_m, *, covariance: bool = True, tol_m: float = 1e-10, max_iter: int = 30,
                refresh_m: float = 1e-2) -> LargeSolution:
    """Solve a large network from initial values.

    Parameters
    ----------
    station_index, target_index : ndarray of int, shape (m,)
        Observation pattern (0-based); every target needs >= 3 stations.
    distance_m, sigma_m : ndarray, shape (m,)
        Measured distances and their standard uncertainties (weights ``1/sigma**2``), metres.
    station_xyz_m : ndarray, shape (s, 3)
        Initial station coordinates; also the datum reference (inner constraints over stations).
    offset_m : ndarray, shape (s,)
        Initial offsets.
    target_xyz_m : ndarray, shape (t, 3)
        Initial target coordinates.
    covariance : bool
        Also compute the station/offset covariance and per-target covariances.
    tol_m, max_iter, refresh_m
        Convergence threshold on the largest step; iteration limit; steps above ``refresh_m`` (1 cm)
        or shrinking by less than a factor 10 trigger a re-assembly of the Schur complement.

    Returns
    -------
    LargeSolution
    """
    t_start = time.perf_counter()
    si = np.asarray(station_index, np.int64)
    ti = np.asarray(target_index, np.int64)
    d = np.asarray(distance_m, float)
    sig = np.asarray(sigma_m, float)
    h = np.array(station_xyz_m, float)
    o = np.array(offset_m, float)
    tg = np.array(target_xyz_m, float)
    m, s, t = len(si), len(h), len(tg)
    if h.shape != (s, 3) or tg.shape != (t, 3) or o.shape != (s,):
        raise MultilatError("station_xyz_m (s, 3), offset_m (s,) and target_xyz_m (t, 3) shapes disagree")
    if not (ti.shape == d.shape == sig.shape == (m,)):
        raise MultilatError("station_index, target_index, distance_m and sigma_m must have one length")
    if m == 0 or si.min() < 0 or si.max() >= s or ti.min() < 0 or ti.max() >= t:
        raise MultilatError("observation indices out of range")
    if not (np.isfinite(d).all() and np.isfinite(sig).all() and np.isfinite(h).all()
            and np.isfinite(tg).all() and np.isfinite(o).all()):
        raise MultilatError("non-finite value in distances, sigmas or initial values")
    if np.any(d <= 0) or np.any(sig <= 0):
        raise MultilatError("distances and sigmas must be > 0")
    counts = np.bincount(ti, minlength=t)
    if counts.min() < 3:
        j = int(np.argmin(counts))
        raise MultilatError(f"target {j} has {int(counts[j])} observations (needs >= 3)")
    if s < 3:
        raise MultilatError(f"{s} stations: a self-calibrating network needs at least 3")
    if np.any(np.diff(ti) < 0):      # group observations by target
        order = np.argsort(ti, kind="stable")
        si, ti, d, sig = si[order], ti[order], d[order], sig[order]
    tptr = np.zeros(t + 1, np.int64)
    np.cumsum(counts, out=tptr[1:])
    w = 1.0 / sig**2
    maxk = int(counts.max())
    h0 = h.copy()
    nch = _nchunks()
    u = np.empty((m, 3))
    ninv = np.empty((t, 3, 3))
    gt = np.empty((t, 3))
    dt = np.empty((t, 3))
    full = True
    n_full = 0
    step = prev_step = np.inf
    it = 0
    chol = None
    for it in range(1, max_iter + 1):
        if full:
            sm, gp, vtpv, dmin = K.assemble(h, o, tg, d, w, si, tptr, u, ninv, gt, nch, maxk)
            if not dmin > 1e-12:
                raise MultilatError("a target is not determined (its lines of sight are (nearly) coplanar "
                                    "or it has too few stations)")
            e = _penalty_basis(h)
            pen = np.trace(sm) / (4 * s) / (np.trace(e.T @ e) / 6) * (e @ e.T)
            try:
                chol = np.linalg.cholesky(sm + pen)
            except np.linalg.LinAlgError:
                raise MultilatError("the station/offset system is singular (degenerate geometry)") from None
            n_full += 1
        else:
            gp, vtpv = K.gradient_frozen(h, o, tg, d, w, si, tptr, u, ninv, gt, nch)
        dxp = _cho_solve(chol, gp)
        K.back_substitute(dxp, gt, ninv, u, w, si, tptr, dt)
        dp = dxp.reshape(s, 4)
        h += dp[:, :3]
        o += dp[:, 3]
        tg += dt
        step = float(max(np.abs(dxp).max(), np.abs(dt).max()))
        if not np.isfinite(step):
            break
        if step < tol_m:
            break
        # re-assemble while far from the solution (step > refresh_m) or when the frozen matrix
        # contracts slowly (step ratio > 0.1); otherwise keep the matrix and iterate on the gradient
        full = step > refresh_m or (prev_step < np.inf and step > 0.1 * prev_step)
        prev_step = step
    converged = bool(np.isfinite(step) and step < tol_m)
    # datum: rigid fit of the stations onto their initial coordinates
    hd, td = Datum.inner("stations").apply(h[None], tg[None], h0, tg,
                                           engine="numba" if K.HAVE_NUMBA else "numpy")
    h, tg = hd[0], td[0]
    dof = m - (4 * s + 3 * t) + 6
    t_solve = time.perf_counter() - t_start
    scov = tcov = None
    t_cov = 0.0
    if covariance and converged:
        t1 = time.perf_counter()
        sm, gp, vtpv, dmin = K.assemble(h, o, tg, d, w, si, tptr, u, ninv, gt, nch, maxk)
        scov, tcov = _covariances(sm, h, tg, u, ninv, w, si, tptr)
        t_cov = time.perf_counter() - t1
    else:
        _, vtpv = K.gradient_frozen(h, o, tg, d, w, si, tptr, u, ninv, gt, nch)
    sigma0 = float(np.sqrt(vtpv / dof)) if dof > 0 else float("nan")
    return LargeSolution(h, o, tg, it, n_full, converged, step, sigma0, dof, scov, tcov,
                         {"solve": t_solve, "covariance": t_cov})


def _cho_solve(chol, b):
    from scipy.linalg import solve_triangular

    y = solve_triangular(chol, b, lower=True, check_finite=False)
    return solve_triangular(chol.T, y, lower=False, check_finite=False)


def _covariances(sm, h, tg, u, ninv, w, si, tptr):
    """Station/offset covariance (flatten layout) and per-target covariances in the station datum."""
    s = len(h)
    c = h.mean(axis=0)
    e = _penalty_basis(h)                           # E (4s, 6): inner constraints over the stations
    c_pen = np.trace(sm) / (4 * s) / (np.trace(e.T @ e) / 6)   # scale E E^T like S: well conditioned
    qa = np.linalg.inv(sm + c_pen * (e @ e.T))     # station block of (N + c E E^T)^-1 (a g-inverse)
    qa = 0.5 * (qa + qa.T)
    kmat = np.linalg.solve(e.T @ e, e.T)           # (E^T G)^-1 E^T with G_p = E (G_t elsewhere)
    sp = np.eye(4 * s) - e @ kmat
    qpp = sp @ qa @ sp.T
    kq = kmat @ qa
    kck = kq @ kmat.T
    tcov = np.empty((len(tg), 3, 3))
    K.target_covariance(ninv, u, w, si, tptr, np.ascontiguousarray(tg - c), qa, np.ascontiguousarray(kq),
                        np.ascontiguousarray(kck), tcov)
    # reorder [x, y, z, o] per station -> [xyz (3s), offsets (s)]
    perm = np.concatenate([(4 * np.arange(s)[:, None] + np.arange(3)).ravel(), 4 * np.arange(s) + 3])
    return qpp[np.ix_(perm, perm)], tcov


@dataclass(frozen=True)
class SyntheticNetwork:
    """A generated network with its truth (see :func:`synthetic_network`)."""

    station_index: np.ndarray
    target_index: np.ndarray
    distance_m: np.ndarray
    sigma_m: np.ndarray
    station_xyz_m: np.ndarray
    offset_m: np.ndarray
    target_xyz_m: np.ndarray


def synthetic_network(n_stations: int = 20, n_targets: int = 200_000, per_target: int = 8, *,
                      sigma_m: float = 5e-6, size_m: float = 20.0, rng=None) -> SyntheticNetwork:
    """A large-volume test network with a known truth.

    Stations on a ring of radius ``0.6 size_m`` at alternating heights (0 and ``0.3 size_m``),
    offsets uniform in +-5 mm; targets uniform in a ``size_m x size_m x 0.25 size_m`` box; each target
    observed by ``per_target`` distinct stations chosen at random, half on each ring (a target seen only
    by the low ring at floor height would have coplanar lines of sight); gaussian noise ``sigma_m``.
    Observations are listed target by target.
    """
    rng = np.random.default_rng(rng)
    if per_target < 3 or per_target > n_stations:
        raise MultilatError(f"per_target must be in 3..n_stations, got {per_target}")
    ang = 2 * np.pi * np.arange(n_stations) / n_stations
    rad = 0.6 * size_m
    hz = np.where(np.arange(n_stations) % 2 == 0, 0.0, 0.3 * size_m)
    h = np.column_stack([rad * np.cos(ang), rad * np.sin(ang), hz])
    off = rng.uniform(-5e-3, 5e-3, n_stations)
    tg = rng.uniform([-size_m / 2, -size_m / 2, 0.0], [size_m / 2, size_m / 2, 0.25 * size_m],
                     (n_targets, 3))
    # per_target distinct stations per target, half from the low ring and half from the high one
    # (all-low stations would leave a target at floor height with coplanar lines of sight)
    low = np.arange(0, n_stations, 2)
    high = np.arange(1, n_stations, 2)
    n_low = min(len(low), per_target // 2)
    n_high = per_target - n_low
    if n_high > len(high):
        n_high = len(high)
        n_low = per_target - n_high
    pick_l = np.argpartition(rng.random((n_targets, len(low))), n_low - 1, axis=1)[:, :n_low]
    pick_h = np.argpartition(rng.random((n_targets, len(high))), n_high - 1, axis=1)[:, :n_high]
    st = np.concatenate([low[pick_l], high[pick_h]], axis=1)
    st.sort(axis=1)
    si = st.ravel().astype(np.int64)
    ti = np.repeat(np.arange(n_targets, dtype=np.int64), per_target)
    diff = h[si] - tg[ti]
    dist = np.sqrt(np.einsum("mi,mi->m", diff, diff)) + off[si]
    dist = dist + rng.normal(0.0, sigma_m, len(si))
    return SyntheticNetwork(si, ti, dist, np.full(len(si), sigma_m), h, off, tg)
