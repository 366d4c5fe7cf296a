"""Angle observations: the model of an azimuth and an elevation read by an oriented station.

A station that reads angles (a laser tracker, or a multilateration head's gimbal encoders) has an
orientation: the rotation ``R`` whose columns are the instrument's x, y, z axes in the world frame.
For a target ``T`` seen from a station at ``H`` the local direction is ``v = R^T (T - H)`` and::

    azimuth_rad   = atan2(v_y, v_x)                 counter-clockwise from the instrument's x axis
    elevation_rad = atan2(v_z, hypot(v_x, v_y))      from the instrument's horizontal plane (+ = up)
    zenith_rad    = pi/2 - elevation_rad

Elevations are measured from the horizontal, as everywhere in multilat (see :mod:`multilat.gimbal`).

Orientation parameters ``(omega, phi, kappa)`` (radians) give ``R = Rz(kappa) Ry(phi) Rx(omega)``:
``kappa`` turns the instrument about the world vertical, ``phi`` and ``omega`` tilt it. A *levelled*
station (a tracker with its level, a head whose standing axis is plumb) has ``omega = phi = 0`` held,
and only ``kappa`` estimated: its vertical is the world's.

All functions are pure and vectorised over observations; angles in radians, lengths in metres.
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError

__all__ = ["rotation_matrix", "rotation_derivatives", "wrap_angle", "local_direction",
           "predicted_angles", "angle_jacobian", "polar_to_xyz", "check_angles"]


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    o, i = np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([i, o, o], -1), np.stack([o, c, -s], -1), np.stack([o, s, c], -1)], -2)


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    o, i = np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([c, o, s], -1), np.stack([o, i, o], -1), np.stack([-s, o, c], -1)], -2)


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    o, i = np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([c, -s, o], -1), np.stack([s, c, o], -1), np.stack([o, o, i], -1)], -2)


_GEN = {  # d R_axis(a) / d a = R_axis(a) @ G_axis
    "x": np.array([[0.0, 0, 0], [0, 0, -1], [0, 1, 0]]),
    "y": np.array([[0.0, 0, 1], [0, 0, 0], [-1, 0, 0]]),
    "z": np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 0]]),
}


def rotation_matrix(orientation_rad) -> np.ndarray:
    """``R = Rz(kappa) Ry(phi) Rx(omega)`` for orientations (..., 3) = (omega, phi, kappa) -> (..., 3, 3)."""
    o = np.asarray(orientation_rad, dtype=float)
    return _rz(o[..., 2]) @ _ry(o[..., 1]) @ _rx(o[..., 0])


def rotation_derivatives(orientation_rad) -> np.ndarray:
    """``dR/d(omega, phi, kappa)`` for orientations (..., 3) -> (..., 3, 3, 3), last-but-two axis the parameter."""
    o = np.asarray(orientation_rad, dtype=float)
    X, Y, Z = _rx(o[..., 0]), _ry(o[..., 1]), _rz(o[..., 2])
    d_omega = Z @ Y @ X @ _GEN["x"]
    d_phi = Z @ Y @ _GEN["y"] @ X
    d_kappa = Z @ _GEN["z"] @ Y @ X
    return np.stack([d_omega, d_phi, d_kappa], axis=-3)


def wrap_angle(a):
    """Angles wrapped to ``[-pi, pi)`` (for azimuth residuals)."""
    return (np.asarray(a, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi


def local_direction(station_xyz_m, orientation_rad, target_xyz_m, station_index, target_index):
    """``v = R_i^T (T_j - H_i)`` per observation (m, 3), in metres, and the rotations ``R_i`` (m, 3, 3)."""
    R = rotation_matrix(np.asarray(orientation_rad, float)[station_index])
    d = np.asarray(target_xyz_m, float)[target_index] - np.asarray(station_xyz_m, float)[station_index]
    return np.einsum("mji,mj->mi", R, d), R, d


def predicted_angles(station_xyz_m, orientation_rad, target_xyz_m, station_index, target_index):
    """Azimuth and elevation (m,) each, radians, of each target seen from its station."""
    v, _, _ = local_direction(station_xyz_m, orientation_rad, target_xyz_m, station_index, target_index)
    return np.arctan2(v[:, 1], v[:, 0]), np.arctan2(v[:, 2], np.hypot(v[:, 0], v[:, 1]))


def angle_jacobian(station_xyz_m, orientation_rad, target_xyz_m, station_index, target_index):
    """Partial derivatives of (azimuth, elevation) per observation.

    Returns
    -------
    d_station : (m, 2, 3)  d(az, el) / d(H_x, H_y, H_z), rad/m
    d_orientation : (m, 2, 3)  d(az, el) / d(omega, phi, kappa), rad/rad
    d_target : (m, 2, 3)  d(az, el) / d(T_x, T_y, T_z) = -d_station
    """
    o = np.asarray(orientation_rad, float)[station_index]
    v, R, d = local_direction(station_xyz_m, orientation_rad, target_xyz_m, station_index, target_index)
    vx, vy, vz = v[:, 0], v[:, 1], v[:, 2]
    h2 = vx * vx + vy * vy
    h = np.sqrt(h2)
    n2 = h2 + vz * vz
    if np.any(h2 <= 0):
        raise MultilatError("an angle observation looks straight up or down its station's vertical axis: "
                            "azimuth undefined")
    d_az_dv = np.stack([-vy / h2, vx / h2, np.zeros_like(vx)], -1)
    d_el_dv = np.stack([-vz * vx / (h * n2), -vz * vy / (h * n2), h / n2], -1)
    d_angles_dv = np.stack([d_az_dv, d_el_dv], 1)                      # (m, 2, 3)
    d_target = np.einsum("mak,mjk->maj", d_angles_dv, R)               # dv/dT = R^T
    dR = rotation_derivatives(o)                                       # (m, 3 params, 3, 3)
    dv_dp = np.einsum("mpji,mj->mpi", dR, d)                           # (m, 3 params, 3)
    d_orientation = np.einsum("mak,mpk->map", d_angles_dv, dv_dp)
    return -d_target, d_orientation, d_target


def polar_to_xyz(station_xyz_m, orientation_rad, distance_m, azimuth_rad, elevation_rad):
    """Target coordinates from a station's polar measurement (a tracker's reading), broadcasting."""
    az, el, r = (np.asarray(a, float) for a in (azimuth_rad, elevation_rad, distance_m))
    local = np.stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)], -1)
    R = rotation_matrix(orientation_rad)
    return np.asarray(station_xyz_m, float) + np.einsum("...ij,...j->...i", R, local)


def check_angles(azimuth_rad, elevation_rad, *, where: str = "angles") -> None:
    """One-line errors for angles outside their range (azimuth in [-2 pi, 2 pi], elevation in [-pi/2, pi/2])."""
    az = np.asarray(azimuth_rad, float)
    el = np.asarray(elevation_rad, float)
    bad = ~np.isfinite(az) | (np.abs(az) > 2 * np.pi)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise MultilatError(f"{where}: azimuth_rad {az.flat[k]!r} at row {k + 1} is outside [-2 pi, 2 pi]")
    bad = ~np.isfinite(el) | (np.abs(el) > np.pi / 2)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise MultilatError(f"{where}: elevation_rad {el.flat[k]!r} at row {k + 1} is outside [-pi/2, pi/2]")
