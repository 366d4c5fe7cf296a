"""Kernels of the statistics at the solution of a large network (:mod:`multilat.network.covariance`):
the hat diagonal and hat rows, the target blocks of the covariance, the covariance and design
products of the downdated snooping rounds, the targets' gains. One pass over targets, observations
grouped by target, as in :mod:`multilat.network._sparse_kernels` (the solve).

Compiled with numba when it is installed; otherwise the same functions run as plain Python (slow,
but identical arithmetic). The tests compare them with the numpy path of ``covariance`` to 1e-12.

IEEE division (``multilat._numba.njit``: ``error_model="numpy"``): a zero divisor gives inf or nan, never an
exception out of a parallel region.
"""

from __future__ import annotations

import numpy as np

from multilat._numba import HAVE_NUMBA, njit, prange  # noqa: F401


# The covariance of :class:`multilat.network.covariance.NetworkCovariance` in its Schur form: ``Qgg``
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


@njit(parallel=True, cache=True)
def hat_diagonal(Qgg, Minv, Js_w, Jt_w, P, si, order, tptr, h):
    """Diagonal of the whitened hat matrix ``A C A^T`` (internal covariance, no factor) into ``h`` (m,):
    ``h_b = S_bb - 2 sum_a BP_ba S_ab + BP_bb + sum_ae BP_ba S_ae BP_be`` over the target's observations."""
    t = tptr.shape[0] - 1
    for j in prange(t):
        ks = order[tptr[j]:tptr[j + 1]]
        n = ks.shape[0]
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


@njit(parallel=True, cache=True)
def target_blocks(Qgg, Minv, Js_w, P, si, order, tptr, out):
    """3x3 covariance of every target in the solving frame (internal, no factor) into ``out`` (t, 3, 3):
    ``Minv_j + sum_ab P_a S_ab P_b^T``."""
    t = tptr.shape[0] - 1
    for j in prange(t):
        ks = order[tptr[j]:tptr[j + 1]]
        n = ks.shape[0]
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
def hat_row(k, Qgg, Minv, Js_w, Jt_w, P, si, ti, order, tptr, out):
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
def cov_times(Qgg, Minv, Js_w, P, si, ti, order, tptr, vg, vt, out_g, out_t, sparse, touched):
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
def design_times(Js_w, Jt_w, si, ti, xg, xt, out):
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
def target_gains(Minv, Jt_w, ti, out):
    """``out[m] = Minv[ti[m]] @ Jt_w[m]`` (the covariance's ``P``), each component summed as numpy's
    einsum("mij,mj->mi") sums it here, (x0 + x2) + x1, without the (m, 3, 3) gather."""
    for m in prange(ti.shape[0]):
        j = ti[m]
        b0 = Jt_w[m, 0]
        b1 = Jt_w[m, 1]
        b2 = Jt_w[m, 2]
        for a in range(3):
            out[m, a] = (Minv[j, a, 0] * b0 + Minv[j, a, 2] * b2) + Minv[j, a, 1] * b1
