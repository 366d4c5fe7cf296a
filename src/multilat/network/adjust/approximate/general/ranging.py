"""Points placed from slope distances to placed points: multilateration and trilateration.

* **Multilateration**: four or more placed ends not near one plane: :func:`multilat.network.adjust.approximate.initial.
  multilaterate` (algebraic solution, then Gauss-Newton on the distances).
* **Trilateration**: three placed ends (or more, near one plane): the distances give two mirror
  positions, one each side of the ends' plane (in the plane's frame: the 2D position from the
  differences of squared distances, the height off the plane ``±sqrt(d^2 - |q - a|^2)``), each
  refined on all the distances (:func:`multilat.network.adjust.approximate.large.refit_point`). Another observation of
  the point picks the side (:func:`side_misfit`: its sights from placed set-ups, elevations of
  levelled ones, height differences); without one it is not placed here.

Instrument constants are ignored (approximations); heights are applied as the kinds do.
"""

from __future__ import annotations

import numpy as np

from multilat.network.adjust.approximate.general.place import sight_equations
from multilat.network.adjust.approximate.initial import multilaterate
from multilat.network.adjust.approximate.large import refit_point

__all__ = ["ends", "candidates", "side_misfit", "COPLANAR"]

#: smallest / largest singular value of the centred ends below which they count as one plane
COPLANAR = 0.05

_EZ = np.array([0.0, 0.0, 1.0])


def ends(dist, rows, j, xyz, known):
    """(anchors (k, 3), distances (k,), distinct placed ends) of point ``j``'s slope distances
    ``rows`` (indices into ``dist``) whose other end is placed; the anchors carry both heights, so
    that ``d = |P_j - anchor|``."""
    r = dist[rows]
    f, t = r[:, 0].astype(int), r[:, 1].astype(int)
    other = np.where(f == j, t, f)
    ok = known[other]
    r, other, f = r[ok], other[ok], f[ok]
    own = np.where(f == j, r[:, 3], r[:, 4])
    far = np.where(f == j, r[:, 4], r[:, 3])
    return xyz[other] + (far - own)[:, None] * _EZ, r[:, 2], len(set(other.tolist()))


def candidates(anchors, d, n_ends):
    """Positions that fit the distances: one (multilateration), two mirror ones (trilateration) or none."""
    if n_ends < 3:
        return []
    c = anchors.mean(0)
    _, sv, vt = np.linalg.svd(anchors - c, full_matrices=False)
    if sv[1] <= 1e-9 * sv[0]:                             # ends on one line: a circle of positions
        return []
    if n_ends >= 4 and sv[2] > COPLANAR * sv[0]:
        p, _ = multilaterate(anchors, d)
        return [p] if np.all(np.isfinite(p)) else []
    e, n = vt[:2], vt[2]
    a2 = (anchors - c) @ e.T                              # the ends in their plane
    A = np.column_stack([np.ones(len(d)), -2 * a2])
    y = d ** 2 - np.einsum("ij,ij->i", a2, a2)
    sol, *_ = np.linalg.lstsq(A, y, rcond=None)
    q = sol[1:]
    h = np.sqrt(max(float(sol[0] - q @ q), 0.0))
    w = np.ones(len(d))
    return [refit_point(c + e.T @ q + sgn * h * n, anchors, d, w)[0] for sgn in (1.0, -1.0)]


def side_misfit(p, sights, frames, reads, own, rises, xyz, known):
    """Misfit (metres, root sum of squares) of a position ``p`` of a point to its observations
    besides distances, and how many there were: its sights ``reads`` [(set-up, reading)] from
    oriented set-ups on placed points (distance to the ray or plane), elevations read by levelled
    set-ups from or to placed points (times the range; ``own``: the set-ups on the point), height
    differences ``rises`` [(placed point, dh)]."""
    A, b, _, _ = sight_equations(sights.setups, frames, reads, xyz, known)
    res = [np.concatenate([np.atleast_2d(a) @ p - np.atleast_1d(bb) for a, bb in zip(A, b)])] if A else []
    for s, k in reads:                                    # elevations of levelled set-ups, not oriented
        su = sights.setups[s]
        if s not in frames and su.levelled and known[su.station] and np.isfinite(su.el[k]):
            res.append([_elevation_misfit(p - xyz[su.station] - su.dz[k] * _EZ, su.el[k])])
    for su in (sights.setups[s] for s in own):
        if su.levelled:
            ok = known[su.to] & np.isfinite(su.el)
            for k in np.flatnonzero(ok):
                res.append([_elevation_misfit(xyz[su.to[k]] - p - su.dz[k] * _EZ, su.el[k])])
    for o, dh in rises:
        if known[o]:
            res.append([p[2] - xyz[o, 2] - dh])
    if not res:
        return np.nan, 0
    r = np.concatenate([np.atleast_1d(x) for x in res])
    return float(np.sqrt(r @ r)), len(r)


def _elevation_misfit(d, el):
    rng = np.linalg.norm(d)
    return (np.arctan2(d[2], np.hypot(d[0], d[1])) - el) * rng
