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

The solver assembles the normal equations from these blocks
(:mod:`multilat.network.adjust.solve.normal_equations`).
"""

from __future__ import annotations

import numpy as np

from multilat.network.model.parameter_layout import STATION_FIELDS, ParameterLayout

Q = len(STATION_FIELDS)  # global parameters per station: x, y, z, offset, scale
COSTS = ("distance", "squared")

__all__ = ["Q", "COSTS", "segment_sum", "range_m", "line_of_sight", "geometric_distance_m", "predicted_distance_m", "residuals",
           "residuals_and_jacobian", "dense_jacobian", "inv3"]


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
    """The residuals of :func:`residuals_and_jacobian` without the Jacobian (for the cost of a trial step;
    the solver's :func:`multilat.network.adjust.solve.system.trial_residuals` runs the compiled copy of
    the distance cost for large networks)."""
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
