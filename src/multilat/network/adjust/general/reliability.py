"""External reliability of a general-network adjustment: the coordinate shift caused by an undetected
bias of the size of each row's minimal detectable bias.

A bias ``∇l`` in the observations moves the adjusted parameters by ``∇x = Q Jᵀ P ∇l`` (``Q`` the
cofactor matrix of the free parameters in the datum of the adjustment: the bordered inverse of a free
network, so the response is the one the inner constraints give). In the whitened rows (``J_w = L⁻¹ J``,
``P = L⁻ᵀ L⁻¹``) a bias of ``b_k`` whitened units in row ``k`` is ``∇x_k = Q J_wᵀ e_k b_k``; the MDB of
the row is ``b_k = sqrt(λ0 / r_k)`` whitened units (× σ̂0 with the variance factor unknown), which for an
independent row is ``MDB_k / σ_k`` (as :func:`multilat.network.adjust.distance.reliability.external_shifts` on the
distance path). A correlated block's rows are the decorrelated ones (the convention of the w-tests).
Reported per row: the largest point shift ``max_p |∇x_k,p|`` (metres, over the three coordinates of
every point; a held coordinate does not move) and which point (ties: the first point), as
:func:`multilat.network.adjust.distance.reliability.largest_point_shift` gives it. Checked against re-adjusting with
the MDB added to one row (``tests/test_general_snooping.py``).

**Dense back end**: the product ``Q J_wᵀ`` in batches of rows (no loop per row, no matrix of rows ×
rows); it holds ``Q`` and ``J_w`` anyway. **Sparse back end** (:class:`SchurShifts`, no ``(n, n)``,
no ``(R, R)``, no ``Q J_wᵀ``): a row touches at most one eliminated point ``p`` (:mod:`.sparse`), so
with ``z = j_K - j_E X`` (:func:`.sparse.row_parts`), ``y_K = Q⁻_KK zᵀ`` and the datum's two
``d``-vectors ``c1 = Hᵀ jᵀ``, ``c2 = Wᵀ jᵀ - BᵀW c1`` the response ``Q jᵀ = N⁻ jᵀ - W c1 - H c2`` is,
point by point::

    point of K:                y_K[q] - W_q c1 - H_q c2
    the row's eliminated p:    N_pp⁻¹ j_p - X_p y_K - W_p c1 - H_p c2
    any other eliminated q:    A_q v,   A_q = -[X_q, W_q, H_q] (3 x (k + 2d)),  v = [y_K, c1, c2]

The first two cost ``O(k)`` a row (the points of ``K`` are at most ``k / 3``). The largest of the
others is searched, as the distance path does (:mod:`multilat.network.adjust.distance.reliability`), in order of the
bound ``|A_q v| <= ||A_q||_2 |v|`` and stops when the bound falls below the largest shift found: exact,
and usually only the row's own point and the points of ``K`` are evaluated (a bias moves its own point
most; the others move with the reduced parameters). Cost ``O(R k²)`` (``y_K``, the redundancy numbers'
product) plus the evaluated points; memory ``O(BATCH k + n)``.
"""

from __future__ import annotations

import numpy as np

from multilat.network.adjust import statistics as st
from multilat.network.adjust.distance.reliability import largest_point_shift

__all__ = ["whitened_jacobian", "dense_rows", "point_columns", "external_shifts", "mdb_whitened", "BATCH",
           "SchurShifts"]

#: rows per batch of the product ``Q J_wᵀ`` (memory: n_free × BATCH floats)
BATCH = 2048


def whitened_jacobian(system, result):
    """``J_w`` (R, n_free) at the adjusted parameters of ``result``: dense, or CSR when the sparse
    back end kept no dense cofactor matrix (a large network)."""
    if result.cofactor is None:                      # the sparse back end's own, at the solution
        return result.blocks.lin.jw
    _, jac = system.evaluate(result.parameters)
    return system.whiten(jac)


def dense_rows(jw, idx) -> np.ndarray:
    """Rows ``idx`` of a dense or sparse ``J_w`` as a dense array."""
    sub = jw[idx]
    return sub.toarray() if hasattr(sub, "toarray") else np.asarray(sub)


def point_columns(result) -> np.ndarray:
    """(n_points, 3) column of each point coordinate in the free parameters, ``n_free`` (a zero row)
    where the coordinate is held."""
    idx = {n: k for k, n in enumerate(result.free_names)}
    nf = len(result.free_names)
    return np.array([[idx.get(f"{c}:{p}", nf) for c in "xyz"] for p in result.ids], dtype=np.intp).reshape(-1, 3)


def external_shifts(result, jw: np.ndarray, bias_w: np.ndarray, *, batch: int = BATCH):
    """Largest point shift (R,) in metres and its point's id (R,) caused by a bias of ``bias_w[k]``
    whitened units in each row ``k`` (inf where the bias is not finite: an uncontrolled row; "" as
    its point). ``jw``: the whitened Jacobian at the solution (:func:`whitened_jacobian`; the sparse
    back end reads its own, the one its blocks were built from)."""
    R = jw.shape[0]
    cols = point_columns(result)
    ids = list(result.ids)
    shift, point = np.full(R, np.inf), [""] * R
    if R == 0 or cols.size == 0:
        return np.zeros(R), tuple(point)
    if "external reliability" in result.not_computed:      # left out by the back end (adjust.EXTERNAL_MAX_WORK)
        return np.full(R, np.nan), tuple(point)
    b = np.asarray(bias_w, float)
    ok = np.isfinite(b)
    if result.blocks is not None:                          # the sparse back end: through the Schur blocks
        ctx = SchurShifts(result)
        for lo in range(0, R, batch):
            hi = min(lo + batch, R)
            norm, where = ctx.shifts(lo, hi, ok[lo:hi])
            shift[lo:hi] = np.where(ok[lo:hi], norm * np.abs(np.where(ok[lo:hi], b[lo:hi], 0.0)), np.inf)
            for k in np.flatnonzero(ok[lo:hi]):
                point[lo + k] = ids[int(where[k])]
        return shift, tuple(point)
    nf = len(result.free_names)
    for lo in range(0, R, batch):
        hi = min(lo + batch, R)
        D = np.zeros((nf + 1, hi - lo))
        D[:-1] = result.cofactor_times(dense_rows(jw, slice(lo, hi)).T)   # response to one whitened unit per row
        D[:-1] *= np.where(ok[lo:hi], b[lo:hi], 0.0)
        norm, where = largest_point_shift(D[cols])     # (points, 3, k)
        shift[lo:hi] = np.where(ok[lo:hi], norm, np.inf)
        for k in range(hi - lo):
            if ok[lo + k]:
                point[lo + k] = ids[int(where[k])]
    return shift, tuple(point)


def mdb_whitened(redundancy, *, alpha: float, power: float, scale: float = 1.0) -> np.ndarray:
    """Each row's MDB in whitened units, ``sqrt(λ0 / r_k)`` × ``scale`` (σ̂0 with the variance factor
    unknown); inf where the row is not controlled (:func:`multilat.network.adjust.statistics.minimal_detectable_bias_m`
    with σ = 1)."""
    r = np.asarray(redundancy, float)
    return st.minimal_detectable_bias_m(np.full(r.shape, float(scale)), r, alpha=alpha, power=power)


class SchurShifts:
    """Each row's largest point response to a whitened unit bias, ``max_p |(Q J_wᵀ e_i)_p|``, and its
    point, through the sparse back end's blocks (module docstring) of ``result`` (its ``blocks``)."""

    CHUNK = 512          # eliminated points per step of the search
    MARGIN = 1e-9        # relative slack on the bound (rounding of the evaluated norms)

    def __init__(self, result):
        from multilat.network.adjust.general.sparse import row_parts

        lin = result.blocks.lin
        red = lin.red
        self.lin, self.red, self.parts = lin, red, row_parts(lin)
        slots = result.blocks.slots                                   # (points, 3) free column, -1 held
        in_e = np.zeros(slots.shape[0], bool)
        in_e[red.points] = True
        self.kp = np.flatnonzero((slots >= 0).any(1) & ~in_e)         # the points of K, ascending
        kc = slots[self.kp]
        self.kvalid = kc >= 0
        posk = np.full(red.n, -1)
        posk[red.ck] = np.arange(red.ck.size)
        self.kfree = np.where(self.kvalid, kc, 0)
        self.kpos = np.where(self.kvalid, posk[self.kfree], 0)
        me = red.slots.shape[0]
        flat = red.slots.ravel()
        valid = (flat >= 0)[:, None]
        g = np.zeros((me, 3, 3))                                      # X_q X_qᵀ
        for a in range(3):
            for c in range(a, 3):
                g[:, a, c] = g[:, c, a] = np.asarray(red.x[a::3].multiply(red.x[c::3]).sum(axis=1)).ravel()
        norms = [_spectral(g)]                                        # ||X_q||, ||W_q||, ||H_q||
        self.we = self.he = None
        if lin.h is not None:
            fe = np.where(flat >= 0, flat, 0)
            self.we, self.he = lin.w[fe] * valid, lin.h[fe] * valid   # (3 me, d)
            for m in (self.we, self.he):
                m3 = m.reshape(me, 3, -1)
                norms.append(_spectral(np.einsum("pad,pbd->pab", m3, m3)))
        self.order = np.argsort(-norms[0], kind="stable")
        # the bound of every point from a position of the order on: the largest of each norm there
        self.bound = np.stack([np.maximum.accumulate(nq[self.order][::-1])[::-1] for nq in norms])
        perm = (3 * self.order[:, None] + np.arange(3)).ravel()
        self.xs = red.x[perm].tocsr()
        if lin.h is not None:
            self.ws, self.hs = self.we[perm], self.he[perm]
        self.epoint = red.points                                      # point index of each eliminated one

    def _datum(self, m, c1, c2):
        """``W_r c1 + H_r c2`` for rows ``m`` of ``W``, ``H`` (r, d) and the rows' (a, d): (a, r)."""
        return c1 @ m[0].T + c2 @ m[1].T

    def shifts(self, lo: int, hi: int, ok: np.ndarray):
        """(largest point response, its point index) of rows ``lo:hi``; ``ok`` False: the row's own
        point and the points of K only (its shift is reported as inf)."""
        lin, red, parts = self.lin, self.red, self.parts
        a = hi - lo
        y = parts.z[lo:hi].toarray() @ red.qk                         # (a, k) y_K
        c1 = c2 = None
        if lin.h is not None:
            jb = lin.jw[lo:hi]
            c1 = np.asarray(jb @ lin.h)
            c2 = np.asarray(jb @ lin.w) - c1 @ lin.m.T
        rows = np.arange(a)
        best, where = np.zeros(a), np.zeros(a, np.intp)               # all zero: the first point (dense rule)
        if self.kp.size:                                              # points of K
            rk = y[:, self.kpos] * self.kvalid
            if c1 is not None:
                f = self.kfree.ravel()
                rk -= (self._datum((lin.w[f], lin.h[f]), c1, c2)).reshape(rk.shape) * self.kvalid
            nk = np.linalg.norm(rk, axis=2)
            j = np.argmax(nk, axis=1)
            best = nk[rows, j]
            where = np.where(best > 0, self.kp[j], 0)
        t, pr = parts.touched[lo:hi], parts.prow[lo:hi]
        if red.points.size:                                           # the row's own eliminated point
            own = np.einsum("iab,ib->ia", red.binv[pr], parts.je3[lo:hi])
            for ax in range(3):
                own[:, ax] -= np.asarray(red.x[3 * pr + ax].multiply(y).sum(axis=1)).ravel()
            if c1 is not None:
                f = 3 * pr[:, None] + np.arange(3)
                own -= np.einsum("iad,id->ia", self.we[f], c1) + np.einsum("iad,id->ia", self.he[f], c2)
            on = np.where(t, np.linalg.norm(own, axis=1), -np.inf)
            op = self.epoint[pr]
            win = (on > best) | ((on == best) & (op < where))
            best, where = np.where(win, on, best), np.where(win, op, where)
        zn = np.stack([np.linalg.norm(u, axis=1) for u in ([y] if c1 is None else [y, c1, c2])])
        return self._others(y, c1, c2, zn, t, pr, np.where(ok, best, np.inf), best, where)

    def _others(self, y, c1, c2, zn, t, pr, limit, best, where):
        """The other eliminated points' responses ``|A_q v|``, largest ``||X_q||`` first, while the bound
        ``||X_q|| |y_K| + ||W_q|| |c1| + ||H_q|| |c2|`` (the largest of each norm over the points left)
        can still win (``limit``: the best so far, inf for rows not searched)."""
        me = self.order.size
        for lo in range(0, me, self.CHUNK):
            act = np.flatnonzero((self.bound[:, lo] @ zn) * (1 + self.MARGIN) > limit)
            if act.size == 0:
                break
            hi = min(lo + self.CHUNK, me)
            val = -(self.xs[3 * lo:3 * hi] @ y[act].T)
            if c1 is not None:
                val -= self._datum((self.ws[3 * lo:3 * hi], self.hs[3 * lo:3 * hi]), c1[act], c2[act]).T
            nv = np.linalg.norm(val.reshape(hi - lo, 3, -1), axis=1)   # (chunk, act)
            q = self.order[lo:hi]
            nv[(q[:, None] == pr[act][None, :]) & t[act][None, :]] = -np.inf   # the own point: done
            vmax = nv.max(axis=0)
            idx = np.where(nv == vmax, self.epoint[q][:, None], np.iinfo(np.intp).max).min(axis=0)
            win = (vmax > best[act]) | ((vmax == best[act]) & (idx < where[act]))
            best[act[win]], where[act[win]] = vmax[win], idx[win]
            limit[act[win]] = vmax[win]
        return best, where


def _spectral(g: np.ndarray) -> np.ndarray:
    """The spectral norms ``||A_q||_2`` (m,) from the Gram matrices ``A_q A_qᵀ`` (m, 3, 3)."""
    return np.sqrt(np.maximum(np.linalg.eigvalsh(g)[:, -1], 0.0)) if len(g) else np.zeros(0)
