"""Sparse back end of the general network adjustment: the whitened Jacobian in ``scipy.sparse``, the
points eliminated by Schur complement, a small dense system on the rest.

**Normal equations.** ``N = J_wᵀ J_w`` (n x n, sparse), ``b = J_wᵀ r_w``. The free parameters split
into ``E``, the eliminated points, and ``K``, the rest (instrument constants and scales,
orientations, frames, the points that stay). ``E`` is a greedy independent set of the points in the
graph "two points share an observation row" (low degree first: targets go, stations stay), among the
points whose own block ``N_pp`` is well conditioned (after scaling it to a unit diagonal, its
smallest eigenvalue is at least :data:`RCOND_BLOCK` of its largest): no row touches two points of
``E``, so ``N_EE`` is block diagonal (1-3 x 1-3 per point) and inverted block by block. With
``X = N_EE⁻¹ N_EK`` (sparse: a point's row of ``X`` touches the K parameters of its rows)::

    S = N_KK - N_KE X                    (the reduced normal matrix, dense, k x k)
    S y_K = b_K - Xᵀ b_E,   y_E = N_EE⁻¹ b_E - X y_K

``S`` is the Schur complement: ``N`` and ``S`` have the same null space up to the back substitution
``g_E = -X g_K`` (``N_EE`` is regular), so the datum defect and the undetermined parameters come
from ``S`` (:func:`..determinability.schur_null_space`: the column-scaled eigen-decomposition,
its threshold and why) and are named by the dense back end's rules (:func:`..determinability.classify`).
A network whose reduced system stays larger than :data:`MAX_REDUCED` is refused in one line.

**Datum.** A defect ``d``: minimal constraints hold the ``d`` columns of ``K`` on which the null
space ``G`` is best conditioned (pivoted QR of ``G_Kᵀ``); ``S`` without them is regular and gives a
reflexive generalised inverse ``N⁻`` (zero on the held columns). The inner constraints ``Bᵀ dx = 0``
of a free network (``B``: the null space on the datum points' free coordinates, minimum trace over
them, as the dense back end) follow by the S-transformation ``P = I - H Bᵀ``, ``H = G (BᵀG)⁻¹``::

    dx = P N⁻ b,    Q = P N⁻ Pᵀ = N⁻ - H Wᵀ - W Hᵀ + H (BᵀW) Hᵀ,    W = N⁻ B

which is the top-left block of the inverse of the bordered matrix ``[[N, B], [Bᵀ, 0]]`` that the
dense back end inverts (the unique symmetric reflexive g-inverse with ``Bᵀ Q = 0``).

**Results** (never an (n, n) or (R, R) matrix): the point 3 x 3 cofactors (``E``: ``N_pp⁻¹ +
X_p Q⁻_KK X_pᵀ`` + the datum terms), the (k, k) cofactor of ``K``, and the redundancy numbers per
row, ``r_i = 1 - j_i Q j_iᵀ`` with (a row touches at most one point of ``E``)::

    j N⁻ jᵀ = j_E N_pp⁻¹ j_Eᵀ + z Q⁻_KK zᵀ,    z = j_K - j_E X_p

minus ``2 (j H)·(j W)`` plus ``(j H) BᵀW (j H)ᵀ``: rows of ``Z = J_K - J_E X`` (sparse) and ``J_w H``,
``J_w W`` (R x d). ``Q m`` for a few columns ``m`` costs one solve (:meth:`SparseCofactor.times`).
Memory O(R + n k). The external reliability, which needs ``Q jᵀ`` for every row, is computed from the
same row split (:func:`row_parts`) by :class:`..reliability.SchurShifts`, O(R k²).

**One step** (:func:`eliminate`, :func:`frozen_step`): the elimination of one linearisation and one
Gauss-Newton step on it with the datum held by given constraints, shared by the adjustment
(:func:`linearise`) and the Monte Carlo's full Gauss-Newton (:mod:`.propagate_blocks`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from multilat.errors import MultilatError
from multilat.network.model.datum import s_factor
from multilat.network.model import kinds as kinds_registry
from multilat.network.model.determinability import Determinability, classify, schur_null_space

__all__ = ["RCOND_BLOCK", "MAX_REDUCED", "SparseCofactor", "Reduced", "RowParts", "assemble", "eliminate",
           "frozen_step", "damped_step", "Linearised", "linearise", "row_parts", "check_reduced_size"]

#: an eliminated point's block, scaled to a unit diagonal, has its smallest eigenvalue at least this
#: fraction of its largest (condition <= 1e6: its explicit inverse is exact to ~1e-10 relative); a
#: weaker point stays in K, where the rank decision sees it
RCOND_BLOCK = 1e-6
#: the largest reduced system (dense k x k, eigen-decomposed at each iteration: O(k³))
MAX_REDUCED = 3000
#: rows per batch of the redundancy numbers' dense products (memory: BATCH x k floats)
BATCH = 4096


def assemble(system, x: np.ndarray):
    """Residuals (R,), whitened residuals (R,) and the whitened Jacobian (R, n_free) as CSR at ``x``."""
    r = np.empty(system.n_rows)
    rows_all, cols_all, vals_all = [], [], []
    for b, cols, sl, L in zip(system.blocks, system.cols, system.rows, system.chol):
        computed, values, columns = kinds_registry.kind(b.kind).evaluate(b, system.layout, cols, x)
        r[sl] = kinds_registry.residual(b, computed)
        red = system.reduced[columns]
        local = np.broadcast_to(np.arange(b.n_rows)[:, None], red.shape)
        keep = red >= 0
        lr, lc, lv = local[keep], red[keep], values[keep]
        if b.cov is None:
            lv = lv / np.asarray(b.sigma, float)[lr]
        else:                                   # a correlated block: L⁻¹ J on the columns it touches
            uc, inv = np.unique(lc, return_inverse=True)
            dense = np.zeros((b.n_rows, uc.size))
            np.add.at(dense, (lr, inv), lv)
            dense = scipy.linalg.solve_triangular(L, dense, lower=True)
            lr, ci = (a.ravel() for a in np.indices(dense.shape))     # structural: every entry kept
            lc, lv = uc[ci], dense[lr, ci]
        rows_all.append(lr + sl.start)
        cols_all.append(lc)
        vals_all.append(lv)
    jw = sp.csr_matrix((_cat(vals_all, float), (_cat(rows_all, int), _cat(cols_all, int))),
                       shape=(system.n_rows, system.n_free))
    return r, system.whiten(r), jw


def _cat(parts: list, dtype) -> np.ndarray:
    return np.concatenate(parts) if parts else np.zeros(0, dtype)


def _point_slots(system) -> np.ndarray:
    """(points, 3) free column of each point coordinate, -1 where held."""
    return system.reduced[system.layout.point_cols]


def _point_blocks(N, slots: np.ndarray) -> np.ndarray:
    """(m, 3, 3) diagonal blocks of ``N`` on the points' slots; identity on held coordinates."""
    m = slots.shape[0]
    ia = np.broadcast_to(slots[:, :, None], (m, 3, 3))
    ib = np.broadcast_to(slots[:, None, :], (m, 3, 3))
    ok = (ia >= 0) & (ib >= 0)
    out = np.zeros((m, 3, 3))
    if ok.any():
        out[ok] = np.asarray(N[ia[ok], ib[ok]]).ravel()
    pad = slots < 0
    out[:, np.arange(3), np.arange(3)] += pad
    return out


def _graph(system, jw, slots: np.ndarray):
    """The points' adjacency (CSR, points x points: two points share an observation row) and each
    point's degree; structural (the kinds' columns do not change between iterations): built once
    per system."""
    cache = system.__dict__.setdefault("_sparse_graph", {})
    if "adj" not in cache:
        n_pts = slots.shape[0]
        pt_of_col = np.full(system.n_free, -1)
        has = slots >= 0
        pt_of_col[slots[has]] = np.nonzero(has)[0]
        coo = jw.tocoo()
        p = pt_of_col[coo.col]
        k = p >= 0
        inc = sp.csr_matrix((np.ones(int(k.sum())), (coo.row[k], p[k])), shape=(jw.shape[0], n_pts))
        adj = (inc.T @ inc).tocsr()
        cache.update(adj=adj, deg=np.diff(adj.indptr))
    return cache


def partition(system, jw, N, slots: np.ndarray) -> np.ndarray:
    """Indices of the points eliminated (module docstring): well conditioned, no shared row. The
    greedy pass is redone only when the set of well-conditioned points changes between iterations."""
    graph = _graph(system, jw, slots)
    blk = _point_blocks(N, slots)
    diag = np.einsum("pii->pi", blk)
    pos = np.all(diag > 0, axis=1) & (slots >= 0).any(1)
    scale = 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0))
    w = np.linalg.eigvalsh(blk * scale[:, :, None] * scale[:, None, :])
    good = pos & (w[:, 0] >= RCOND_BLOCK * w[:, -1])
    if "good" in graph and np.array_equal(graph["good"], good):
        return graph["taken"]
    cand = np.flatnonzero(good)
    order = cand[np.argsort(graph["deg"][cand], kind="stable")]
    taken = np.zeros(slots.shape[0], bool)
    blocked = np.zeros(slots.shape[0], bool)
    ind, ptr = graph["adj"].indices, graph["adj"].indptr
    for q in order:
        if not blocked[q]:
            taken[q] = True
            blocked[ind[ptr[q]:ptr[q + 1]]] = True
    graph.update(good=good, taken=np.flatnonzero(taken))
    return graph["taken"]


@dataclass(frozen=True, eq=False)
class Reduced:
    """One linearisation's elimination: ``slots`` (m, 3) free columns of the eliminated points (-1
    held), ``ck`` (k,) the other free columns, ``binv`` (m, 3, 3) ``N_pp⁻¹``, ``x`` (3m, k) CSR ``X``,
    ``qk`` (k, k) ``Q⁻_KK`` (zero on the held columns), ``null`` (n, d) the null space, ``n`` free,
    ``points`` (m,) the eliminated points' indices."""

    slots: np.ndarray
    ck: np.ndarray
    binv: np.ndarray
    x: sp.csr_matrix
    qk: np.ndarray
    null: np.ndarray
    n: int
    points: np.ndarray

    def ginv(self, rhs: np.ndarray) -> np.ndarray:
        """``N⁻ rhs`` for rhs (n,) or (n, c)."""
        one = rhs.ndim == 1
        b = rhs[:, None] if one else rhs
        flat = self.slots.ravel()
        valid = flat >= 0
        be = np.where(valid[:, None], b[np.where(valid, flat, 0)], 0.0)
        yk = self.qk @ (b[self.ck] - self.x.T @ be)
        m = self.slots.shape[0]
        c = b.shape[1]                          # explicit: no point eliminated leaves m = 0
        ye = np.einsum("pab,pbc->pac", self.binv, be.reshape(m, 3, c)).reshape(3 * m, c) - self.x @ yk
        out = np.zeros_like(b, dtype=float)
        out[self.ck] = yk
        out[flat[valid]] = ye[valid]
        return out[:, 0] if one else out


def _reduce(system, N, slots_all, mask_e) -> tuple:
    """``X``, ``S``, ``N_pp⁻¹`` and the K columns for the eliminated points ``mask_e``."""
    slots = slots_all[mask_e]
    flat = slots.ravel()
    valid = flat >= 0
    in_e = np.zeros(system.n_free, bool)
    in_e[flat[valid]] = True
    ck = np.flatnonzero(~in_e)
    if ck.size > MAX_REDUCED:
        raise MultilatError(
            f"the general model's sparse back end takes a reduced system of at most {MAX_REDUCED} parameters; "
            f"this network leaves {ck.size} after eliminating {int(mask_e.sum())} of {slots_all.shape[0]} points "
            f"({system.n_free} unknowns, {system.n_rows} observation rows)")
    rows = sp.diags(valid.astype(float)) @ N[np.where(valid, flat, 0)]
    nek = rows[:, ck].tocsr()
    m = slots.shape[0]
    binv = np.linalg.inv(_point_blocks(N, slots)) if m else np.zeros((0, 3, 3))
    binv = binv * valid.reshape(m, 3)[:, :, None] * valid.reshape(m, 3)[:, None, :]
    r = np.repeat(np.arange(3 * m).reshape(m, 3), 3, axis=1).ravel()
    c = np.tile(np.arange(3 * m).reshape(m, 3), (1, 3)).ravel()
    bs = sp.csr_matrix((binv.ravel(), (r, c)), shape=(3 * m, 3 * m))
    x = (bs @ nek).tocsr()
    nkk = N[ck][:, ck].toarray()
    S = nkk - (nek.T @ x).toarray()
    return slots, ck, binv, x, S, np.sqrt(np.clip(np.diag(nkk), 0, None))


def _g_inverse(S, col_norms, slots, ck, binv, x, n, points) -> tuple[Reduced, np.ndarray]:
    """The rank decision on ``S``, the full null space, and ``Q⁻_KK`` under minimal constraints; with
    the singular values of the rank decision (:func:`..determinability.schur_null_space`)."""
    v0, scale, sv = schur_null_space(S, col_norms)
    d = v0.shape[1]
    qk = np.zeros_like(S)
    keep = np.ones(ck.size, bool)
    if d:
        _, _, perm = scipy.linalg.qr(v0.T, pivoting=True, mode="economic")
        keep[perm[:d]] = False
    if keep.any():
        ss = S[np.ix_(keep, keep)] * scale[keep][:, None] * scale[keep][None, :]
        qi = np.linalg.inv(0.5 * (ss + ss.T))
        qk[np.ix_(keep, keep)] = qi * scale[keep][:, None] * scale[keep][None, :]
    g = np.zeros((n, d))
    if d:
        gk = v0 * scale[:, None]
        g[ck] = gk
        ge = -(x @ gk)
        flat = slots.ravel()
        g[flat[flat >= 0]] = ge[flat >= 0]
        g /= np.linalg.norm(g, axis=0, keepdims=True).clip(1e-300)
    return Reduced(slots, ck, binv, x, 0.5 * (qk + qk.T), g, n, points), sv


def eliminate(system, jw: sp.csr_matrix, damping: float = 0.0) -> tuple[Reduced, np.ndarray]:
    """The elimination of one linearisation (module docstring): ``N = J_wᵀ J_w``, the points
    eliminated (:func:`partition`), the reduced system and its generalised inverse under minimal
    constraints. Returns the :class:`Reduced` and the singular values of the rank decision on ``S``
    (for :func:`..determinability.classify`). ``damping`` > 0: of ``N`` with each ``N_ii`` times
    ``1 + damping`` (Levenberg-Marquardt, :func:`damped_step`)."""
    N = (jw.T @ jw).tocsr()
    if damping:
        N = (N + sp.diags(damping * N.diagonal())).tocsr()
    slots_all = _point_slots(system)
    e = np.zeros(slots_all.shape[0], bool)
    e[partition(system, jw, N, slots_all)] = True
    slots, ck, binv, x, S, norms = _reduce(system, N, slots_all, e)
    return _g_inverse(S, norms, slots, ck, binv, x, system.n_free, np.flatnonzero(e))


def frozen_step(red: Reduced, jw: sp.csr_matrix, rw: np.ndarray, constraints: np.ndarray | None = None):
    """One Gauss-Newton step on a fixed linearisation (``J_w``, ``r_w``; its elimination ``red`` from
    :func:`eliminate`) with the datum held by ``constraints`` ``B`` (n_free, d): ``dx = P N⁻ J_wᵀ r_w``,
    ``P = I - H Bᵀ``, ``H = G (BᵀG)⁻¹`` (module docstring, "Datum"); None: no datum defect, ``dx = N⁻
    J_wᵀ r_w``. The adjustment's step (:func:`linearise`, ``B`` from the determinability at the
    iterate) and the Monte Carlo's full Gauss-Newton (:func:`.propagate_blocks.sparse_gauss_newton`,
    ``B`` frozen at the adjustment's solution). Returns ``(dx, H)`` (``H`` None without ``B``)."""
    dx = red.ginv(jw.T @ rw)
    if constraints is None:
        return dx, None
    h = s_factor(red.null, constraints)
    return dx - h @ (constraints.T @ dx), h


@dataclass(frozen=True, eq=False)
class Linearised:
    """One linearisation: residuals, whitened residuals and Jacobian, the elimination, the
    determinability, the datum terms ``H``, ``W``, ``BᵀW`` (None without a defect) and the step."""

    r: np.ndarray
    rw: np.ndarray
    jw: sp.csr_matrix
    red: Reduced
    det: Determinability
    h: np.ndarray | None
    w: np.ndarray | None
    m: np.ndarray | None
    dx: np.ndarray


def linearise(system, x_full: np.ndarray, mask: np.ndarray, undetermined) -> Linearised:
    """At ``x_full``: the constrained Gauss-Newton step (``undetermined(det)`` raises the dense back
    end's error when the observations and the datum leave parameters undetermined)."""
    r, rw, jw = assemble(system, x_full)
    red, sv = eliminate(system, jw)
    det = classify(red.null, sv, mask)
    if det.undetermined.size:
        undetermined(det)
    B = w = m = None
    if det.defect:
        B = det.constraints
        if B is None or B.shape[1] != det.defect:
            raise MultilatError("the datum points do not remove the datum defect of the observations")
        w = red.ginv(B)
        m = B.T @ w
    x0, h = frozen_step(red, jw, rw, B)
    return Linearised(r, rw, jw, red, det, h, w, m, x0)


def damped_step(system, lin: Linearised, lam: float) -> np.ndarray:
    """The Levenberg-Marquardt step at ``lin``: ``(N + lam diag N) dx = J_wᵀ r_w`` under the datum's
    inner constraints ``Bᵀ dx = 0``, as the dense back end's damped bordered system. The damped ``N``
    is regular (every free column has a positive diagonal, or ``lin`` named it undetermined), so with
    ``y = N_λ⁻¹ b`` and ``W = N_λ⁻¹ B``: ``dx = y - W (BᵀW)⁻¹ Bᵀ y``."""
    red, _ = eliminate(system, lin.jw, damping=lam)
    dx, _ = frozen_step(red, lin.jw, lin.rw)
    if not lin.det.defect:
        return dx
    B = lin.det.constraints
    w = red.ginv(B)
    return dx - s_factor(w, B) @ (B.T @ dx)       # the S-transformation onto Bᵀ dx = 0 (model.datum)


@dataclass(frozen=True, eq=False)
class SparseCofactor:
    """The cofactor matrix of a sparse adjustment, in blocks (module docstring).

    point : (points, 3, 3) each point's cofactor (zero rows and columns on held coordinates)
    ck : (k,) free columns of the reduced system; qkk : (k, k) their cofactor
    """

    point: np.ndarray
    ck: np.ndarray
    qkk: np.ndarray
    lin: Linearised
    slots: np.ndarray

    def diagonal(self) -> np.ndarray:
        """(n_free,) the diagonal of ``Q``."""
        out = np.zeros(self.lin.red.n)
        has = self.slots >= 0
        out[self.slots[has]] = np.einsum("pii->pi", self.point)[has]
        out[self.ck] = np.diag(self.qkk)
        return out

    def times(self, m: np.ndarray) -> np.ndarray:
        """``Q m`` for m (n_free,) or (n_free, c): one solve per column batch."""
        lin = self.lin
        B = lin.det.constraints
        if lin.h is None:
            return lin.red.ginv(m)
        y = lin.red.ginv(m - B @ (lin.h.T @ m))
        return y - lin.h @ (B.T @ y)


def _datum_terms(lin: Linearised, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """``- H_r W_cᵀ - W_r H_cᵀ + H_r M H_cᵀ`` for free rows/columns (zero without a defect)."""
    if lin.h is None:
        return np.zeros((rows.size, cols.size))
    h, w, m = lin.h, lin.w, lin.m
    return -h[rows] @ w[cols].T - w[rows] @ h[cols].T + h[rows] @ m @ h[cols].T


def cofactor(system, lin: Linearised) -> SparseCofactor:
    """The point cofactors and the reduced system's cofactor at the solution."""
    red = lin.red
    slots_all = _point_slots(system)
    qkk = red.qk + _datum_terms(lin, red.ck, red.ck)
    pos_k = np.full(red.n, -1)
    pos_k[red.ck] = np.arange(red.ck.size)
    point = np.zeros((slots_all.shape[0], 3, 3))
    # points in K: their block of Q_KK
    pk = slots_all >= 0
    ia = np.where(pk, pos_k[np.where(pk, slots_all, 0)], -1)
    both = (ia[:, :, None] >= 0) & (ia[:, None, :] >= 0)
    ii = np.broadcast_to(ia[:, :, None], both.shape)
    jj = np.broadcast_to(ia[:, None, :], both.shape)
    point[both] = qkk[ii[both], jj[both]]
    # eliminated points: N_pp⁻¹ + X_p Q⁻_KK X_pᵀ + datum terms, in batches of points
    flat = red.slots.ravel()
    valid = flat >= 0
    me = red.slots.shape[0]
    idx_e = red.points
    step = max(1, BATCH // 3)
    for lo in range(0, me, step):
        hi = min(lo + step, me)
        xs = red.x[3 * lo:3 * hi].toarray()
        q = red.binv[lo:hi] + np.einsum("pak,pbk->pab", (xs @ red.qk).reshape(hi - lo, 3, -1),
                                        xs.reshape(hi - lo, 3, -1))
        if lin.h is not None:
            f = np.where(valid[3 * lo:3 * hi], flat[3 * lo:3 * hi], 0)
            hh, ww = lin.h[f].reshape(hi - lo, 3, -1), lin.w[f].reshape(hi - lo, 3, -1)
            q = q - np.einsum("pad,pbd->pab", hh, ww) - np.einsum("pad,pbd->pab", ww, hh) \
                + np.einsum("pad,de,pbe->pab", hh, lin.m, hh)
        v = valid[3 * lo:3 * hi].reshape(hi - lo, 3)
        point[idx_e[lo:hi]] = q * v[:, :, None] * v[:, None, :]
    return SparseCofactor(point, red.ck, qkk, lin, slots_all)


@dataclass(frozen=True, eq=False)
class RowParts:
    """The whitened rows split by the elimination (a row touches at most one eliminated point):
    ``z`` (R, k) CSR ``J_K - J_E X``, ``je3`` (R, 3) each row's entries on its eliminated point's
    three slots, ``prow`` (R,) that point's position in ``Reduced.points`` (0 where none), ``touched``
    (R,) whether the row has one."""

    z: sp.csr_matrix
    je3: np.ndarray
    prow: np.ndarray
    touched: np.ndarray


def row_parts(lin: Linearised) -> RowParts:
    """:class:`RowParts` of the whitened Jacobian of ``lin`` (O(nnz J_w + nnz X))."""
    red, jw = lin.red, lin.jw
    R = jw.shape[0]
    flat = red.slots.ravel()
    slot_of = np.full(red.n, -1)
    slot_of[flat[flat >= 0]] = np.nonzero(flat >= 0)[0]
    coo = jw.tocoo()
    s = slot_of[coo.col]
    e = s >= 0
    me = red.slots.shape[0]
    je = sp.csr_matrix((coo.data[e], (coo.row[e], s[e])), shape=(R, 3 * me))
    jk = jw[:, red.ck]
    z = (jk - je @ red.x).tocsr()
    je3 = np.zeros((R, 3))
    prow = np.zeros(R, int)
    touched = np.zeros(R, bool)
    je3[coo.row[e], s[e] % 3] = coo.data[e]
    prow[coo.row[e]] = s[e] // 3
    touched[coo.row[e]] = True
    return RowParts(z, je3, prow, touched)


def redundancy(lin: Linearised) -> np.ndarray:
    """Redundancy numbers ``1 - (J_w Q J_wᵀ)_ii`` per row, from the blocks (module docstring)."""
    red, jw = lin.red, lin.jw
    R = jw.shape[0]
    parts = row_parts(lin)
    z, je3, prow = parts.z, parts.je3, parts.prow
    # j_E N_pp⁻¹ j_Eᵀ: each row's E entries lie in one point's 3 slots
    quad = np.einsum("ia,iab,ib->i", je3, red.binv[prow], je3) if red.slots.shape[0] else np.zeros(R)
    for lo in range(0, R, BATCH):
        hi = min(lo + BATCH, R)
        zc = z[lo:hi].toarray()
        quad[lo:hi] += ((zc @ red.qk) * zc).sum(axis=1)
    if lin.h is not None:
        jh, jwm = jw @ lin.h, jw @ lin.w
        quad += -2.0 * np.einsum("id,id->i", jh, jwm) + np.einsum("id,de,ie->i", jh, lin.m, jh)
    return 1.0 - quad


def check_reduced_size(system) -> None:
    """Refuse, before any approximate coordinate, a network whose reduced system cannot stay within
    :data:`MAX_REDUCED` (the message of the check in the elimination, with the bounds). From the
    design alone: the Jacobian's structure (evaluated at arbitrary distinct coordinates: the kinds'
    columns do not depend on the values) gives the graph "two points share a row"; the points
    eliminated form an independent set of it, and a matching ``M`` bounds what any independent set
    takes: at most the free coordinates of all points less ``min(w_u, w_v)`` for each edge of ``M``
    (``w``: a point's free coordinates; a greedy maximal matching, low degree first). So the reduced
    system keeps at least ``n_free`` less that many: a lower bound, never a refusal of a network the
    elimination would take (ill-conditioned points only add to it). The points the adjustment will
    leave out as undetermined are counted (they are not known before the approximate chain).

    First, without the Jacobian: a vertex cover ``C`` of that graph (every point a row references but
    one, all the points of a correlated block) bounds the bound, ``Σ_M min(w) <= Σ_C w``; when even
    that leaves at most :data:`MAX_REDUCED`, nothing more is done (a tracker network: ``C`` = the
    stations, the reduced system the elimination forms)."""
    from multilat.network.model.observations import point_keys

    if system.n_free <= MAX_REDUCED:
        return
    slots = _point_slots(system)
    n = slots.shape[0]
    w = (slots >= 0).sum(axis=1)
    cover = np.zeros(n, bool)
    for b in system.blocks:
        keys = point_keys(b)
        if b.cov is not None:                    # whitening couples its rows: any two of its points
            cover[np.concatenate([np.asarray(b.index[k], int).ravel() for k in keys])] = True
        elif len(keys) > 1:
            rest = [k for k in keys if k != "to"] if "to" in keys else keys[:-1]
            for k in rest:
                cover[np.asarray(b.index[k], int).ravel()] = True
    if system.n_free - int(w.sum()) + int(w[cover].sum()) <= MAX_REDUCED:
        return
    x = system.layout.initial()
    x[system.layout.point_cols] = ((np.arange(3 * n) + 1) * 0.6180339887498949 % 1.0).reshape(n, 3) * 100.0
    with np.errstate(all="ignore"):
        _, _, jw = assemble(system, x)
    graph = _graph(system, jw, slots)
    ind, ptr, deg = graph["adj"].indices, graph["adj"].indptr, graph["deg"]
    matched = np.zeros(n, bool)
    lost = 0                                     # coordinates no independent set can take
    for u in np.argsort(deg, kind="stable"):
        if matched[u] or not w[u]:
            continue
        for v in ind[ptr[u]:ptr[u + 1]]:
            if v != u and not matched[v] and w[v]:
                matched[u] = matched[v] = True
                lost += min(int(w[u]), int(w[v]))
                break
    k_min = system.n_free - (int(w.sum()) - lost)
    if k_min > MAX_REDUCED:
        m_max = int(np.count_nonzero(w)) - int(matched.sum()) // 2
        raise MultilatError(
            f"the general model's sparse back end takes a reduced system of at most {MAX_REDUCED} parameters; "
            f"this network leaves at least {k_min} after eliminating at most {m_max} of {n} points "
            f"({system.n_free} unknowns, {system.n_rows} observation rows)")
