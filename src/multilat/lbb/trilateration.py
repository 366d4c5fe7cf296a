"""Trilateration of the tool socket from the six tetrahedron edges (seed 003, eq. 1).

Frame (the *base frame*, used by every LBB module): socket 1 at the origin, socket 2 on the +x
axis, socket 3 in the xy-plane with y > 0, the tool socket above the base plane (z > 0).
Edge names: ``l12_m, l13_m, l23_m`` are the base edges, ``l1_m, l2_m, l3_m`` the tool-to-socket
edges (metres). Every function broadcasts over leading axes, so the same call serves one point,
a grid of points, or a Monte Carlo ensemble ``(trials, points)``.

Closed form::

    x3 = (l12² + l13² - l23²) / (2 l12),   y3 = sqrt(l13² - x3²)            (socket 3)
    x  = (l12² + l1² - l2²) / (2 l12)
    y  = (l1² - l3² + x3² + y3² - 2 x3 x) / (2 y3)
    z² = l1² - x² - y²,                     z = +sqrt(z²)                     (tool)

The singularity: when the tool socket approaches the base plane, ``dz/dl = l/z`` grows like
``1/z`` and at ``z² <= 0`` the edges admit no (or a double) solution. Such points are *reported*
(:attr:`Trilateration.valid` is False and :attr:`Trilateration.z_squared_m2` shows why) or, with
``on_singular="raise"``, rejected with a :class:`~multilat.errors.MultilatError` naming the point;
their z is set to 0, never NaN.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError

__all__ = ["Trilateration", "base_sockets_xyz", "trilaterate", "edges_from_points",
           "check_edges", "EDGE_NAMES"]

EDGE_NAMES = ("l12_m", "l13_m", "l23_m", "l1_m", "l2_m", "l3_m")

#: default singularity threshold: a point is flagged when z < 1e-6 * (largest edge), i.e. 1 um
#: for a 1 m tetrahedron; at that height a 0.1 um edge error already moves z by ~0.1 m.
DEFAULT_MIN_HEIGHT_RATIO = 1e-6


@dataclass(frozen=True)
class Trilateration:
    """Tool socket coordinates in the base frame.

    Attributes
    ----------
    xyz_m : ndarray, shape (..., 3)
        Tool socket centre (m). For invalid points z is 0 (x, y are still the closed-form values).
    valid : ndarray of bool, shape (...)
        False where the point is at/too close to the base plane or the edges are inconsistent.
    z_squared_m2 : ndarray, shape (...)
        ``l1² - x² - y²`` (m²); negative means the six edges do not close a tetrahedron.
    """

    xyz_m: np.ndarray
    valid: np.ndarray
    z_squared_m2: np.ndarray


def _arrays(*edges):
    arrs = np.broadcast_arrays(*[np.asarray(e, dtype=float) for e in edges])
    return [np.asarray(a) for a in arrs]


def check_edges(l12_m, l13_m, l23_m, l1_m, l2_m, l3_m, *, labels=None) -> None:
    """Validate edges at the boundary: finite, > 0, every face satisfies the strict triangle inequality.

    Parameters
    ----------
    l12_m, l13_m, l23_m, l1_m, l2_m, l3_m : array_like, broadcastable, metres
    labels : sequence of str, optional
        One label per point (flattened order) used in the message instead of ``point i``
        (e.g. ``"edges.csv:4: point P3"``).

    Raises
    ------
    MultilatError
        Naming the first offending point and the edge or face.
    """
    arrs = [a.ravel() for a in _arrays(l12_m, l13_m, l23_m, l1_m, l2_m, l3_m)]

    def name(i):
        return str(labels[i]) if labels is not None else f"point {i}"

    for nm, a in zip(EDGE_NAMES, arrs):
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise MultilatError(f"{name(bad[0])}: {nm} must be finite, got {a[bad[0]]!r}")
        bad = np.flatnonzero(a <= 0)
        if bad.size:
            raise MultilatError(f"{name(bad[0])}: {nm} must be > 0, got {a[bad[0]]!r}")
    l12, l13, l23, l1, l2, l3 = arrs
    faces = (("base face 1-2-3", l12, l13, l23), ("face tool-1-2", l1, l2, l12),
             ("face tool-1-3", l1, l3, l13), ("face tool-2-3", l2, l3, l23))
    for fname, a, b, c in faces:
        viol = (a >= b + c) | (b >= a + c) | (c >= a + b)
        bad = np.flatnonzero(viol)
        if bad.size:
            i = bad[0]
            raise MultilatError(f"{name(i)}: {fname} violates the triangle inequality "
                                f"(edges {a[i]:.9g}, {b[i]:.9g}, {c[i]:.9g} m)")


def base_sockets_xyz(l12_m, l13_m, l23_m) -> np.ndarray:
    """Base socket coordinates from the three base edges.

    Parameters
    ----------
    l12_m, l13_m, l23_m : array_like, broadcastable, metres

    Returns
    -------
    ndarray, shape (..., 3, 3)
        Rows are sockets 1, 2, 3 in the base frame (socket 1 origin, 2 on +x, 3 in xy with y > 0).
        A degenerate base (socket 3 on the x axis) raises :class:`MultilatError`.
    """
    l12, l13, l23 = _arrays(l12_m, l13_m, l23_m)
    x3 = (l12**2 + l13**2 - l23**2) / (2 * l12)
    y3sq = l13**2 - x3**2
    if np.any(~(y3sq > 0)):
        i = int(np.flatnonzero(~(y3sq > 0).ravel())[0])
        raise MultilatError(f"point {i}: the base sockets are collinear or the base edges violate the "
                            "triangle inequality")
    out = np.zeros(l12.shape + (3, 3))
    out[..., 1, 0] = l12
    out[..., 2, 0] = x3
    out[..., 2, 1] = np.sqrt(y3sq)
    return out


def trilaterate(l12_m, l13_m, l23_m, l1_m, l2_m, l3_m, *, on_singular: str = "mask",
                min_height_ratio: float = DEFAULT_MIN_HEIGHT_RATIO, labels=None,
                validate: bool = True) -> Trilateration:
    """Tool socket from the six tetrahedron edges (eq. 1), closed form, broadcasting.

    Parameters
    ----------
    l12_m, l13_m, l23_m : array_like, metres
        Base edges (socket 1-2, 1-3, 2-3).
    l1_m, l2_m, l3_m : array_like, metres
        Tool-to-socket edges. All six broadcast to a common shape ``(...)``.
    on_singular : {"mask", "raise"}
        ``"mask"``: flag points with ``z² <= (min_height_ratio * max edge)²`` (too close to the
        base plane, or negative ``z²`` from inconsistent edges) in :attr:`Trilateration.valid`.
        ``"raise"``: raise :class:`MultilatError` naming the first such point.
    min_height_ratio : float
        Singularity threshold relative to the longest edge of the point's tetrahedron.
    labels : sequence of str, optional
        Point labels for messages (flattened order).
    validate : bool
        Check finiteness, positivity and the triangle inequality of every face first (the public
        boundary). Monte Carlo inner loops pass ``False`` and rely on the mask.

    Returns
    -------
    Trilateration
        ``xyz_m`` of shape ``(..., 3)``, ``valid`` and ``z_squared_m2`` of shape ``(...)``.
    """
    if on_singular not in ("mask", "raise"):
        raise MultilatError(f"on_singular must be 'mask' or 'raise', got {on_singular!r}")
    if validate:
        check_edges(l12_m, l13_m, l23_m, l1_m, l2_m, l3_m, labels=labels)
    l12, l13, l23, l1, l2, l3 = _arrays(l12_m, l13_m, l23_m, l1_m, l2_m, l3_m)
    x3 = (l12**2 + l13**2 - l23**2) / (2 * l12)
    y3sq = l13**2 - x3**2
    if np.any(~(y3sq > 0)):
        i = int(np.flatnonzero(~(y3sq > 0).ravel())[0])
        name = str(labels[i]) if labels is not None else f"point {i}"
        raise MultilatError(f"{name}: the base sockets are collinear (degenerate base triangle)")
    y3 = np.sqrt(y3sq)
    x = (l12**2 + l1**2 - l2**2) / (2 * l12)
    y = (l1**2 - l3**2 + x3**2 + y3sq - 2 * x3 * x) / (2 * y3)
    z2 = l1**2 - x**2 - y**2
    scale = np.maximum.reduce([l12, l13, l23, l1, l2, l3])
    valid = z2 > (min_height_ratio * scale) ** 2
    if on_singular == "raise" and not np.all(valid):
        i = int(np.flatnonzero(~valid.ravel())[0])
        name = str(labels[i]) if labels is not None else f"point {i}"
        why = ("the edges do not close a tetrahedron" if z2.ravel()[i] < 0
               else "the tool socket is at the base plane (trilateration singularity)")
        raise MultilatError(f"{name}: {why} (z^2 = {z2.ravel()[i]:.3g} m^2)")
    z = np.sqrt(np.where(valid, z2, 0.0))
    return Trilateration(np.stack([x, y, z], axis=-1), valid, z2)


def edges_from_points(base_xyz_m, tool_xyz_m) -> np.ndarray:
    """The six tetrahedron edges from socket coordinates (the inverse of :func:`trilaterate`).

    Parameters
    ----------
    base_xyz_m : array_like, shape (..., 3, 3)
        Sockets 1, 2, 3 (rows), any frame.
    tool_xyz_m : array_like, shape (..., 3)
        Tool socket, same frame; broadcast against ``base_xyz_m[..., 0, :]``.

    Returns
    -------
    ndarray, shape (..., 6)
        ``l12, l13, l23, l1, l2, l3`` in metres (order of :data:`EDGE_NAMES`).
    """
    b = np.asarray(base_xyz_m, dtype=float)
    t = np.asarray(tool_xyz_m, dtype=float)
    s1, s2, s3 = b[..., 0, :], b[..., 1, :], b[..., 2, :]
    t = t + np.zeros_like(s1)
    s1, s2, s3 = (s + np.zeros_like(t) for s in (s1, s2, s3))

    def d(a, c):
        return np.sqrt(np.sum((a - c) ** 2, axis=-1))

    return np.stack([d(s1, s2), d(s1, s3), d(s2, s3), d(t, s1), d(t, s2), d(t, s3)], axis=-1)
