"""Each observation kind of the general network: its Jacobian rows against central finite
differences of its own model (seeded random networks), its model against a closed form written
here, and the registry's contract.

Finite differences: step 1e-6 (metres or radians) on parameters of order 1-100; the central
difference's truncation error is O(h^2 f''') ~ 1e-12 relative and its rounding ~ eps |f| / h ~
1e-8 for values of order 100: tolerance 1e-6 absolute on derivatives of order 1e-2 .. 1.
"""

from __future__ import annotations

import numpy as np
import pytest

from multilat.network.model.angles import rotation_matrix
from multilat.network.model.kinds import KINDS, kind
from multilat.network.model.layout import Layout
from multilat.network.model.observations import Block
from multilat.network.model.points import PointSet


def _network(rng, n=6):
    xyz = rng.uniform(-50, 50, (n, 3))
    xyz[:, 2] *= 0.2
    return PointSet.build([f"P{i}" for i in range(n)], xyz)


def _pairs(rng, n, m):
    a = rng.integers(0, n, m)
    b = (a + rng.integers(1, n, m)) % n
    return a, b


def _blocks(rng, n, m=8):
    """One block of every kind, random references, heights, instruments, sets, set-ups."""
    a, b = _pairs(rng, n, m)
    c = (b + rng.integers(1, n - 1, m)) % n
    c = np.where(c == a, (c + 1) % n, c)
    c = np.where(c == b, (c + 1) % n, c)
    c = np.where(c == a, (c + 1) % n, c)
    h = {"from_dh": rng.uniform(0, 2, m), "to_dh": rng.uniform(0, 2, m)}
    one = np.ones(m)
    return [
        Block("slope_distance", one, one, None, {"from": a, "to": b, "instrument": rng.integers(-1, 2, m)}, h,
              names={"instrument": ("I1", "I2")}, options={"estimate_offset": True, "estimate_scale": True}),
        Block("direction", one, one, None, {"from": a, "to": b, "set": rng.integers(0, 3, m)},
              names={"set": ("S1", "S2", "S3")}),
        Block("zenith_angle", one, one, None, {"from": a, "to": b}, h),
        Block("horizontal_distance", one, one, None, {"from": a, "to": b}),
        Block("horizontal_angle", one, one, None, {"from": a, "bs": b, "fs": c}),
        Block("height_difference", one, one, None, {"from": a, "to": b}),
        Block("coordinate_difference", np.ones(m), one, None, {"from": a, "to": b, "axis": rng.integers(0, 3, m)}),
        Block("observed_coordinates", one, one, None, {"point": a, "axis": rng.integers(0, 3, m)}),
        Block("tracker_angles", one, one, None, {"from": a, "to": b, "setup": rng.integers(0, 2, m),
                                                  "component": rng.integers(0, 2, m)}, h,
              names={"setup": ("U1", "U2")}, options={"levelled": False}),
    ]


def test_every_kind_is_registered_and_tested():
    assert sorted(KINDS) == sorted(b.kind for b in _blocks(np.random.default_rng(0), 6))
    with pytest.raises(Exception, match="unknown observation kind 'laser'"):
        kind("laser")


@pytest.mark.parametrize("seed", range(5))
def test_jacobian_against_central_differences(seed):
    rng = np.random.default_rng(seed)
    pts = _network(rng)
    layout = Layout(pts)
    blocks = _blocks(rng, pts.n)
    cols = [kind(b.kind).register(b, layout) for b in blocks]
    x = layout.initial()
    extra = ~layout.point_coordinate_mask()
    x[extra] = rng.uniform(-0.3, 0.3, extra.sum())          # offsets, scales, orientations, frames
    step = 1e-6
    for b, c in zip(blocks, cols):
        mod = kind(b.kind)
        f0, values, columns = mod.evaluate(b, layout, c, x)
        dense = np.zeros((len(f0), layout.n))
        keep = columns >= 0
        np.add.at(dense, (np.broadcast_to(np.arange(len(f0))[:, None], columns.shape)[keep], columns[keep]),
                  values[keep])
        numeric = np.empty_like(dense)
        for j in range(layout.n):
            xp, xm = x.copy(), x.copy()
            xp[j] += step
            xm[j] -= step
            diff = mod.evaluate(b, layout, c, xp)[0] - mod.evaluate(b, layout, c, xm)[0]
            if mod.ANGULAR:
                diff = np.angle(np.exp(1j * diff))
            numeric[:, j] = diff / (2 * step)
        assert np.abs(dense - numeric).max() < 1e-6, b.kind


def test_models_against_closed_forms():
    """Each model at one hand-made configuration (values worked out here, not by the kinds)."""
    pts = PointSet.build(["A", "B", "C"], [[0, 0, 10], [3, 4, 10], [-4, 3, 12]])
    layout = Layout(pts)
    one = np.ones(1)
    ab = {"from": np.array([0]), "to": np.array([1])}

    def model(block):
        c = kind(block.kind).register(block, layout)       # new parameters start at 0
        return kind(block.kind).evaluate(block, layout, c, layout.initial())[0][0]

    sd = Block("slope_distance", one, one, None, ab, {"from_dh": np.array([1.5]), "to_dh": np.array([2.5])})
    assert model(sd) == pytest.approx(np.sqrt(25 + 1))                 # rise 1 m between the heights
    assert model(Block("zenith_angle", one, one, None, ab, {"from_dh": np.array([1.5]), "to_dh": np.array([2.5])})) \
        == pytest.approx(np.arctan2(5, 1))
    assert model(Block("horizontal_distance", one, one, None, ab)) == pytest.approx(5)
    d = Block("direction", one, one, None, {**ab, "set": np.array([0])}, names={"set": ("A#1",)})
    assert model(d) == pytest.approx(np.arctan2(4, 3))                 # orientation 0: counter-clockwise from east
    ang = Block("horizontal_angle", one, one, None, {"from": np.array([0]), "bs": np.array([1]), "fs": np.array([2])})
    assert model(ang) == pytest.approx(np.pi / 2)                       # (3,4) -> (-4,3): a quarter turn left
    assert model(Block("height_difference", one, one, None, {"from": np.array([0]), "to": np.array([2])})) == 2
    vec = Block("coordinate_difference", one, one, None, {**ab, "axis": np.array([1])})
    assert model(vec) == 4
    ta = Block("tracker_angles", one, one, None, {**ab, "setup": np.array([0]), "component": np.array([0])},
               names={"setup": ("U",)})
    assert model(ta) == pytest.approx(np.arctan2(4, 3))
    R = rotation_matrix([0.0, 0.0, 0.3])
    assert R[0, 0] == pytest.approx(np.cos(0.3))                          # kappa turns counter-clockwise
