"""Numba kernel of :mod:`multilat.network.montecarlo.batched` (frozen method). Imported only when numba exists.

Same arithmetic as ``BatchedNetwork._step(method="frozen")``: exact gradient of each trial, frozen
Schur-reduced normal matrix of the nominal solution; one pass over the observations per iteration,
trials in parallel (``prange``). The tests compare it with the numpy path.

The station system's columns come in ``cols`` (s, 4): station ``i``'s ``x, y, z, offset`` rows of
``s0inv`` and of the gradient (:meth:`multilat.network.model.parameter_layout.ParameterLayout.station_system`).

IEEE division (``multilat._numba.njit``: ``error_model="numpy"``): a zero divisor gives inf or nan, never an
exception out of a parallel region.
"""

from __future__ import annotations

import numpy as np
from multilat._numba import boundary, njit, prange


@njit(cache=True, inline="always")
def _load4(v, c, i):  # pragma: no cover - jit
    """Station ``i``'s four sums ``v[c[i]]``."""
    return v[c[i, 0]], v[c[i, 1]], v[c[i, 2]], v[c[i, 3]]


@njit(cache=True, inline="always")
def _store4(v, c, i, a0, a1, a2, a3):  # pragma: no cover - jit
    v[c[i, 0]] = a0
    v[c[i, 1]] = a1
    v[c[i, 2]] = a2
    v[c[i, 3]] = a3


@njit(parallel=True, cache=True, fastmath=False, nogil=True)
def solve_frozen(d, h, o, tg, si, ti, w, u0, ninv0, s0inv, cols, tol, max_iter):  # pragma: no cover - jit
    n, m = d.shape
    s = h.shape[1]
    t = tg.shape[1]
    p = s0inv.shape[0]
    iters = np.full(n, max_iter, np.int64)
    last = np.full(n, np.inf)
    vtpv = np.empty(n)
    for r in prange(n):
        gh = np.empty(p)            # station rows [x, y, z, offset] of station i at cols[i]
        gt = np.empty((t, 3))
        yt = np.empty((t, 3))
        dxp = np.empty(p)
        for it in range(max_iter):
            gh[:] = 0.0
            gt[:] = 0.0
            # a station's sums stay in registers over its run of observations (stored when the
            # station changes): the same additions, in the same order, as adding into gh each time
            cur = si[0]
            a0, a1, a2, a3 = _load4(gh, cols, cur)
            for k in range(m):
                i = si[k]
                if i != cur:
                    _store4(gh, cols, cur, a0, a1, a2, a3)
                    cur = i
                    a0, a1, a2, a3 = _load4(gh, cols, i)
                j = ti[k]
                dx = h[r, i, 0] - tg[r, j, 0]
                dy = h[r, i, 1] - tg[r, j, 1]
                dz = h[r, i, 2] - tg[r, j, 2]
                rho = np.sqrt(dx * dx + dy * dy + dz * dz)
                e = w[k] * (d[r, k] - rho - o[r, i]) / rho
                a0 += e * dx
                a1 += e * dy
                a2 += e * dz
                a3 += e * rho
                gt[j, 0] -= e * dx
                gt[j, 1] -= e * dy
                gt[j, 2] -= e * dz
            _store4(gh, cols, cur, a0, a1, a2, a3)
            for j in range(t):
                for a in range(3):
                    yt[j, a] = ninv0[j, a, 0] * gt[j, 0] + ninv0[j, a, 1] * gt[j, 1] + ninv0[j, a, 2] * gt[j, 2]
            cur = si[0]
            a0, a1, a2, a3 = _load4(gh, cols, cur)
            for k in range(m):
                i = si[k]
                if i != cur:
                    _store4(gh, cols, cur, a0, a1, a2, a3)
                    cur = i
                    a0, a1, a2, a3 = _load4(gh, cols, i)
                j = ti[k]
                sk = w[k] * (u0[k, 0] * yt[j, 0] + u0[k, 1] * yt[j, 1] + u0[k, 2] * yt[j, 2])
                a0 += sk * u0[k, 0]
                a1 += sk * u0[k, 1]
                a2 += sk * u0[k, 2]
                a3 += sk
            _store4(gh, cols, cur, a0, a1, a2, a3)
            # dxp = s0inv @ gh, each row summed over b in order; four rows at a time (independent
            # sums side by side instead of one long chain of dependent additions; p = 4 s rows)
            a = 0
            while a + 4 <= p:
                c0 = 0.0
                c1 = 0.0
                c2 = 0.0
                c3 = 0.0
                for b in range(p):
                    g = gh[b]
                    c0 += s0inv[a, b] * g
                    c1 += s0inv[a + 1, b] * g
                    c2 += s0inv[a + 2, b] * g
                    c3 += s0inv[a + 3, b] * g
                dxp[a] = c0
                dxp[a + 1] = c1
                dxp[a + 2] = c2
                dxp[a + 3] = c3
                a += 4
            step = 0.0
            nan = False
            for i in range(s):
                for a in range(3):
                    h[r, i, a] += dxp[cols[i, a]]
                    step = max(step, abs(dxp[cols[i, a]]))
                    nan = nan or not np.isfinite(dxp[cols[i, a]])
                o[r, i] += dxp[cols[i, 3]]
                step = max(step, abs(dxp[cols[i, 3]]))
                nan = nan or not np.isfinite(dxp[cols[i, 3]])
            for k in range(m):
                i = si[k]
                j = ti[k]
                q = w[k] * (u0[k, 0] * dxp[cols[i, 0]] + u0[k, 1] * dxp[cols[i, 1]] + u0[k, 2] * dxp[cols[i, 2]]
                            + dxp[cols[i, 3]])
                gt[j, 0] += q * u0[k, 0]
                gt[j, 1] += q * u0[k, 1]
                gt[j, 2] += q * u0[k, 2]
            for j in range(t):
                for a in range(3):
                    v = ninv0[j, a, 0] * gt[j, 0] + ninv0[j, a, 1] * gt[j, 1] + ninv0[j, a, 2] * gt[j, 2]
                    tg[r, j, a] += v
                    step = max(step, abs(v))
                    nan = nan or not np.isfinite(v)
            if nan or not np.isfinite(step):
                step = np.inf
            last[r] = step
            if step < tol:
                iters[r] = it + 1
                break
        acc = 0.0
        for k in range(m):
            i = si[k]
            j = ti[k]
            dx = h[r, i, 0] - tg[r, j, 0]
            dy = h[r, i, 1] - tg[r, j, 1]
            dz = h[r, i, 2] - tg[r, j, 2]
            res = d[r, k] - np.sqrt(dx * dx + dy * dy + dz * dz) - o[r, i]
            acc += w[k] * res * res
        vtpv[r] = acc
    return iters, last, vtpv


@njit(parallel=True, cache=True, nogil=True)
def apply_inner(pts, idx, x0c, proj, c0, iterations):  # pragma: no cover - jit
    """Rigid least-squares fit of ``pts[:, idx]`` onto ``x0c + c0`` per trial, in place.

    pts (n, P, 3); idx (q,) datum point indices; x0c (q, 3) nominal datum points minus centroid c0;
    proj (q, 3, 6) = G (G^T G)^-1 of the Helmert basis about the centroid. Same iteration as the
    numpy path of :meth:`TrialDatum.apply` (linearised fit, exact Rodrigues rotation, repeated).
    """
    n, npts, _ = pts.shape
    q = idx.shape[0]
    for r in prange(n):
        for p in range(npts):
            for a in range(3):
                pts[r, p, a] -= c0[a]
        for it in range(iterations):
            xi = np.zeros(6)
            for b in range(q):
                pb = idx[b]
                for a in range(3):
                    dev = pts[r, pb, a] - x0c[b, a]
                    for c in range(6):
                        xi[c] -= proj[b, a, c] * dev
            wx, wy, wz = xi[3], xi[4], xi[5]
            th2 = wx * wx + wy * wy + wz * wz
            th = np.sqrt(th2)
            if th < 1e-8:
                ca = 1.0 - th2 / 6.0
                cb = 0.5 - th2 / 24.0
            else:
                ca = np.sin(th) / th
                cb = (1.0 - np.cos(th)) / th2
            # R = I + ca K + cb K^2, K = [w]x
            r00 = 1.0 - cb * (wy * wy + wz * wz)
            r11 = 1.0 - cb * (wx * wx + wz * wz)
            r22 = 1.0 - cb * (wx * wx + wy * wy)
            r01 = -ca * wz + cb * wx * wy
            r10 = ca * wz + cb * wx * wy
            r02 = ca * wy + cb * wx * wz
            r20 = -ca * wy + cb * wx * wz
            r12 = -ca * wx + cb * wy * wz
            r21 = ca * wx + cb * wy * wz
            for p in range(npts):
                x = pts[r, p, 0]
                y = pts[r, p, 1]
                z = pts[r, p, 2]
                pts[r, p, 0] = r00 * x + r01 * y + r02 * z + xi[0]
                pts[r, p, 1] = r10 * x + r11 * y + r12 * z + xi[1]
                pts[r, p, 2] = r20 * x + r21 * y + r22 * z + xi[2]
            mx = 0.0
            for c in range(6):
                mx = max(mx, abs(xi[c]))
            if mx < 1e-15:
                break
        for p in range(npts):
            for a in range(3):
                pts[r, p, a] += c0[a]


# Python entry points: read-only inputs (arrays read from a file) passed as writeable copies, so the
# warm-up's compiled variant serves them (multilat._numba.boundary)
solve_frozen = boundary(solve_frozen)
apply_inner = boundary(apply_inner)
