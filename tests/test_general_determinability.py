"""Determinability from the observations, not from counts: the defect of a distance-only free
network, a point with as many observations as unknowns that they still cannot fix (coplanar lines
of sight), and non-convergence, each named in one line."""

from __future__ import annotations

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.adjust.general.adjust import AdjustOptions, adjust
from multilat.network.model.observations import Block, Network
from multilat.network.model.points import FIXED, FREE, PointSet

STATIONS = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 10.0, 0.0], [10.0, 10.0, 3.0]])


def _distances(xyz, pairs, rng, sigma=1e-5):
    a, b = np.array(pairs).T
    d = np.linalg.norm(xyz[b] - xyz[a], axis=1) + sigma * rng.standard_normal(len(a))
    return Block("slope_distance", d, np.full(len(a), sigma), None, {"from": a, "to": b})


def test_free_distance_network_defect_six():
    rng = np.random.default_rng(1)
    xyz = np.vstack([STATIONS, rng.uniform(0, 10, (6, 3))])
    pairs = [(i, j) for i in range(4) for j in range(4, 10)] + [(0, 1), (0, 2), (1, 3)]
    pts = PointSet.build([f"P{i}" for i in range(10)], xyz + 1e-3 * rng.standard_normal((10, 3)))
    res = adjust(Network(pts, (_distances(xyz, pairs, rng),)), options=AdjustOptions(datum="free"))
    assert res.defect == 6 and res.dof == len(pairs) - 30 + 6
    # with no datum points the same network is refused, naming points
    with pytest.raises(MultilatError, match=r"not determined by the observations \(datum defect 6, no datum points"):
        adjust(Network(pts, (_distances(xyz, pairs, rng),)), options=AdjustOptions(datum="fixed"))


def test_coplanar_lines_of_sight_are_named_whatever_the_count():
    """Three distances from three fixed stations to a target in their plane: 3 observations for 3
    unknowns, yet its height is not determined (the Jacobian's rows are coplanar)."""
    rng = np.random.default_rng(2)
    xyz = np.vstack([STATIONS[:3], [[4.0, 3.0, 0.0]], [[5.0, 5.0, 2.0]]])
    pairs = [(0, 3), (1, 3), (2, 3), (0, 4), (1, 4), (2, 4)]
    pts = PointSet.build(["S1", "S2", "S3", "FLAT", "GOOD"], xyz + np.array([[0, 0, 0]] * 3 + [[1e-3, 0, 0], [0, 1e-3, 0]]),
                         status=[FIXED] * 3 + [FREE] * 2)
    with pytest.raises(MultilatError, match=r"^point 'FLAT' not determined by the observations \(datum defect 1"):
        adjust(Network(pts, (_distances(xyz, pairs, rng),)))


def test_non_convergence_is_one_line():
    rng = np.random.default_rng(3)
    xyz = np.vstack([STATIONS, [[5.0, 5.0, 2.0]]])
    pts = PointSet.build([f"P{i}" for i in range(5)], xyz + np.array([[0, 0, 0]] * 4 + [[0.5, -0.3, 0.4]]),
                         status=[FIXED] * 4 + [FREE])
    with pytest.raises(MultilatError, match=r"did not converge in 1 iterations \(last step") as e:
        adjust(Network(pts, (_distances(xyz, [(i, 4) for i in range(4)], rng),)),
               options=AdjustOptions(max_iterations=1))
    assert "\n" not in str(e.value)
