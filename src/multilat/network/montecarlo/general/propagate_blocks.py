"""The general Monte Carlo on networks the sparse back end adjusts (no dense ``Q``): the chord steps
of :mod:`.propagate` with ``Q g`` solved through the adjustment's Schur structure.

The sparse back end (:mod:`.sparse`) keeps the cofactor matrix in blocks: the eliminated points'
3 x 3 inverses ``N_pp⁻¹``, the coupling ``X`` (sparse) and the reduced system's ``Q⁻_KK`` (k x k,
factored once at x̂), and the datum's low-rank terms. A chord step ``dx = Q J(x_t)^T P r_t`` is then,
for a block of trials at once, the gradients ``g_t`` (compiled, :func:`._frozen_numba.gradients`, or
the kinds in numpy) and one :meth:`.sparse.SparseCofactor.times` on the (n_free, T) matrix of them:
``O(R + nnz X + k²)`` a trial and step instead of the dense path's ``O(n_free²)``, memory ``O(T n_free)``
instead of ``n_free²`` (Q) and ``n_free R`` (the gain ``K``). The first step is a chord step like the
others (at x̂ the gradient is ``J(x̂)^T P (l - f(x̂))``, so ``Q`` of it is ``K (l - f(x̂))``); the
convergence rule, the far trials' full Gauss-Newton (here by the sparse back end's step in the frozen
datum ``B``, :func:`.sparse.frozen_step`, the adjustment's own), the seeding and the outputs are
:mod:`.propagate`'s.

Limits (:func:`check_size`): the trials' deviations are kept (float32, one column per free parameter and
reported distance) until summarised, and the work grows as ``trials x (R + nnz X + k²)``; a run past
:data:`MAX_SAMPLE_BYTES` or :data:`MAX_WORK` is refused in one line before any work.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError

__all__ = ["MAX_SAMPLE_BYTES", "MAX_WORK", "Schur", "check_size", "linear", "schur", "solve_blocks",
           "sparse_gauss_newton"]

#: the kept deviations (float32, trials x (free parameters + reported distances)) at most this many bytes
MAX_SAMPLE_BYTES = 4e9
#: at most this many operations, ``trials x 3 chord steps x (40 R + 2 nnz X + 2 k²)`` (measured
#: 5e8 to 1e9 a CPU second on distance-only networks of 8 x 4 000 and 8 x 1 000 targets: 16 to 33 CPU
#: minutes, docs/cli.md "Size limits")
MAX_WORK = 1e12


def work(frozen, trials: int) -> float:
    """The operations of a run (the estimate :data:`MAX_WORK` bounds)."""
    red = frozen.cofactor.blocks.lin.red
    k = red.ck.size
    return float(trials) * 3.0 * (40.0 * frozen.n_rows + 2.0 * red.x.nnz + 2.0 * k * k)


def check_size(frozen, trials: int, n_outputs: int) -> None:
    """Refuse a run past the limits (module docstring) in one line, naming the size and the limit."""
    nbytes = 4.0 * trials * n_outputs
    if nbytes > MAX_SAMPLE_BYTES:
        raise MultilatError(
            f"the general Monte Carlo keeps {trials} trials x {n_outputs} outputs (free parameters and reported "
            f"distances) = {nbytes / 1e9:.1f} GB of deviations; the limit is {MAX_SAMPLE_BYTES / 1e9:g} GB: "
            f"run at most {int(MAX_SAMPLE_BYTES // (4 * n_outputs))} trials")
    if frozen.q is None:
        w = work(frozen, trials)
        if w > MAX_WORK:
            raise MultilatError(
                f"the general Monte Carlo of this network ({len(frozen.free)} unknowns, {frozen.n_rows} observation "
                f"rows, reduced system {frozen.cofactor.blocks.lin.red.ck.size}) takes ~{w:.1e} operations for "
                f"{trials} trials; the limit is {MAX_WORK:.0e} (16 to 33 CPU minutes): run at most "
                f"{int(trials * MAX_WORK / w)} trials")


#: ``X`` is kept dense (one BLAS product a step) up to this many bytes, sparse above
DENSE_X_BYTES = 4e8


@dataclass(frozen=True, eq=False)
class Schur:
    """The sparse back end's ``Q`` at x̂ as the chord step needs it, trials along rows
    (:meth:`.sparse.SparseCofactor.times`, the same algebra): ``ck`` (k,) the reduced columns, ``qk``
    (k, k) ``Q⁻_KK``, ``x`` (3m, k) ``X`` (dense up to :data:`DENSE_X_BYTES`, else CSR), ``binv``
    (m, 3, 3) ``N_pp⁻¹``, ``fv`` the free columns of the eliminated slots ``valid``, ``h`` (n, d) and
    ``b`` (n, d) the datum's ``H`` and constraints ``B`` (None without a defect)."""

    ck: np.ndarray
    qk: np.ndarray
    x: object
    binv: np.ndarray
    valid: np.ndarray
    fv: np.ndarray
    h: np.ndarray | None
    b: np.ndarray | None

    def ginv(self, g: np.ndarray) -> np.ndarray:
        """``N⁻`` applied to every row of ``g`` (T, n)."""
        t, m = len(g), len(self.binv)
        if self.fv.size == 3 * m:
            be = g[:, self.fv]
        else:
            be = np.zeros((t, 3 * m))
            be[:, self.valid] = g[:, self.fv]
        xt = self.x
        yk = (g[:, self.ck] - (be @ xt if isinstance(xt, np.ndarray) else (xt.T @ be.T).T)) @ self.qk
        ye = np.matmul(self.binv, be.reshape(t, m, 3).transpose(1, 2, 0)).transpose(2, 0, 1).reshape(t, 3 * m)
        ye -= yk @ xt.T if isinstance(xt, np.ndarray) else (xt @ yk.T).T
        out = np.zeros_like(g)
        out[:, self.ck] = yk
        out[:, self.fv] = ye[:, self.valid]
        return out

    def times(self, g: np.ndarray) -> np.ndarray:
        """``Q g_t`` for every row ``g_t`` of ``g`` (T, n) (the datum ``B^T dx = 0`` applied)."""
        if self.h is None:
            return self.ginv(g)
        gb = (g @ self.h) @ -self.b.T          # in place: (T, n) temporaries are the cost here
        gb += g
        y = self.ginv(gb)
        yh = (y @ self.b) @ -self.h.T
        yh += y
        return yh


def schur(result) -> Schur:
    """:class:`Schur` of a sparse adjustment's result (its ``blocks``)."""
    lin = result.blocks.lin
    red = lin.red
    flat = red.slots.ravel()
    valid = flat >= 0
    x = red.x
    if 8.0 * x.shape[0] * x.shape[1] <= DENSE_X_BYTES:
        x = x.toarray()
    return Schur(red.ck, np.ascontiguousarray(red.qk), x, np.ascontiguousarray(red.binv), valid, flat[valid],
                 lin.h, None if lin.h is None else lin.det.constraints)


def _times(frozen, g: np.ndarray) -> np.ndarray:
    """``Q g`` for rows ``g`` (T, n_free) through the blocks."""
    return frozen.schur.times(g)


def _gradients(frozen, obs: np.ndarray, x: np.ndarray, compiled: bool):
    """``J(x_t)^T P r_t`` (T, n_free) and ``r_t^T P r_t`` (T,) of every trial."""
    if not compiled:
        from multilat.network.montecarlo.general.propagate import _gradient

        return _gradient(frozen, obs, x)
    from multilat.network.montecarlo.general._frozen_numba import gradients

    p = frozen.program
    g = np.empty((len(x), len(frozen.free)))
    v = np.empty(len(x))
    gradients(np.ascontiguousarray(obs), np.ascontiguousarray(x), p["code"], p["cols"], p["pair"], p["ref"],
              p["rcols"], p["hz"], p["comp"], p["setup"], p["frames"], frozen.angular, p["wdiag"], p["p_ptr"],
              p["p_idx"], p["p_val"], g, v)
    return g, v


def solve_blocks(frozen, obs: np.ndarray, x: np.ndarray, tol: float, max_iter: int, contraction: float,
                 compiled: bool):
    """Chord steps of every trial from ``x`` (= x̂, in place) with ``Q g`` through the blocks; the rule of
    :func:`.propagate.solve`. Returns (converged, iterations, far, vtpv)."""
    from multilat.network.montecarlo.general.propagate import settle

    t = len(obs)
    iters = np.zeros(t, np.int64)
    vtpv = np.full(t, np.nan)
    done = np.zeros(t, bool)
    far = np.zeros(t, bool)
    prev = np.full(t, np.inf)
    active = np.arange(t)
    free = frozen.free
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        for it in range(max_iter):
            xa = x[active]
            g, v = _gradients(frozen, obs[active], xa, compiled)
            dx = _times(frozen, g)
            v = v - np.einsum("tj,tj->t", g, dx)          # vTPv after the step, to second order
            xa[:, free] += dx
            x[active] = xa
            iters[active] += 1
            step = np.abs(dx).max(axis=1, initial=0.0)
            step = np.where(np.isfinite(step), step, np.inf)
            if it == 0:                                   # the first step: linear in the noise, no test
                prev[active] = step
                continue
            active = settle(active, step, v, prev, tol, contraction, vtpv, done, far)
            if not active.size:
                break
    far[active] = True
    return done, iters, far, vtpv


def sparse_gauss_newton(frozen, obs: np.ndarray, *, tol: float = 1e-10, max_iter: int = 50):
    """One trial by full Gauss-Newton from x̂ with the sparse back end's step (its elimination at every
    iterate, :func:`.sparse.eliminate` and :func:`.sparse.frozen_step`) in the frozen datum ``B``:
    ``(x, converged, vTPv)`` (:func:`.propagate.iterate_trial`)."""
    from multilat.network.adjust.general import sparse
    from multilat.network.montecarlo.general.propagate import iterate_trial, whitened_residual

    s = frozen.system
    det = frozen.determinability
    B = det.constraints if det.defect else None

    def step(x, d):
        r0, _, jw = sparse.assemble(s, x)
        rw = whitened_residual(frozen, r0 + d)
        return rw, sparse.frozen_step(sparse.eliminate(s, jw)[0], jw, rw, B)[0]

    return iterate_trial(frozen, obs, step, tol=tol, max_iter=max_iter)


def linear(frozen, pairs: np.ndarray, model=None, batch: int = 256):
    """Linear std of the outputs (free parameters, then the pairs' distances) and the full-layout
    covariance of the points (P, 3, 3), from the blocks: ``Q`` (its diagonal, point blocks, ``g Q gᵀ``
    per pair by a solve per batch of pairs), plus ``K_m (S² - C_m) K_mᵀ`` for the model's rows
    (:func:`.propagate._noise_cofactor`; ``K_m = Q J_mᵀ P_m`` a batch of rows at a time)."""
    res = frozen.cofactor
    blocks = res.blocks
    n_free = len(frozen.free)
    pc = frozen.system.layout.point_cols
    red_cols = frozen.system.layout.reduced
    var = res.cofactor_diagonal()
    point = blocks.point.copy()
    g = np.zeros((n_free, len(pairs)))
    if len(pairs):
        u = frozen.x_hat[pc[pairs[:, 1]]] - frozen.x_hat[pc[pairs[:, 0]]]
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        for end, sign in ((1, 1.0), (0, -1.0)):
            c = red_cols[pc[pairs[:, end]]]
            q_i, a_i = np.nonzero(c >= 0)
            np.add.at(g, (c[q_i, a_i], q_i), sign * u[q_i, a_i])
    pair_var = np.concatenate([(g[:, lo:lo + batch] * _times(frozen, g[:, lo:lo + batch].T).T).sum(0)
                               for lo in range(0, len(pairs), batch)] or [np.zeros(0)])
    if model is not None:
        from multilat.network.adjust.general import sparse

        _, _, jw = sparse.assemble(frozen.system, frozen.x_hat)
        jm = jw[model.rows].tocsr()
        d = model.std_m ** 2 - model.prior_std_m ** 2
        slots = blocks.slots
        have = slots >= 0
        sl = np.where(have, slots, 0)
        for lo in range(0, len(model.rows), batch):
            hi = min(lo + batch, len(model.rows))
            a = (jm[lo:hi].T / model.prior_std_m[lo:hi]).toarray()      # J_m^T P_m (whitened: J/σ, so /σ again)
            k = _times(frozen, a.T).T                                  # K_m, (n_free, c)
            var += (k * k) @ d[lo:hi]
            pair_var += ((g.T @ k) ** 2) @ d[lo:hi]
            kp = k[sl] * have[:, :, None]                              # (P, 3, c)
            point += np.einsum("pac,pbc,c->pab", kp, kp, d[lo:hi])
    std = np.sqrt(np.clip(np.concatenate([var, pair_var]), 0, None))
    return std, point
