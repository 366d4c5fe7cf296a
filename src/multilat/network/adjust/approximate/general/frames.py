"""Frames of set-ups: orientation on a placed point, and free-station resection.

* **Orientation** of a set-up whose point is placed, from its readings to placed points: a levelled
  one (a direction set, a levelled tracker, a horizontal angle) by the circular mean of
  ``bearing - t`` (one placed target suffices); an unlevelled tracker by the rotation that best maps
  its sight rays onto the world's (Kabsch, :func:`multilat.network.model.datum.rigid_fit`; two placed
  targets in different directions).
* **Resection** of a set-up whose point is not placed: the rigid fit of its reading vectors ``v`` onto
  the placed targets, about z for a levelled set-up (two placed targets with distance and height:
  2D resection from directions and distances, its height the mean of the targets' less their rises)
  and in 3D for an unlevelled tracker (three placed targets, not on one line); or, for a levelled
  set-up with directions alone, from three or more placed targets: the orientation whose back-rays
  from the targets meet best (least-squares point of the lines, on a grid of :data:`GRID_STEPS`
  over half a turn: a line has two senses), then Gauss-Newton on ``x, y, o`` with the directions
  themselves; its height from the elevations (zenith angles) of the sights, which it needs.

Each returns the frame ``R`` (3 x 3, world = R instrument) and, for a resection, the point; or None
when the readings do not suffice.
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.datum import rigid_fit
from multilat.network.model.distance import line_of_sight

__all__ = ["orient", "resect", "resect_directions", "rz"]

#: orientation steps of the grid that starts a resection from directions alone
GRID_STEPS = 360


def rz(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def orient(setup, xyz, known):
    """The frame of ``setup`` on its placed point from its readings to placed points, or None."""
    ok = known[setup.to]
    if not ok.any():
        return None
    world = xyz[setup.to[ok]] - xyz[setup.station] - setup.dz[ok, None] * [0.0, 0.0, 1.0]
    if setup.levelled:
        h = np.hypot(world[:, 0], world[:, 1]) > 0
        if not h.any():
            return None
        a = np.arctan2(world[h, 1], world[h, 0]) - setup.t[ok][h]
        return rz(float(np.angle(np.mean(np.exp(1j * a)))))
    u = setup.u[ok]
    rho, w = line_of_sight(world, floor_m=1.0)
    use = np.all(np.isfinite(u), 1) & (rho > 0)
    if use.sum() < 2:
        return None
    w = w[use]
    try:                                                  # rays from one origin: the origin is a point too
        R, _ = rigid_fit(np.vstack([np.zeros(3), u[use]]), np.vstack([np.zeros(3), w]))
    except MultilatError:
        return None
    return R


def resect(setup, xyz, known):
    """(point (3,), frame R) of a set-up whose point is not placed, from its reading vectors to
    placed targets, or None."""
    ok = known[setup.to] & np.all(np.isfinite(setup.v), 1)
    need = 2 if setup.levelled else 3
    if len(set(setup.to[ok].tolist())) < need:
        return None
    world = xyz[setup.to[ok]] - setup.dz[ok, None] * [0.0, 0.0, 1.0]
    local = setup.v[ok]
    if setup.levelled and np.ptp(world[:, :2], axis=0).max() <= 0:
        return None
    try:
        R, p = rigid_fit(local, world, about_z=setup.levelled)
    except MultilatError:
        return None
    return p, R


def resect_directions(setup, xyz, known):
    """(point, frame) of a levelled set-up on an unplaced point from its horizontal readings to
    three or more placed targets (no distance) and its elevations for the height; or None."""
    ok = known[setup.to]
    if not setup.levelled or len(set(setup.to[ok].tolist())) < 3 or not np.isfinite(setup.el[ok]).any():
        return None
    P, t = xyz[setup.to[ok], :2], setup.t[ok]

    def meet(o):
        n = np.column_stack([-np.sin(t + o), np.cos(t + o)])
        b = np.einsum("ij,ij->i", n, P)
        xy, *_ = np.linalg.lstsq(n, b, rcond=None)
        return xy, float(np.sum((n @ xy - b) ** 2))

    grid = np.linspace(0.0, np.pi, GRID_STEPS, endpoint=False)
    xy = meet(grid[int(np.argmin([meet(o)[1] for o in grid]))])[0]
    d = P - xy
    o = float(np.angle(np.mean(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - t)))))
    q = np.array([xy[0], xy[1], o])
    for _ in range(20):                                   # Gauss-Newton on the directions
        d = P - q[:2]
        h2 = np.sum(d * d, 1)
        if np.any(h2 <= 0):
            return None
        r = np.angle(np.exp(1j * (t + q[2] - np.arctan2(d[:, 1], d[:, 0]))))
        J = np.column_stack([d[:, 1] / h2, -d[:, 0] / h2, -np.ones(len(t))])   # d(bearing - t - o)/dq
        step, *_ = np.linalg.lstsq(J, r, rcond=None)
        q += step
        if np.abs(step).max() < 1e-13:
            break
    d = P - q[:2]
    if np.any(np.cos(np.arctan2(d[:, 1], d[:, 0]) - t - q[2]) < 0.5):      # a sight points away: no fix
        return None
    e = np.isfinite(setup.el[ok])
    z = xyz[setup.to[ok], 2][e] - setup.dz[ok][e] - np.hypot(d[e, 0], d[e, 1]) * np.tan(setup.el[ok][e])
    return np.array([q[0], q[1], float(np.mean(z))]), rz(q[2])
