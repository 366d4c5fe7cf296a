"""The datum of a distance-only network: which rigid motion (3 translations, 3 rotations) is chosen.

Distances fix the shape and size of the network but not where it sits: 6 degrees of freedom are
undetermined. :func:`~multilat.network.adjust.distance.adjust.adjust` always solves with a minimal constraint
(3-2-1 on three stations, in their own frame) and then moves the solution and its covariance to
the requested datum:

``Datum.free(points=None)``  *free network, inner constraints* (default). The solution is moved
    rigidly so that the datum points (all stations and targets, or the chosen ones) fit their
    reference coordinates (the initial values, or ``--points``) best in least squares (Kabsch
    fit); the covariance is S-transformed with the inner-constraint matrix ``E = G`` restricted to
    the datum points, which gives the minimum-trace covariance over those points (the pseudo-inverse
    of the normal matrix when all points are datum points).

``Datum.three_two_one(a, b, c)``  the paper's small-volume frame: point ``a`` at the origin, ``b``
    on the +x axis, ``c`` in the xy-plane (y > 0). The covariance is S-transformed so that those
    6 coordinates have zero variance.

``Datum.control(points=None)``  fixed control points: the given coordinates (``--points``) of the
    chosen points (default: every point given) are held fixed in the adjustment (hard constraints).
    With more than a minimal set (3 non-collinear points = 9 > 6 coordinates) this also constrains
    the shape; the results equal the other datums' only when the control coordinates are consistent
    with the measured distances.

Distances between points, their uncertainties, offsets, scales and sigma0 do not depend on the
datum choice among ``free`` and ``three_two_one`` (tested to 1 nm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.distance import Q

__all__ = ["Datum", "parse_datum", "helmert_basis", "rigid_fit", "frame_321", "frame_axes", "apply_rigid",
           "datum_matrices", "s_coefficients", "s_factor", "s_transform", "RIGID_FIT_ITERATIONS", "ABOUT_Z_COLUMNS"]

#: the columns of :func:`helmert_basis` left when the vertical is observed (levelled stations): the
#: three translations and the rotation about z
ABOUT_Z_COLUMNS = [0, 1, 2, 5]

#: Gauss-Newton iterations of the per-trial rigid fit (batched solver, numpy and numba alike)
RIGID_FIT_ITERATIONS = 4

KINDS = ("free", "321", "control")


@dataclass(frozen=True)
class Datum:
    """Datum definition. ``kind`` is ``"free"``, ``"321"`` or ``"control"``; ``points`` the ids it
    uses (None: all points for free, every given point for control; exactly 3 for 321)."""

    kind: str = "free"
    points: tuple[str, ...] | None = None

    def __post_init__(self):
        if self.kind not in KINDS:
            raise MultilatError(f"datum kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        if self.points is not None:
            pts = tuple(str(p) for p in self.points)
            if len(set(pts)) != len(pts):
                raise MultilatError(f"datum {self.kind}: repeated point id")
            object.__setattr__(self, "points", pts)
        if self.kind == "321" and (self.points is None or len(self.points) != 3):
            raise MultilatError("datum 321 needs exactly three point ids (origin, x-axis, xy-plane), "
                                "e.g. 321:B,D,C")

    @classmethod
    def free(cls, points=None) -> "Datum":
        return cls("free", None if points is None else tuple(points))

    @classmethod
    def three_two_one(cls, a: str, b: str, c: str) -> "Datum":
        return cls("321", (a, b, c))

    @classmethod
    def control(cls, points=None) -> "Datum":
        return cls("control", None if points is None else tuple(points))

    def describe(self) -> str:
        if self.kind == "free":
            return "free network, inner constraints over " + (
                "all points" if self.points is None else ", ".join(self.points))
        if self.kind == "321":
            a, b, c = self.points
            return f"3-2-1: {a} at origin, {b} on +x, {c} in the xy-plane"
        return "fixed control points " + ("(all given)" if self.points is None else ", ".join(self.points))


def parse_datum(text: str | Datum | None) -> Datum:
    """Parse ``free``, ``free:P1,P2,...``, ``321:A,B,C``, ``control`` or ``control:P1,P2,...``."""
    if text is None:
        return Datum()
    if isinstance(text, Datum):
        return text
    kind, _, rest = str(text).strip().partition(":")
    kind = kind.strip().lower()
    pts = tuple(p.strip() for p in rest.split(",")) if rest.strip() else None
    if pts is not None and any(p == "" for p in pts):
        raise MultilatError(f"datum {text!r}: empty point id")
    if kind not in KINDS:
        raise MultilatError(f"datum must be free[:P,..], 321:A,B,C or control[:P,..], got {text!r}")
    return Datum(kind, pts)


def helmert_basis(xyz_m) -> np.ndarray:
    """Infinitesimal rigid motions of points, shape (3p, 6): columns are x, y, z translations and
    rotations about x, y, z (about the centroid of ``xyz_m`` (p, 3)); rows ordered point-major."""
    x = np.asarray(xyz_m, dtype=float)
    c = x - x.mean(axis=0)
    p = x.shape[0]
    G = np.zeros((p, 3, 6))
    G[:, 0, 0] = G[:, 1, 1] = G[:, 2, 2] = 1.0
    # d(point) = w x c  for rotation vector w
    G[:, 1, 3], G[:, 2, 3] = -c[:, 2], c[:, 1]
    G[:, 0, 4], G[:, 2, 4] = c[:, 2], -c[:, 0]
    G[:, 0, 5], G[:, 1, 5] = -c[:, 1], c[:, 0]
    return G.reshape(3 * p, 6)


def rigid_fit(src_xyz_m, dst_xyz_m, *, allow_reflection: bool = False, about_z: bool = False):
    """Rotation ``R`` (3, 3) and translation ``t`` (3,) minimising ``sum |R src + t - dst|**2``
    (Kabsch). Needs >= 3 non-collinear points.

    ``allow_reflection``: allow ``det R = -1`` (a mirror), for comparing networks known only from
    distances (which cannot tell a network from its mirror image). ``about_z``: rotations about the
    vertical z only (networks whose vertical is observed: levelled stations).
    """
    a = np.asarray(src_xyz_m, float)
    b = np.asarray(dst_xyz_m, float)
    if a.shape != b.shape or a.ndim != 2 or a.shape[1] != 3:
        raise MultilatError("rigid_fit: expected two (p, 3) arrays")
    if about_z:
        ca, cb = a.mean(axis=0), b.mean(axis=0)
        p, q = a[:, :2] - ca[:2], b[:, :2] - cb[:2]
        th = np.arctan2(np.sum(p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]), np.sum(p[:, 0] * q[:, 0] + p[:, 1] * q[:, 1]))
        c, s = np.cos(th), np.sin(th)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return R, cb - R @ ca
    if a.shape[0] < 3:
        raise MultilatError(f"datum: need at least 3 points to fix the frame, got {a.shape[0]}")
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    sv = np.linalg.svd(a - ca, compute_uv=False)
    if sv[1] <= 1e-9 * max(sv[0], 1e-300):
        raise MultilatError("datum: the datum points are collinear and cannot fix the rotation")
    H = (a - ca).T @ (b - cb)
    U, _, Vt = np.linalg.svd(H)
    d = 1.0 if allow_reflection else (np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0)
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return R, cb - R @ ca


def frame_axes(p_origin, p_x, p_xy):
    """Unit axes ``(ex, ey, ez)`` of the 3-2-1 frame of three points (each (..., 3), broadcast over
    leading axes): ``ex`` along origin -> x, ``ez`` normal to the plane of the three, ``ey = ez x ex``
    (so the third point has y > 0). Raises when the points are (nearly) collinear."""
    o = np.asarray(p_origin, float)
    ex = np.asarray(p_x, float) - o
    v = np.asarray(p_xy, float) - o
    nx = np.linalg.norm(ex, axis=-1, keepdims=True)
    ez = np.cross(ex, v)
    nz = np.linalg.norm(ez, axis=-1, keepdims=True)
    if np.any(nx == 0) or np.any(nz <= 1e-9 * nx * np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)):
        raise MultilatError("datum 321: the three points are (nearly) collinear")
    ex = ex / nx
    ez = ez / nz
    return ex, np.cross(ez, ex), ez


def frame_321(p_origin, p_x, p_xy):
    """Rotation and translation taking coordinates into the 3-2-1 frame of three points: the first
    at the origin, the second on +x, the third in the xy-plane with y > 0."""
    R = np.vstack(frame_axes(p_origin, p_x, p_xy))
    return R, -R @ np.asarray(p_origin, float)


def apply_rigid(R, t, xyz_m):
    """``R x + t`` for points (..., 3)."""
    return np.asarray(xyz_m) @ np.asarray(R).T + t


def datum_matrices(datum: Datum, station_ids, target_ids, sx, tx):
    """G (n, 6) rigid motions of all coordinates, E (n, 6) the datum's constraint matrix."""
    s, t = len(station_ids), len(target_ids)
    n = Q * s + 3 * t
    rows = np.concatenate([(Q * np.arange(s)[:, None] + np.arange(3)).ravel(),
                           Q * s + np.arange(3 * t)])
    Gp = helmert_basis(np.vstack([sx, tx]))
    G = np.zeros((n, 6))
    G[rows] = Gp
    pos = {pid: k for k, pid in enumerate(tuple(station_ids) + tuple(target_ids))}

    def prow(pid, c):
        return rows[3 * pos[pid] + c]

    E = np.zeros((n, 6))
    if datum.kind == "321":
        a, b, c = datum.points
        for col, (pid, comp) in enumerate([(a, 0), (a, 1), (a, 2), (b, 1), (b, 2), (c, 2)]):
            E[prow(pid, comp), col] = 1.0
    else:
        if datum.points is None:
            E[rows] = G[rows]
        else:
            for pid in datum.points:
                for comp in range(3):
                    r = prow(pid, comp)
                    E[r] = G[r]
    return G, E


def s_coefficients(G, E) -> np.ndarray:
    """``H = (Eᵀ G)⁻¹ Eᵀ`` (d, n) of the S-transformation ``S = I - G H`` (:func:`s_transform`), for
    products with ``S`` that never form it (the adjustment's covariance operator)."""
    return np.linalg.solve(E.T @ G, E.T)


def s_factor(G, E) -> np.ndarray:
    """``G (Eᵀ G)⁻¹`` (n, d): the S-transformation's other factor, ``S = I - s_factor(G, E) Eᵀ``
    (:func:`s_transform`), for back ends that apply ``S`` through products (the general layer's sparse one)."""
    return np.linalg.solve((E.T @ G).T, G.T).T


def s_transform(G, E) -> np.ndarray:
    """The S-transformation ``S = I - G (Eᵀ G)⁻¹ Eᵀ`` (n, n) onto the datum ``Eᵀ dx = 0``: ``G`` (n, d)
    the datum defects (rigid motions, :func:`helmert_basis` / :func:`datum_matrices`), ``E`` (n, d)
    the datum's constraints; a covariance in any datum becomes ``S C Sᵀ`` in this one. The one copy
    (``tests/test_each_concept_once.py``)."""
    return np.eye(G.shape[0]) - G @ s_coefficients(G, E)
