"""LBB trilateration (seed 003, eq. 1): round trips, frame conventions, singularity, bad input."""

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.lbb.trilateration import (base_sockets_xyz, check_edges, edges_from_points, trilaterate)


def _random_base(rng, n):
    """Random non-degenerate base triangles already in the base frame."""
    l12 = rng.uniform(0.3, 1.0, n)
    x3 = rng.uniform(-0.2, 1.0, n) * l12
    y3 = rng.uniform(0.2, 1.0, n)
    b = np.zeros((n, 3, 3))
    b[:, 1, 0] = l12
    b[:, 2, 0] = x3
    b[:, 2, 1] = y3
    return b


def test_round_trip_coordinates_edges_coordinates():
    # independent check: forward distances (edges_from_points) then the closed-form inverse
    rng = np.random.default_rng(4)
    n = 20_000
    base = _random_base(rng, n)
    tool = np.c_[rng.uniform(-0.5, 1.5, n), rng.uniform(-0.5, 1.5, n), rng.uniform(0.05, 1.5, n)]
    e = edges_from_points(base, tool)
    res = trilaterate(*e.T)
    assert res.valid.all()
    assert np.max(np.abs(res.xyz_m - tool)) < 1e-9
    np.testing.assert_allclose(base_sockets_xyz(*e[:, :3].T), base, atol=1e-12)


def test_round_trip_is_frame_free():
    # rotate and translate the whole tetrahedron: edges (and so coordinates) must not change
    rng = np.random.default_rng(5)
    base = _random_base(rng, 1)[0]
    tool = np.array([0.3, 0.2, 0.4])
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    t = rng.normal(size=3)
    e1 = edges_from_points(base, tool)
    e2 = edges_from_points(base @ q.T + t, q @ tool + t)
    np.testing.assert_allclose(e1, e2, atol=1e-14)
    np.testing.assert_allclose(trilaterate(*e2).xyz_m, tool, atol=1e-12)


def test_broadcasts_over_trials_and_points():
    base = base_sockets_xyz(0.564, 0.564, 0.564)
    pts = np.array([[0.28, 0.16, 0.2], [0.1, 0.1, 0.3]])
    e = edges_from_points(base, pts)                           # (2, 6)
    noisy = e + np.random.default_rng(0).normal(0, 1e-7, (50, 2, 6))  # (trials, points, 6)
    res = trilaterate(*np.moveaxis(noisy, -1, 0))
    assert res.xyz_m.shape == (50, 2, 3) and res.valid.shape == (50, 2)
    # base scalars broadcast against per-point tool edges
    res2 = trilaterate(0.564, 0.564, 0.564, e[:, 3], e[:, 4], e[:, 5])
    np.testing.assert_allclose(res2.xyz_m, pts, atol=1e-12)


def test_frame_convention():
    base = base_sockets_xyz(0.5, 0.4, 0.45)
    assert np.allclose(base[0], 0) and base[1, 0] > 0 and np.allclose(base[1, 1:], 0)
    assert base[2, 1] > 0 and base[2, 2] == 0
    tool = trilaterate(0.5, 0.4, 0.45, 0.3, 0.35, 0.32).xyz_m
    assert tool[2] > 0


def test_points_on_the_base_plane_are_flagged_not_nan():
    base = base_sockets_xyz(0.564, 0.564, 0.564)
    e = edges_from_points(base, np.array([[0.28, 0.16, 0.0], [0.28, 0.16, 0.2]]))
    res = trilaterate(*e.T)
    assert res.valid.tolist() == [False, True]
    assert np.all(np.isfinite(res.xyz_m)) and res.xyz_m[0, 2] == 0.0
    # inconsistent edges (tool edges too short to meet): negative z^2, flagged
    bad = trilaterate(0.564, 0.564, 0.564, 0.3, 0.3, 0.3)
    assert not bad.valid and bad.z_squared_m2 < 0
    with pytest.raises(MultilatError, match=r"^point 0: the tool socket is at the base plane"):
        trilaterate(*e.T, on_singular="raise")
    with pytest.raises(MultilatError, match="do not close a tetrahedron"):
        trilaterate(0.564, 0.564, 0.564, 0.3, 0.3, 0.3, on_singular="raise", labels=["P9"])


def test_bad_edges_name_the_row():
    good = [0.564, 0.564, 0.564, 0.4, 0.4, 0.4]
    rows = np.array([good, good, good])
    rows[2, 3] = -0.1
    with pytest.raises(MultilatError, match=r"^point 2: l1_m must be > 0"):
        check_edges(*rows.T)
    rows[2, 3] = 0.4
    rows[1, 0] = 1.2                          # l12 > l13 + l23
    with pytest.raises(MultilatError, match=r"^P-b: base face 1-2-3 violates the triangle inequality"):
        trilaterate(*rows.T, labels=["P-a", "P-b", "P-c"])
    rows[1, 0] = 0.564
    rows[0, 4] = 1.0                          # l2 > l1 + l12? 1.0 > 0.4 + 0.564 -> violation
    with pytest.raises(MultilatError, match=r"^point 0: face tool-1-2"):
        trilaterate(*rows.T)
    rows[0, 4] = np.nan
    with pytest.raises(MultilatError, match="l2_m must be finite"):
        trilaterate(*rows.T)


from hypothesis import given, settings, strategies as st  # noqa: E402


@settings(max_examples=200, deadline=None)
@given(st.floats(0.2, 2.0), st.floats(-0.5, 1.5), st.floats(0.1, 2.0),
       st.floats(-2.0, 2.0), st.floats(-2.0, 2.0), st.floats(0.01, 2.0))
def test_round_trip_property(l12, x3_frac, y3, x, y, z):
    base = np.array([[0, 0, 0], [l12, 0, 0], [x3_frac * l12, y3, 0]], dtype=float)
    tool = np.array([x, y, z])
    res = trilaterate(*edges_from_points(base, tool))
    assert res.valid
    # conditioning: dz/dl ~ l/z, so the float64 round-off of l^2 (1e-16 l^2) shows as ~1e-16 l^2 / z
    assert np.max(np.abs(res.xyz_m - tool)) < 1e-9
