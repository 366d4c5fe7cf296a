"""Points placed from oriented set-ups and from observed vectors: polar points, intersection,
coordinate differences and observed coordinates.

* **Polar point**: one reading with its vector ``v`` from an oriented set-up on a placed point:
  ``P_j = P_i + dz e_z + R v`` (direction or tracker azimuth/elevation with a slope distance and a
  zenith angle or elevation; a horizontal distance with a height difference).
* **Polar point on a height**: a horizontal reading and a slope distance from an oriented levelled
  set-up, the point's height given or levelled from a placed point (a height difference):
  ``hz = sqrt(s^2 - up^2)`` with ``up`` the rise from instrument to reflector.
* **Intersection**: sights to ``j`` from two or more oriented set-ups on placed points (different
  points): a sight with its elevation (zenith angle, tracker elevation) is a ray, ``j`` on it; a
  direction alone is a vertical plane; a height difference from a placed point is a horizontal
  plane. ``P_j`` is the least-squares point of these lines and planes (each line two equations
  ``(I - w w^T)(P - a) = 0``). Rays closer to parallel than :data:`WEAK_RAD` are flagged (a note);
  a singular system places nothing.
* **Vector**: a complete coordinate difference from a placed point, or the point's three observed
  coordinates.
"""

from __future__ import annotations

import numpy as np

__all__ = ["polar", "polar_on_height", "intersect", "by_vector", "WEAK_RAD", "SINGULAR"]

#: intersection angle below which the rays meeting at a point are flagged as near-parallel (1 degree)
WEAK_RAD = np.radians(1.0)
#: relative smallest singular value of an intersection's equations below which nothing is placed
SINGULAR = 1e-9

_EZ = np.array([0.0, 0.0, 1.0])


def polar(setup, R, xyz, known) -> int:
    """Places the unplaced targets of an oriented set-up on a placed point that have a vector;
    the number placed."""
    new = ~known[setup.to] & np.all(np.isfinite(setup.v), 1)
    n = 0
    for k in np.flatnonzero(new):
        j = setup.to[k]
        if not known[j]:                                  # a point read twice: the first reading
            xyz[j] = xyz[setup.station] + setup.dz[k] * _EZ + R @ setup.v[k]
            known[j] = True
            n += 1
    return n


def polar_on_height(setups, frames, reads, rises, xyz, known, j):
    """P_j from a horizontal reading and a slope distance of an oriented levelled set-up on a placed
    point and the height of ``j`` (given, or from a height difference off a placed point); or None."""
    z = xyz[j, 2] if np.isfinite(xyz[j, 2]) else next((xyz[p, 2] + dh for p, dh in rises if known[p]), None)
    if z is None:
        return None
    for s, k in reads:
        su, R = setups[s], frames.get(s)
        if R is None or not su.levelled or not known[su.station] or not np.isfinite(su.s[k]):
            continue
        up = z - xyz[su.station, 2] - su.sdz[k]
        if su.s[k] > abs(up):
            hz = np.sqrt(su.s[k] ** 2 - up ** 2)
            return np.array([*(xyz[su.station, :2] + hz * (R[:2, :2] @ [np.cos(su.t[k]), np.sin(su.t[k])])), z])
    return None


def sight_equations(setups, frames, reads, xyz, known):
    """Equations ``A P = b`` of the sights ``reads`` [(set-up, reading)] to one point from oriented
    set-ups on placed points, the stations they come from and their directions (a plane's: its
    horizontal line)."""
    A, b, st, dirs = [], [], [], []
    for s, k in reads:
        su, R = setups[s], frames.get(s)
        if R is None or not known[su.station]:
            continue
        a = xyz[su.station] + su.dz[k] * _EZ
        u = su.u[k]
        if np.all(np.isfinite(u)):
            w = R @ u
            P = np.eye(3) - np.outer(w, w)
            A.append(P)
            b.append(P @ a)
            dirs.append(w)
        else:                                         # a horizontal reading alone: a vertical plane
            n = R @ np.array([-np.sin(su.t[k]), np.cos(su.t[k]), 0.0])
            A.append(n[None])
            b.append([n @ a])
            dirs.append(np.array([n[1], -n[0], 0.0]))
        st.append(su.station)
    return A, b, st, dirs


def intersect(setups, frames, reads, rises, xyz, known):
    """(P, the largest angle between its sights from different stations, radians) of one point by
    intersection of its sights ``reads``, with its rises [(from point, dh)] from height
    differences; or None."""
    A, b, st, dirs = sight_equations(setups, frames, reads, xyz, known)
    if len(set(st)) < 2:
        return None
    for p, dh in rises:
        if known[p]:
            A.append(_EZ[None])
            b.append([xyz[p, 2] + dh])
    A, b = np.vstack(A), np.concatenate([np.atleast_1d(x) for x in b])
    sv = np.linalg.svd(A, compute_uv=False)
    if sv.size < 3 or sv[2] <= SINGULAR * sv[0]:
        return None
    p, *_ = np.linalg.lstsq(A, b, rcond=None)
    first = {}                                            # one direction per station
    for s, w in zip(st, dirs):
        first.setdefault(s, w / np.linalg.norm(w))
    u = np.array(list(first.values()))
    cos = np.clip(np.abs(u @ u.T), 0.0, 1.0)
    best = float(np.arccos(cos[np.triu_indices(len(u), 1)]).max())
    return p, best


def by_vector(vec, coord, xyz, known) -> int:
    """Places points from complete observed coordinates and from vectors off placed points."""
    n = 0
    for p, c in coord.items():
        if not known[p]:
            xyz[p], known[p] = c, True
            n += 1
    grew = True
    while grew:
        grew = False
        for (i, j), d in vec.items():
            if known[i] and not known[j]:
                xyz[j], known[j] = xyz[i] + d, True
                n += 1
                grew = True
    return n
