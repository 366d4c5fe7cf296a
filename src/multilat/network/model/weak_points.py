"""A point determined only weakly by its observations: one rule for both adjustments.

Distances fix a point along a direction ``v`` to first order through the spread of its lines of
sight along ``v``: for sights in one plane, through the point's height ``h`` above it. When ``h`` is
small the linearised standard uncertainty ``σ_v`` along ``v`` grows as ``σ L / (h sqrt(k))`` and the
distances' second-order term takes over: below ``h ≈ K_PLANE σ_v`` (about ``sqrt(K_PLANE σ L)``)
the point's position along ``v`` is not determined by its distances, whatever its covariance says.

:func:`weak_points` decides it from what both adjustments have:

* the point's distance sights: the vectors ``T - H_k`` from each station to it, and their σ;
* the information of the point's other observations (angles from a tracker, weighted control,
  levelling, directions, ...): a 3x3 normal block per point (zero for a distance-only point).

Per point: ``N = N_d + N_o`` (``N_d = sum u_k u_k^T / σ_k^2``, ``u_k`` the unit sights), its weakest
direction ``v`` (smallest eigenvalue λ) with ``σ_v = λ^-1/2``, and the RMS spread
``h = rms((T - H_k).v)``. The point is **weak** when

1. its sights are coplanar within its uncertainty, ``h < K_PLANE σ_v`` (or ``N`` is numerically
   singular), **and**
2. its distances carry at least as much of the information along ``v`` as everything else,
   ``vᵀ N_d v >= vᵀ N_o v``: a point that angles, control or levelling fix along ``v`` is
   determined linearly by them, whatever the spread of its sights.

For a distance-only point (``N_o = 0``) condition 2 always holds and the rule is the distance
path's (issue 25) unchanged. The distance path
(:func:`multilat.network.adjust.distance.exclusion.undetermined_targets`) and the general layer
(:mod:`multilat.network.adjust.general.weak`) both call it and leave a weak point out, named with
:func:`weak_reason` (the same words on both paths).
"""

from __future__ import annotations

import numpy as np

from multilat.network.model.distance import line_of_sight, range_m

__all__ = ["K_PLANE", "COPLANAR_REASON", "weak_points", "weak_reason"]

#: a point set is coplanar within its uncertainty when its RMS out-of-plane spread is below
#: K_PLANE times the RMS standard uncertainty of its points along the plane's normal
K_PLANE = 10.0

#: the reason of a weak point whose normal block is numerically singular (rank < 3)
COPLANAR_REASON = "is undetermined: its lines of sight are coplanar (its 3x3 normal block is singular)"


def weak_reason(spread_m: float, sigma_m: float, singular: bool) -> str:
    """The one phrase naming a weak point (after ``target 'T' left out: `` / ``point 'T' left out: ``)."""
    if singular:
        return COPLANAR_REASON
    return (f"is undetermined: its lines of sight are coplanar within their uncertainty "
            f"(spread {spread_m * 1e3:.3g} mm along its weakest direction, {spread_m / sigma_m:.2g} times "
            f"its standard uncertainty {sigma_m * 1e3:.2g} mm there; {K_PLANE:g} times is needed)")


def weak_points(point_index, sight_m, sigma_m, n_points: int, *, tested, other=None) -> dict:
    """The weak points (module docstring): {point index: reason}.

    Parameters
    ----------
    point_index : (m,) int   the point each distance sight ends on
    sight_m : (m, 3)   the sight vectors ``T - H`` (station to point), m; non-finite rows ignored
    sigma_m : (m,)   the distances' σ, m; non-finite or non-positive rows ignored
    n_points : int
    tested : (n_points,) bool   the points to test (free, with finite coordinates)
    other : (n_points, 3, 3), optional   the whitened normal block of each point's other
        observations, m⁻²; None: distances only

    Returns
    -------
    dict  point index -> :func:`weak_reason`, in index order
    """
    pi = np.asarray(point_index, int)
    d = np.asarray(sight_m, float)
    sig = np.asarray(sigma_m, float)
    L = range_m(d)
    ok = np.isfinite(L) & (L > 0) & np.isfinite(sig) & (sig > 0)
    _, u = line_of_sight(np.where(ok[:, None], d, 0.0), floor_m=1.0)     # 0 on the rows left out
    w = np.where(ok, 1.0 / np.where(ok, sig, 1.0) ** 2, 0.0)
    t = int(n_points)
    nd = np.zeros((t, 9))
    for k in range(9):          # one column at a time: no (m, 9) products (110 MiB at 1.6 M distances)
        nd[:, k] = np.bincount(pi, weights=w * u[:, k // 3] * u[:, k % 3], minlength=t)
    nd = nd.reshape(t, 3, 3)
    n_all = nd if other is None else nd + np.asarray(other, float)
    ev, V = np.linalg.eigh(n_all)
    v = V[:, :, 0]
    along = np.einsum("mi,mi->m", np.where(ok[:, None], d, 0.0), v[pi])
    n_ok = np.bincount(pi[ok], minlength=t)
    h = np.sqrt(np.bincount(pi, weights=along ** 2, minlength=t) / np.maximum(n_ok, 1))
    singular = ~(ev[:, 0] > 1e-12 * ev[:, 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        sv = 1.0 / np.sqrt(ev[:, 0])
    weak = np.asarray(tested, bool) & (n_ok > 0) & (singular | (h < K_PLANE * sv))
    if other is not None:       # condition 2: the distances carry the information along v
        share_d = np.einsum("pi,pij,pj->p", v, nd, v)
        share_o = np.einsum("pi,pij,pj->p", v, np.asarray(other, float), v)
        weak &= share_o <= share_d
    return {int(j): weak_reason(float(h[j]), float(sv[j]), bool(singular[j])) for j in np.flatnonzero(weak)}
