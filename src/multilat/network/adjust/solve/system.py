"""What a back end hands to the solver loop: the reduced normal equations at one point."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from multilat.network.model.distance import Q, residuals, residuals_and_jacobian
from multilat.network.model.problem import Params, Problem

__all__ = ["Assembly", "whitened", "trial_residuals", "weighted_cost"]


@dataclass(frozen=True, eq=False)
class Assembly:
    """Reduced normal equations ``N dg = b`` at a point (targets eliminated by the Schur complement).

    N : (5s, 5s)  (rows/columns of held parameters are zero)
    b : (5s,)
    Ntt : (t, 3, 3)  target blocks (damped as assembled); Ntt_inv their inverses (zero if held)
    vtpv : float  weighted sum of squared residuals at the point
    back_substitute : callable dg (5s,) -> dt (t, 3)
    """

    N: np.ndarray
    b: np.ndarray
    Ntt: np.ndarray
    Ntt_inv: np.ndarray
    vtpv: float
    back_substitute: Callable[[np.ndarray], np.ndarray]
    coupled: object = None     # the coupled path's target elimination (solve.coupled.CoupledTargets)
    back_orientation: Callable[[np.ndarray], np.ndarray] | None = None   # dg -> orientation step (angles)


def whitened(problem: Problem, p: Params):
    """Whitened residuals (m,) and Jacobian blocks (m, 5), (m, 3) with held columns zeroed (one
    compiled pass for large networks and the distance cost: the same numbers, tested)."""
    o = problem.obs
    if problem.cost == "distance":
        from multilat.network.adjust.covariance import compiled_for

        if compiled_for(o.n_obs):
            from multilat.network.adjust.solve import _sparse_kernels as K

            m = o.n_obs
            r_w, Js_w, Jt_w = np.empty(m), np.empty((m, Q)), np.empty((m, 3))
            c = np.ascontiguousarray
            K.whitened_distances(c(p.station_xyz_m, float), c(p.target_xyz_m, float), c(p.offset_m, float),
                                 c(p.scale, float), o.station_index, o.target_index, c(o.distance_m, float),
                                 c(o.sigma_m, float), c(problem.station_free), c(problem.target_free),
                                 r_w, Js_w, Jt_w)
            return r_w, Js_w, Jt_w
    r, Js, Jt = residuals_and_jacobian(o.distance_m, p.station_xyz_m, p.target_xyz_m, p.offset_m,
                                       p.scale, o.station_index, o.target_index, cost=problem.cost)
    w = problem.weight_sqrt
    Js_w = Js * w[:, None] * problem.station_free[o.station_index]
    Jt_w = Jt * w[:, None] * problem.target_free[o.target_index][:, None]
    return r * w, Js_w, Jt_w


def trial_residuals(distance_m, station_xyz_m, target_xyz_m, offset_m, scale, station_index, target_index, *,
                    cost="distance"):
    """:func:`multilat.network.model.distance.residuals` (the cost of a trial step), compiled for large
    networks and the distance cost (the same operations, bit for bit: ``tests/test_fast_output.py``)."""
    if cost == "distance":
        from multilat.network.adjust.covariance import compiled_for

        if compiled_for(len(station_index)):
            from multilat.network.adjust.solve import _sparse_kernels as K

            out = np.empty(len(station_index))
            K.distance_residuals(np.ascontiguousarray(station_xyz_m, float), np.ascontiguousarray(target_xyz_m, float),
                                 np.asarray(offset_m, float), np.asarray(scale, float), station_index,
                                 target_index, np.asarray(distance_m, float), out)
            return out
    return residuals(distance_m, station_xyz_m, target_xyz_m, offset_m, scale, station_index, target_index,
                     cost=cost)


def weighted_cost(problem: Problem, p: Params) -> float:
    """``sum (w r)^2`` at ``p`` (inf when not finite)."""
    o = problem.obs
    r = trial_residuals(o.distance_m, p.station_xyz_m, p.target_xyz_m, p.offset_m, p.scale,
                  o.station_index, o.target_index, cost=problem.cost)
    v = float(np.sum((r * problem.weight_sqrt) ** 2))
    if problem.couplings is not None:
        from multilat.network.model.couplings import flatten_params

        c = problem.couplings
        v += float(np.sum((c.residuals(flatten_params(p)) / c.sigma_m) ** 2))
    if problem.angles is not None:
        a = problem.angles
        v += float(np.sum((a.residuals(p.station_xyz_m, p.target_xyz_m, p.orientation_rad) / a.sigma_rad) ** 2))
    return v if np.isfinite(v) else np.inf
