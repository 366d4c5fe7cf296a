"""Homogeneous transformation matrices (HTMs) of the laser ball bar (seed 003, §3.1, eqs. 2-5).

Every transform is a 4x4 matrix ``A_to_B`` mapping homogeneous coordinates in frame A to frame B,
batched over leading axes: parameters of shape ``(...)`` give matrices of shape ``(..., 4, 4)``.
Composition reads left to right: ``cs2_to_cs1 @ cs3_to_cs2 == cs3_to_cs1``.

Frames of the bar (seed 003, §3.1, Fig. 4):

- CS1: origin at the left ball centre, x along the DMI measurement axis, z horizontal and
  perpendicular to x, y = z × x (in the vertical plane through the bar, upward component >= 0).
- CS2: on the middle tube, origin at the centre of the linear bearing that carries the inner tube,
  x along that bearing's axis.
- CS3: origin at the right ball centre, x through the apex of the moving retroreflector.

Section lengths along the DMI axis: ``La`` left ball to the outer tube's bearing (fixed), ``Lb``
that bearing to CS2 (the middle tube's extension), ``Lc`` CS2 to the right ball (the inner tube's
extension); the nominal bar length is ``La + Lb + Lc`` (eq. 2).
"""

from __future__ import annotations

import numpy as np

__all__ = ["identity", "translation", "rot_x", "rot_y", "rot_z", "small_angle_htm",
           "cs2_to_cs1_nominal", "cs3_to_cs2_nominal", "cs2_to_cs1", "cs3_to_cs2",
           "transform_point", "origin"]


def _shape(*params):
    return np.broadcast_shapes(*[np.shape(p) for p in params])


def identity(shape=()) -> np.ndarray:
    """Identity HTMs of shape ``shape + (4, 4)``."""
    out = np.zeros(tuple(shape) + (4, 4))
    out[..., 0, 0] = out[..., 1, 1] = out[..., 2, 2] = out[..., 3, 3] = 1.0
    return out


def translation(dx_m=0.0, dy_m=0.0, dz_m=0.0) -> np.ndarray:
    """Pure translation by ``(dx, dy, dz)`` metres; shape ``(..., 4, 4)``."""
    out = identity(_shape(dx_m, dy_m, dz_m))
    out[..., 0, 3] = dx_m
    out[..., 1, 3] = dy_m
    out[..., 2, 3] = dz_m
    return out


def _rot(angle_rad, i, j):
    a = np.asarray(angle_rad, dtype=float)
    out = identity(a.shape)
    c, s = np.cos(a), np.sin(a)
    out[..., i, i] = c
    out[..., j, j] = c
    out[..., i, j] = -s
    out[..., j, i] = s
    return out


def rot_x(angle_rad) -> np.ndarray:
    """Exact rotation about x by ``angle_rad`` (right hand); shape ``(..., 4, 4)``."""
    return _rot(angle_rad, 1, 2)


def rot_y(angle_rad) -> np.ndarray:
    """Exact rotation about y by ``angle_rad`` (right hand); shape ``(..., 4, 4)``."""
    return _rot(angle_rad, 2, 0)


def rot_z(angle_rad) -> np.ndarray:
    """Exact rotation about z by ``angle_rad`` (right hand); shape ``(..., 4, 4)``."""
    return _rot(angle_rad, 0, 1)


def small_angle_htm(ex_rad=0.0, ey_rad=0.0, ez_rad=0.0, dx_m=0.0, dy_m=0.0, dz_m=0.0) -> np.ndarray:
    """First-order error HTM (rotations ``e``, translations ``d``) as used for machine error motions::

        [[  1, -ez,  ey, dx],
         [ ez,   1, -ex, dy],
         [-ey,  ex,   1, dz],
         [  0,   0,   0,  1]]

    Valid for angles << 1 rad (the LBB's are < 1e-3 rad: the neglected second-order terms are
    < 1e-6 rad).
    """
    shape = _shape(ex_rad, ey_rad, ez_rad, dx_m, dy_m, dz_m)
    out = identity(shape)
    out[..., 0, 1] = -np.asarray(ez_rad)
    out[..., 1, 0] = ez_rad
    out[..., 0, 2] = ey_rad
    out[..., 2, 0] = -np.asarray(ey_rad)
    out[..., 1, 2] = -np.asarray(ex_rad)
    out[..., 2, 1] = ex_rad
    out[..., 0, 3] = dx_m
    out[..., 1, 3] = dy_m
    out[..., 2, 3] = dz_m
    return out


def cs2_to_cs1_nominal(la_m, lb_m) -> np.ndarray:
    """Nominal ``1T2`` of eq. (2): translation by ``La + Lb`` along x."""
    return translation(np.asarray(la_m) + np.asarray(lb_m))


def cs3_to_cs2_nominal(lc_m) -> np.ndarray:
    """Nominal ``2T3`` of eq. (2): translation by ``Lc`` along x."""
    return translation(lc_m)


def cs2_to_cs1(la_m, lb_m, *, ey_rad=0.0, ez_rad=0.0, sy_m=0.0, sz_m=0.0,
               sag_dy_m=0.0, sag_ez_rad=0.0) -> np.ndarray:
    """Actual ``1T2`` (the middle-tube half of eq. 3).

    The middle tube tilts by ``(ey, ez)`` in the outer tube's bearing (at ``x = La``) and its
    far end (CS2, ``Lb`` further) is displaced by the straightness ``(sy, sz)``; so CS2's origin
    moves laterally by ``s + e·Lb`` as in Table 1. Gravity sag (computed in CS1) adds ``sag_dy``
    to CS2's origin and ``sag_ez`` to its orientation::

        1T2 = T(0, sag_dy, 0) · T(La) · Rz(ez) · Ry(ey) · T(Lb) · T(0, sy, sz) · Rz(sag_ez)

    All arguments broadcast; returns shape ``(..., 4, 4)``.
    """
    return (translation(0.0, sag_dy_m, 0.0) @ translation(la_m) @ rot_z(ez_rad) @ rot_y(ey_rad)
            @ translation(lb_m, sy_m, sz_m) @ rot_z(sag_ez_rad))


def cs3_to_cs2(lc_m, *, ey_rad=0.0, ez_rad=0.0, sy_m=0.0, sz_m=0.0, compliance_ez_rad=0.0,
               sag_dy_m=0.0, sag_ez_rad=0.0) -> np.ndarray:
    """Actual ``2T3`` (the inner-tube half of eq. 3).

    The inner tube pivots in the middle tube's bearing (CS2's origin) by its axis-motion errors
    ``(ey, ez)`` plus the bearing compliance ``compliance_ez`` (§3.1.3, a rotation about z whose
    lateral motion of CS3, ``compliance_ez·Lc``, is the "added y displacement" of the paper);
    the right ball (CS3, ``Lc`` further) is displaced by the straightness ``(sy, sz)``; sag adds
    ``sag_dy`` (in CS2) and ``sag_ez``::

        2T3 = T(0, sag_dy, 0) · Rz(compliance_ez) · Rz(ez) · Ry(ey) · T(Lc, sy, sz) · Rz(sag_ez)
    """
    return (translation(0.0, sag_dy_m, 0.0) @ rot_z(compliance_ez_rad) @ rot_z(ez_rad)
            @ rot_y(ey_rad) @ translation(lc_m, sy_m, sz_m) @ rot_z(sag_ez_rad))


def transform_point(a_to_b, p_a) -> np.ndarray:
    """Map points ``p_a`` (shape (..., 3), metres, frame A) to frame B with HTMs (..., 4, 4)."""
    t = np.asarray(a_to_b)
    p = np.asarray(p_a, dtype=float)
    return np.einsum("...ij,...j->...i", t[..., :3, :3], p) + t[..., :3, 3]


def origin(a_to_b) -> np.ndarray:
    """The origin of frame A expressed in frame B: the translation column, shape (..., 3)."""
    return np.asarray(a_to_b)[..., :3, 3]
