"""The angle observation model (network/model/angles.py) against closed forms, symmetries and finite differences."""

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.model import angles as A


def _random_case(rng, m=40, s=4, t=15):
    H = rng.uniform(-3, 3, (s, 3))
    T = rng.uniform(-3, 3, (t, 3)) + np.array([0, 0, 0.5])
    O = rng.uniform(-0.3, 0.3, (s, 3)) + np.array([0, 0, 1.0]) * rng.uniform(-3, 3, (s, 1))
    si = rng.integers(0, s, m)
    ti = rng.integers(0, t, m)
    return H, O, T, si, ti


def test_rotation_is_orthonormal_and_ordered():
    rng = np.random.default_rng(1)
    o = rng.uniform(-np.pi, np.pi, (20, 3))
    R = A.rotation_matrix(o)
    assert np.allclose(R @ np.swapaxes(R, -1, -2), np.eye(3), atol=1e-14)
    assert np.allclose(np.linalg.det(R), 1.0, atol=1e-14)
    # kappa alone turns about the world vertical: a closed form
    k = 0.7
    Rk = A.rotation_matrix([0, 0, k])
    assert np.allclose(Rk, [[np.cos(k), -np.sin(k), 0], [np.sin(k), np.cos(k), 0], [0, 0, 1]], atol=1e-15)


def test_closed_form_angles_of_a_levelled_station():
    H = np.zeros((1, 3))
    T = np.array([[1.0, 1.0, np.sqrt(2.0)], [0.0, -2.0, 0.0], [-3.0, 0.0, -3.0]])
    az, el = A.predicted_angles(H, np.zeros((1, 3)), T, np.zeros(3, int), np.arange(3))
    assert np.allclose(A.wrap_angle(az - np.array([np.pi / 4, -np.pi / 2, np.pi])), 0, atol=1e-15)
    assert np.allclose(el, [np.pi / 4, 0.0, -np.pi / 4], atol=1e-15)
    # the station turned by kappa sees every azimuth kappa smaller, elevations unchanged
    az2, el2 = A.predicted_angles(H, np.array([[0, 0, 0.3]]), T, np.zeros(3, int), np.arange(3))
    assert np.allclose(A.wrap_angle(az2 - (az - 0.3)), 0, atol=1e-14)
    assert np.allclose(el2, el, atol=1e-15)


def test_angles_invariant_under_a_common_rigid_motion():
    """Moving the world and every station orientation together changes no angle (the datum defect)."""
    rng = np.random.default_rng(2)
    H, O, T, si, ti = _random_case(rng)
    az, el = A.predicted_angles(H, O, T, si, ti)
    k = 1.1
    Rk = A.rotation_matrix([0, 0, k])
    shift = np.array([2.0, -1.0, 0.5])
    az2, el2 = A.predicted_angles(H @ Rk.T + shift, O + [0, 0, k], T @ Rk.T + shift, si, ti)
    assert np.allclose(A.wrap_angle(az2 - az), 0, atol=1e-12)
    assert np.allclose(el2, el, atol=1e-12)


def test_polar_round_trip():
    rng = np.random.default_rng(3)
    H, O, T, si, ti = _random_case(rng)
    az, el = A.predicted_angles(H, O, T, si, ti)
    r = np.linalg.norm(T[ti] - H[si], axis=1)
    back = A.polar_to_xyz(H[si], O[si], r, az, el)
    assert np.max(np.abs(back - T[ti])) < 1e-12  # rounding of a few-metre vector


def test_jacobian_against_central_differences():
    rng = np.random.default_rng(4)
    H, O, T, si, ti = _random_case(rng)
    dH, dO, dT = A.angle_jacobian(H, O, T, si, ti)
    h = 1e-6

    def angles(H_, O_, T_):
        az, el = A.predicted_angles(H_, O_, T_, si, ti)
        return np.stack([az, el], 1)

    base = angles(H, O, T)
    for name, arr, J in (("station", H, dH), ("orientation", O, dO), ("target", T, dT)):
        for c in range(3):
            num = np.zeros_like(base)
            idx = si if name != "target" else ti
            for k in range(arr.shape[0]):
                p, q = arr.copy(), arr.copy()
                p[k, c] += h
                q[k, c] -= h
                args_p = {"station": (p, O, T), "orientation": (H, p, T), "target": (H, O, p)}[name]
                args_q = {"station": (q, O, T), "orientation": (H, q, T), "target": (H, O, q)}[name]
                diff = A.wrap_angle(angles(*args_p) - angles(*args_q)) / (2 * h)
                num[idx == k] = diff[idx == k]
            # central differences are exact to O(h^2) ~ 1e-12 relative to the curvature; 1e-7 rad/unit allows it
            assert np.max(np.abs(num - J[:, :, c])) < 1e-7, (name, c)


def test_azimuth_undefined_on_the_vertical_and_ranges_checked():
    H = np.zeros((1, 3))
    with pytest.raises(MultilatError, match="vertical"):
        A.angle_jacobian(H, np.zeros((1, 3)), np.array([[0, 0, 2.0]]), np.zeros(1, int), np.zeros(1, int))
    with pytest.raises(MultilatError, match="elevation_rad .* row 2"):
        A.check_angles([0.1, 0.2], [0.0, 2.0], where="obs.csv")
    with pytest.raises(MultilatError, match="azimuth_rad"):
        A.check_angles([np.nan], [0.0])
