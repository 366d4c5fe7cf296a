"""Kernels of the sparse back end :mod:`multilat.network.adjust.solve.sparse` and of the multilateration of
:mod:`multilat.network.adjust.approximate.large` (one pass over targets; observations grouped by target).

Compiled with numba when it is installed; otherwise the same functions run as plain Python (slow,
but identical arithmetic — the tests run a tiny network both ways).

Notation: observation ``k`` of target ``j`` (``tptr[j] <= k < tptr[j+1]``) from station ``i = si[k]``;
``u_k`` unit vector target -> station; station/offset row ``a_k = [u_k, 1]``; weight ``w_k``; station
``i``'s ``x, y, z, offset`` are columns ``cols[i]`` of the reduced system (the layout's
``station_block``, :class:`multilat.network.model.parameter_layout.ParameterLayout`: the kernels do
no column arithmetic of their own).

IEEE division (``multilat._numba.njit``: ``error_model="numpy"``): a zero divisor gives inf or nan, never an
exception out of a parallel region.
"""

from __future__ import annotations

import numpy as np

from multilat._numba import HAVE_NUMBA, boundary, get_num_threads, njit, prange  # noqa: F401


@njit(cache=True)
def _inv3(a00, a01, a02, a11, a12, a22, out):
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    det = a00 * c00 + a01 * c01 + a02 * c02
    inv = 1.0 / det
    out[0, 0] = c00 * inv
    out[0, 1] = c01 * inv
    out[1, 0] = c01 * inv
    out[0, 2] = c02 * inv
    out[2, 0] = c02 * inv
    out[1, 1] = c11 * inv
    out[1, 2] = c12 * inv
    out[2, 1] = c12 * inv
    out[2, 2] = c22 * inv
    return det


@njit(cache=True, inline="always")
def _sub_outer(scc, r, c, cc, x0, x1, x2, y0, y1, y2):
    """``scc[r[a], c[q]] -= (cc * x_a) * y_q`` for ``x = (x0, x1, x2, 1)``, ``y = (y0, y1, y2, 1)``: the
    4x4 block of one observation pair, unrolled (the products in the order of the loop it replaces)."""
    r0, r1, r2, r3 = r[0], r[1], r[2], r[3]
    c0, c1, c2, c3 = c[0], c[1], c[2], c[3]
    e = cc * x0
    scc[r0, c0] -= e * y0
    scc[r0, c1] -= e * y1
    scc[r0, c2] -= e * y2
    scc[r0, c3] -= e
    e = cc * x1
    scc[r1, c0] -= e * y0
    scc[r1, c1] -= e * y1
    scc[r1, c2] -= e * y2
    scc[r1, c3] -= e
    e = cc * x2
    scc[r2, c0] -= e * y0
    scc[r2, c1] -= e * y1
    scc[r2, c2] -= e * y2
    scc[r2, c3] -= e
    e = cc
    scc[r3, c0] -= e * y0
    scc[r3, c1] -= e * y1
    scc[r3, c2] -= e * y2
    scc[r3, c3] -= e


@njit(parallel=True, cache=True)
def assemble(h, o, tg, d, w, si, tptr, cols, p, u, nblk, ninv, gt, nchunks, maxk, damping):
    """Full Gauss-Newton assembly at the current point.

    ``cols`` (s, 4): station ``i``'s ``x, y, z, offset`` columns in the reduced system of ``p`` columns.
    ``damping``: Levenberg-Marquardt factor applied to the diagonal of every target block
    (``N_jj[a, a] *= 1 + damping``) before its inverse; the caller damps the station diagonal.

    Writes ``u`` (m, 3), the target blocks ``nblk`` (t, 3, 3) (damped) and their inverses ``ninv``,
    ``gt`` (t, 3) = ``-sum w r u`` per target; returns the
    reduced system ``S`` (p, p) (no datum; zero outside ``cols``), the reduced gradient ``gp`` (p,),
    ``vtpv``, and the smallest target-block determinant relative to its trace cubed (conditioning check).
    """
    s = h.shape[0]
    t = tg.shape[0]
    sc = np.zeros((nchunks, p, p))
    gc = np.zeros((nchunks, p))
    vc = np.zeros(nchunks)
    dc = np.full(nchunks, np.inf)
    step = (t + nchunks - 1) // nchunks
    for c in prange(nchunks):
        scc = sc[c]
        gcc = gc[c]
        v = np.empty((maxk, 3))
        vacc = 0.0
        dmin = np.inf
        for j in range(c * step, min(t, (c + 1) * step)):
            k0 = tptr[j]
            k1 = tptr[j + 1]
            n00 = n01 = n02 = n11 = n12 = n22 = 0.0
            g0 = g1 = g2 = 0.0
            tx = tg[j, 0]; ty = tg[j, 1]; tz = tg[j, 2]
            for k in range(k0, k1):
                i = si[k]
                dx = h[i, 0] - tx
                dy = h[i, 1] - ty
                dz = h[i, 2] - tz
                rho = np.sqrt(dx * dx + dy * dy + dz * dz)
                ux = dx / rho
                uy = dy / rho
                uz = dz / rho
                u[k, 0] = ux
                u[k, 1] = uy
                u[k, 2] = uz
                r = d[k] - rho - o[i]
                wk = w[k]
                e = wk * r
                vacc += e * r
                n00 += wk * ux * ux
                n01 += wk * ux * uy
                n02 += wk * ux * uz
                n11 += wk * uy * uy
                n12 += wk * uy * uz
                n22 += wk * uz * uz
                g0 -= e * ux
                g1 -= e * uy
                g2 -= e * uz
                b = cols[i]
                gcc[b[0]] += e * ux
                gcc[b[1]] += e * uy
                gcc[b[2]] += e * uz
                gcc[b[3]] += e
                _sub_outer(scc, b, b, -wk, ux, uy, uz, ux, uy, uz)
            if damping != 0.0:
                n00 *= 1.0 + damping
                n11 *= 1.0 + damping
                n22 *= 1.0 + damping
            bj = nblk[j]
            bj[0, 0] = n00
            bj[0, 1] = n01
            bj[0, 2] = n02
            bj[1, 0] = n01
            bj[1, 1] = n11
            bj[1, 2] = n12
            bj[2, 0] = n02
            bj[2, 1] = n12
            bj[2, 2] = n22
            nj = ninv[j]
            det = _inv3(n00, n01, n02, n11, n12, n22, nj)
            tr = n00 + n11 + n22
            rel = det / (tr * tr * tr)
            if rel < dmin:
                dmin = rel
            gt[j, 0] = g0
            gt[j, 1] = g1
            gt[j, 2] = g2
            y0 = nj[0, 0] * g0 + nj[0, 1] * g1 + nj[0, 2] * g2
            y1 = nj[1, 0] * g0 + nj[1, 1] * g1 + nj[1, 2] * g2
            y2 = nj[2, 0] * g0 + nj[2, 1] * g1 + nj[2, 2] * g2
            for k in range(k0, k1):
                kk = k - k0
                for a in range(3):
                    v[kk, a] = w[k] * (nj[a, 0] * u[k, 0] + nj[a, 1] * u[k, 1] + nj[a, 2] * u[k, 2])
            for k in range(k0, k1):
                i = si[k]
                b = cols[i]
                wk = w[k]
                ux = u[k, 0]; uy = u[k, 1]; uz = u[k, 2]
                sk = wk * (ux * y0 + uy * y1 + uz * y2)
                gcc[b[0]] += sk * ux
                gcc[b[1]] += sk * uy
                gcc[b[2]] += sk * uz
                gcc[b[3]] += sk
                for l in range(k, k1):
                    il = si[l]
                    ll = l - k0
                    cc = wk * (ux * v[ll, 0] + uy * v[ll, 1] + uz * v[ll, 2])
                    lx = u[l, 0]; ly = u[l, 1]; lz = u[l, 2]
                    if i == il and l > k:
                        for a in range(4):
                            xa = ux if a == 0 else (uy if a == 1 else (uz if a == 2 else 1.0))
                            ya = lx if a == 0 else (ly if a == 1 else (lz if a == 2 else 1.0))
                            for q in range(4):
                                xq = ux if q == 0 else (uy if q == 1 else (uz if q == 2 else 1.0))
                                yq = lx if q == 0 else (ly if q == 1 else (lz if q == 2 else 1.0))
                                scc[b[a], b[q]] -= cc * (xa * yq + ya * xq)
                    elif i <= il:
                        _sub_outer(scc, b, cols[il], cc, ux, uy, uz, lx, ly, lz)
                    else:
                        _sub_outer(scc, cols[il], b, cc, lx, ly, lz, ux, uy, uz)
        vc[c] = vacc
        dc[c] = dmin
    sm = np.zeros((p, p))
    gp = np.zeros(p)
    vt = 0.0
    dmn = np.inf
    for c in range(nchunks):
        sm += sc[c]
        gp += gc[c]
        vt += vc[c]
        dmn = min(dmn, dc[c])
    # upper block triangle -> full symmetric matrix (diagonal blocks are complete and symmetric)
    full = sm + sm.T
    for i in range(s):
        b = cols[i]
        for a in range(4):
            for q in range(4):
                full[b[a], b[q]] = 0.5 * (sm[b[a], b[q]] + sm[b[q], b[a]])
    return full, gp, vt, dmn


@njit(parallel=True, cache=True)
def back_substitute(dxp, cols, gt, ninv, u, w, si, tptr, dt):
    """Target steps ``dt_j = Ninv_j (gt_j + sum_k w_k u_k (a_k . dxp_i))`` into ``dt`` (t, 3); station
    ``i``'s step is ``dxp[cols[i]]`` (``x, y, z, offset``)."""
    t = gt.shape[0]
    for j in prange(t):
        r0 = gt[j, 0]
        r1 = gt[j, 1]
        r2 = gt[j, 2]
        for k in range(tptr[j], tptr[j + 1]):
            b = cols[si[k]]
            q = w[k] * (u[k, 0] * dxp[b[0]] + u[k, 1] * dxp[b[1]] + u[k, 2] * dxp[b[2]] + dxp[b[3]])
            r0 += q * u[k, 0]
            r1 += q * u[k, 1]
            r2 += q * u[k, 2]
        nj = ninv[j]
        for a in range(3):
            dt[j, a] = nj[a, 0] * r0 + nj[a, 1] * r1 + nj[a, 2] * r2


@njit(cache=True)
def _sym3_eig_min_mid_max(a00, a01, a02, a11, a12, a22):
    """Eigenvalues (ascending) of a symmetric 3x3 matrix, closed form (trigonometric)."""
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    q = (a00 + a11 + a22) / 3.0
    p2 = (a00 - q) ** 2 + (a11 - q) ** 2 + (a22 - q) ** 2 + 2.0 * p1
    if p2 <= 0.0:
        return q, q, q
    p = np.sqrt(p2 / 6.0)
    b00, b11, b22 = (a00 - q) / p, (a11 - q) / p, (a22 - q) / p
    b01, b02, b12 = a01 / p, a02 / p, a12 / p
    r = 0.5 * (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02))
    r = min(1.0, max(-1.0, r))
    phi = np.arccos(r) / 3.0
    e_max = q + 2.0 * p * np.cos(phi)
    e_min = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    return e_min, 3.0 * q - e_max - e_min, e_max


@njit(parallel=True, cache=True)
def degenerate_blocks(N, rel_tol, bad):
    """``bad[j]`` for each symmetric 3x3 block ``N[j]``: not ``lambda_min > rel_tol * lambda_max``
    (closed-form eigenvalues: absolute error ~1e-16 lambda_max, far below a tolerance of 1e-10;
    a non-finite block is bad)."""
    for j in prange(N.shape[0]):
        a = N[j]
        ok = True
        for x in range(3):
            for y in range(3):
                if not np.isfinite(a[x, y]):
                    ok = False
        if ok:
            e0, _, e2 = _sym3_eig_min_mid_max(a[0, 0], a[0, 1], a[0, 2], a[1, 1], a[1, 2], a[2, 2])
            ok = e0 > rel_tol * e2
        bad[j] = not ok


@njit(parallel=True, cache=True)
def multilaterate(h, o, d, w, si, tptr, side, iterations, flat_tol, x_out, rms_out, status):
    """Each target from known stations ``h`` (s, 3) and offsets ``o`` (s,), one target per loop.

    Linear solution of the differenced squared-distance equations about the centroid ``c`` of the
    target's stations, ``M p = b`` with ``M = sum a a^T``, ``b = -1/2 sum a (r^2 - |a|^2)``,
    ``a = H - c``, ``r = d - o``; when ``M``'s smallest eigenvalue is below ``flat_tol`` times its
    largest (coplanar stations), the in-plane solution plus the height ``sqrt(mean(r^2 - |p - a|^2))``
    along the plane's normal, on the side of ``side`` (3,). Then ``iterations`` Gauss-Newton steps
    (weights ``w``). Writes ``x_out`` (t, 3), ``rms_out`` (t,) (RMS residual) and ``status`` (t,):
    0 ok, 1 coplanar stations (mirror side chosen), 2 collinear stations, 3 singular normal matrix.
    """
    t = len(tptr) - 1
    for j in prange(t):
        k0, k1 = tptr[j], tptr[j + 1]
        n = k1 - k0
        cx = cy = cz = 0.0
        for k in range(k0, k1):
            i = si[k]
            cx += h[i, 0]
            cy += h[i, 1]
            cz += h[i, 2]
        cx /= n
        cy /= n
        cz /= n
        m00 = m01 = m02 = m11 = m12 = m22 = 0.0
        b0 = b1 = b2 = 0.0
        for k in range(k0, k1):
            i = si[k]
            ax, ay, az = h[i, 0] - cx, h[i, 1] - cy, h[i, 2] - cz
            r = d[k] - o[i]
            y = r * r - (ax * ax + ay * ay + az * az)
            m00 += ax * ax
            m01 += ax * ay
            m02 += ax * az
            m11 += ay * ay
            m12 += ay * az
            m22 += az * az
            b0 += ax * y
            b1 += ay * y
            b2 += az * y
        b0 *= -0.5
        b1 *= -0.5
        b2 *= -0.5
        e0, e1, e2 = _sym3_eig_min_mid_max(m00, m01, m02, m11, m12, m22)
        st = 0
        if e1 <= 1e-6 * e2:
            status[j] = 2
            x_out[j, 0] = x_out[j, 1] = x_out[j, 2] = np.nan
            rms_out[j] = np.nan
            continue
        inv = np.empty((3, 3))
        nx = ny = nz = 0.0
        if e0 <= flat_tol * e2:
            st = 1
            # normal: null vector of M - e0 I, the largest cross product of two of its rows
            a00, a11, a22 = m00 - e0, m11 - e0, m22 - e0
            best = -1.0
            for q in range(3):          # cross products of row pairs (0,1), (0,2), (1,2) of M - e0 I
                if q == 0:
                    u0, u1, u2, v0, v1, v2 = a00, m01, m02, m01, a11, m12
                elif q == 1:
                    u0, u1, u2, v0, v1, v2 = a00, m01, m02, m02, m12, a22
                else:
                    u0, u1, u2, v0, v1, v2 = m01, a11, m12, m02, m12, a22
                cxx = u1 * v2 - u2 * v1
                cyy = u2 * v0 - u0 * v2
                czz = u0 * v1 - u1 * v0
                nn = cxx * cxx + cyy * cyy + czz * czz
                if nn > best:
                    best = nn
                    nx, ny, nz = cxx, cyy, czz
            nn = np.sqrt(best)
            nx /= nn
            ny /= nn
            nz /= nn
            tr = m00 + m11 + m22
            _inv3(m00 + tr * nx * nx, m01 + tr * nx * ny, m02 + tr * nx * nz, m11 + tr * ny * ny,
                  m12 + tr * ny * nz, m22 + tr * nz * nz, inv)
            bn = b0 * nx + b1 * ny + b2 * nz
            b0 -= bn * nx
            b1 -= bn * ny
            b2 -= bn * nz
        else:
            _inv3(m00, m01, m02, m11, m12, m22, inv)
        px = inv[0, 0] * b0 + inv[0, 1] * b1 + inv[0, 2] * b2
        py = inv[1, 0] * b0 + inv[1, 1] * b1 + inv[1, 2] * b2
        pz = inv[2, 0] * b0 + inv[2, 1] * b1 + inv[2, 2] * b2
        if st == 1:
            s2 = 0.0
            for k in range(k0, k1):
                i = si[k]
                r = d[k] - o[i]
                dx, dy, dz = px - (h[i, 0] - cx), py - (h[i, 1] - cy), pz - (h[i, 2] - cz)
                s2 += r * r - (dx * dx + dy * dy + dz * dz)
            hgt = np.sqrt(max(s2 / n, 0.0))
            if (side[0] - cx) * nx + (side[1] - cy) * ny + (side[2] - cz) * nz < 0.0:
                hgt = -hgt
            px += hgt * nx
            py += hgt * ny
            pz += hgt * nz
        x0, x1, x2 = px + cx, py + cy, pz + cz
        for _ in range(iterations):
            n00 = n01 = n02 = n11 = n12 = n22 = 0.0
            g0 = g1 = g2 = 0.0
            for k in range(k0, k1):
                i = si[k]
                dx, dy, dz = x0 - h[i, 0], x1 - h[i, 1], x2 - h[i, 2]
                rho = np.sqrt(dx * dx + dy * dy + dz * dz)
                if rho <= 0.0:
                    rho = 1e-300
                ux, uy, uz = dx / rho, dy / rho, dz / rho
                v = d[k] - o[i] - rho
                wk = w[k]
                n00 += wk * ux * ux
                n01 += wk * ux * uy
                n02 += wk * ux * uz
                n11 += wk * uy * uy
                n12 += wk * uy * uz
                n22 += wk * uz * uz
                g0 += wk * ux * v
                g1 += wk * uy * v
                g2 += wk * uz * v
            det = _inv3(n00, n01, n02, n11, n12, n22, inv)
            if not (abs(det) > 1e-12 * (n00 + n11 + n22) ** 3):
                st = 3
                break
            x0 += inv[0, 0] * g0 + inv[0, 1] * g1 + inv[0, 2] * g2
            x1 += inv[1, 0] * g0 + inv[1, 1] * g1 + inv[1, 2] * g2
            x2 += inv[2, 0] * g0 + inv[2, 1] * g1 + inv[2, 2] * g2
        s2 = 0.0
        for k in range(k0, k1):
            i = si[k]
            dx, dy, dz = x0 - h[i, 0], x1 - h[i, 1], x2 - h[i, 2]
            v = d[k] - o[i] - np.sqrt(dx * dx + dy * dy + dz * dz)
            s2 += v * v
        x_out[j, 0] = x0
        x_out[j, 1] = x1
        x_out[j, 2] = x2
        rms_out[j] = np.sqrt(s2 / n)
        status[j] = st


@njit(cache=True, inline="always")
def _difference(h, tg, i, j):
    """``h_i - tg_j`` and its length, the squares summed as numpy's einsum("mi,mi->m") sums them
    (numpy 2.4, x86-64: (x0² + x2²) + x1²), which keeps the kernels bit-identical to the numpy path."""
    dx = h[i, 0] - tg[j, 0]
    dy = h[i, 1] - tg[j, 1]
    dz = h[i, 2] - tg[j, 2]
    return dx, dy, dz, np.sqrt((dx * dx + dz * dz) + dy * dy)


@njit(parallel=True, cache=True)
def distance_residuals(h, tg, off, scale, si, ti, d, out):
    """``out[k] = d[k] - ((1 + scale[i]) |h_i - tg_j| + off[i])`` (i = si[k], j = ti[k]): the residuals
    of :func:`multilat.network.model.distance.residuals` (cost "distance") with the same operations in the
    same order, without the (m, 3) differences."""
    for k in prange(si.shape[0]):
        i = si[k]
        _, _, _, rho = _difference(h, tg, i, ti[k])
        out[k] = d[k] - ((1.0 + scale[i]) * rho + off[i])


@njit(parallel=True, cache=True)
def whitened_distances(h, tg, off, scale, si, ti, d, sigma, sfree, tfree, r_w, Js_w, Jt_w):
    """The whitened residuals and Jacobian blocks of the distance cost
    (:func:`multilat.network.adjust.solve.system.whitened` over
    :func:`multilat.network.model.distance.residuals_and_jacobian`) in one pass, the same operations in the
    same order: ``w = 1/sigma``, ``u = (h_i - tg_j)/rho``, ``r = d - ((1 + k_i) rho + o_i)``,
    ``J_s = [(1 + k_i) u, 1, rho]``, ``J_t = -(1 + k_i) u``, each times ``w`` then times its free flag
    (0 or 1: a held parameter's column is zero)."""
    for k in prange(si.shape[0]):
        i = si[k]
        j = ti[k]
        dx, dy, dz, rho = _difference(h, tg, i, j)
        k1 = 1.0 + scale[i]
        w = 1.0 / sigma[k]
        r_w[k] = (d[k] - (k1 * rho + off[i])) * w
        tf = 1.0 if tfree[j] else 0.0
        js0 = k1 * (dx / rho)
        js1 = k1 * (dy / rho)
        js2 = k1 * (dz / rho)
        Js_w[k, 0] = (js0 * w) * (1.0 if sfree[i, 0] else 0.0)
        Js_w[k, 1] = (js1 * w) * (1.0 if sfree[i, 1] else 0.0)
        Js_w[k, 2] = (js2 * w) * (1.0 if sfree[i, 2] else 0.0)
        Js_w[k, 3] = (1.0 * w) * (1.0 if sfree[i, 3] else 0.0)
        Js_w[k, 4] = (rho * w) * (1.0 if sfree[i, 4] else 0.0)
        Jt_w[k, 0] = (-js0 * w) * tf
        Jt_w[k, 1] = (-js1 * w) * tf
        Jt_w[k, 2] = (-js2 * w) * tf


# Python entry points: read-only inputs (arrays read from a file) passed as writeable copies, so the
# warm-up's compiled variant serves them (multilat._numba.boundary)
assemble = boundary(assemble)
back_substitute = boundary(back_substitute)
degenerate_blocks = boundary(degenerate_blocks)
multilaterate = boundary(multilaterate)
distance_residuals = boundary(distance_residuals)
whitened_distances = boundary(whitened_distances)
