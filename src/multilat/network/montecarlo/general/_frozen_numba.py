"""Compiled chord steps of :mod:`.propagate`: the same arithmetic as :func:`.propagate.solve`'s numpy
path (the kinds' models and Jacobians, ``P r``, ``dx = Q J^T P r``), one trial at a time, trials in
parallel (``prange``). The tests compare it with the numpy path and the kinds.

Rows are a small program: a kind code per row, its full-layout columns (at most 9: the kind's
Jacobian columns, in the kind's order), per-row numbers (the height difference along z, the tracker
component, the set-up of a tracker row: its frame is computed once per set-up and trial; ``pair``:
the elevation row computed with an azimuth row, :func:`_tracker_pair`; ``ref``: cos, sin and value
of each row at x̂), and each Jacobian slot's free column (``rcols``, -1 for none), so ``J^T P r`` is
added row by row into the free columns.
The columns are static, so only the values change per trial. ``P`` is the diagonal ``wdiag`` for
rows of uncorrelated blocks, a CSR matrix (the blocks' ``C^-1``) for the others. Codes: :data:`CODES`.

Speed (``benchmarks/bench_general_propagate.py``): arrays are indexed element by element, never
through a view per row (a view's reference counting cost more than most rows' arithmetic), and the
work arrays are allocated once per :data:`UNIT` trials. No ``fastmath``: a trial's bits do not
depend on how the trials are split.

IEEE division (``multilat._numba.njit``): a zero divisor gives inf or nan, never an exception; the
trial then does not converge and goes to full Gauss-Newton in numpy.
"""

from __future__ import annotations

import math

import numpy as np

from multilat._numba import boundary, njit, prange

#: kind name -> row code of the kernel
CODES = {"slope_distance": 0, "direction": 1, "zenith_angle": 2, "horizontal_distance": 3,
         "horizontal_angle": 4, "height_difference": 5, "coordinate_difference": 5, "observed_coordinates": 6,
         "tracker_angles": 7}


@njit(cache=True, inline="always")
def _rot(w, p, k, out):  # pragma: no cover - jit
    """``out[0]`` = R = Rz(k) Ry(p) Rx(w), ``out[1..3]`` its derivatives by w, p, k (written in place:
    no allocation per row)."""
    cw, sw, cp, sp, ck, sk = math.cos(w), math.sin(w), math.cos(p), math.sin(p), math.cos(k), math.sin(k)
    R, W, P, K = out[0], out[1], out[2], out[3]
    R[0, 0], R[0, 1], R[0, 2] = ck * cp, ck * sp * sw - sk * cw, ck * sp * cw + sk * sw
    R[1, 0], R[1, 1], R[1, 2] = sk * cp, sk * sp * sw + ck * cw, sk * sp * cw - ck * sw
    R[2, 0], R[2, 1], R[2, 2] = -sp, cp * sw, cp * cw
    W[0, 0], W[0, 1], W[0, 2] = 0.0, ck * sp * cw + sk * sw, -ck * sp * sw + sk * cw
    W[1, 0], W[1, 1], W[1, 2] = 0.0, sk * sp * cw - ck * sw, -sk * sp * sw - ck * cw
    W[2, 0], W[2, 1], W[2, 2] = 0.0, cp * cw, -cp * sw
    P[0, 0], P[0, 1], P[0, 2] = -ck * sp, ck * cp * sw, ck * cp * cw
    P[1, 0], P[1, 1], P[1, 2] = -sk * sp, sk * cp * sw, sk * cp * cw
    P[2, 0], P[2, 1], P[2, 2] = -cp, -sp * sw, -sp * cw
    K[0, 0], K[0, 1], K[0, 2] = -sk * cp, -sk * sp * sw - ck * cw, -sk * sp * cw + ck * sw
    K[1, 0], K[1, 1], K[1, 2] = ck * cp, ck * sp * sw - sk * cw, ck * sp * cw + sk * sw
    K[2, 0], K[2, 1], K[2, 2] = 0.0, 0.0, 0.0


@njit(cache=True, inline="always")
def _row(code, i, cols, hz, comp, x, val, rot, u):  # pragma: no cover - jit
    """Model of row ``i`` at ``x`` and its Jacobian values ``val[i, :9]`` (in the kind's column order);
    ``rot[u]`` (4, 3, 3): the row's set-up frame and its derivatives (tracker rows, :func:`_rotations`).
    Arrays are indexed element by element (no row views: a view per row cost ~20 ns in reference
    counting, more than most rows' arithmetic)."""
    if code == 5:                     # x[c1] - x[c0]
        val[i, 0] = -1.0
        val[i, 1] = 1.0
        return x[cols[i, 1]] - x[cols[i, 0]]
    if code == 6:
        val[i, 0] = 1.0
        return x[cols[i, 0]]
    if code == 4:                     # horizontal angle: from, bs, fs (x, y each)
        fx, fy = x[cols[i, 4]] - x[cols[i, 0]], x[cols[i, 5]] - x[cols[i, 1]]
        bx, by = x[cols[i, 2]] - x[cols[i, 0]], x[cols[i, 3]] - x[cols[i, 1]]
        hf, hb = fx * fx + fy * fy, bx * bx + by * by
        gfx, gfy, gbx, gby = -fy / hf, fx / hf, -by / hb, bx / hb
        val[i, 0], val[i, 1], val[i, 2], val[i, 3], val[i, 4], val[i, 5] = gbx - gfx, gby - gfy, -gbx, -gby, gfx, gfy
        return math.atan2(fy, fx) - math.atan2(by, bx)
    if code == 1 or code == 3:        # from xy, to xy
        dx, dy = x[cols[i, 2]] - x[cols[i, 0]], x[cols[i, 3]] - x[cols[i, 1]]
        h2 = dx * dx + dy * dy
        if code == 3:
            h = math.sqrt(h2)
            val[i, 0], val[i, 1], val[i, 2], val[i, 3] = -dx / h, -dy / h, dx / h, dy / h
            return h
        val[i, 0], val[i, 1], val[i, 2], val[i, 3], val[i, 4] = dy / h2, -dx / h2, -dy / h2, dx / h2, -1.0
        return math.atan2(dy, dx) - x[cols[i, 4]]
    dx = x[cols[i, 3]] - x[cols[i, 0]]
    dy = x[cols[i, 4]] - x[cols[i, 1]]
    dz = x[cols[i, 5]] - x[cols[i, 2]] + hz
    if code == 0:
        rho = math.sqrt(dx * dx + dy * dy + dz * dz)
        off = x[cols[i, 6]] if cols[i, 6] >= 0 else 0.0
        k1 = 1.0 + (x[cols[i, 7]] if cols[i, 7] >= 0 else 0.0)
        f = k1 / rho
        val[i, 0], val[i, 1], val[i, 2], val[i, 3], val[i, 4], val[i, 5] = -f * dx, -f * dy, -f * dz, f * dx, f * dy, f * dz
        val[i, 6], val[i, 7] = 1.0, rho
        return k1 * rho + off
    if code == 2:
        h2 = dx * dx + dy * dy
        h = math.sqrt(h2)
        r2 = h2 + dz * dz
        gx, gy, gz = dz * dx / (h * r2), dz * dy / (h * r2), -h / r2
        val[i, 0], val[i, 1], val[i, 2], val[i, 3], val[i, 4], val[i, 5] = -gx, -gy, -gz, gx, gy, gz
        return math.atan2(h, dz)
    # code 7: tracker angles, v = R^T d
    v0 = rot[u, 0, 0, 0] * dx + rot[u, 0, 1, 0] * dy + rot[u, 0, 2, 0] * dz
    v1 = rot[u, 0, 0, 1] * dx + rot[u, 0, 1, 1] * dy + rot[u, 0, 2, 1] * dz
    v2 = rot[u, 0, 0, 2] * dx + rot[u, 0, 1, 2] * dy + rot[u, 0, 2, 2] * dz
    h2 = v0 * v0 + v1 * v1
    h = math.sqrt(h2)
    if comp == 0:
        a0, a1, a2 = -v1 / h2, v0 / h2, 0.0
        f = math.atan2(v1, v0)
    else:
        n2 = h2 + v2 * v2
        a0, a1, a2 = -v2 * v0 / (h * n2), -v2 * v1 / (h * n2), h / n2
        f = math.atan2(v2, h)
    _angle_jacobian(i, a0, a1, a2, dx, dy, dz, val, rot, u)
    return f


@njit(cache=True, inline="always")
def _angle_jacobian(i, a0, a1, a2, dx, dy, dz, val, rot, u):  # pragma: no cover - jit
    """``val[i]`` of a tracker angle with ``d angle / d v = a``: ``a R^T`` (target; the station the
    negative), ``a (dR_p)^T d`` (the set-up's omega, phi, kappa)."""
    for j in range(3):
        t = a0 * rot[u, 0, j, 0] + a1 * rot[u, 0, j, 1] + a2 * rot[u, 0, j, 2]
        val[i, 3 + j] = t
        val[i, j] = -t
    for p in range(1, 4):
        val[i, 5 + p] = ((a0 * rot[u, p, 0, 0] + a1 * rot[u, p, 0, 1] + a2 * rot[u, p, 0, 2]) * dx
                         + (a0 * rot[u, p, 1, 0] + a1 * rot[u, p, 1, 1] + a2 * rot[u, p, 1, 2]) * dy
                         + (a0 * rot[u, p, 2, 0] + a1 * rot[u, p, 2, 1] + a2 * rot[u, p, 2, 2]) * dz)


@njit(cache=True, inline="always")
def _small_atan2(y, x):  # pragma: no cover - jit
    """``atan2(y, x)`` for a small angle: ``atan(z)``, ``z = y / x``, by its series to z^7 when
    |z| < 1e-2 (the first term left out, z^9/9, is below 1.2e-17 |z|: the rounding of the result);
    ``math.atan2`` otherwise."""
    if x > 0.0:
        z = y / x
        if -1e-2 < z < 1e-2:
            z2 = z * z
            return z * (1.0 - z2 * (1.0 / 3.0 - z2 * (0.2 - z2 / 7.0)))
    return math.atan2(y, x)


@njit(cache=True, inline="always")
def _tracker_pair(i, j, cols, hz, x, val, rot, u, ref, f):  # pragma: no cover - jit
    """Azimuth row ``i`` and elevation row ``j`` of the same station, target and set-up together
    (``v = R^T d`` and ``(dR_p)^T d`` once): models into ``f[0], f[1]``, Jacobians into ``val[i],
    val[j]`` (the derivatives of :func:`_row`). Each angle is its value at x̂ plus the angle from
    there (``ref[i]``: cos and sin of the value at x̂), a small angle (:func:`_small_atan2`)."""
    dx = x[cols[i, 3]] - x[cols[i, 0]]
    dy = x[cols[i, 4]] - x[cols[i, 1]]
    dz = x[cols[i, 5]] - x[cols[i, 2]] + hz
    v0 = rot[u, 0, 0, 0] * dx + rot[u, 0, 1, 0] * dy + rot[u, 0, 2, 0] * dz
    v1 = rot[u, 0, 0, 1] * dx + rot[u, 0, 1, 1] * dy + rot[u, 0, 2, 1] * dz
    v2 = rot[u, 0, 0, 2] * dx + rot[u, 0, 1, 2] * dy + rot[u, 0, 2, 2] * dz
    h2 = v0 * v0 + v1 * v1
    h = math.sqrt(h2)
    n2 = h2 + v2 * v2
    f[0] = ref[i, 2] + _small_atan2(ref[i, 0] * v1 - ref[i, 1] * v0, ref[i, 0] * v0 + ref[i, 1] * v1)
    f[1] = ref[j, 2] + _small_atan2(ref[j, 0] * v2 - ref[j, 1] * h, ref[j, 0] * h + ref[j, 1] * v2)
    a0, a1 = -v1 / h2, v0 / h2                      # d az / d v (third 0)
    b0, b1, b2 = -v2 * v0 / (h * n2), -v2 * v1 / (h * n2), h / n2
    for c in range(3):                              # d/dT = a R^T (the station: minus)
        ta = a0 * rot[u, 0, c, 0] + a1 * rot[u, 0, c, 1]
        tb = b0 * rot[u, 0, c, 0] + b1 * rot[u, 0, c, 1] + b2 * rot[u, 0, c, 2]
        val[i, 3 + c] = ta
        val[i, c] = -ta
        val[j, 3 + c] = tb
        val[j, c] = -tb
    for p in range(1, 4):                           # d/dp = a (dR_p)^T d
        w0 = rot[u, p, 0, 0] * dx + rot[u, p, 1, 0] * dy + rot[u, p, 2, 0] * dz
        w1 = rot[u, p, 0, 1] * dx + rot[u, p, 1, 1] * dy + rot[u, p, 2, 1] * dz
        w2 = rot[u, p, 0, 2] * dx + rot[u, p, 1, 2] * dy + rot[u, p, 2, 2] * dz
        val[i, 5 + p] = a0 * w0 + a1 * w1
        val[j, 5 + p] = b0 * w0 + b1 * w1 + b2 * w2


@njit(cache=True)
def _rotations(frames, x, rot):  # pragma: no cover - jit
    """Each set-up's frame (its omega, phi, kappa columns ``frames`` (U, 3)) at ``x``: ``rot`` (U, 4, 3, 3)."""
    for u in range(len(frames)):
        _rot(x[frames[u, 0]], x[frames[u, 1]], x[frames[u, 2]], rot[u])


@njit(cache=True)
def model_rows(code, cols, hz, comp, setup, frames, x, out_f, out_val, pair=None,
               ref=None):  # pragma: no cover - jit
    """Model and Jacobian values of every row at one ``x`` (for the tests); with ``pair`` (the
    program's, with its ``ref``), azimuth and elevation rows together as in the solver."""
    rot = np.empty((max(len(frames), 1), 4, 3, 3))
    f2 = np.empty(2)
    _rotations(frames, x, rot)
    for i in range(len(code)):
        if pair is not None and pair[i] != -1:
            if pair[i] >= 0:
                _tracker_pair(i, pair[i], cols, hz[i], x, out_val, rot, max(setup[i], 0), ref, f2)
                out_f[i] = f2[0]
                out_f[pair[i]] = f2[1]
            continue
        out_f[i] = _row(code[i], i, cols, hz[i], comp[i], x, out_val, rot, max(setup[i], 0))


@njit(cache=True, inline="always")
def _residual(e, angular):  # pragma: no cover - jit
    """``e`` wrapped to [-pi, pi) when ``angular`` (wrap_angle; unchanged inside)."""
    if angular and not -math.pi <= e < math.pi:
        e = (e + math.pi) % (2.0 * math.pi) - math.pi
    return e


@njit(cache=True, inline="always")
def _trial_gradient(obs, t, xt, code, cols, pair, ref, rcols, hz, comp, setup, frames, angular, wdiag,
                    p_ptr, p_idx, p_val, val, r, pr, rot, f2, g):  # pragma: no cover - jit
    """``g = J(x_t)^T P r`` with ``r = obs[t] - f(x_t)`` (angles wrapped); returns ``r^T P r``. A row
    with a diagonal weight (``wdiag[i] > 0``) takes ``(P r)_i = wdiag[i] r_i``, others their CSR row
    of ``P``; tracker rows paired by ``pair`` (:func:`_tracker_pair`). ``g`` is summed row by row, each
    slot added to its free column (``rcols``, -1 for none): per column the rows in order, the same
    sums as column by column; no index to follow to the slot's value (gathered column by column
    through a CSC index, the same sums cost 0.7-1.0 µs more a trial on the tracker network)."""
    _rotations(frames, xt, rot)
    for i in range(len(code)):
        k = pair[i]
        if k == -1:
            r[i] = _residual(obs[t, i] - _row(code[i], i, cols, hz[i], comp[i], xt, val, rot, max(setup[i], 0)),
                             angular[i])
        elif k >= 0:
            _tracker_pair(i, k, cols, hz[i], xt, val, rot, max(setup[i], 0), ref, f2)
            r[i] = _residual(obs[t, i] - f2[0], angular[i])
            r[k] = _residual(obs[t, k] - f2[1], angular[k])
    v = 0.0
    for i in range(len(code)):
        w = wdiag[i]
        if w > 0.0:
            s = w * r[i]
        else:
            s = 0.0
            for k in range(p_ptr[i], p_ptr[i + 1]):
                s += p_val[k] * r[p_idx[k]]
        pr[i] = s
        v += s * r[i]
    for a in range(len(g)):
        g[a] = 0.0
    for i in range(len(code)):
        s = pr[i]
        for j in range(9):
            a = rcols[i, j]
            if a >= 0:
                g[a] += val[i, j] * s
    return v


#: Trials per unit of the parallel loop (work arrays allocated once per unit; each trial's arithmetic
#: is its own, so the numbers never depend on it).
UNIT = 32


@njit(cache=True, parallel=True, nogil=True)
def _chord(obs, x, code, cols, pair, ref, rcols, hz, comp, setup, frames, angular, wdiag, p_ptr, p_idx, p_val, free, q,
           computed, kt, tol, max_iter, contraction, converged, iters, far, vtpv):  # pragma: no cover - jit
    """Chord steps ``x_t += Q J(x_t)^T P r`` of every trial ``t`` (in place, from ``x̂``), the rule of
    :func:`.propagate.solve`: the first ``K (l - f(x̂))`` (``kt`` = K^T (R, n_free), ``computed`` =
    f(x̂)); converged when the largest step, or its bound on the error left ``step c / (1 - c)``
    (c = this step / the one before), is below ``tol``; ``far`` when a step is larger than
    ``contraction`` times the one before, or after ``max_iter`` steps."""
    t_n, r_n = obs.shape
    nf = len(free)
    for unit in prange((t_n + UNIT - 1) // UNIT):
        val = np.zeros((r_n, 9))
        r = np.empty(r_n)
        pr = np.empty(r_n)
        g = np.empty(nf)
        dx = np.empty(nf)
        f2 = np.empty(2)
        rot = np.empty((max(len(frames), 1), 4, 3, 3))
        for t in range(unit * UNIT, min(t_n, unit * UNIT + UNIT)):
            xt = x[t]
            dx[:] = 0.0
            for i in range(r_n):              # the first step, linear in the noise: K (l - f(x̂))
                e = _residual(obs[t, i] - computed[i], angular[i])
                for a in range(nf):
                    dx[a] += kt[i, a] * e
            prev = 0.0
            for a in range(nf):
                xt[free[a]] += dx[a]
                s = abs(dx[a])
                if not s <= prev:
                    prev = s if s == s else np.inf
            iters[t] = 1
            for it in range(1, max_iter):
                v = _trial_gradient(obs, t, xt, code, cols, pair, ref, rcols, hz, comp, setup, frames, angular, wdiag,
                                    p_ptr, p_idx, p_val, val, r, pr, rot, f2, g)
                dx[:] = 0.0
                for b in range(nf):           # dx = Q g, by rows of the symmetric Q (independent sums: vectorised)
                    gb = g[b]
                    for a in range(nf):
                        dx[a] += q[b, a] * gb
                step = 0.0
                for a in range(nf):
                    v -= g[a] * dx[a]         # vTPv after the step, to second order: v - g^T Q g
                    xt[free[a]] += dx[a]
                    s = abs(dx[a])
                    if not s <= step:
                        step = s if s == s else np.inf
                iters[t] = it + 1
                c = step / prev               # the contraction of the last step
                if step < tol or (c <= contraction and step * c < tol * (1.0 - c)):
                    converged[t] = True
                    vtpv[t] = v
                    break
                if c > contraction:
                    far[t] = True
                    break
                prev = step
            if not converged[t]:
                far[t] = True


chord = boundary(_chord)


@njit(cache=True, parallel=True, nogil=True)
def _gradients(obs, x, code, cols, pair, ref, rcols, hz, comp, setup, frames, angular, wdiag, p_ptr, p_idx, p_val,
               g_out, v_out):  # pragma: no cover - jit
    """``g_out[t] = J(x_t)^T P r_t`` and ``v_out[t] = r_t^T P r_t`` of every trial ``t`` (``obs``,
    ``x`` (T, R), (T, n)): :func:`_trial_gradient` alone, for the block-structured solve of
    :mod:`.propagate_blocks` (its ``Q g`` is a Schur solve for a block of trials, in numpy)."""
    t_n, r_n = obs.shape
    for unit in prange((t_n + UNIT - 1) // UNIT):
        val = np.zeros((r_n, 9))
        r = np.empty(r_n)
        pr = np.empty(r_n)
        f2 = np.empty(2)
        rot = np.empty((max(len(frames), 1), 4, 3, 3))
        for t in range(unit * UNIT, min(t_n, unit * UNIT + UNIT)):
            v_out[t] = _trial_gradient(obs, t, x[t], code, cols, pair, ref, rcols, hz, comp, setup, frames, angular,
                                       wdiag, p_ptr, p_idx, p_val, val, r, pr, rot, f2, g_out[t])


gradients = boundary(_gradients)
