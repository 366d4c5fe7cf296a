"""Kernels of the statistics at the solution of a large network (:mod:`multilat.network.adjust.covariance`):
the hat diagonal and hat rows, the target blocks of the covariance, the covariance and design
products of the downdated snooping rounds, the targets' gains. One pass over targets, observations
grouped by target, as in :mod:`multilat.network.adjust.solve._sparse_kernels` (the solve).

Compiled with numba when it is installed; otherwise the same functions run as plain Python (slow,
but identical arithmetic). The tests compare them with the numpy path of ``covariance`` to 1e-12.

IEEE division (``multilat._numba.njit``: ``error_model="numpy"``): a zero divisor gives inf or nan, never an
exception out of a parallel region.

The public functions at the end are the boundary the rest of the package calls: they pass every
input array as a writeable C-contiguous array of the kernel's dtype (:func:`writable`: one compiled
variant per kernel, the one the install's warm-up compiles) and run the per-target kernels in blocks
of targets (:data:`BLOCK_OBS` observations), so a Ctrl-C or SIGTERM acts between blocks. Every
kernel is linear in the observations of a target (:data:`FEW_PER_TARGET`).
"""

from __future__ import annotations

import numpy as np

from multilat._numba import HAVE_NUMBA, njit, prange  # noqa: F401
from multilat._numba import writable as _writable


# The covariance of :class:`multilat.network.adjust.covariance.NetworkCovariance` in its Schur form: ``Qgg``
# (Qs, Qs) station/offset/scale block (Q = 5 parameters per station), ``Minv`` (t, 3, 3) target
# blocks, whitened Jacobian rows ``A_k = Js_w[k]`` (Q,) and ``B_k = Jt_w[k]`` (3,), ``P_k = Minv_j B_k``.
# Observations are visited per target through ``order[tptr[j]:tptr[j+1]]`` (any row order).
# For the observations a, b of one target: ``S_ab = A_a^T Qgg[st_a, st_b] A_b`` and ``BP_ab = B_a . P_b``.

@njit(cache=True)
def _target_S(Qgg, Js_w, si, ks, S):
    nq = Js_w.shape[1]
    n = ks.shape[0]
    for a in range(n):
        ka = ks[a]
        ra = nq * si[ka]
        for b in range(a, n):
            kb = ks[b]
            rb = nq * si[kb]
            acc = 0.0
            for q in range(nq):
                aq = Js_w[ka, q]
                if aq == 0.0:
                    continue
                row = 0.0
                for r in range(nq):
                    row += Qgg[ra + q, rb + r] * Js_w[kb, r]
                acc += aq * row
            S[a, b] = acc
            S[b, a] = acc


@njit(cache=True)
def _target_stations(Js_w, si, ks, loc):
    """The distinct stations of one target's observations ``ks``, numbered in order of first
    appearance into ``loc`` (ns,) (callers reset it to -1); returns the station of each local index."""
    n = ks.shape[0]
    U = np.empty(n, np.int64)
    u = 0
    for a in range(n):
        i = si[ks[a]]
        if loc[i] < 0:
            loc[i] = u
            U[u] = i
            u += 1
    return U[:u]


@njit(cache=True)
def _target_sum(Js_w, X, si, ks, loc, u):
    """For one target: ``W = sum_a Abar_a X_a^T`` over its observations ``ks`` (``Abar_a`` the station
    row ``A_a`` placed at station ``a``'s parameters, on the rows of the target's ``u`` stations only,
    numbered by ``loc``: (u nq, 3)). O(n nq)."""
    nq = Js_w.shape[1]
    W = np.zeros((u * nq, 3))
    for a in range(ks.shape[0]):
        ka = ks[a]
        r0 = nq * loc[si[ka]]
        for q in range(nq):
            aq = Js_w[ka, q]
            for c in range(3):
                W[r0 + q, c] += aq * X[ka, c]
    return W


@njit(cache=True)
def _station_block(Qgg, U, nq):
    """``Qgg`` on the parameters of stations ``U`` ((u nq, u nq))."""
    u = U.shape[0]
    G = np.empty((u * nq, u * nq))
    for la in range(u):
        for lb in range(u):
            for q in range(nq):
                for r in range(nq):
                    G[nq * la + q, nq * lb + r] = Qgg[nq * U[la] + q, nq * U[lb] + r]
    return G


@njit(parallel=True, cache=True)
def _hat_diagonal(Qgg, Minv, Js_w, Jt_w, P, si, order, tptr, h, j0, j1, few):
    """Diagonal of the whitened hat matrix ``A C A^T`` (internal covariance, no factor) into ``h`` (m,)
    for targets ``j0 .. j1 - 1``: ``h_b = S_bb - 2 sum_a BP_ba S_ab + BP_bb + sum_ae BP_ba S_ae BP_be``
    over the target's observations. Targets of at most ``few`` observations sum the n x n products
    (O(n^3)); larger ones take :func:`_hat_diagonal_many`, linear in n (10 000 repeated readings of
    one pair ran for hours in the n^3 sum, with two n x n matrices of 800 MB)."""
    ns = Qgg.shape[0] // Js_w.shape[1]
    for j in prange(j0, j1):
        ks = order[tptr[j]:tptr[j + 1]]
        n = ks.shape[0]
        if n > few:
            _hat_diagonal_many(Qgg, Js_w, Jt_w, P, si, ks, h, ns)
            continue
        S = np.empty((n, n))
        BP = np.empty((n, n))
        _target_S(Qgg, Js_w, si, ks, S)
        for a in range(n):
            for b in range(n):
                BP[a, b] = (Jt_w[ks[a], 0] * P[ks[b], 0] + Jt_w[ks[a], 1] * P[ks[b], 1]
                            + Jt_w[ks[a], 2] * P[ks[b], 2])
        for b in range(n):
            t2 = 0.0
            t3 = 0.0
            for a in range(n):
                t2 += BP[b, a] * S[a, b]
                inner = 0.0
                for e in range(n):
                    inner += S[a, e] * BP[b, e]
                t3 += BP[b, a] * inner
            h[ks[b]] = S[b, b] - 2.0 * t2 + BP[b, b] + t3


@njit(cache=True)
def _hat_diagonal_many(Qgg, Js_w, Jt_w, P, si, ks, h, ns):
    """:func:`_hat_diagonal` of one target with many observations, linear in their number: with
    ``W = sum_a Abar_a B_a^T`` (``BP_ba = P_b . B_a``) the expanded sum is ``h_b = z_b^T Qgg z_b + B_b . P_b``,
    ``z_b = Abar_b - W P_b``; evaluated as ``|R z_b|^2`` with ``R^T R = Qgg`` on the target's stations
    (eigenvalues clipped at 0: Qgg is semi-definite), a sum of squares without the cancellation of
    the expanded terms (which lost 1e-10 of h on 300 repeated readings). O(n u nq^2 + (u nq)^3)."""
    nq = Js_w.shape[1]
    loc = np.full(ns, -1, np.int64)
    U = _target_stations(Js_w, si, ks, loc)
    W = _target_sum(Js_w, Jt_w, si, ks, loc, U.shape[0])
    lam, vec = np.linalg.eigh(_station_block(Qgg, U, nq))
    nr = lam.shape[0]
    R = np.empty((nr, nr))
    for i in range(nr):
        sl = np.sqrt(lam[i]) if lam[i] > 0.0 else 0.0
        for r in range(nr):
            R[i, r] = sl * vec[r, i]
    RW = R @ W
    for b in range(ks.shape[0]):
        kb = ks[b]
        lb = nq * loc[si[kb]]
        acc = 0.0
        for i in range(nr):
            y = -(RW[i, 0] * P[kb, 0] + RW[i, 1] * P[kb, 1] + RW[i, 2] * P[kb, 2])
            for q in range(nq):
                y += R[i, lb + q] * Js_w[kb, q]
            acc += y * y
        h[kb] = acc + (Jt_w[kb, 0] * P[kb, 0] + Jt_w[kb, 1] * P[kb, 1] + Jt_w[kb, 2] * P[kb, 2])


@njit(parallel=True, cache=True)
def _target_blocks(Qgg, Minv, Js_w, P, si, order, tptr, out, j0, j1, few):
    """3x3 covariance of targets ``j0 .. j1 - 1`` in the solving frame (internal, no factor) into
    ``out`` (t, 3, 3): ``Minv_j + sum_ab P_a S_ab P_b^T``; above ``few`` observations as
    ``Minv_j + V^T Qgg V`` with ``V = sum_a Abar_a P_a^T`` (O(n), as in :func:`_hat_diagonal`)."""
    ns = Qgg.shape[0] // Js_w.shape[1]
    for j in prange(j0, j1):
        ks = order[tptr[j]:tptr[j + 1]]
        n = ks.shape[0]
        if n > few:
            loc = np.full(ns, -1, np.int64)
            U = _target_stations(Js_w, si, ks, loc)
            V = _target_sum(Js_w, P, si, ks, loc, U.shape[0])
            QV = _station_block(Qgg, U, Js_w.shape[1]) @ V
            for c in range(3):
                for d in range(3):
                    acc = 0.0
                    for r in range(V.shape[0]):
                        acc += V[r, c] * QV[r, d]
                    out[j, c, d] = Minv[j, c, d] + acc
            continue
        S = np.empty((n, n))
        _target_S(Qgg, Js_w, si, ks, S)
        for c in range(3):
            for d in range(3):
                acc = 0.0
                for a in range(n):
                    inner = 0.0
                    for b in range(n):
                        inner += S[a, b] * P[ks[b], d]
                    acc += P[ks[a], c] * inner
                out[j, c, d] = Minv[j, c, d] + acc


@njit(parallel=True, cache=True)
def _hat_row(k, Qgg, Minv, Js_w, Jt_w, P, si, ti, order, tptr, out):
    """Row ``k`` of the whitened hat matrix ``A C A^T`` (internal, no factor) into ``out`` (m,):
    ``v = C a_k``; ``out_l = A_l . v_station(l) + B_l . v_target(l)``."""
    nq = Js_w.shape[1]
    ns = Qgg.shape[0] // nq
    t = tptr.shape[0] - 1
    i = si[k]
    j = ti[k]
    # station part of C a_k:  u = Qgg (a_k - sum_{m in j} A_m (P_m . B_k))
    acc = np.zeros(nq * ns)
    for q in range(nq):
        acc[nq * i + q] += Js_w[k, q]
    for p in range(tptr[j], tptr[j + 1]):
        m = order[p]
        pv = P[m, 0] * Jt_w[k, 0] + P[m, 1] * Jt_w[k, 1] + P[m, 2] * Jt_w[k, 2]
        for q in range(nq):
            acc[nq * si[m] + q] -= Js_w[m, q] * pv
    u = np.zeros(nq * ns)
    for r in range(nq * ns):
        if acc[r] == 0.0:
            continue
        for q in range(nq * ns):
            u[q] += Qgg[q, r] * acc[r]
    # target part: Minv_l b_k [l == j] - sum_{m in l} P_m (A_m . u_station(m)); then the row
    for l in prange(t):
        v0 = 0.0
        v1 = 0.0
        v2 = 0.0
        if l == j:
            for c in range(3):
                v0 += Minv[j, 0, c] * Jt_w[k, c]
                v1 += Minv[j, 1, c] * Jt_w[k, c]
                v2 += Minv[j, 2, c] * Jt_w[k, c]
        for p in range(tptr[l], tptr[l + 1]):
            m = order[p]
            au = 0.0
            for q in range(nq):
                au += Js_w[m, q] * u[nq * si[m] + q]
            out[m] = au
            v0 -= P[m, 0] * au
            v1 -= P[m, 1] * au
            v2 -= P[m, 2] * au
        for p in range(tptr[l], tptr[l + 1]):
            m = order[p]
            out[m] += Jt_w[m, 0] * v0 + Jt_w[m, 1] * v1 + Jt_w[m, 2] * v2


@njit(parallel=True, cache=True)
def _cov_times(Qgg, Minv, Js_w, P, si, ti, order, tptr, vg, vt, out_g, out_t, sparse, touched):
    """Internal covariance (no factor) times one vector ``[vg (Qs,), vt (t, 3)]`` into ``out_g``,
    ``out_t``: ``u = Qgg (vg - sum_m A_m (P_m . vt_j(m)))``, ``out_t_l = Minv_l vt_l - sum_{m in l}
    P_m (A_m . u_station(m))`` (:meth:`NetworkCovariance._times` for one column). ``sparse``: the
    sum over m visits only ``touched``, the observations of the targets where ``vt`` is not zero,
    ascending (the others add nothing; the same terms in the same order: the same result)."""
    nq = Js_w.shape[1]
    ns = Qgg.shape[0] // nq
    t = tptr.shape[0] - 1
    n_sum = touched.shape[0] if sparse else si.shape[0]
    acc = vg.copy()
    for mm in range(n_sum):
        m = touched[mm] if sparse else mm
        j = ti[m]
        pv = P[m, 0] * vt[j, 0] + P[m, 1] * vt[j, 1] + P[m, 2] * vt[j, 2]
        if pv != 0.0:
            for q in range(nq):
                acc[nq * si[m] + q] -= Js_w[m, q] * pv
    for q in range(nq * ns):
        out_g[q] = 0.0
    for r in range(nq * ns):
        if acc[r] == 0.0:
            continue
        for q in range(nq * ns):
            out_g[q] += Qgg[q, r] * acc[r]
    for l in prange(t):
        v0 = Minv[l, 0, 0] * vt[l, 0] + Minv[l, 0, 1] * vt[l, 1] + Minv[l, 0, 2] * vt[l, 2]
        v1 = Minv[l, 1, 0] * vt[l, 0] + Minv[l, 1, 1] * vt[l, 1] + Minv[l, 1, 2] * vt[l, 2]
        v2 = Minv[l, 2, 0] * vt[l, 0] + Minv[l, 2, 1] * vt[l, 1] + Minv[l, 2, 2] * vt[l, 2]
        for p in range(tptr[l], tptr[l + 1]):
            m = order[p]
            au = 0.0
            for q in range(nq):
                au += Js_w[m, q] * out_g[nq * si[m] + q]
            v0 -= P[m, 0] * au
            v1 -= P[m, 1] * au
            v2 -= P[m, 2] * au
        out_t[l, 0] = v0
        out_t[l, 1] = v1
        out_t[l, 2] = v2


@njit(parallel=True, cache=True)
def _design_times(Js_w, Jt_w, si, ti, xg, xt, out):
    """``out[k] = Js_w[k] . xg[si[k]] + Jt_w[k] . xt[ti[k]]``: the whitened design times a
    parameter-space vector (station part ``xg`` (s, Q), target part ``xt`` (t, 3))."""
    nq = Js_w.shape[1]
    for k in prange(si.shape[0]):
        i = si[k]
        j = ti[k]
        acc = 0.0
        for q in range(nq):
            acc += Js_w[k, q] * xg[i, q]
        out[k] = acc + (Jt_w[k, 0] * xt[j, 0] + Jt_w[k, 1] * xt[j, 1] + Jt_w[k, 2] * xt[j, 2])


@njit(parallel=True, cache=True)
def _target_gains(Minv, Jt_w, ti, out):
    """``out[m] = Minv[ti[m]] @ Jt_w[m]`` (the covariance's ``P``), each component summed as numpy's
    einsum("mij,mj->mi") sums it here, (x0 + x2) + x1, without the (m, 3, 3) gather."""
    for m in prange(ti.shape[0]):
        j = ti[m]
        b0 = Jt_w[m, 0]
        b1 = Jt_w[m, 1]
        b2 = Jt_w[m, 2]
        for a in range(3):
            out[m, a] = (Minv[j, a, 0] * b0 + Minv[j, a, 2] * b2) + Minv[j, a, 1] * b1


# ------------------------------------------------------------------ Python boundary
#: Targets with more observations than this take the linear-time sums of :func:`_hat_diagonal` and
#: :func:`_target_blocks` (repeated readings of a pair, a target seen from many places); smaller ones
#: the n x n products, whose bits the shipped benchmark documents were recorded with.
FEW_PER_TARGET = 32

#: Observations per call of a per-target kernel: each call returns to Python (well under a second),
#: where a Ctrl-C or SIGTERM handler can run (a signal that arrives inside compiled code waits for it).
BLOCK_OBS = 1 << 17


def _out(x):
    """An output array, written in place: it must already be what the kernel was compiled for."""
    if not (x.flags.c_contiguous and x.flags.writeable and x.dtype == np.float64):
        raise ValueError("kernel output must be a writeable C-contiguous float64 array")
    return x


def writable(x, dtype=float):
    """``x`` as a writeable C-contiguous array of ``dtype`` (:func:`multilat._numba.writable`)."""
    return _writable(x, dtype)


def target_ranges(tptr, block_obs: int | None = None):
    """Consecutive target ranges ``(j0, j1)`` of about ``block_obs`` (default :data:`BLOCK_OBS`)
    observations each (a target with more is a range of its own)."""
    block_obs = BLOCK_OBS if block_obs is None else block_obs
    t = tptr.shape[0] - 1
    j0 = 0
    while j0 < t:
        j1 = int(np.searchsorted(tptr, tptr[j0] + block_obs, side="right")) - 1
        j1 = min(max(j1, j0 + 1), t)
        yield j0, j1
        j0 = j1


def hat_diagonal(Qgg, Minv, Js_w, Jt_w, P, si, order, tptr, h):
    """:func:`_hat_diagonal` over all targets, in blocks of :data:`BLOCK_OBS` observations."""
    a = (writable(Qgg), writable(Minv), writable(Js_w), writable(Jt_w), writable(P),
         writable(si, np.int64), writable(order, np.int64), writable(tptr, np.int64))
    for j0, j1 in target_ranges(a[-1]):
        _hat_diagonal(*a, _out(h), j0, j1, FEW_PER_TARGET)


def target_blocks(Qgg, Minv, Js_w, P, si, order, tptr, out):
    """:func:`_target_blocks` over all targets, in blocks of :data:`BLOCK_OBS` observations."""
    a = (writable(Qgg), writable(Minv), writable(Js_w), writable(P), writable(si, np.int64),
         writable(order, np.int64), writable(tptr, np.int64))
    for j0, j1 in target_ranges(a[-1]):
        _target_blocks(*a, _out(out), j0, j1, FEW_PER_TARGET)


def hat_row(k, Qgg, Minv, Js_w, Jt_w, P, si, ti, order, tptr, out):
    """:func:`_hat_row` (O(m + (5 s)^2): one call)."""
    w, i = writable, np.int64
    _hat_row(int(k), w(Qgg), w(Minv), w(Js_w), w(Jt_w), w(P), w(si, i), w(ti, i), w(order, i), w(tptr, i),
             _out(out))


def cov_times(Qgg, Minv, Js_w, P, si, ti, order, tptr, vg, vt, out_g, out_t, sparse, touched):
    """:func:`_cov_times` (O(m + (5 s)^2): one call)."""
    w, i = writable, np.int64
    _cov_times(w(Qgg), w(Minv), w(Js_w), w(P), w(si, i), w(ti, i), w(order, i), w(tptr, i), w(vg), w(vt),
               _out(out_g), _out(out_t), bool(sparse), w(touched, i))


def design_times(Js_w, Jt_w, si, ti, xg, xt, out):
    """:func:`_design_times` (O(m): one call)."""
    w, i = writable, np.int64
    _design_times(w(Js_w), w(Jt_w), w(si, i), w(ti, i), w(xg), w(xt), _out(out))


def target_gains(Minv, Jt_w, ti, out):
    """:func:`_target_gains` (O(m): one call)."""
    _target_gains(writable(Minv), writable(Jt_w), writable(ti, np.int64), _out(out))
