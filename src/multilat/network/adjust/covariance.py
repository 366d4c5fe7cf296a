"""Covariance of a network adjustment without forming the full matrix.

The inverse of the normal matrix is kept in its Schur form (the station/offset/scale block
``Q_gg``, the target blocks ``M_j = N_jj^-1`` and the per-observation coupling), so products
``C V``, per-point 3x3 blocks and any small joint block cost O(m) each. The covariance is then
expressed in the chosen datum: rotated into the final frame (``R``) and S-transformed::

    C_datum = S C S^T,   S = I - G (E^T G)^-1 E^T

with ``G`` the infinitesimal rigid motions (6 columns) and ``E`` the datum's constraint matrix
(``G`` on the datum points for inner constraints; unit vectors on the 6 fixed coordinates for 3-2-1).

Parameter layout: :mod:`multilat.network.model.distance` (5 per station, then 3 per target).
"""

from __future__ import annotations

import numpy as np

from multilat.network.model.datum import s_coefficients
from multilat.network.adjust.solve.normal_equations import (reduced_normal_equations, repeat_share, slot_gain,
                                                           target_slots)
from multilat.network.model.distance import Q, residuals_and_jacobian, segment_sum
from multilat.network.model.parameter_layout import STATION_FIELDS, ParameterLayout
from multilat.network.adjust.statistics import correlated_with

__all__ = ["NetworkCovariance", "CoupledCovariance", "distance_covariance", "KERNELS_ABOVE_OBS",
           "JACOBIAN_ON_DEMAND_OBS"]

#: Networks with at least this many observations get their hat diagonal, hat rows and target blocks
#: from the compiled kernels of :mod:`multilat.network.adjust._covariance_kernels` (numba, when installed); smaller
#: ones from the numpy code below (no compile/load cost; the tests compare the two to 1e-12).
KERNELS_ABOVE_OBS = 10_000

#: Adjustments of at least this many observations do not keep their whitened Jacobian blocks and gains
#: (88 bytes per observation) once their own statistics are computed: each later product recomputes
#: them from the adjusted parameters (O(m), 0.1 s at 1.6 M; :meth:`NetworkCovariance.release_jacobian`).
#: Smaller ones keep them (a few MB, reused by every round of data snooping).
JACOBIAN_ON_DEMAND_OBS = 1 << 18


def compiled_for(m: int) -> bool:
    """Whether a network of ``m`` observations runs the compiled kernels (its statistics here, its
    residuals and Jacobian in the solve's system, :mod:`multilat.network.adjust.solve.system`): at least
    :data:`KERNELS_ABOVE_OBS` observations and numba installed (not imported below the size)."""
    if m < KERNELS_ABOVE_OBS:
        return False
    from multilat._numba import HAVE_NUMBA

    return HAVE_NUMBA


def _kernels(m: int):
    """The compiled statistics kernels for a network of ``m`` observations, or None (numpy path)."""
    if not compiled_for(m):
        return None
    from multilat.network.adjust import _covariance_kernels as K

    return K


class NetworkCovariance:
    """Labelled covariance of all parameters (m², m·1, 1 for scales) in the final datum.

    Parameters
    ----------
    Qgg : ndarray (5s, 5s)   inverse of the reduced normal matrix (zeros for fixed parameters)
    Minv : ndarray (t, 3, 3) inverses of the target blocks (zeros for fixed targets)
    Js_w, Jt_w : ndarray (m, 5), (m, 3) whitened Jacobian blocks at the solution (fixed columns zero)
    station_index, target_index : ndarray of int (m,)
    factor : float   multiplies everything (sigma0**2 for an unweighted cost, else 1)
    R : ndarray (3, 3)   rotation from the solving frame to the final frame
    G, E : ndarray (n, d) or None   S-transformation (None: no datum transformation); d = 6 for the
        rigid datum, 7 when the network's scale is a datum defect too (scales of every station)
    jacobian : callable () -> (Js_w, Jt_w), or None   recomputes the blocks (the same numbers), so
        that :meth:`release_jacobian` can drop them (the adjustment does at
        :data:`JACOBIAN_ON_DEMAND_OBS` observations and more)
    """

    def __init__(self, Qgg, Minv, Js_w, Jt_w, station_index, target_index, *, factor=1.0,
                 R=None, G=None, E=None, jacobian=None):
        self.Qgg = Qgg
        self.Minv = Minv
        self.si = station_index
        self.ti = target_index
        self.s = Qgg.shape[0] // Q
        self.t = Minv.shape[0]
        self.layout = ParameterLayout.adjustment(self.s, self.t)    # the columns of every product
        # (s, 5) the stations' columns, which are Q_gg's rows and columns too (the station block comes
        # first), and (t, 3) the targets'
        self._g, self._tg = self.layout.station_block(), self.layout.target_block()
        self.n_station_params = self._g.size
        self.n = self.layout.n
        self.factor = float(factor)
        self.R = np.eye(3) if R is None else np.asarray(R)
        self._jacobian = jacobian
        self._held = (Js_w, Jt_w, self._gains(Jt_w))
        self._csr = None
        self.G = G
        if G is not None:
            H = s_coefficients(G, E)                     # (6, n)
            self.H = H
            self.CHt = self._rot_times(H.T)               # (n, 6)  C_rot H^T
            self.HCHt = H @ self.CHt
        self._point_rows = None

    # ------------------------------------------------------------ the whitened Jacobian blocks
    def _gains(self, Jt_w):
        """``P_k = M_j b_k`` (m, 3) per observation from the target blocks (compiled above the size:
        no (m, 3, 3) gather, 115 MB at 1.6 M)."""
        K = _kernels(len(self.ti))
        if K is None:
            return np.einsum("mij,mj->mi", self.Minv[self.ti], Jt_w)
        P = np.empty((len(self.ti), 3))
        K.target_gains(np.ascontiguousarray(self.Minv, float), np.ascontiguousarray(Jt_w, float),
                       np.asarray(self.ti, np.int64), P)
        return P

    def release_jacobian(self) -> bool:
        """Stop holding the whitened Jacobian blocks and the gains ``P`` (64 + 24 bytes per
        observation: 135 MiB at 1.6 M distances) when the covariance can recompute them (its
        ``jacobian`` callable, e.g. from the adjusted parameters): every later product recomputes
        them, O(m), and drops them again; the numbers are the same (the same function of the same
        inputs). Returns whether they were released."""
        if self._jacobian is None:
            return False
        self._held = None
        return True

    def _blocks(self):
        """``(Js_w, Jt_w, P)``: the held blocks, or recomputed for one use after
        :meth:`release_jacobian`."""
        if self._held is not None:
            return self._held
        Js_w, Jt_w = self._jacobian()
        return Js_w, Jt_w, self._gains(Jt_w)

    @property
    def Js_w(self):
        """Whitened station Jacobian blocks (m, 5) (recomputed on each access once released)."""
        return self._blocks()[0]

    @property
    def Jt_w(self):
        """Whitened target Jacobian blocks (m, 3) (recomputed on each access once released)."""
        return self._blocks()[1]

    @property
    def P(self):
        """``P_k = M_j b_k`` (m, 3) (recomputed on each access once released)."""
        return self._blocks()[2]

    # ------------------------------------------------------------ internal (solving frame)
    def _times(self, V):
        """Internal covariance times V (n, c) -> (n, c)."""
        g, tg = self._g, self._tg
        V = np.asarray(V, float)
        out = np.empty((self.n, V.shape[1]))
        K = _kernels(self.si.shape[0])
        if K is not None:       # one column at a time: no (m, 5, c) temporaries
            Qgg, Minv, Js, _, P, si, ti, order, tptr = self._kernel_args()
            og, ot = np.empty(g.size), np.empty(tg.shape)
            for c in range(V.shape[1]):
                col = np.ascontiguousarray(V[:, c])
                K.cov_times(Qgg, Minv, Js, P, si, ti, order, tptr, col[g.ravel()], col[tg], og, ot, False,
                            np.zeros(0, np.int64))
                out[g.ravel(), c] = og
                out[tg.ravel(), c] = ot.ravel()
            return out * self.factor
        Vg, VT = V[g], V[tg]                               # (s, 5, c), (t, 3, c)
        # Vg - K^T VT : per obs a_k (p_k . VT_j)
        Js_w, _, P = self._blocks()
        pv = np.einsum("mi,mic->mc", P, VT[self.ti])
        acc = Vg - segment_sum(self.si, Js_w[:, :, None] * pv[:, None, :], self.s)
        out[g.ravel()] = self.Qgg @ acc.reshape(g.size, -1)      # u (5s, c)
        # M VT - K u : per obs p_k (a_k . u_station)
        au = np.einsum("mq,mqc->mc", Js_w, out[g][self.si])
        out[tg] = (np.einsum("tij,tjc->tic", self.Minv, VT)
                   - segment_sum(self.ti, P[:, :, None] * au[:, None, :], self.t))
        return out * self.factor

    def _rotate_rows(self, V, R):
        """Apply the 3x3 ``R`` to every coordinate triple of V's rows (n, c)."""
        out = V.copy()
        for cols in (self._g[:, :3], self._tg):            # the stations' x, y, z, then the targets'
            out[cols] = np.einsum("ij,sjc->sic", R, V[cols])
        return out

    def _rot_times(self, V):
        """Rotated covariance (final frame, before S) times V."""
        return self._rotate_rows(self._times(self._rotate_rows(np.asarray(V, float), self.R.T)), self.R)

    # ------------------------------------------------------------ public
    def times(self, V):
        """Final-datum covariance times V (n, c)."""
        V = np.asarray(V, float)
        if self.G is None:
            return self._rot_times(V)
        # S C S^T V with S = I - G H
        W = V - self.H.T @ (self.G.T @ V)
        Y = self._rot_times(W)
        out = Y - self.G @ (self.H @ Y)
        return out

    def linear_covariance(self, cols=None, *, weight_sigma_m=None, sigma_m=None, cov_m2=None,
                          chunk_elements: int = 1 << 22) -> np.ndarray:
        """First-order (GUM) covariance (k, k) of the parameters ``cols`` (default all) in the final
        datum when the distances' covariance is ``C`` rather than the weights' ``diag(weight_sigma_m**2)``
        (the Monte Carlo's linear propagation, :mod:`multilat.network.montecarlo.batched`): the
        sandwich ``Q A^T W C W A Q`` of the least-squares estimator, computed as::

            Q + K (W^1/2 C W^1/2 - I) K^T,    K = S R Q_int A_w^T

        with ``A_w`` the whitened distance rows held here: no correction when ``C`` is the weights' (the
        block of :meth:`full`); couplings and angles keep their own variances. ``sigma_m`` (m,):
        independent distances; ``cov_m2`` (m, m): correlated ones. ``chunk_elements`` bounds the
        ``(m, 5, c)`` temporaries of ``c`` columns at a time (the numbers do not depend on it beyond
        rounding). ``S Q N Q S^T = S Q S^T`` holds for every generalised inverse ``Q`` (the penalty of
        :func:`distance_covariance` too). For the distance cost (``factor`` 1)."""
        cols = np.arange(self.n) if cols is None else np.asarray(cols, np.intp)
        D = None
        if cov_m2 is not None:
            wsig = np.asarray(weight_sigma_m, float)
            D = np.asarray(cov_m2, float) / np.outer(wsig, wsig) - np.eye(wsig.size)
        elif sigma_m is not None:
            D = (np.asarray(sigma_m, float) / np.asarray(weight_sigma_m, float)) ** 2 - 1.0
        if D is not None and not np.any(D):                        # the weights' own σ: no correction
            D = None
        if D is not None and self.factor != 1.0:
            raise ValueError("the sandwich covariance needs a-priori weights (factor 1)")
        k, m = cols.size, len(self.si)
        out = np.empty((k, k))
        B = None if D is None else np.empty((m, k))                # K^T (m, k)
        step = max(1, chunk_elements // max(1, m * self._g.shape[1]))   # columns per product: (m, 5, step)
        for lo in range(0, k, step):
            c = cols[lo:lo + step]
            V = np.zeros((self.n, c.size))
            V[c, np.arange(c.size)] = 1.0
            if self.G is not None:
                V = V - self.H.T @ (self.G.T @ V)
            Y = self._times(self._rotate_rows(V, self.R.T))        # Q_int R^T S^T e_c
            Z = self._rotate_rows(Y, self.R)
            if self.G is not None:
                Z = Z - self.G @ (self.H @ Z)
            out[:, lo:lo + step] = Z[cols]
            if B is not None:
                B[:, lo:lo + step] = self._design_times_columns(Y)
        if B is not None:
            out = out + B.T @ (D @ B if D.ndim == 2 else D[:, None] * B)
        return 0.5 * (out + out.T)

    def _design_times_columns(self, Y) -> np.ndarray:
        """``A_w Y`` (m, c) for parameter-space columns ``Y`` (n, c) in the internal frame."""
        Js_w, Jt_w, _ = self._blocks()
        return (np.einsum("mq,mqc->mc", Js_w, Y[self._g][self.si])
                + np.einsum("mi,mic->mc", Jt_w, Y[self._tg][self.ti]))

    def block(self, idx):
        """Dense covariance of the parameters ``idx`` (k,) -> (k, k)."""
        idx = np.asarray(idx, dtype=np.intp)
        E = np.zeros((self.n, idx.size))
        E[idx, np.arange(idx.size)] = 1.0
        return self.times(E)[idx]

    def full(self):
        """The whole (n, n) matrix (small networks only)."""
        return self.times(np.eye(self.n))

    def global_block(self):
        """Covariance of the station parameters (5s, 5s): x, y, z, offset, scale per station."""
        g = self._g.ravel()                                # Q_gg's rows: the station block's columns
        Rb = np.eye(g.size)
        for xyz in self._g[:, :3]:
            Rb[np.ix_(xyz, xyz)] = self.R
        out = Rb @ (self.Qgg * self.factor) @ Rb.T
        if self.G is not None:
            Gg, Cg = self.G[g], self.CHt[g]
            out = out - Gg @ Cg.T - Cg @ Gg.T + Gg @ self.HCHt @ Gg.T
        return 0.5 * (out + out.T)

    def _by_target(self):
        """Observations grouped by target: ``(order, tptr)`` (CSR, for the kernels)."""
        if self._csr is None:
            ti = np.asarray(self.ti)
            order = np.argsort(ti, kind="stable").astype(np.int64)
            tptr = np.zeros(self.t + 1, np.int64)
            np.cumsum(np.bincount(ti, minlength=self.t), out=tptr[1:])
            self._csr = (order, tptr)
        return self._csr

    def _kernel_args(self):
        order, tptr = self._by_target()
        c = np.ascontiguousarray
        Js_w, Jt_w, P = self._blocks()
        return (c(self.Qgg, dtype=float), c(self.Minv, dtype=float), c(Js_w, dtype=float),
                c(Jt_w, dtype=float), c(P, dtype=float), c(self.si, dtype=np.int64),
                c(self.ti, dtype=np.int64), order, tptr)

    def _qgg_blocks(self) -> np.ndarray:
        """``Q_gg`` as (s, 5, s, 5) station blocks."""
        return self.Qgg[self._g[:, :, None, None], self._g[None, None]]

    def _target_blocks_internal(self, chunk_targets: int = 20000, *, kernels=True):
        """Per-target 3x3 blocks of the internal covariance (solving frame, without ``factor``)."""
        K = _kernels(self.si.shape[0]) if kernels else None
        if K is not None:
            Qgg, Minv, Js, _, P, si, _, order, tptr = self._kernel_args()
            out = np.empty((self.t, 3, 3))
            K.target_blocks(Qgg, Minv, Js, P, si, order, tptr, out)
            return out
        s, t = self.s, self.t
        Js_w, Jt_w, P_all = self._blocks()
        slots = target_slots(self.si, self.ti, s, t)
        gain = slot_gain(slots, self.si, self.ti, Js_w, Jt_w)     # repeated readings
        Q4 = self._qgg_blocks()
        out = np.empty((t, 3, 3))
        for lo in range(0, t, chunk_targets):
            sl = slots[lo:lo + chunk_targets]
            seen = sl >= 0
            ix = np.where(seen, sl, 0)
            sc = seen if gain is None else seen * gain[ix]
            A = Js_w[ix] * sc[..., None]                  # (c, s, Q)
            P = P_all[ix] * sc[..., None]                 # (c, s, 3)
            S = np.einsum("caq,aqbr,cbr->cab", A, Q4, A, optimize=True)
            out[lo:lo + chunk_targets] = (self.Minv[lo:lo + chunk_targets]
                                          + np.einsum("cai,cab,cbj->cij", P, S, P, optimize=True))
        return out

    def target_blocks(self, chunk_targets: int = 20000, *, kernels=True):
        """3x3 covariance of every target (t, 3, 3) in the final datum, O(t s^2)."""
        out = self._target_blocks_internal(chunk_targets, kernels=kernels)
        out *= self.factor
        out = np.einsum("ij,tjk,lk->til", self.R, out, self.R)
        if self.G is not None:
            Gp, Cp = self.G[self._tg], self.CHt[self._tg]          # (t, 3, d)
            out = (out - np.einsum("tia,tja->tij", Gp, Cp) - np.einsum("tia,tja->tij", Cp, Gp)
                   + np.einsum("tia,ab,tjb->tij", Gp, self.HCHt, Gp))
        return 0.5 * (out + np.swapaxes(out, 1, 2))

    def hat_row(self, k: int, *, kernels=True):
        """Row ``k`` of the whitened hat matrix ``A C A^T`` (m,) (datum-free; for the correlation
        of w-tests: ``rho_kl = -hat_kl / sqrt(r_k r_l)``)."""
        K = _kernels(self.si.shape[0]) if kernels else None
        if K is not None:
            Qgg, Minv, Js, Jt, P, si, ti, order, tptr = self._kernel_args()
            out = np.empty(si.shape[0])
            K.hat_row(int(k), Qgg, Minv, Js, Jt, P, si, ti, order, tptr, out)
            return out
        v = self._times(self.design_row(k)[:, None])[:, 0] / self.factor
        vg, vt = v[self._g], v[self._tg]
        Js_w, Jt_w, _ = self._blocks()
        return (np.einsum("mq,mq->m", Js_w, vg[self.si])
                + np.einsum("mi,mi->m", Jt_w, vt[self.ti]))

    def internal_times(self, g) -> np.ndarray:
        """The internal covariance (solving frame, datum-free, without ``factor``) times one
        parameter-space vector ``g`` (n,) -> (n,): ``C a_k`` for the design row ``a_k`` of
        observation ``k`` is the solution's response to it."""
        g = np.asarray(g, float)
        K = _kernels(self.si.shape[0])
        if K is None:
            return self._times(g[:, None])[:, 0] / self.factor
        Qgg, Minv, Js, _, P, si, ti, order, tptr = self._kernel_args()
        og, ot = np.empty(self._g.size), np.empty(self._tg.shape)
        gt = g[self._tg]
        nz = np.unique(np.flatnonzero(gt) // 3)             # targets with a non-zero part (few, usually)
        sparse = nz.size <= self.t // 8        # a few targets (a design row, a downdate's generator)
        touched = (np.sort(np.concatenate([order[tptr[j]:tptr[j + 1]] for j in nz] + [np.zeros(0, np.int64)]))
                   .astype(np.int64) if sparse else np.zeros(0, np.int64))
        K.cov_times(Qgg, Minv, Js, P, si, ti, order, tptr, g[self._g.ravel()], gt, og, ot, sparse, touched)
        out = np.empty(self.n)
        out[self._g.ravel()], out[self._tg.ravel()] = og, ot.ravel()
        return out

    def design_times(self, x) -> np.ndarray:
        """The whitened design times a parameter-space vector ``x`` (n,) -> (m,): ``A x``, so that
        ``design_times(internal_times(g))`` is the hat-matrix row of the combination ``g`` of design
        rows (:meth:`hat_row` for ``g = a_k``)."""
        x = np.asarray(x, float)
        xg, xt = x[self._g], x[self._tg]
        K = _kernels(self.si.shape[0])
        if K is None:
            Js_w, Jt_w, _ = self._blocks()
            return np.einsum("mq,mq->m", Js_w, xg[self.si]) + np.einsum("mi,mi->m", Jt_w, xt[self.ti])
        _, _, Js, Jt, _, si, ti, _, _ = self._kernel_args()
        out = np.empty(si.shape[0])
        K.design_times(Js, Jt, si, ti, np.ascontiguousarray(xg), np.ascontiguousarray(xt), out)
        return out

    def target_coupling(self) -> np.ndarray:
        """The Schur coupling of every target to the station parameters, ``L_j = sum_l p_l a_l^T``
        over target j's observations (``p_l = M_j b_l``, ``a_l`` at station ``si_l``'s columns)
        -> (t, 3, 5s), internal frame: the internal response of target j to a station-part
        vector ``g`` is ``-L_j Q_gg g`` (the off-diagonal block of :meth:`_times`)."""
        s, t = self.s, self.t
        key = np.asarray(self.ti, np.int64) * s + np.asarray(self.si, np.int64)
        Js_w, _, P = self._blocks()
        L = segment_sum(key, P[:, :, None] * Js_w[:, None, :], t * s)      # (t s, 3, 5)
        out = np.empty((t, 3, self._g.size))
        out[:, :, self._g] = L.reshape(t, s, 3, -1).transpose(0, 2, 1, 3)
        return out

    def design_row(self, k: int) -> np.ndarray:
        """Row ``k`` of the whitened design as a parameter-space vector (n,) (station and target parts)."""
        a = np.zeros(self.n)
        Js_w, Jt_w, _ = self._blocks()
        a[self._g[self.si[k]]] = Js_w[k]
        a[self._tg[self.ti[k]]] = Jt_w[k]
        return a

    def perfectly_correlated(self, k: int, redundancy, tol: float = 1e-6) -> np.ndarray:
        """Observations ``l`` whose w-test is perfectly correlated with ``k``'s: ``|rho_kl| > 1 - tol``,
        ``rho_kl = -hat_kl / sqrt(r_k r_l)`` (``k`` itself included when ``r_k > 0``). A zero denominator
        counts as correlated when ``hat_kl != 0`` (an infinite ``rho``), not when ``hat_kl`` is 0 too."""
        red = np.asarray(redundancy, float)
        return correlated_with(self.hat_row(int(k)), red, int(k), tol)

    def hat_diagonal(self, chunk_targets: int = 20000, *, kernels=True):
        """Diagonal of the whitened hat matrix ``A C A^T`` per observation (m,) (datum-free).

        ``1 - hat`` are the redundancy numbers. ``kernels=False``: the numpy path whatever the size.
        """
        K = _kernels(self.si.shape[0]) if kernels else None
        if K is not None:
            Qgg, Minv, Js, Jt, P, si, _, order, tptr = self._kernel_args()
            h = np.empty(si.shape[0])
            K.hat_diagonal(Qgg, Minv, Js, Jt, P, si, order, tptr, h)
            return h
        s, t = self.s, self.t
        Js_w, Jt_w, P_all = self._blocks()
        slots = target_slots(self.si, self.ti, s, t)
        # repeated readings of a pair: the pair's hat as one observation of all their weight, shared
        # among them by weight (their rows are proportional)
        gain = slot_gain(slots, self.si, self.ti, Js_w, Jt_w)
        Q4 = self._qgg_blocks()
        h = np.empty(self.si.shape[0])
        for lo in range(0, t, chunk_targets):
            sl = slots[lo:lo + chunk_targets]
            seen = sl >= 0
            ix = np.where(seen, sl, 0)
            sc = seen if gain is None else seen * gain[ix]
            A = Js_w[ix] * sc[..., None]
            B = Jt_w[ix] * sc[..., None]
            P = P_all[ix] * sc[..., None]
            S = np.einsum("caq,aqbr,cbr->cab", A, Q4, A, optimize=True)      # a Q a
            BP = np.einsum("cai,cbi->cab", B, P)                             # b_a . p_b
            diagS = np.einsum("cbb->cb", S)
            term2 = np.einsum("cba,cab->cb", BP, S)
            term3 = np.einsum("cbb->cb", BP) + np.einsum("cba,cae,cbe->cb", BP, S, BP, optimize=True)
            hh = diagS - 2.0 * term2 + term3
            h[sl[seen]] = hh[seen]
        if gain is not None:
            key = self.ti.astype(np.int64) * s + self.si
            h = h[slots.ravel()[key]] * repeat_share(slots, self.si, self.ti, Js_w, Jt_w)
        return h


class CoupledCovariance(NetworkCovariance):
    """The covariance when targets are coupled (scale bars, weighted control;
    :mod:`multilat.network.adjust.solve.coupled`): the same Schur form with the targets' block inverse
    ``N_tt^-1`` (3t, 3t) dense and ``X = N_tt^-1 N_tg``::

        C V = [u ; N_tt^-1 V_t - X u],   u = Q_gg (V_g - X^T V_t)

    Same interface and datum handling as :class:`NetworkCovariance` (a parameterisation of it: only
    the eliminated block's product differs); per-target blocks and the hat diagonal from the dense form
    (small networks). The eliminated rows of ``X`` and ``N_tt^-1`` are the targets' (in the layout's
    order, the first ``3t``), then the orientations' (:func:`multilat.network.adjust.solve.coupled.
    assemble_coupled`).
    """

    def __init__(self, Qgg, coupled, Minv, Js_w, Jt_w, station_index, target_index, **kw):
        self.X = coupled.X
        self.Ntt_full_inv = coupled.Ntt_inv
        super().__init__(Qgg, Minv, Js_w, Jt_w, station_index, target_index, **kw)

    @property
    def _xt(self) -> np.ndarray:
        """(t, 3) the targets' rows of ``X`` and ``N_tt^-1`` (their columns counted from the first)."""
        return self._tg - self._tg.min()

    @property
    def _xo(self) -> slice:
        """The orientations' rows of ``X`` and ``N_tt^-1`` (after the targets')."""
        return slice(self._tg.size, None)

    def _times(self, V):
        """``C V`` in the internal frame. The eliminated block may hold the stations' orientation
        unknowns after the targets (angle observations): ``V`` (n, c) of the coordinate length
        (5s + 3t) has zeros for them and the product is cut to that length; ``V`` (n + n_o, c) holds
        them in its last rows (:func:`multilat.network.model.angle_rows.orientation_covariance`)."""
        V = np.asarray(V, float)
        g, tg, xt = self._g.ravel(), self._tg.ravel(), self._xt.ravel()
        Vt = np.zeros((self.X.shape[0],) + V.shape[1:])
        Vt[xt] = V[tg]
        if V.shape[0] > self.n:
            Vt[self._xo] = V[self.n:]
        u = self.Qgg @ (V[g] - self.X.T @ Vt)
        el = self.Ntt_full_inv @ Vt - self.X @ u
        out = np.empty(V.shape)
        out[g], out[tg], out[self.n:] = u, el[xt], el[self._xo][:V.shape[0] - self.n]
        return out * self.factor

    def _target_blocks_internal(self, chunk_targets: int = 20000, *, kernels=True):
        Xb = self.X[self._xt]                                         # (t, 3, 5s)
        XQ = (self.X[self._xt.ravel()] @ self.Qgg)[self._xt]
        D = self.Ntt_full_inv[self._xt[:, :, None], self._xt[:, None, :]]      # the 3x3 diagonal blocks
        return D + np.einsum("tiq,tjq->tij", XQ, Xb)

    def orientation_cov_internal(self) -> np.ndarray:
        """Covariance (n_o, n_o) of the orientation unknowns in the internal frame (rad²)."""
        Xo = self.X[self._xo]
        return (self.Ntt_full_inv[self._xo, self._xo] + Xo @ self.Qgg @ Xo.T) * self.factor

    def hat_row(self, k: int, **_):
        """As :meth:`NetworkCovariance.hat_row` through the coupled product (the compiled kernels know
        only independent targets)."""
        return super().hat_row(k, kernels=False)

    def hat_diagonal(self, chunk_targets: int = 20000, **_):
        """``a_k C a_k`` per distance from the blocks it touches: ``Q_gg`` (station), the target's
        3x3 block and the station-target block ``-(Q_gg X^T)``; O(t s^2)."""
        Ctt = self._target_blocks_internal()
        QX = self.Qgg @ self.X[self._xt.ravel()].T                          # (5s, 3t) = -C_gt
        QXt = QX[self._g[:, :, None, None], self._xt.reshape(1, 1, *self._xt.shape)]     # (s, 5, t, 3)
        Q4 = self._qgg_blocks()
        i, j = self.si, self.ti
        a, b, _ = self._blocks()
        hs = np.einsum("mq,mqr,mr->m", a, Q4[i, :, i, :], a)
        ht = np.einsum("mc,mcd,md->m", b, Ctt[j], b)
        hst = np.einsum("mq,mqc,mc->m", a, QXt[i, :, j, :], b)
        return hs + ht - 2.0 * hst

    def quadratic(self, rows: np.ndarray) -> np.ndarray:
        """``diag(E C_int E^T)`` for whitened rows ``E`` (q, n) in the internal frame (datum-free;
        the redundancy of a coupling observation is ``1 -`` this)."""
        rows = np.asarray(rows, float)
        return np.einsum("qi,iq->q", rows, self._times(rows.T) / self.factor)


def distance_covariance(station_xyz_m, target_xyz_m, offset_m, scale, station_index, target_index, sigma_m, *,
                        station_free=None, target_free=None, head_index=None, G=None, E=None) -> NetworkCovariance:
    """The adjustment's covariance (:class:`NetworkCovariance`, final frame, a-priori weights) of a
    distance network at a given point, without an adjustment: the Monte Carlo's linear propagation of a
    known truth (:meth:`multilat.network.montecarlo.batched.BatchedNetwork.linear_covariance`).

    The model's Jacobian (:func:`multilat.network.model.distance.residuals_and_jacobian`), the
    adjustment's reduced normal equations (:mod:`multilat.network.adjust.solve.normal_equations`), heads
    tied as :func:`~multilat.network.adjust.solve.loop.solve_reduced` ties them. The datum defect is lifted
    by a penalty on the stations' rigid motions (``G``'s station rows) instead of held coordinates: the
    same covariance once S-transformed onto ``E``, to rounding (3.7e-12 of the largest element on the
    small volume).

    station_free (s, 5) bool   free ``x, y, z, offset, scale`` (default: all but the scale)
    target_free (t,) bool      False for held targets (default: all free)
    head_index (s,) int        the head of each station (offsets and scales tied; default one each)
    G, E (5s + 3t, d)          rigid motions and datum conditions in the adjustment layout, or None
    """
    h, tg = np.asarray(station_xyz_m, float), np.asarray(target_xyz_m, float)
    si, ti = np.asarray(station_index, np.int64), np.asarray(target_index, np.int64)
    s, t, m = len(h), len(tg), len(si)
    sf = np.ones((s, Q), bool) if station_free is None else np.asarray(station_free, bool)
    if station_free is None:
        sf[:, STATION_FIELDS.index("scale")] = False
    tf = np.ones(t, bool) if target_free is None else np.asarray(target_free, bool)
    _, Js, Jt = residuals_and_jacobian(np.zeros(m), h, tg, np.asarray(offset_m, float), np.asarray(scale, float),
                                       si, ti)
    w = 1.0 / np.asarray(sigma_m, float)
    Js_w = Js * w[:, None] * sf[si]
    Jt_w = Jt * w[:, None] * tf[ti][:, None]
    sys_ = reduced_normal_equations(np.zeros(m), Js_w, Jt_w, si, ti, s, t, target_free=tf)
    red = sys_.layout
    src = red.tie_source(np.arange(s) if head_index is None else head_index)
    T = np.zeros((red.n, red.n))
    T[np.arange(red.n), src] = 1.0                                     # g = T g_r (the head tie)
    free = np.zeros(red.n, bool)
    free[red.station_block()] = sf
    free &= src == np.arange(red.n)                                    # a head's offset and scale at its lead
    Nf = (T.T @ sys_.N @ T)[np.ix_(free, free)]
    if G is not None:                                                  # the defect: penalise rigid motions
        Gs = np.asarray(G, float)[red.index_in(ParameterLayout.adjustment(s, t))][free]
        c = np.trace(Nf) / free.sum() / max(np.trace(Gs.T @ Gs) / Gs.shape[1], 1e-300)
        Nf = Nf + c * (Gs @ Gs.T)
    Qr = np.zeros((red.n, red.n))
    Qr[np.ix_(free, free)] = np.linalg.inv(Nf)
    return NetworkCovariance(T @ Qr @ T.T, sys_.Ntt_inv, Js_w, Jt_w, si, ti, G=G, E=E)
