"""The paper's two experiments as configurations: every constraint the text of seed 000 §4 states."""

import numpy as np
import pytest
from scipy.spatial import Delaunay

from multilat.errors import MultilatError
from multilat.network.synthetic.configs import (LARGE_FLOOR_Z_M, NetworkConfig, get_config, large_volume,
                                      small_volume, triplet_points)
from multilat.network.model.data import ReferenceLengths


def test_head_coordinates_as_published():
    # §4.1 and §4.2, in mm
    # (to 1e-12 mm: the mm -> m conversion rounds)
    np.testing.assert_allclose(small_volume().station_xyz_m * 1e3,
                               [[504, 938, 491], [0, 0, 0], [524, -7, 909], [1050, 0, 0]], rtol=0, atol=1e-12)
    np.testing.assert_allclose(large_volume().station_xyz_m * 1e3,
                               [[0, 0, 0], [2736, 56, 1406], [5289, 0, 0], [2692, 6236, 793]], rtol=0, atol=1e-12)
    for cfg in (small_volume(), large_volume()):
        assert cfg.station_ids == ("A", "B", "C", "D")
        assert cfg.target_ids == tuple(str(k) for k in range(1, 15))   # 14 positions, 56 distances
        assert cfg.geometric_distances_m().size == 56


def test_small_tetrahedron_edges_1091_pm_71_mm():
    """§4.1: 'a tetrahedron with edges of 1091 mm ± 71 mm' (mean ± sample std of the 6 edges,
    published to the mm: tolerance 0.5 mm)."""
    H = small_volume().station_xyz_m
    e = [np.linalg.norm(H[i] - H[j]) for i in range(4) for j in range(i + 1, 4)]
    assert abs(np.mean(e) - 1.091) < 0.5e-3
    assert abs(np.std(e, ddof=1) - 0.071) < 0.5e-3


def test_small_volume_triplets_are_exact():
    cfg = small_volume()
    refs = cfg.reference_lengths
    assert len(refs) == 9
    np.testing.assert_allclose(refs.length_m * 1e3, [150.022, 174.615, 324.636] * 3, rtol=1e-15)
    assert [(a, b) for a, b in zip(refs.target_a, refs.target_b)] == [
        ("1", "2"), ("2", "3"), ("1", "3"), ("6", "7"), ("7", "8"), ("6", "8"),
        ("12", "13"), ("13", "14"), ("12", "14")]
    # the truth matches every published length (1e-12 m: rounding only)
    np.testing.assert_allclose(cfg.true_lengths_m(), refs.length_m, rtol=0, atol=1e-12)
    # 'aligned': P2 within 0.5 mm of the P1-P3 line (the lengths force 0.40 mm off it)
    T = cfg.target_xyz_m
    for p1, p2, p3 in ((0, 1, 2), (5, 6, 7), (11, 12, 13)):
        u = (T[p3] - T[p1]) / np.linalg.norm(T[p3] - T[p1])
        off = np.linalg.norm(np.cross(T[p2] - T[p1], u))
        assert 0.39e-3 < off < 0.41e-3


def test_large_volume_couples_and_pillars():
    cfg = large_volume()
    refs = cfg.reference_lengths
    np.testing.assert_allclose(refs.length_m * 1e3, [324.071] * 3 + [2232.037, 6700.471, 8932.509], rtol=1e-15)
    diff = cfg.true_lengths_m() - refs.length_m
    np.testing.assert_allclose(diff[:5], 0.0, atol=1e-12)
    # 2232.037 + 6700.471 = 8932.508 < 8932.509: no three points match all three; the truth is on a
    # line, 1 um short of the published P1-P3
    assert abs(diff[5] + 1e-6) < 1e-12
    T = cfg.target_xyz_m
    p = T[[2, 6, 11]]
    assert np.linalg.matrix_rank(p[1:] - p[0], tol=1e-12) == 1        # aligned pillars
    assert np.ptp(p[:, 2]) == 0.0                                         # same height


def test_distance_ranges_as_published():
    small = small_volume().geometric_distances_m()
    assert abs(small.max() - 1.47) < 0.5e-3          # 'maximal measured distance is 1.47 m'
    large = large_volume().geometric_distances_m()
    assert abs(large.min() - 0.34) < 0.5e-3          # 'from 0.34 m to 11.54 m'
    assert abs(large.max() - 11.54) < 0.5e-3


def test_volumes_as_published():
    def box(cfg):
        P = np.vstack([cfg.station_xyz_m, cfg.target_xyz_m])
        return np.ptp(P, axis=0)

    assert 0.8 < np.prod(box(small_volume())) < 1.2          # 'about one cubic meter'
    np.testing.assert_allclose(box(large_volume()), [5.6, 10.3, 2.6], atol=0.005)


def test_large_volume_heights_and_outside_targets():
    cfg = large_volume()
    height = cfg.target_xyz_m[:, 2] - LARGE_FLOOR_Z_M
    assert np.all(height > 0)
    assert np.sum(height < 1.5) >= 10        # 'most of the targets have a height less than 1.5 m'
    hull = Delaunay(cfg.station_xyz_m)
    outside = hull.find_simplex(cfg.target_xyz_m) < 0
    assert outside.sum() >= 5                # 'some of them largely outside the volume bounded by the heads'
    assert cfg.target_xyz_m[:, 1].max() > cfg.station_xyz_m[:, 1].max() + 3.0   # 'largely'


def test_small_volume_up_axis_and_offsets():
    cfg = small_volume()
    assert cfg.vertical_axis == 1 and large_volume().vertical_axis == 2
    # three heads share the table plane y ~ 0; targets above the table
    assert np.sum(np.abs(cfg.station_xyz_m[:, 1]) < 0.01) == 3
    assert np.all(cfg.target_xyz_m[:, 1] > 0)
    for c in (small_volume(), large_volume()):
        assert np.all(np.abs(c.offset_m) <= 5e-3) and np.any(c.offset_m != 0)


def test_triplet_points_closed_form():
    P = triplet_points((0, 0, 0), (1, 0, 0), a_m=3.0, b_m=4.0, c_m=5.0)   # 3-4-5 right triangle
    assert np.linalg.norm(P[1] - P[0]) == pytest.approx(3.0, abs=1e-15)
    assert np.linalg.norm(P[2] - P[1]) == pytest.approx(4.0, abs=1e-15)
    np.testing.assert_allclose(P[1], [1.8, 0, 2.4], atol=1e-15)          # height 3*4/5 towards +z
    with pytest.raises(MultilatError, match="no triangle"):
        triplet_points((0, 0, 0), (1, 0, 0), a_m=1.0, b_m=1.0, c_m=2.5)


def test_config_validation():
    refs = ReferenceLengths(("1",), ("2",), np.array([1.0]), np.array([np.nan]))
    H = np.eye(4, 3)
    T = np.array([[0, 0, 1.0], [1, 1, 1.0]])
    with pytest.raises(MultilatError, match="at least 4 stations"):
        NetworkConfig("x", ("A", "B", "C"), H[:3], ("1", "2"), T, np.zeros(3), refs)
    with pytest.raises(MultilatError, match="unknown point id '9'"):
        NetworkConfig("x", ("A", "B", "C", "D"), H, ("1", "2"), T, np.zeros(4),
                      ReferenceLengths(("1",), ("9",), np.array([1.0]), np.array([np.nan])))
    with pytest.raises(MultilatError, match="finite"):
        NetworkConfig("x", ("A", "B", "C", "D"), H, ("1", "2"), T * np.nan, np.zeros(4), refs)
    with pytest.raises(MultilatError, match="unknown configuration 'medium'"):
        get_config("medium")
    assert get_config("large-volume").name == "large-volume"
