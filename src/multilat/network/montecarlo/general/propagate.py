"""Monte Carlo on the general layer: the adjustment's own system, frozen at its solution.

Every network :func:`~.adjust.adjust` takes (any kind, heads over several stations, scale bars,
weighted control, direction sets, tracker angles, correlated blocks, a free network's inner
constraints) is propagated by the same :class:`~.adjust.System`:

* **trials.** ``l_t = f(x̂) + L e_t`` with ``x̂`` the adjusted parameters, ``f`` the kinds' model,
  ``L`` the blocks' Cholesky factors (``C = L L^T``, the whiteners of the adjustment) and ``e_t``
  standard normal: the input distributions are centred on the adjusted observations, so every trial's
  solution scatters about ``x̂`` with covariance ``Q`` (σ0 a priori = 1) to first order.
* **chord steps.** Each trial starts at ``x̂`` (its first step, linear in the noise, is one matrix
  product for a block of trials: ``K (l_t - f(x̂))``, ``K = Q J(x̂)^T P``) and iterates
  ``x_{k+1} = x_k + Q J(x_k)^T P (l_t - f(x_k))``: the model and its Jacobian exact per trial (the
  kinds, vectorised over the trials), ``P = C^-1``, and ``Q`` the adjustment's cofactor matrix
  (the top-left block of the inverse of its bordered normal matrix at ``x̂``, :func:`~.adjust._step`):
  factorised once. The fixed point satisfies ``J(x*)^T P r(x*) = 0`` exactly, so each trial's
  solution is the least-squares solution of its observations (what ``adjust`` gives for them, to the
  step tolerance), in the datum ``B^T (x - x̂) = 0`` of the adjustment (``B`` its inner constraints;
  none when the datum is fixed points). A network the sparse back end adjusted (``Q`` in blocks, no
  dense ``Q`` above 2 000 unknowns) takes every step, the first too, as ``Q (J^T P r)`` solved through
  those blocks for a block of trials (:mod:`.propagate_blocks`, with its size limits).
* **convergence.** A trial has converged when its largest step, or the bound on the error left after
  it for a contraction, ``step c / (1 - c)`` with ``c`` this step over the one before, is below
  ``tol`` (1e-10 m and rad): with a contraction of ~1e-4 (µm trials on metre networks) two steps.
* **far trials.** A trial whose step does not shrink by half from one iteration to the next, or that
  has not converged after ``max_iter`` chord steps, is solved again from ``x̂`` by full Gauss-Newton
  (the Jacobian and the bordered system at every iterate, same datum): counted in
  ``n_retried``. One that still does not converge is dropped and counted (``n_failed``).
* **seeding.** Trials are drawn and solved in fixed blocks of :data:`BLOCK`; block ``b`` draws its
  ``(n, R)`` standard normals, rows in the system's row order, from the Monte Carlo engine's
  ``block_generator(entropy, spawn_key, b)``; a chunk (the unit of work handed to ``map``) is a run of
  whole blocks, so the numbers are bit-identical for any chunk size, map or number of workers.

Outputs: per free parameter (point coordinates, instrument constants and scales, orientations,
set-up angles) and per interpoint distance the Monte Carlo mean, standard deviation with its Monte
Carlo standard error, 95 % coverage intervals, beside the linear standard deviation from ``Q``; per
point the Monte Carlo 3 x 3 covariance beside ``Q``'s.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse

from multilat.errors import MultilatError
from multilat.montecarlo import block_generator, block_trials, chunk_ranges, resolve_map, resolve_seed
from multilat.network.model.angles import wrap_angle
from multilat.network.model import kinds as kinds_registry
from multilat.network.adjust.general.adjust import GeneralResult, System, _step
from multilat.network.montecarlo.general.propagate_result import SCHEMA, GeneralPropagation, default_pairs, summarise

__all__ = ["BLOCK", "DistanceNoise", "Frozen", "GeneralPropagation", "Solution", "default_pairs", "distance_noise",
           "draw", "freeze", "gauss_newton", "iterate_trial", "propagate", "solve", "whitened_residual", "SCHEMA"]

#: Trials per seeded block (the unit of reproducibility; :data:`multilat.network.montecarlo.propagate.BLOCK`).
BLOCK = 1000
#: A chord step larger than this fraction of the previous one sends the trial to full Gauss-Newton.
CONTRACTION = 0.5


@dataclass(frozen=True, eq=False)
class Frozen:
    """The adjustment's system frozen at its solution (everything a block of trials needs).

    system : System;  x_hat : (n,) adjusted full parameter vector;  computed : (R,) ``f(x̂)``
    q : (n_free, n_free) the cofactor matrix (σ0 a priori = 1);  free : (n_free,) full columns of the free parameters
    angular : (R,) rows wrapped to [-pi, pi);  weight : per block ``1/σ²`` (R_b,) or ``C^-1`` (R_b, R_b)
    scatter : sparse (Σ R_b k_b, n_free): Jacobian value slots -> free columns;  slots : (R,) slots per row
    determinability : the adjustment's at x̂ (its ``constraints`` B: the datum of the fall-back)
    dof : degrees of freedom;  program : the rows for the compiled kernel (:func:`_program`)
    gain : (n_free, R) ``K = Q J(x̂)^T P``, the first step
    scale : (R,) each row's σ for the draws, 1 for a correlated block's rows (drawn through its ``L``)
    cofactor : the adjustment's result when the sparse back end adjusted it (its ``Q`` in blocks, dense
        only up to :data:`~.adjust.MAX_DENSE_UNKNOWNS`): ``q`` and ``gain`` are then None and every
        step's ``Q g`` is a solve through the blocks (:mod:`.propagate_blocks`: 2.6x the trials/s of
        the dense ``Q`` on 8 x 300 targets, 932 unknowns)
    """

    system: System
    x_hat: np.ndarray
    computed: np.ndarray
    q: np.ndarray
    free: np.ndarray
    angular: np.ndarray
    weight: tuple
    scatter: object
    slots: np.ndarray
    determinability: object
    dof: int
    program: dict | None = None
    gain: np.ndarray | None = None
    cofactor: GeneralResult | None = None
    schur: object = None
    scale: np.ndarray | None = None

    def __post_init__(self):
        if self.scale is None:    # (R,) each row's σ, 1 for the rows of correlated blocks (drawn through L)
            object.__setattr__(self, "scale", np.concatenate(
                [np.ones(b.n_rows) if b.cov is not None else np.broadcast_to(np.asarray(b.sigma, float), (b.n_rows,))
                 for b in self.system.blocks]))

    @property
    def n_rows(self) -> int:
        return self.system.n_rows

    def residuals(self, x: np.ndarray, obs: np.ndarray, jacobian: bool = True):
        """Residuals ``obs - f(x)`` (T, R) (angles wrapped) and the Jacobian values (T, Σ R_b k_b)."""
        s = self.system
        r = np.empty(obs.shape)
        vals = []
        for b, cols, sl in zip(s.blocks, s.cols, s.rows):
            computed, values, _ = kinds_registry.kind(b.kind).evaluate(b, s.layout, cols, x, jacobian)
            r[:, sl] = obs[:, sl] - computed
            if jacobian:
                vals.append(values.reshape(len(x), -1))
        r[:, self.angular] = wrap_angle(r[:, self.angular])
        return r, (np.concatenate(vals, 1) if jacobian else None)

    def weighted(self, r: np.ndarray) -> np.ndarray:
        """``P r`` row block by row block (T, R)."""
        out = np.empty_like(r)
        for w, sl in zip(self.weight, self.system.rows):
            out[:, sl] = r[:, sl] * w if w.ndim == 1 else r[:, sl] @ w
        return out

    def gradient(self, pr: np.ndarray, vals: np.ndarray) -> np.ndarray:
        """``J^T P r`` per trial (T, n_free) from the Jacobian values and ``P r``."""
        return np.asarray((self.scatter.T @ (np.repeat(pr, self.slots, axis=1) * vals).T).T)


def freeze(system: System, result: GeneralResult) -> Frozen:
    """The frozen system of an adjusted network (``system`` and ``result`` of one adjustment). Each
    block's model and Jacobian at x̂ is evaluated once: ``f(x̂)``, the scatter, the kernel's program
    and the first step's ``J(x̂)`` all come from it (the dense ``J`` as :meth:`System.evaluate` builds
    it, the same bits: 3 evaluations of every kind were a third of a 10 000-trial run's set-up)."""
    x = np.asarray(result.parameters, float)
    lay = system.layout
    red = lay.reduced
    computed = np.empty(system.n_rows)
    angular = np.zeros(system.n_rows, bool)
    weight, rows_i, cols_i, repeat, evaluated = [], [], [], [], []
    offset = 0
    for b, cols, sl in zip(system.blocks, system.cols, system.rows):
        mod = kinds_registry.kind(b.kind)
        c, values, columns = mod.evaluate(b, lay, cols, x)
        evaluated.append((values, columns))
        computed[sl] = c
        angular[sl] = mod.ANGULAR
        weight.append(1.0 / np.asarray(b.sigma, float) ** 2 if b.cov is None else np.linalg.inv(b.covariance))
        rc = red[columns]
        slot = offset + np.arange(rc.size)
        keep = rc.ravel() >= 0
        rows_i.append(slot[keep])
        cols_i.append(rc.ravel()[keep])
        repeat.append(np.full(b.n_rows, columns.shape[1]))
        offset += rc.size
    ri, ci = np.concatenate(rows_i), np.concatenate(cols_i)
    scatter = scipy.sparse.csr_matrix((np.ones(len(ri)), (ri, ci)), shape=(offset, system.n_free))
    blocks = result.blocks is not None        # the sparse back end's: Q g through its Schur blocks
    fr = Frozen(system, x, computed, None if blocks else np.ascontiguousarray(result.cofactor, float),
                np.flatnonzero(lay.free), angular, tuple(weight), scatter, np.concatenate(repeat),
                result.determinability, int(result.dof), _program(system, [c for _, c in evaluated], weight),
                cofactor=result if blocks else None, schur=_schur(result) if blocks else None)
    fr.program["ref"] = np.column_stack([np.cos(computed), np.sin(computed), computed])
    if blocks:                  # no dense Q: every step through the Schur blocks (.propagate_blocks)
        return fr
    jac = np.zeros((system.n_rows, system.n_free))   # System.evaluate's dense Jacobian, from the values above
    for (values, columns), sl in zip(evaluated, system.rows):
        rc = red[columns]
        rows = np.broadcast_to(np.arange(sl.start, sl.stop)[:, None], rc.shape)
        keep = rc >= 0
        np.add.at(jac, (rows[keep], rc[keep]), values[keep])
    gain = fr.q @ fr.weighted(np.ascontiguousarray(jac.T))
    fr.program["kt"] = np.ascontiguousarray(gain.T)
    return dataclasses.replace(fr, gain=gain)


def _schur(result: GeneralResult):
    from multilat.network.montecarlo.general.propagate_blocks import schur

    return schur(result)


def _program(system: System, columns_of: list, weight) -> dict:
    """The rows as the compiled kernel's program (:mod:`._frozen_numba`): codes, full and free columns
    (R, 9: ``cols``, ``rcols``; ``columns_of`` each block's Jacobian columns, as its kind evaluates
    them), the vertical height offsets, the tracker components, ``P`` as CSR."""
    from multilat.network.montecarlo.general._frozen_numba import CODES
    from multilat.network.model.kinds.geometry import _heights

    R = system.n_rows
    code, hz, comp, setup = np.empty(R, np.int64), np.zeros(R), np.zeros(R, np.int64), np.full(R, -1, np.int64)
    frames: dict = {}
    cols = np.full((R, 9), -1, np.int64)
    for b, columns, sl in zip(system.blocks, columns_of, system.rows):
        code[sl] = CODES[b.kind]
        cols[sl, :columns.shape[1]] = columns
        if b.kind in ("slope_distance", "zenith_angle", "tracker_angles"):
            hz[sl] = _heights(b, "to_dh") - _heights(b, "from_dh")
        if b.kind == "tracker_angles":
            comp[sl] = b.index["component"]
            for k, f in enumerate(map(tuple, columns[:, 6:9])):
                setup[sl.start + k] = frames.setdefault(f, len(frames))
    red = system.layout.reduced
    p_ptr, p_idx, p_val = _weight_csr(weight, system.rows)
    rcols = np.where(cols >= 0, red[cols], -1).astype(np.int64)     # each slot's free column, -1 for none
    n_in_row = np.diff(p_ptr)
    wdiag = np.zeros(R)
    one = np.flatnonzero(n_in_row == 1)
    one = one[p_idx[p_ptr[one]] == one]
    wdiag[one] = p_val[p_ptr[one]]
    return {"code": code, "cols": cols, "pair": _tracker_pairs(code, cols, hz, comp), "wdiag": wdiag,
            "rcols": rcols, "hz": hz, "comp": comp, "setup": setup,
            "frames": np.array(list(frames), np.int64).reshape(-1, 3),
            "p_ptr": p_ptr, "p_idx": p_idx, "p_val": p_val}


def _weight_csr(weight, rows) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``P``, block diagonal (each block's ``1/σ²`` (R_b,) or ``C⁻¹`` (R_b, R_b)), as CSR arrays
    ``(indptr, indices, data)``, zeros not stored, columns in order within a row: what
    ``scipy.sparse.block_diag`` of the blocks gives, without its set-up (half of ``freeze``)."""
    idx, val, count = [], [], []
    for w, sl in zip(weight, rows):
        nz = w != 0
        if w.ndim == 1:
            idx.append(sl.start + np.flatnonzero(nz))
        else:
            idx.append(sl.start + np.nonzero(nz)[1])
        val.append(w[nz])
        count.append(nz.reshape(len(nz), -1).sum(1))
    ptr = np.concatenate([[0], np.cumsum(np.concatenate(count))]).astype(np.int64)
    return ptr, np.concatenate(idx).astype(np.int64), np.concatenate(val).astype(float)


def _tracker_pairs(code, cols, hz, comp) -> np.ndarray:
    """Per row: the row of its elevation for a tracker azimuth with one (same station, target, set-up
    and heights: the kernel computes the two together), -2 for that elevation, -1 otherwise."""
    from multilat.network.montecarlo.general._frozen_numba import CODES

    pair = np.full(len(code), -1, np.int64)
    az = {}
    for i in np.flatnonzero((code == CODES["tracker_angles"]) & (comp == 0)):
        az.setdefault((tuple(cols[i]), hz[i]), []).append(i)
    for j in np.flatnonzero((code == CODES["tracker_angles"]) & (comp == 1)):
        waiting = az.get((tuple(cols[j]), hz[j]))
        if waiting:
            i = waiting.pop(0)
            pair[i], pair[j] = j, -2
    return pair


# ---------------------------------------------------------------------------------------------- solving
@dataclass(frozen=True, eq=False)
class Solution:
    """x : (T, n) full parameter vectors; converged : (T,) bool; iterations : (T,) chord steps
    full_gauss_newton : (T,) bool (re-solved by full Gauss-Newton); vtpv : (T,) at the solution (of the
    chord steps: ``r^T P r - g^T Q g`` at the last iterate, the value after its step to second order)"""

    x: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    full_gauss_newton: np.ndarray
    vtpv: np.ndarray


def solve(frozen: Frozen, obs: np.ndarray, *, tol: float = 1e-10, max_iter: int = 10,
          fallback: bool = True, engine: str = "auto") -> Solution:
    """Solve the trials ``obs`` (T, R) from ``x̂`` by chord steps (module docstring); trials whose step
    does not shrink by :data:`CONTRACTION`, or not converged after ``max_iter`` steps, by full
    Gauss-Newton (``fallback``). ``engine``: ``numba`` (compiled, :mod:`._frozen_numba`), ``numpy``
    (the kinds vectorised over the trials), ``auto`` (numba when installed)."""
    from multilat._numba import HAVE_NUMBA

    if engine not in ("auto", "numpy", "numba"):
        raise MultilatError(f"engine must be auto, numpy or numba, got {engine!r}")
    obs = np.atleast_2d(np.asarray(obs, float))
    t = len(obs)
    x = np.repeat(frozen.x_hat[None], t, 0)
    iters = np.zeros(t, np.int64)
    vtpv = np.full(t, np.nan)
    done = np.zeros(t, bool)
    far = np.zeros(t, bool)
    compiled = engine == "numba" or (engine == "auto" and HAVE_NUMBA)
    if frozen.q is None:
        from multilat.network.montecarlo.general.propagate_blocks import solve_blocks

        done, iters, far, vtpv = solve_blocks(frozen, obs, x, tol, max_iter, CONTRACTION, compiled)
        return _fall_back(frozen, obs, x, done, iters, far, vtpv, tol, fallback)
    if compiled:
        from multilat.network.montecarlo.general._frozen_numba import chord

        p = frozen.program
        chord(obs, x, p["code"], p["cols"], p["pair"], p["ref"], p["rcols"], p["hz"], p["comp"], p["setup"],
              p["frames"], frozen.angular, p["wdiag"], p["p_ptr"], p["p_idx"], p["p_val"], frozen.free.astype(np.int64),
              frozen.q, frozen.computed, p["kt"], float(tol), int(max_iter), CONTRACTION, done, iters, far, vtpv)
        return _fall_back(frozen, obs, x, done, iters, far, vtpv, tol, fallback)
    # the first step is linear in the noise (at x̂ the model and Jacobian are the adjustment's): one
    # matrix product for all trials, dx = K (l - f(x̂)), K = Q J(x̂)^T P
    r0 = obs - frozen.computed
    r0[:, frozen.angular] = wrap_angle(r0[:, frozen.angular])
    dx = r0 @ frozen.gain.T
    x[:, frozen.free] += dx
    iters[:] = 1
    with np.errstate(invalid="ignore"):
        prev = np.abs(dx).max(axis=1, initial=0.0)
    prev = np.where(np.isfinite(prev), prev, np.inf)
    active = np.arange(t)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        for _ in range(1, max_iter):
            xa = x[active]
            g, v = _gradient(frozen, obs[active], xa)
            dx = g @ frozen.q
            v = v - np.einsum("tj,tj->t", g, dx)          # vTPv after the step, to second order
            xa[:, frozen.free] += dx
            x[active] = xa
            iters[active] += 1
            step = np.abs(dx).max(axis=1)
            step = np.where(np.isfinite(step), step, np.inf)
            active = settle(active, step, v, prev, tol, CONTRACTION, vtpv, done, far)
            if not active.size:
                break
    far[active] = True
    return _fall_back(frozen, obs, x, done, iters, far, vtpv, tol, fallback)


def settle(active, step, v, prev, tol: float, contraction: float, vtpv, done, far) -> np.ndarray:
    """The chord steps' rule, after a step of the ``active`` trials (``step`` its largest |dx|): converged
    when the step is below ``tol`` or the contraction ``c = step / previous`` predicts the rest below it
    (their vᵀPv ``v`` kept, ``done`` set); ``far`` (for full Gauss-Newton) when ``c > contraction``.
    Updates the arrays in place; returns the trials still active."""
    c = step / prev[active]
    ok = (step < tol) | ((c <= contraction) & (step * c < tol * (1.0 - c)))
    vtpv[active[ok]] = v[ok]
    done[active[ok]] = True
    slow = ~ok & (c > contraction)
    far[active[slow]] = True
    prev[active] = step
    return active[~ok & ~slow]


def _gradient(frozen: Frozen, obs: np.ndarray, x: np.ndarray):
    """``J(x)^T P r`` (T, n_free) and ``r^T P r`` (T,) with ``r = obs - f(x)`` per trial, by the kinds
    vectorised over the trials (the numpy engine; the compiled one: :mod:`._frozen_numba`)."""
    r, vals = frozen.residuals(x, obs)
    pr = frozen.weighted(r)
    return frozen.gradient(pr, vals), np.einsum("tr,tr->t", r, pr)


def _fall_back(frozen, obs, x, done, iters, far, vtpv, tol, fallback) -> Solution:
    """Far trials (``far``) solved again from ``x̂`` by full Gauss-Newton."""
    if fallback:
        if frozen.q is None:
            from multilat.network.montecarlo.general.propagate_blocks import sparse_gauss_newton as full
        else:
            full = gauss_newton
        for i in np.flatnonzero(far):
            x[i], done[i], vtpv[i] = full(frozen, obs[i], tol=tol)
    return Solution(x, done, iters, far if fallback else np.zeros(len(x), bool), vtpv)


def whitened_residual(frozen: Frozen, r: np.ndarray) -> np.ndarray:
    """The whitened residual of one trial: angles wrapped to (-π, π], then the system's whitening."""
    r[frozen.angular] = wrap_angle(r[frozen.angular])
    return frozen.system.whiten(r)


def iterate_trial(frozen: Frozen, obs: np.ndarray, step, *, tol: float = 1e-10, max_iter: int = 50):
    """One trial by full Gauss-Newton from ``x̂`` in the frozen datum: ``step(x, d)`` gives the
    whitened residual and the step at ``x`` (``d`` = observed minus the adjustment's values, added to
    the residual at ``x``); the back ends differ only in it (:func:`gauss_newton` dense,
    :func:`.propagate_blocks.sparse_gauss_newton`). ``(x, converged, vTPv)``; a step that fails
    (singular, undefined model) ends the trial unconverged."""
    x = frozen.x_hat.copy()
    d = obs - np.concatenate([np.asarray(b.value, float) for b in frozen.system.blocks])
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        for _ in range(max_iter):
            try:
                rw, dx = step(x, d)
            except (MultilatError, np.linalg.LinAlgError):
                return x, False, np.nan
            x[frozen.free] += dx
            size = float(np.abs(dx).max(initial=0.0))
            if not np.isfinite(size):
                return x, False, np.nan
            if size < tol:
                return x, True, float(rw @ rw)
    return x, False, np.nan


def gauss_newton(frozen: Frozen, obs: np.ndarray, *, tol: float = 1e-10, max_iter: int = 50):
    """One trial by full Gauss-Newton from ``x̂`` (the adjustment's dense step at every iterate, in the
    frozen datum ``B``): ``(x, converged, vTPv)`` (:func:`iterate_trial`)."""
    s, det = frozen.system, frozen.determinability

    def step(x, d):
        r0, jac = s.evaluate(x)
        rw = whitened_residual(frozen, r0 + d)
        return rw, _step(s.whiten(jac), rw, det)[0]

    return iterate_trial(frozen, obs, step, tol=tol, max_iter=max_iter)


# ---------------------------------------------------------------------------------------------- blocks of trials
def draw(frozen: Frozen, n: int, rng: np.random.Generator, model: DistanceNoise | None = None) -> np.ndarray:
    """Observations of ``n`` trials (n, R): ``f(x̂) + L e``, ``e`` standard normal (n, R) in row order;
    with ``model`` its slope distances' errors then drawn from the instrument's distance model instead
    (:func:`multilat.distance_errors.draw_errors`, one seed taken from ``rng`` after the normals)."""
    e = rng.standard_normal((n, frozen.n_rows))
    s = frozen.system
    for L, b, sl in zip(s.chol, s.blocks, s.rows):
        if b.cov is not None:
            e[:, sl] = e[:, sl] @ L.T
    e *= frozen.scale             # σ of the independent rows, 1 of the correlated: one pass, the same bits
    if model is not None:
        from multilat.distance_errors import draw_errors

        e[:, model.rows] = draw_errors(model.error_model, model.head_row, model.distance_m, n, rng)
    e += frozen.computed          # in place: a fresh (n, R) array costs its page faults (~3 ms per 1000 x 130)
    return e


@dataclass(frozen=True, eq=False)
class DistanceNoise:
    """The slope distances drawn from an instrument's distance model (``noise="model"``).

    rows : (m,) system rows;  error_model : :class:`multilat.distance_errors.ErrorModel` (a row per head)
    head_row : (m,) its row per distance;  distance_m : (m,) ``f(x̂)`` of those rows
    std_m : (m,) the model's standard deviation of each (:func:`multilat.budget.distance_std_m`)
    prior_std_m : (m,) their a-priori σ (the adjustment's weights, which the model's draws replace)
    """

    rows: np.ndarray
    error_model: object
    head_row: np.ndarray
    distance_m: np.ndarray
    std_m: np.ndarray
    prior_std_m: np.ndarray


def distance_noise(frozen: Frozen, instrument) -> DistanceNoise:
    """The noise model of the network's slope distances with an instrument (``noise="model"``): every
    slope distance with an instrument (its head) is drawn from that head's model; refused in one line
    when there is none, or when a head is a laser tracker (no such model: gaussian from its MPE)."""
    from multilat import budget
    from multilat import instrument as _instrument
    from multilat.distance_errors import error_model

    inst = _instrument.load_instrument(instrument) if isinstance(instrument, str) else instrument
    rows, heads, prior = [], [], []
    for b, sl in zip(frozen.system.blocks, frozen.system.rows):
        if b.kind != "slope_distance" or b.index.get("instrument") is None:
            continue
        idx = np.asarray(b.index["instrument"], int)
        keep = np.flatnonzero(idx >= 0)
        if keep.size and b.cov is not None:
            raise MultilatError("noise model draws each slope distance alone; a block of them with a covariance "
                                "(correlated distances) cannot be drawn from the distance model: use noise gaussian")
        rows.append(sl.start + keep)
        prior.append(np.broadcast_to(np.asarray(b.sigma, float), (b.n_rows,))[keep])
        heads.extend(b.names["instrument"][i] for i in idx[keep])
    if not heads:
        raise MultilatError("noise model draws the slope distances of an instrument's heads; this network has "
                            "none (no slope distance names its instrument): use noise gaussian")
    names = tuple(dict.fromkeys(heads))
    for hd in names:
        if getattr(inst, "is_tracker", lambda _: False)(hd):
            raise MultilatError(f"noise model: head {hd!r} is a laser tracker, which has no distance model to "
                                "draw from here; use noise gaussian (its σ from the MPE)")
    rows = np.concatenate(rows)
    head_row = np.array([names.index(h) for h in heads], np.int64)
    d = frozen.computed[rows]
    std = np.empty(len(rows))
    for k, hd in enumerate(names):
        sel = head_row == k
        std[sel] = budget.distance_std_m(inst, d[sel], head=hd)
    return DistanceNoise(rows, error_model(inst, names), head_row, d, std, np.concatenate(prior))


def _noise_cofactor(frozen: Frozen, model: DistanceNoise | None) -> np.ndarray:
    """The linear covariance of the free parameters for the drawn inputs (σ0 a priori 1): ``Q`` for the
    a-priori covariance, ``Q + K_m (S² - C_m) K_m^T`` when the model's rows ``m`` (uncorrelated, σ²
    ``C_m``) are drawn with the model's σ² ``S²`` instead (``K = Q J^T P``: ``K C K^T = Q``)."""
    if model is None:
        return frozen.q
    km = frozen.gain[:, model.rows]
    return frozen.q + (km * (model.std_m ** 2 - model.prior_std_m ** 2)) @ km.T


@dataclass(frozen=True, eq=False)
class _Spec:
    frozen: Frozen
    pairs: np.ndarray          # (q, 2) point indices
    tol: float
    max_iter: int
    engine: str = "auto"
    model: DistanceNoise | None = None


def _outputs(frozen: Frozen, pairs: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Deviations from x̂ of the free parameters, then of the pairs' distances (T, n_free + q), float32:
    each computed in float64 and rounded once as it is written (what ``.astype(np.float32)`` of the
    float64 deviations gives, without the (T, n_free + q) float64 array)."""
    pc = frozen.system.layout.point_cols
    nf = len(frozen.free)
    out = np.empty((len(x), nf + len(pairs)), np.float32)
    np.subtract(x[:, frozen.free], frozen.x_hat[frozen.free], out=out[:, :nf])
    if len(pairs):
        a, b = pc[pairs[:, 0]], pc[pairs[:, 1]]
        d0 = np.linalg.norm(frozen.x_hat[b] - frozen.x_hat[a], axis=-1)
        np.subtract(np.linalg.norm(x[:, b] - x[:, a], axis=-1), d0, out=out[:, nf:])
    return out


def _solve_block(spec: _Spec, entropy, spawn_key: tuple, b: int, n: int) -> dict:
    obs = draw(spec.frozen, n, block_generator(entropy, spawn_key, b), spec.model)
    sol = solve(spec.frozen, obs, tol=spec.tol, max_iter=spec.max_iter, engine=spec.engine)
    ok = sol.converged
    all_ok = bool(ok.all())
    return {"dev": _outputs(spec.frozen, spec.pairs, sol.x if all_ok else sol.x[ok]), "n": n,
            "n_failed": int(n - ok.sum()), "n_retried": int(sol.full_gauss_newton.sum()),
            "iterations": int(sol.iterations.sum()), "vtpv": sol.vtpv if all_ok else sol.vtpv[ok]}


def _run_chunk(args) -> list:
    """Blocks ``[start, stop)`` of a run of ``trials`` trials (module level: process pools pickle it)."""
    spec, entropy, spawn_key, start, stop, trials = args
    return [_solve_block(spec, entropy, spawn_key, b, block_trials(b, trials, BLOCK)) for b in range(start, stop)]


def propagate(system: System, result: GeneralResult, *, trials: int = 100_000, rng=None, pairs=None,
              chunk_size: int = 10_000, map=None, progress: Callable[[int], None] | None = None,
              keep_samples: bool = False, tol: float = 1e-10, max_iter: int = 10,
              engine: str = "auto", noise: str | None = None, instrument=None) -> GeneralPropagation:
    """Monte Carlo of an adjusted general network (``system``, ``result`` of one adjustment, e.g.
    :func:`.run.adjust_network`'s) through its frozen system (module docstring).

    trials : fixed number of trials;  rng : root seed (:func:`multilat.montecarlo.resolve_seed`)
    pairs : (point id, point id) pairs whose distances to report (default :func:`default_pairs`)
    chunk_size : trials per unit of work given to ``map`` (whole blocks; never changes a number)
    map : ordered map (:func:`multilat.parallel.map_from_options`); default in-process threads
    tol : convergence on the largest step (m, rad);  max_iter : chord steps before full Gauss-Newton
    engine : ``auto`` | ``numba`` | ``numpy`` (:func:`solve`; the same solutions to the step tolerance)
    noise, instrument : ``gaussian`` (every observation from its a-priori covariance) or ``model`` (the
        slope distances from ``instrument``'s distance model, :func:`distance_noise`; the rest gaussian);
        the rule of :func:`multilat.network.montecarlo.propagate.noise_choice` (model needs the instrument named)
    """
    t0 = time.perf_counter()
    for name, v, lo in (("trials", trials, 2), ("chunk_size", chunk_size, 1), ("max_iter", max_iter, 1)):
        if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < lo:
            raise MultilatError(f"{name} must be an integer >= {lo}, got {v!r}")
    from multilat.network.montecarlo.propagate import noise_choice

    noise, instrument = noise_choice(noise, instrument)
    frozen = freeze(system, result)
    model = distance_noise(frozen, instrument) if noise == "model" else None
    ids = system.network.points.ids
    if pairs is None:
        pidx = default_pairs(system)
    else:
        idx = {p: i for i, p in enumerate(ids)}
        bad = [p for ab in pairs for p in ab if p not in idx]
        if bad:
            raise MultilatError(f"pair point {bad[0]!r} is not a point of the adjusted network")
        pidx = np.array([(idx[a], idx[b]) for a, b in pairs], int).reshape(-1, 2)
    from multilat.network.montecarlo.general.propagate_blocks import check_size, linear

    check_size(frozen, trials, len(frozen.free) + len(pidx))
    spec = _Spec(frozen, pidx, float(tol), int(max_iter), engine, model)
    ss = resolve_seed(rng)
    entropy, key = ss.entropy, tuple(ss.spawn_key)
    if map is None:
        from multilat.parallel import thread_map

        mapper, unit = thread_map, BLOCK
    else:
        mapper, unit = resolve_map(map), chunk_size
    blocks, done = [], 0
    for res in mapper(_run_chunk, [(spec, entropy, key, c0, c1, trials)
                                   for c0, c1 in chunk_ranges(trials, unit, BLOCK)]):
        blocks.extend(res)
        done += sum(r["n"] for r in res)
        if progress:
            progress(done)
    if frozen.q is None:
        return summarise(frozen, pidx, blocks, entropy, t0, keep_samples, noise, linear=linear(frozen, pidx, model))
    return summarise(frozen, pidx, blocks, entropy, t0, keep_samples, noise, _noise_cofactor(frozen, model))
