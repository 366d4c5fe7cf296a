"""The one Gauss-Newton / Levenberg-Marquardt loop of the network adjustments.

:func:`iterate` owns the iteration: it asks a problem (:class:`Steps`) for a step at the current
point, damped by ``lambda`` (Levenberg-Marquardt: every diagonal element ``N_ii`` of the normal
equations becomes ``(1 + lambda) N_ii``), accepts it when the weighted cost decreases (``lambda``
then shrinks) or retries with more damping, tells a rise of the cost from its rounding noise, stops by
:func:`.convergence.step_verdict` and returns the point with a :class:`.convergence.Convergence`
record. No non-finite value leaves it: a step that produces one is rejected like any step that does
not decrease the cost. The problems give only their step:

* the distance path (:func:`gauss_newton`): the reduced normal equations from a back end
  (:mod:`.dense`, :mod:`.sparse`), the station system solved by a scaled eigen-decomposition (with a
  conditioning check that names the weak parameters), the targets back-substituted;
* the general layer (:mod:`multilat.network.adjust.general.adjust`): its dense bordered system or its
  sparse Schur elimination (:mod:`multilat.network.adjust.general.sparse`).
"""

from __future__ import annotations

from typing import Callable, Protocol

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.parameter_layout import ParameterLayout
from multilat.network.model.problem import Params, Problem, param_names
from multilat.network.adjust.distance.solvability import CONDITION_LIMIT, diagnose_degeneracy
from multilat.network.adjust.solve.convergence import Convergence, step_verdict
from multilat.network.adjust.solve.system import weighted_cost

__all__ = ["BACKENDS", "make_backend", "choose_backend", "gauss_newton", "iterate", "Steps", "solve_reduced",
           "check_target_blocks", "SPARSE_ABOVE_OBS", "LAMBDA_START", "LAMBDA_MAX"]

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


#: the first damping factor after a step that raised the cost; x10 per further rise, /10 per accepted step
LAMBDA_START = 1e-4
#: damping beyond this without a decrease of the cost: "no decrease of the cost" (not converged)
LAMBDA_MAX = 1e8
#: accepted steps damped below this go back to undamped Gauss-Newton
LAMBDA_MIN = 1e-6


class Steps(Protocol):
    """What :func:`iterate` asks of a problem (``x`` and ``dx`` are the problem's own objects).

    ``n_rows`` : the number of whitened residuals; ``rounding`` : the rounding error of one whitened
    residual (read after the first :meth:`step`, so a problem may set it from its first linearisation);
    together they bound the rounding noise of the cost (:func:`iterate`).
    """

    n_rows: int
    rounding: float

    def cost(self, x) -> float:
        """The weighted cost ``vᵀPv`` at ``x``; ``inf`` where ``x`` or the cost is not finite."""

    def step(self, x, lam: float) -> tuple:
        """``(dx, step length in sigma)``: the step at ``x`` damped by ``lam`` (0: Gauss-Newton)."""

    def apply(self, x, dx):
        """``x + dx`` as a new object (``x`` is kept: a rejected step leaves it)."""


def iterate(steps: Steps, x, *, max_iter: int, on_accept: Callable | None = None):
    """Minimise the weighted cost of ``steps`` from ``x``.

    Returns ``(x, cost, convergence)``: the lowest-cost point reached (finite), its cost, the
    :class:`Convergence`. ``on_accept(x, dx, cost)`` is called for each accepted step with the point
    it starts from and that point's cost (an iteration record). A rise of the cost is accepted when
    the step is below one sigma and the rise within the rounding noise of the cost: each whitened
    residual is known to about ``delta`` = ``steps.rounding``, so over ``m`` rows the cost to
    ``2 sqrt(cost m) delta + m delta^2`` (Cauchy-Schwarz), plus 1e-12 of the cost for its sum.
    """
    lam = 0.0
    cost = steps.cost(x)
    prev = np.inf
    step_sigma = np.inf
    for it in range(1, max_iter + 1):
        while True:
            dx, step_sigma = steps.step(x, lam)
            q = steps.apply(x, dx)
            new_cost = steps.cost(q)
            m, delta = steps.n_rows, steps.rounding
            noise = 2.0 * np.sqrt(cost * m) * delta + m * delta * delta + 1e-12 * cost
            if new_cost <= cost or (step_sigma < 1.0 and new_cost <= cost + noise):
                break
            lam = LAMBDA_START if lam == 0.0 else lam * 10.0
            if lam > LAMBDA_MAX:
                return x, cost, Convergence(False, it, float(step_sigma), "no decrease of the cost")
        if on_accept is not None:
            on_accept(x, dx, cost)
        x, cost = q, new_cost
        undamped = lam == 0.0
        lam = 0.0 if lam < LAMBDA_MIN else lam / 10.0
        why = step_verdict(step_sigma, prev) if undamped else None
        if why:
            return x, cost, Convergence(True, it, float(step_sigma), why)
        prev = step_sigma
    return x, cost, Convergence(False, max_iter, float(step_sigma), "iteration limit")


class _DistanceSteps:
    """The distance path's step: the reduced normal equations of a back end, damped, solved for the
    stations, the targets (and orientations) back-substituted; its length the largest change of a
    length parameter (scales times the largest distance) in units of the smallest sigma."""

    def __init__(self, problem: Problem, backend):
        self.problem, self.backend = problem, backend
        self.free = problem.station_free.ravel()
        self.layout = ParameterLayout.adjustment(problem.obs.n_stations)
        self.sig = problem.sigma_ref_m
        self.scale_len = float(np.max(np.abs(problem.obs.distance_m)))
        # each whitened residual is known to about delta = 4 eps L / sigma (distance cost) or
        # 4 eps L^2 (squared cost, unweighted)
        self.n_rows = problem.obs.n_obs
        self.rounding = 4 * np.finfo(float).eps * (self.scale_len / self.sig if problem.cost == "distance"
                                                   else self.scale_len ** 2)

    def cost(self, p: Params) -> float:
        return weighted_cost(self.problem, p) if p.is_finite() else np.inf

    def step(self, p: Params, lam: float):
        a = self.backend.assemble(p, lam)
        check_target_blocks(a.Ntt, self.problem)
        dg, _, _ = solve_reduced(a.N, a.b, self.free, self.problem, p)
        dt = a.back_substitute(dg)
        do = None if a.back_orientation is None else a.back_orientation(dg)
        return (dg, dt, do), _step_length_m(dg, dt, self.scale_len, self.layout, do) / self.sig

    def apply(self, p: Params, dx) -> Params:
        return p.step(*dx)


def gauss_newton(problem: Problem, start: Params, backend, *, max_iter: int = 100):
    """Minimise the weighted cost of ``problem`` from ``start`` (:func:`iterate` with the distance
    path's step).

    Returns ``(params, convergence)``; ``params`` is the lowest-cost point reached (finite).
    Raises :class:`MultilatError` only for degenerate geometry (named).
    """
    p, _, conv = iterate(_DistanceSteps(problem, backend), start, max_iter=max_iter)
    return p, conv
