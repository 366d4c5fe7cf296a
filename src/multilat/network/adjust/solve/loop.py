"""The one Gauss-Newton / Levenberg-Marquardt loop of the network adjustment.

Each iteration asks the back end for the reduced normal equations at the current point (damped by
``lambda`` on the diagonal of station and target blocks), solves the station system by a scaled
eigen-decomposition (with a conditioning check that names the weak parameters), back-substitutes the
targets, and accepts the step when the cost decreases (``lambda`` then shrinks) or retries with more
damping. It stops by :func:`.convergence.step_verdict` and returns the parameters with a
:class:`.convergence.Convergence` record; no non-finite value leaves it (a step that produces one is
rejected like any step that does not decrease the cost).
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.parameter_layout import ParameterLayout
from multilat.network.model.problem import Params, Problem, param_names
from multilat.network.adjust.distance.solvability import CONDITION_LIMIT, diagnose_degeneracy
from multilat.network.adjust.solve.convergence import Convergence, step_verdict
from multilat.network.adjust.solve.system import weighted_cost

__all__ = ["BACKENDS", "make_backend", "choose_backend", "gauss_newton", "solve_reduced",
           "check_target_blocks", "SPARSE_ABOVE_OBS"]

BACKENDS = ("auto", "dense", "sparse")
SPARSE_ABOVE_OBS = 20_000   # ``auto``: the compiled back end above this many observations


def choose_backend(problem: Problem, solver: str = "auto") -> str:
    """``"dense"`` or ``"sparse"`` for ``solver`` in :data:`BACKENDS`; raises for an explicit
    ``"sparse"`` on a problem it cannot handle."""
    from multilat.network.adjust.solve.sparse import supports

    if solver not in BACKENDS:
        raise MultilatError(f"solver must be one of {', '.join(BACKENDS)}, got {solver!r}")
    why = supports(problem)
    if solver == "sparse" and why:
        raise MultilatError(f"the sparse solver does not handle {why}: use --solver dense (or auto)")
    if solver == "auto":
        return "sparse" if (why is None and problem.obs.n_obs > SPARSE_ABOVE_OBS) else "dense"
    return solver


def make_backend(problem: Problem, name: str, *, chunk_targets: int = 20000):
    if name == "sparse":
        from multilat.network.adjust.solve.sparse import SparseBackend

        return SparseBackend(problem)
    from multilat.network.adjust.solve.dense import DenseBackend

    return DenseBackend(problem, chunk_targets=chunk_targets)


def solve_reduced(N, b, free, problem: Problem, p: Params):
    """Solve the free part of ``N dg = b`` after a conditioning check.

    Returns ``(dg (5s,), Qgg (5s, 5s), condition)``: the step, the inverse of the free block
    (zeros elsewhere) and the condition number of the unit-diagonal matrix. Raises
    :class:`MultilatError` naming the weak parameters when it is not below ``CONDITION_LIMIT``.

    Heads that occupy several stations are tied here, the one place: with ``T = problem.tie``
    (:mod:`multilat.network.model.problem`) the system solved is ``T^T N T dg_r = T^T b`` over the free
    reduced unknowns (``free`` and the head leads), and the step and covariance returned are the
    per-station ``T dg_r`` and ``T Q_r T^T``.
    """
    obs = problem.obs
    T = problem.tie
    if T is not None:
        N = T.T @ N @ T
        b = T.T @ b
    free = np.asarray(free, bool) & problem.lead_mask.ravel()
    Nf = N[np.ix_(free, free)]
    diag = np.diag(Nf)
    if not (np.all(np.isfinite(diag)) and np.all(diag > 0)):
        k = int(np.flatnonzero(~(diag > 0))[0]) if np.any(~(diag > 0)) else 0
        name = np.array(param_names(obs.station_ids, obs.head_of_station))[free][k]
        raise MultilatError(f"near-degenerate geometry: {name} is not determined by the observations")
    d = np.sqrt(diag)
    Ns = Nf / np.outer(d, d)
    if not np.all(np.isfinite(Ns)):
        raise MultilatError("the normal equations are not finite: check the observations for absurd "
                            "values (distances or sigmas)")
    ev, V = np.linalg.eigh(Ns)
    cond = float(ev[-1] / ev[0]) if ev[0] > 0 else np.inf
    if not cond < CONDITION_LIMIT:
        nv = np.zeros(free.size)
        nv[free] = V[:, 0] / d
        raise MultilatError(diagnose_degeneracy(p.station_xyz_m, p.target_xyz_m, obs.station_ids,
                                                obs.target_ids, nv,
                                                param_names(obs.station_ids, obs.head_of_station),
                                                condition=cond, sigma_m=float(np.median(obs.sigma_m)),
                                                n_obs=obs.n_obs))
    Qf = ((V / ev) @ V.T) / np.outer(d, d)
    dg = np.zeros(free.size)
    dg[free] = Qf @ b[free]
    Qgg = np.zeros((free.size, free.size))
    Qgg[np.ix_(free, free)] = Qf
    if T is not None:
        dg = T @ dg
        Qgg = T @ Qgg @ T.T
    return dg, Qgg, cond


#: from this many free targets the blocks' eigenvalue test runs compiled (closed form, parallel)
KERNEL_MIN_TARGETS = 2000


def check_target_blocks(Ntt, problem: Problem) -> None:
    """Raise naming the first free target whose 3x3 normal block is (nearly) singular."""
    tf = problem.target_free
    blocks = Ntt[tf]
    if blocks.shape[0] >= KERNEL_MIN_TARGETS:
        from multilat.network.adjust.solve._sparse_kernels import degenerate_blocks

        bad = np.empty(blocks.shape[0], bool)
        degenerate_blocks(np.ascontiguousarray(blocks, float), 1e-10, bad)
    else:
        with np.errstate(invalid="ignore"):
            ev = np.linalg.eigvalsh(np.where(np.isfinite(blocks), blocks, 0.0))
        bad = ~(ev[:, 0] > 1e-10 * ev[:, 2])
    if np.any(bad):     # named and left out by the adjustment (exclusion.leaving_out_undetermined)
        from multilat.network.adjust.distance.exclusion import COPLANAR_REASON, UndeterminedTargets

        raise UndeterminedTargets({problem.obs.target_ids[j]: COPLANAR_REASON
                                   for j in np.flatnonzero(tf)[np.flatnonzero(bad)]})


def _step_length_m(dg, dt, scale_len, layout: ParameterLayout, do=None):
    """The largest step in metres: coordinates and offsets, scales and orientations times the length."""
    k = layout.columns("station", "scale")
    rot = 0.0 if do is None else float(np.max(np.abs(do), initial=0.0)) * scale_len   # rad x length
    return max(float(np.max(np.abs(np.delete(dg, k)))), float(np.max(np.abs(dt), initial=0.0)),
               float(np.max(np.abs(dg[k]))) * scale_len, rot)


def gauss_newton(problem: Problem, start: Params, backend, *, max_iter: int = 100):
    """Minimise the weighted cost of ``problem`` from ``start``.

    Returns ``(params, convergence)``; ``params`` is the lowest-cost point reached (finite).
    Raises :class:`MultilatError` only for degenerate geometry (named).
    """
    free = problem.station_free.ravel()
    layout = ParameterLayout.adjustment(problem.obs.n_stations)
    sig = problem.sigma_ref_m
    scale_len = float(np.max(np.abs(problem.obs.distance_m)))
    p = start
    lam = 0.0
    cost = weighted_cost(problem, p)
    prev = np.inf
    step_sigma = np.inf
    # rounding noise of the cost: each whitened residual is known to about delta = 4 eps L / sigma
    # (distance cost) or 4 eps L^2 (squared cost, unweighted)
    m = problem.obs.n_obs
    delta = 4 * np.finfo(float).eps * (scale_len / sig if problem.cost == "distance" else scale_len ** 2)
    for it in range(1, max_iter + 1):
        while True:
            a = backend.assemble(p, lam)
            check_target_blocks(a.Ntt, problem)
            dg, _, _ = solve_reduced(a.N, a.b, free, problem, p)
            dt = a.back_substitute(dg)
            do = None if a.back_orientation is None else a.back_orientation(dg)
            q = p.step(dg, dt, do)
            new_cost = weighted_cost(problem, q) if q.is_finite() else np.inf
            step_sigma = _step_length_m(dg, dt, scale_len, layout, do) / sig
            noise = 2.0 * np.sqrt(cost * m) * delta + m * delta * delta + 1e-12 * cost
            if new_cost <= cost or (step_sigma < 1.0 and new_cost <= cost + noise):
                break
            lam = 1e-4 if lam == 0.0 else lam * 10.0
            if lam > 1e8:
                return p, Convergence(False, it, float(step_sigma), "no decrease of the cost")
        p, cost = q, new_cost
        undamped = lam == 0.0
        lam = 0.0 if lam < 1e-6 else lam / 10.0
        why = step_verdict(step_sigma, prev) if undamped else None
        if why:
            return p, Convergence(True, it, float(step_sigma), why)
        prev = step_sigma
    return p, Convergence(False, max_iter, float(step_sigma), "iteration limit")
