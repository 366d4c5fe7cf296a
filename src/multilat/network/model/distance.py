"""The observation model of self-calibrating multilateration as pure array functions.

Model (seed 000 §4.3, with an optional scale per station)::

    d_k = (1 + k_i) |H_i - T_j| + o_i          i = station_index[k], j = target_index[k]

``H_i`` station (head) coordinates, ``T_j`` target coordinates, ``o_i`` additive instrument offset,
``k_i`` scale (dimensionless; 0 and fixed unless asked). All lengths in metres.

Two costs:

``"distance"`` (default)  residual ``r_k = d_k,obs - d_k(x)``, weighted by ``1/sigma_k**2``.
``"squared"``  the paper's eq. (6) generalised to offsets and scales:
    ``r_k = (d_k,obs - o_i)**2 - ((1 + k_i) |H_i - T_j|)**2``, unweighted (units m**2).

Parameter layout (used everywhere in :mod:`multilat.network`)::

    [station 0: x, y, z, offset, scale, station 1: ..., ..., target 0: x, y, z, target 1: ...]

i.e. ``Q = 5`` global parameters per station followed by ``3`` per target: the columns of
:meth:`multilat.network.model.parameter_layout.ParameterLayout.adjustment`, the one layout. Jacobians are
of the *model* ``f(x)`` (so ``r = obs - f`` for the distance cost, and ``r = g(obs, x) - f(x)``
generally; the solver uses ``J = d f / d x - d g / d x``).

The normal equations are reduced by the Schur complement over the 3x3 target blocks, so the
linear algebra is a dense ``5s x 5s`` system plus ``t`` 3x3 inverses: cost linear in the number of
targets. :func:`reduced_normal_equations` works in chunks of targets to bound memory.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.network.model.parameter_layout import STATION_FIELDS, ParameterLayout

Q = len(STATION_FIELDS)  # global parameters per station: x, y, z, offset, scale
COSTS = ("distance", "squared")

__all__ = ["Q", "COSTS", "segment_sum", "range_m", "line_of_sight", "geometric_distance_m", "predicted_distance_m", "residuals",
           "residuals_and_jacobian", "dense_jacobian", "target_slots", "slot_gain", "repeat_share",
           "ReducedSystem", "reduced_normal_equations", "back_substitute", "inv3"]


def segment_sum(index, values, n):
    """``out[i] = sum of values[k] over k with index[k] == i``; values (m, ...) -> (n, ...).

    (A fast ``np.add.at``: bincount per column for few columns or rows, a sparse product otherwise.)
    """
    values = np.asarray(values, dtype=float)
    m = values.shape[0]
    flat = values.reshape(m, -1)
    if flat.shape[1] <= 8 or m <= 4096:    # small: bincount is faster and scipy.sparse stays unloaded
        out = np.stack([np.bincount(index, weights=flat[:, c], minlength=n) for c in range(flat.shape[1])],
                       axis=1)
    else:
        from scipy.sparse import csr_matrix

        S = csr_matrix((np.ones(m), (index, np.arange(m))), shape=(n, m))
        out = np.asarray(S @ flat)
    return out.reshape((n,) + values.shape[1:])


def range_m(diff_m):
    """``|H - T|`` (...) of differences ``diff_m`` (..., 3), as :func:`line_of_sight` (without ``u``)."""
    return np.sqrt(np.einsum("...i,...i->...", diff_m, diff_m))


def line_of_sight(diff_m, *, floor_m=None):
    """Ranges and unit vectors of station-minus-target differences: the distance model's Jacobian.

    ``diff_m = H - T`` (..., 3), any leading axes (observations, trials). Returns ``rho = |H - T|``
    (...) and ``u = (H - T) / rho`` (..., 3): one distance's Jacobian row is ``[(1 + k) u, 1, rho]`` on
    its station's ``x, y, z, offset, scale`` and ``-(1 + k) u`` on its target. The one numpy copy
    (``tests/test_each_concept_once.py``); each compiled kernel keeps its own inline one. ``floor_m``:
    ``u`` divides by ``floor_m`` where ``rho`` is 0 (the starting-value solvers; ``rho`` is returned as
    it is).
    """
    rho = range_m(diff_m)
    den = rho if floor_m is None else np.where(rho > 0, rho, floor_m)
    return rho, diff_m / den[..., None]


def geometric_distance_m(station_xyz_m, target_xyz_m, station_index, target_index):
    """Euclidean distances ``|H_i - T_j|`` per observation.

    Parameters
    ----------
    station_xyz_m : ndarray (s, 3)
    target_xyz_m : ndarray (t, 3)
    station_index, target_index : ndarray of int (m,)

    Returns
    -------
    rho_m : ndarray (m,)
    diff_m : ndarray (m, 3), ``H_i - T_j``
    """
    diff = station_xyz_m[station_index] - target_xyz_m[target_index]
    return range_m(diff), diff


def predicted_distance_m(station_xyz_m, target_xyz_m, offset_m, scale, station_index, target_index):
    """Model distances ``(1 + k_i) |H_i - T_j| + o_i``, shape (m,), metres."""
    rho, _ = geometric_distance_m(station_xyz_m, target_xyz_m, station_index, target_index)
    return (1.0 + scale[station_index]) * rho + offset_m[station_index]


def _residual(distance_m, rho, k1, o, cost):
    """``observed - computed`` from the geometric distances ``rho`` and each observation's ``1 + k``
    and offset ``o`` (m, or m**2 for the squared cost)."""
    if cost == "distance":
        return distance_m - (k1 * rho + o)
    if cost == "squared":
        a = distance_m - o
        c = k1 * rho
        return a * a - c * c
    raise ValueError(f"cost must be one of {COSTS}, got {cost!r}")


def residuals(distance_m, station_xyz_m, target_xyz_m, offset_m, scale, station_index, target_index, *,
              cost="distance"):
    """The residuals of :func:`residuals_and_jacobian` without the Jacobian (for the cost of a trial step);
    compiled for large networks (the same operations, bit for bit: ``tests/test_fast_output.py``)."""
    if cost == "distance":
        from multilat.network.model.covariance import compiled_for     # lazy: covariance imports this module

        if compiled_for(len(station_index)):
            from multilat.network.model import _sparse_kernels as K

            out = np.empty(len(station_index))
            K.distance_residuals(np.ascontiguousarray(station_xyz_m, float), np.ascontiguousarray(target_xyz_m, float),
                                 np.asarray(offset_m, float), np.asarray(scale, float), station_index,
                                 target_index, np.asarray(distance_m, float), out)
            return out
    rho, _ = geometric_distance_m(station_xyz_m, target_xyz_m, station_index, target_index)
    return _residual(distance_m, rho, 1.0 + scale[station_index], offset_m[station_index], cost)


def residuals_and_jacobian(distance_m, station_xyz_m, target_xyz_m, offset_m, scale,
                           station_index, target_index, *, cost="distance"):
    """Residuals and the analytic Jacobian blocks of each observation.

    Parameters
    ----------
    distance_m : ndarray (m,)  observed distances, metres
    station_xyz_m (s, 3), target_xyz_m (t, 3), offset_m (s,), scale (s,) : current parameters
    station_index, target_index : ndarray of int (m,)
    cost : "distance" or "squared"

    Returns
    -------
    r : ndarray (m,)
        Residual ``observed - computed`` (m, or m**2 for ``"squared"``).
    J_station : ndarray (m, 5)
        Derivative of the *computed* side minus the observed side with respect to the station's
        ``x, y, z, offset, scale`` (so a Gauss-Newton step solves ``J dx = r``).
    J_target : ndarray (m, 3)
        Same with respect to the target's ``x, y, z``.
    """
    rho, u = line_of_sight(station_xyz_m[station_index] - target_xyz_m[target_index])
    k1 = 1.0 + scale[station_index]
    o = offset_m[station_index]
    m = rho.shape[0]
    Js = np.empty((m, Q))
    r = _residual(distance_m, rho, k1, o, cost)
    if cost == "distance":
        Js[:, :3] = k1[:, None] * u
        Js[:, 3] = 1.0
        Js[:, 4] = rho
        Jt = -Js[:, :3]
    elif cost == "squared":
        a = distance_m - o
        g = 2.0 * k1 * k1 * rho
        Js[:, :3] = g[:, None] * u
        Js[:, 3] = 2.0 * a          # d/do of (c^2 - a^2)
        Js[:, 4] = 2.0 * k1 * rho * rho
        Jt = -Js[:, :3]
    else:
        raise ValueError(f"cost must be one of {COSTS}, got {cost!r}")
    return r, Js, np.ascontiguousarray(Jt)


def dense_jacobian(J_station, J_target, station_index, target_index, n_stations, n_targets):
    """The full (m, 5s + 3t) Jacobian from its blocks (for small problems and tests)."""
    m = J_station.shape[0]
    lay = ParameterLayout.adjustment(n_stations, n_targets)
    J = np.zeros((m, lay.n))
    rows = np.arange(m)[:, None]
    J[rows, lay.station_block()[station_index]] = J_station
    J[rows, lay.target_block()[target_index]] = J_target
    return J


def target_slots(station_index, target_index, n_stations, n_targets):
    """Dense ``(t, s)`` table of observation indices (-1 where a target is not seen by a station).

    With repeated readings of a pair the table holds one of them; :func:`slot_gain` scales its
    whitened row so that it stands for all of them.
    """
    slots = np.full((n_targets, n_stations), -1, dtype=np.intp)
    slots[target_index, station_index] = np.arange(station_index.shape[0])
    return slots


def slot_gain(slots, station_index, target_index, *rows):
    """Per-observation factors ``g`` (m,) for the pair table of :func:`target_slots`, or None when
    every pair has one reading.

    Repeated readings of one (station, target) pair have proportional whitened Jacobian rows (same
    geometry, weights ``1/sigma_k**2``), so their sum of outer products is that of the table's
    reading scaled by ``g**2 = sum_k |row_k|**2 / |row_slot|**2``; ``rows`` are the whitened blocks
    (e.g. ``Js_w, Jt_w``) whose concatenation is the row.
    """
    m = station_index.shape[0]
    n2 = sum(np.einsum("mi,mi->m", r, r) for r in rows)
    key = target_index.astype(np.int64) * slots.shape[1] + station_index
    flat = slots.ravel()
    if np.count_nonzero(flat >= 0) == m:
        return None
    tot = np.bincount(key, weights=n2, minlength=flat.size)
    g = np.ones(m)
    own = n2[flat[flat >= 0]]
    ok = own > 0
    idx = flat[flat >= 0]
    g[idx[ok]] = np.sqrt(tot[flat >= 0][ok] / own[ok])
    return g


def repeat_share(slots, station_index, target_index, *rows):
    """Share ``|row_k|**2 / sum over the pair's readings`` (m,) of each reading (1 without repeats)."""
    n2 = sum(np.einsum("mi,mi->m", r, r) for r in rows)
    key = target_index.astype(np.int64) * slots.shape[1] + station_index
    tot = np.bincount(key, weights=n2, minlength=slots.size)[key]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(tot > 0, n2 / np.where(tot > 0, tot, 1.0), 1.0)


def inv3(A):
    """Inverses of stacked symmetric 3x3 matrices (..., 3, 3) by the adjugate (closed form).

    Singular blocks give inf/nan; callers check :func:`numpy.linalg.eigvalsh` beforehand.
    """
    a, b, c = A[..., 0, 0], A[..., 0, 1], A[..., 0, 2]
    d, e, f = A[..., 1, 1], A[..., 1, 2], A[..., 2, 2]
    c00 = d * f - e * e
    c01 = c * e - b * f
    c02 = b * e - c * d
    c11 = a * f - c * c
    c12 = b * c - a * e
    c22 = a * d - b * b
    det = a * c00 + b * c01 + c * c02
    out = np.empty_like(A)
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 2] = c00, c01, c02
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2] = c01, c11, c12
    out[..., 2, 0], out[..., 2, 1], out[..., 2, 2] = c02, c12, c22
    with np.errstate(divide="ignore", invalid="ignore"):
        return out / det[..., None, None]


@dataclass(frozen=True)
class ReducedSystem:
    """Normal equations ``N dx = b`` reduced to the station/offset/scale parameters.

    Attributes
    ----------
    N : ndarray (5s, 5s)   reduced normal matrix ``N_gg - N_gt N_tt^-1 N_tg`` (fixed columns zero)
    b : ndarray (5s,)      reduced right-hand side
    Ntt : ndarray (t, 3, 3)  target blocks of the (damped) normal matrix
    Ntt_inv : ndarray (t, 3, 3)  their inverses (zero for fixed targets)
    bt : ndarray (t, 3)    target right-hand sides
    layout : ParameterLayout  the columns of ``N`` and ``b`` (the adjustment's station system)
    """

    N: np.ndarray
    b: np.ndarray
    Ntt: np.ndarray
    Ntt_inv: np.ndarray
    bt: np.ndarray
    layout: ParameterLayout = None


def reduced_normal_equations(r_w, Js_w, Jt_w, station_index, target_index, n_stations, n_targets, *,
                             target_free=None, damping=0.0, chunk_targets=20000):
    """Assemble the Schur-reduced normal equations from whitened Jacobian blocks.

    Parameters
    ----------
    r_w : ndarray (m,)          whitened residuals ``r_k / sigma_k``
    Js_w : ndarray (m, 5)       whitened station blocks (columns of fixed parameters set to zero)
    Jt_w : ndarray (m, 3)       whitened target blocks
    station_index, target_index : ndarray of int (m,)
    n_stations, n_targets : int
    target_free : ndarray of bool (t,), optional
        False for targets held fixed (control points): their blocks are dropped.
    damping : float
        Levenberg-Marquardt factor: every diagonal element ``N_ii`` becomes ``(1 + damping) N_ii``.
    chunk_targets : int
        Targets per chunk in the coupling term (memory ``chunk * s**2`` floats).

    Returns
    -------
    ReducedSystem
    """
    s, t = n_stations, n_targets
    if target_free is None:
        target_free = np.ones(t, dtype=bool)
    Jt_w = Jt_w * target_free[target_index][:, None]
    # target blocks and rhs
    Ntt = segment_sum(target_index, Jt_w[:, :, None] * Jt_w[:, None, :], t)
    bt = segment_sum(target_index, Jt_w * r_w[:, None], t)
    if damping:
        idx = np.arange(3)
        Ntt[:, idx, idx] *= 1.0 + damping
    Minv = np.zeros_like(Ntt)
    Minv[target_free] = inv3(Ntt[target_free])
    # station blocks (block diagonal in stations) and rhs
    Ngg = segment_sum(station_index, Js_w[:, :, None] * Js_w[:, None, :], s)
    if damping:
        idx = np.arange(Q)
        Ngg[:, idx, idx] *= 1.0 + damping
    bg = segment_sum(station_index, Js_w * r_w[:, None], s)
    # rhs reduction: b_g - sum_j N_gj M_j b_j
    y = np.einsum("tij,tj->ti", Minv, bt)                      # (t, 3)
    e = np.einsum("mi,mi->m", Jt_w, y[target_index])           # (m,)
    bg -= segment_sum(station_index, Js_w * e[:, None], s)
    # coupling: sum_j N_gj M_j N_jg in station-slot form
    slots = target_slots(station_index, target_index, s, t)
    gain = slot_gain(slots, station_index, target_index, Js_w, Jt_w)     # repeated readings
    R = np.zeros((s, Q, s, Q))
    for lo in range(0, t, chunk_targets):
        sl = slots[lo:lo + chunk_targets]                       # (c, s)
        seen = sl >= 0
        ix = np.where(seen, sl, 0)
        sc = seen if gain is None else seen * gain[ix]
        A = Js_w[ix] * sc[..., None]                            # (c, s, Q)
        B = Jt_w[ix] * sc[..., None]                            # (c, s, 3)
        MB = np.einsum("cij,csj->csi", Minv[lo:lo + chunk_targets], B)
        C = np.einsum("cai,cbi->cab", B, MB)                    # (c, s, s)
        R += np.einsum("caq,cab,cbr->aqbr", A, C, A, optimize=True)
    lay = ParameterLayout.adjustment(s)
    cols = lay.station_block()                                  # (s, Q)
    N = np.zeros((cols.size, cols.size))
    N[cols.reshape(-1, 1), cols.reshape(1, -1)] = -R.reshape(cols.size, cols.size)
    for i in range(s):
        N[np.ix_(cols[i], cols[i])] += Ngg[i]
    b = np.zeros(cols.size)
    b[cols] = bg
    return ReducedSystem(N=N, b=b, Ntt=Ntt, Ntt_inv=Minv, bt=bt, layout=lay)


def back_substitute(system: ReducedSystem, dg, Js_w, Jt_w, station_index, target_index):
    """Target steps ``dt_j = M_j (b_j - N_jg dg)`` from the global step ``dg`` (5s,) -> (t, 3)."""
    n_t = system.bt.shape[0]
    cols = system.layout.station_block()
    s_k = np.einsum("mq,mq->m", Js_w, dg[cols][station_index])
    ng = segment_sum(target_index, Jt_w * s_k[:, None], n_t)
    return np.einsum("tij,tj->ti", system.Ntt_inv, system.bt - ng)
