"""Numba kernel of :mod:`multilat.network.montecarlo.batched` (frozen method). Imported only when numba exists.

Same arithmetic as ``BatchedNetwork._step(method="frozen")``: exact gradient of each trial, frozen
Schur-reduced normal matrix of the nominal solution. The tests compare it with the numpy path, and its
bits with the iteration of one trial written out in plain Python floats.

:data:`LANES` trials are iterated side by side, every array lane-minor (``H[i, a, lane]``), so that each
loop over the lanes is one SIMD loop: each trial's own additions, multiplications, square roots and
divisions in the scalar order (no fused multiply-add, no reassociation: ``fastmath=False``), only
several trials per instruction (the kernel took 1.7-2x less CPU than one trial at a time). A trial
leaves its lane when it has converged or reached ``max_iter`` and the next one takes the lane, so no
lane waits for the slowest of its neighbours; a trial's numbers do not depend on its lane, its
neighbours or the split of the trials between threads (``prange`` over contiguous runs).

The station system's columns come in ``cols`` (s, 4): station ``i``'s ``x, y, z, offset`` rows of
``s0inv`` and of the gradient (:meth:`multilat.network.model.parameter_layout.ParameterLayout.station_system`).

IEEE division (``multilat._numba.njit``: ``error_model="numpy"``): a zero divisor gives inf or nan, never an
exception out of a parallel region.
"""

from __future__ import annotations

import numpy as np
from multilat._numba import boundary, get_num_threads, njit, prange


#: Trials side by side in the frozen kernel: every loop over them is one SIMD loop (numba/LLVM
#: vectorises it at 32 lanes, not at 8 or 16, where it unrolls them into scalar code instead).
LANES = 32


@njit(cache=True, inline="always")
def _load(r, l, d, h, o, tg, D, H, O, TG):  # pragma: no cover - jit
    """Trial ``r`` into lane ``l`` of the lane-minor arrays."""
    for k in range(d.shape[1]):
        D[k, l] = d[r, k]
    for i in range(h.shape[1]):
        O[i, l] = o[r, i]
        for a in range(3):
            H[i, a, l] = h[r, i, a]
    for j in range(tg.shape[1]):
        for a in range(3):
            TG[j, a, l] = tg[r, j, a]


@njit(cache=True, inline="always")
def _store(r, l, h, o, tg, H, O, TG):  # pragma: no cover - jit
    """Lane ``l``'s solution into trial ``r``."""
    for i in range(h.shape[1]):
        o[r, i] = O[i, l]
        for a in range(3):
            h[r, i, a] = H[i, a, l]
    for j in range(tg.shape[1]):
        for a in range(3):
            tg[r, j, a] = TG[j, a, l]


@njit(cache=True, inline="always")
def _vtpv(l, D, H, O, TG, si, ti, w):  # pragma: no cover - jit
    """Weighted sum of squared residuals of lane ``l``, observations in order."""
    acc = 0.0
    for k in range(si.shape[0]):
        i = si[k]
        j = ti[k]
        dx = H[i, 0, l] - TG[j, 0, l]
        dy = H[i, 1, l] - TG[j, 1, l]
        dz = H[i, 2, l] - TG[j, 2, l]
        res = D[k, l] - np.sqrt(dx * dx + dy * dy + dz * dz) - O[i, l]
        acc += w[k] * res * res
    return acc


@njit(cache=True, inline="always")
def _gradient(D, H, O, TG, GH, GT, EX, si, ti, w, cols):  # pragma: no cover - jit
    """Gradient ``A^T W r`` of every lane: station rows into GH (rows ``cols``), targets into GT.
    Each observation's four terms first (one SIMD loop with the square root and the division), then
    added: the same additions, in observation order, as the scalar loop."""
    GH[:] = 0.0
    GT[:] = 0.0
    ex, ey, ez, er = EX[0], EX[1], EX[2], EX[3]
    for k in range(si.shape[0]):
        i = si[k]
        j = ti[k]
        wk = w[k]
        hx, hy, hz, tx, ty, tz = H[i, 0], H[i, 1], H[i, 2], TG[j, 0], TG[j, 1], TG[j, 2]
        dk, oi = D[k], O[i]
        for l in range(LANES):
            dx = hx[l] - tx[l]
            dy = hy[l] - ty[l]
            dz = hz[l] - tz[l]
            rho = np.sqrt(dx * dx + dy * dy + dz * dz)
            e = wk * (dk[l] - rho - oi[l]) / rho
            ex[l] = e * dx
            ey[l] = e * dy
            ez[l] = e * dz
            er[l] = e * rho
        g0, g1, g2, g3 = GH[cols[i, 0]], GH[cols[i, 1]], GH[cols[i, 2]], GH[cols[i, 3]]
        for l in range(LANES):
            g0[l] += ex[l]
            g1[l] += ey[l]
            g2[l] += ez[l]
            g3[l] += er[l]
        gx, gy, gz = GT[j, 0], GT[j, 1], GT[j, 2]
        for l in range(LANES):
            gx[l] -= ex[l]
            gy[l] -= ey[l]
            gz[l] -= ez[l]


@njit(cache=True, inline="always")
def _targets(ninv0, GT, YT):  # pragma: no cover - jit
    """``YT = ninv0 GT`` per target (the frozen 3x3 inverses)."""
    for j in range(GT.shape[0]):
        gx, gy, gz = GT[j, 0], GT[j, 1], GT[j, 2]
        for a in range(3):
            n0, n1, n2 = ninv0[j, a, 0], ninv0[j, a, 1], ninv0[j, a, 2]
            y = YT[j, a]
            for l in range(LANES):
                y[l] = n0 * gx[l] + n1 * gy[l] + n2 * gz[l]


@njit(cache=True, inline="always")
def _reduce(YT, GH, si, ti, w, u0, cols):  # pragma: no cover - jit
    """Station right-hand side of the Schur reduction: ``GH += sum_k w_k (u0_k . YT_j) [u0_k, 1]``."""
    for k in range(si.shape[0]):
        i = si[k]
        j = ti[k]
        wk, ux, uy, uz = w[k], u0[k, 0], u0[k, 1], u0[k, 2]
        yx, yy, yz = YT[j, 0], YT[j, 1], YT[j, 2]
        g0, g1, g2, g3 = GH[cols[i, 0]], GH[cols[i, 1]], GH[cols[i, 2]], GH[cols[i, 3]]
        for l in range(LANES):
            sk = wk * (ux * yx[l] + uy * yy[l] + uz * yz[l])
            g0[l] += sk * ux
            g1[l] += sk * uy
            g2[l] += sk * uz
            g3[l] += sk


@njit(cache=True, inline="always")
def _stations(s0inv, GH, DXP):  # pragma: no cover - jit
    """``DXP = s0inv @ GH``, each row summed over the columns in order from 0.0."""
    p = s0inv.shape[0]
    DXP[:] = 0.0
    for a in range(p):
        x = DXP[a]
        for b in range(p):
            sab = s0inv[a, b]
            g = GH[b]
            for l in range(LANES):
                x[l] += sab * g[l]


@njit(cache=True, inline="always")
def _back(DXP, GT, si, ti, w, u0, cols):  # pragma: no cover - jit
    """Targets' right-hand side of the back-substitution: ``GT += sum_k w_k (u0_k . dh_i + do_i) u0_k``."""
    for k in range(si.shape[0]):
        i = si[k]
        j = ti[k]
        wk, ux, uy, uz = w[k], u0[k, 0], u0[k, 1], u0[k, 2]
        d0, d1, d2, d3 = DXP[cols[i, 0]], DXP[cols[i, 1]], DXP[cols[i, 2]], DXP[cols[i, 3]]
        gx, gy, gz = GT[j, 0], GT[j, 1], GT[j, 2]
        for l in range(LANES):
            q = wk * (ux * d0[l] + uy * d1[l] + uz * d2[l] + d3[l])
            gx[l] += q * ux
            gy[l] += q * uy
            gz[l] += q * uz


@njit(cache=True, inline="always")
def _add(x, v, step, bad):  # pragma: no cover - jit
    """``x += v`` per lane; the largest ``|v|`` into step, a non-finite ``v`` flagged in bad."""
    for l in range(LANES):
        x[l] += v[l]
        step[l] = max(step[l], abs(v[l]))
        bad[l] = bad[l] | (not np.isfinite(v[l]))


@njit(cache=True, inline="always")
def _iteration(D, H, O, TG, GH, GT, YT, DXP, EX, step, bad, si, ti, w, u0, ninv0, s0inv, cols):  # pragma: no cover
    """One frozen Gauss-Newton step of every lane (the lanes' parameters updated in place); the
    largest step of each lane in ``step``, a non-finite one flagged in ``bad``."""
    _gradient(D, H, O, TG, GH, GT, EX, si, ti, w, cols)
    _targets(ninv0, GT, YT)
    _reduce(YT, GH, si, ti, w, u0, cols)
    _stations(s0inv, GH, DXP)
    step[:] = 0.0
    bad[:] = False
    for i in range(H.shape[0]):
        for a in range(3):
            _add(H[i, a], DXP[cols[i, a]], step, bad)
        _add(O[i], DXP[cols[i, 3]], step, bad)
    _back(DXP, GT, si, ti, w, u0, cols)
    _targets(ninv0, GT, YT)
    for j in range(TG.shape[0]):
        for a in range(3):
            _add(TG[j, a], YT[j, a], step, bad)


@njit(parallel=True, cache=True, fastmath=False, nogil=True)
def _solve_frozen(d, h, o, tg, si, ti, w, u0, ninv0, s0inv, cols, tol, max_iter, tasks):  # pragma: no cover - jit
    n, m = d.shape
    s = h.shape[1]
    t = tg.shape[1]
    p = s0inv.shape[0]
    iters = np.full(n, max_iter, np.int64)
    last = np.full(n, np.inf)
    vtpv = np.empty(n)
    for c in prange(tasks):                     # contiguous runs of trials, one per thread
        r0 = c * n // tasks
        r1 = (c + 1) * n // tasks
        D = np.empty((m, LANES))
        H = np.empty((s, 3, LANES))
        O = np.empty((s, LANES))
        TG = np.empty((t, 3, LANES))
        GH = np.empty((p, LANES))
        GT = np.empty((t, 3, LANES))
        YT = np.empty((t, 3, LANES))
        DXP = np.empty((p, LANES))
        EX = np.empty((4, LANES))
        step = np.empty(LANES)
        bad = np.empty(LANES, np.bool_)
        row = np.full(LANES, -1, np.int64)      # the trial in each lane (-1: none left)
        it = np.zeros(LANES, np.int64)
        nxt = r0
        for l in range(LANES):                  # an idle lane computes on a copy of the run's first trial
            _load(nxt if nxt < r1 else r0, l, d, h, o, tg, D, H, O, TG)
            if nxt < r1:
                row[l] = nxt
                nxt += 1
        busy = min(LANES, r1 - r0)
        while busy > 0:
            _iteration(D, H, O, TG, GH, GT, YT, DXP, EX, step, bad, si, ti, w, u0, ninv0, s0inv, cols)
            for l in range(LANES):
                r = row[l]
                if r < 0:
                    continue
                it[l] += 1
                last[r] = np.inf if (bad[l] or not np.isfinite(step[l])) else step[l]
                if last[r] < tol:
                    iters[r] = it[l]
                if last[r] < tol or it[l] == max_iter:    # done: out of the lane, the next trial in
                    vtpv[r] = _vtpv(l, D, H, O, TG, si, ti, w)
                    _store(r, l, h, o, tg, H, O, TG)
                    it[l] = 0
                    row[l] = nxt if nxt < r1 else -1
                    if nxt < r1:
                        _load(nxt, l, d, h, o, tg, D, H, O, TG)
                        nxt += 1
                    else:
                        busy -= 1
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


@njit(cache=True, nogil=True)
def deviations(h, o, tg, keep, x0, pair_a, pair_b, dist0, dev):  # pragma: no cover - jit
    """Row ``q`` of ``dev`` (float32): trial ``keep[q]``'s stations, offsets and targets minus ``x0``
    (the :func:`multilat.network.montecarlo.batched.flatten` layout), then its interpoint distances
    minus ``dist0``; the points ``pair_a``, ``pair_b`` index the stations then the targets. Each value
    as numpy computes it (a float64 difference rounded once to float32; a distance as
    ``np.linalg.norm``: the squares added in order, then the square root)."""
    s = h.shape[1]
    t = tg.shape[1]
    for q in range(keep.shape[0]):
        r = keep[q]
        c = 0
        for i in range(s):
            for a in range(3):
                dev[q, c] = h[r, i, a] - x0[c]
                c += 1
        for i in range(o.shape[1]):
            dev[q, c] = o[r, i] - x0[c]
            c += 1
        for j in range(t):
            for a in range(3):
                dev[q, c] = tg[r, j, a] - x0[c]
                c += 1
        for k in range(pair_a.shape[0]):
            acc = 0.0
            for a in range(3):
                pa = h[r, pair_a[k], a] if pair_a[k] < s else tg[r, pair_a[k] - s, a]
                pb = h[r, pair_b[k], a] if pair_b[k] < s else tg[r, pair_b[k] - s, a]
                acc += (pa - pb) * (pa - pb)
            dev[q, c] = np.sqrt(acc) - dist0[k]
            c += 1


# Python entry points: read-only inputs (arrays read from a file) passed as writeable copies, so the
# warm-up's compiled variant serves them (multilat._numba.boundary)
_solve_frozen = boundary(_solve_frozen)


def solve_frozen(d, h, o, tg, si, ti, w, u0, ninv0, s0inv, cols, tol, max_iter):
    """Frozen iterations of the ``n`` trials of ``d`` (n, m) from ``h, o, tg`` (updated in place):
    ``(iterations, last step, vtpv)`` per trial. The trials are split into one contiguous run per numba
    thread of the calling thread (read here: numba's count is per thread, and a compiled read of it
    could not be cached); each trial's numbers do not depend on the split."""
    tasks = max(1, min(get_num_threads(), d.shape[0] // LANES))
    return _solve_frozen(d, h, o, tg, si, ti, w, u0, ninv0, s0inv, cols, tol, max_iter, tasks)
apply_inner = boundary(apply_inner)
deviations = boundary(deviations)
