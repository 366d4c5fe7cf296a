"""Approximate coordinates of the general network (:mod:`multilat.network.adjust.approximate.general`).

Every method against a closed-form geometry: the observations are computed from a known truth by
the kinds' own models (:class:`~multilat.network.adjust.general.adjust.System` evaluated at the truth, set
orientations and tracker frames included), the free points' coordinates blanked, and the chain must
give the truth back. Noise-free, each method is exact in closed form (circular mean, Kabsch,
least-squares lines, Gauss-Newton on the distances to its fixed point), so the tolerance is 1e-9 m
on these 10-50 m networks (float64 rounding of ~1e-14 relative, amplified by the geometry).
With noise, the adjustment from the approximations must reach the same minimum as from the truth
(coordinates to 1e-8 m, vᵀPv to 1e-9 relative: both converge to a step of 1e-10).

Seeded random networks mix the kinds with occlusions and weak geometry (stations near one plane,
trilateration from three ends); the gama-local reference networks of ``tests/data/gama3d`` are
adjusted from blanked free points and must reach gama-local's solution.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.adjust.general.adjust import AdjustOptions, System, adjust
from multilat.network.adjust.approximate.general import approximate, reasons, unreachable
from multilat.network.model.observations import Block, Network, without_points
from multilat.network.model.points import FIXED, FREE, PointSet
from multilat.network.adjust.general.run import adjust_network

SD, SA = 2e-4, 1.5e-5                      # σ of distances (m) and angles (rad)
TOL = 1e-9                                 # noise-free: closed forms (module docstring)


class Design:
    """A network's design from a truth: observations added by kind, values computed by the kinds."""

    def __init__(self, truth: dict, fixed=()):
        self.ids = list(truth)
        self.truth = np.array([truth[p] for p in self.ids], float)
        self.fixed = set(fixed)
        self.blocks, self.params = [], {}

    def ix(self, p):
        return np.array([self.ids.index(q) for q in np.atleast_1d(p)], int)

    def add(self, kind, n, index, *, sigma, data=None, names=None, options=None, params=None):
        self.blocks.append(Block(kind, np.zeros(n), np.full(n, sigma), None, index, data or {},
                                 tuple(f"{kind} {k + 1}" for k in range(n)), names or {}, options or {}))
        self.params.update(params or {})

    def dist(self, pairs, from_dh=0.0, to_dh=0.0):
        f, t = zip(*pairs)
        m = len(f)
        self.add("slope_distance", m, {"from": self.ix(f), "to": self.ix(t)}, sigma=SD,
                 data={"from_dh": np.full(m, from_dh), "to_dh": np.full(m, to_dh)})

    def directions(self, station, targets, orientation, name=None):
        name = name or f"{station}#{sum(b.kind == 'direction' for b in self.blocks) + 1}"
        m = len(targets)
        self.add("direction", m, {"from": self.ix([station] * m), "to": self.ix(targets), "set": np.zeros(m, int)},
                 sigma=SA, names={"set": (name,)}, params={f"orientation:{name}": orientation})

    def zenith(self, pairs, from_dh=0.0, to_dh=0.0):
        f, t = zip(*pairs)
        m = len(f)
        self.add("zenith_angle", m, {"from": self.ix(f), "to": self.ix(t)}, sigma=SA,
                 data={"from_dh": np.full(m, from_dh), "to_dh": np.full(m, to_dh)})

    def pairs_kind(self, kind, pairs, sigma=SD):
        f, t = zip(*pairs)
        self.add(kind, len(f), {"from": self.ix(f), "to": self.ix(t)}, sigma=sigma)

    def tracker(self, station, targets, frame, levelled=True, name=None):
        name = name or station
        m = len(targets)
        self.add("tracker_angles", 2 * m, {"from": self.ix([station] * 2 * m), "to": np.tile(self.ix(targets), 2),
                                           "setup": np.zeros(2 * m, int), "component": np.repeat([0, 1], m)},
                 sigma=SA, names={"setup": (name,)}, options={"levelled": levelled},
                 params={f"{a}:{name}": v for a, v in zip(("omega", "phi", "kappa"), frame)})

    def vector(self, pairs):
        f, t = zip(*pairs)
        m = len(f)
        self.add("coordinate_difference", 3 * m, {"from": np.repeat(self.ix(f), 3), "to": np.repeat(self.ix(t), 3),
                                                  "axis": np.tile([0, 1, 2], m)}, sigma=SD)

    def network(self, rng=None, blank=True) -> Network:
        """The network: values from the truth (plus noise with ``rng``), free points blanked."""
        status = np.array([FIXED if p in self.fixed else FREE for p in self.ids])
        sys_ = System(Network(PointSet.build(self.ids, self.truth, status=status), tuple(self.blocks)))
        for name, v in self.params.items():
            sys_.layout.set_value(name, v)
        r, _ = sys_.evaluate(sys_.layout.initial())
        blocks = []
        for b, sl in zip(sys_.blocks, sys_.rows):
            v = -r[sl]
            if rng is not None:
                v = v + b.sigma * rng.standard_normal(len(v))
            blocks.append(Block(b.kind, v, b.sigma, None, b.index, b.data, b.labels, b.names, b.options))
        xyz = self.truth.copy()
        if blank:
            xyz[status == FREE] = np.nan
        return Network(PointSet.build(self.ids, xyz, status=status), tuple(blocks))

    def err(self, net: Network):
        """Largest coordinate error (m) of the approximations against the truth."""
        return float(np.nanmax(np.abs(net.points.xyz_m - self.truth)))


def _with_truth(net: Network, truth) -> Network:
    p = net.points
    return Network(PointSet(p.ids, np.array(truth, float), p.status, p.sigma_m, p.constrained), net.blocks)


def _same_minimum(net: Network, truth, datum="auto"):
    """Adjusted from the approximations and from the truth: the same minimum."""
    opt = AdjustOptions(datum=datum)
    a = adjust(approximate(net), options=opt)
    b = adjust(_with_truth(net, truth), options=opt)
    assert a.dof == b.dof
    vtpv = [float(np.sum(s.residuals ** 2)) for s in (a, b)]
    assert a.sigma0 == pytest.approx(b.sigma0, rel=1e-9, nan_ok=True)
    if datum == "free":                                   # the datum follows the approximations: shape only
        da, db = (np.linalg.norm(x.xyz_m[:, None] - x.xyz_m[None], axis=-1) for x in (a, b))
        assert np.abs(da - db).max() < 1e-8
    else:
        assert np.abs(a.xyz_m - b.xyz_m).max() < 1e-8
    return vtpv


CONTROL = {"A": [0.0, 0.0, 0.0], "B": [30.0, 2.0, 1.0], "C": [12.0, 25.0, -0.5], "D": [-8.0, 18.0, 3.0]}


# ----------------------------------------------------------------------------- each method, closed form


def test_polar_points_from_a_direction_set_with_heights():
    """S (fixed) oriented on A and B; P1, P2 polar by direction + slope distance + zenith angle with
    instrument and reflector heights; P3 by direction + horizontal distance + height difference."""
    truth = dict(CONTROL, S=[5.0, 5.0, 1.2], P1=[20.0, 14.0, 2.5], P2=[-3.0, 22.0, -1.0], P3=[14.0, -6.0, 0.3])
    d = Design(truth, fixed=["A", "B", "C", "D", "S"])
    d.directions("S", ["A", "B", "P1", "P2", "P3"], orientation=1.234)
    d.dist([("S", "P1"), ("S", "P2")], from_dh=1.55, to_dh=0.2)
    d.zenith([("S", "P1"), ("S", "P2")], from_dh=1.55, to_dh=0.2)
    d.pairs_kind("horizontal_distance", [("S", "P3")])
    d.pairs_kind("height_difference", [("S", "P3")])
    net = d.network()
    assert d.err(approximate(net)) < TOL
    _same_minimum(d.network(np.random.default_rng(1)), d.truth)


@pytest.mark.parametrize("levelled, frame", [(True, (0.0, 0.0, 2.5)), (False, (0.02, -0.03, -1.0))])
def test_polar_points_from_a_tracker(levelled, frame):
    """A tracker on fixed T oriented by its angles to fixed points (κ levelled: one suffices; ω φ κ
    unlevelled: two, here four), then its polar points (distance, azimuth, elevation)."""
    truth = dict(CONTROL, T=[6.0, 8.0, 1.0], P1=[20.0, 14.0, 2.5], P2=[-3.0, 22.0, -1.0], P3=[14.0, -6.0, 0.3])
    d = Design(truth, fixed=["A", "B", "C", "D", "T"])
    d.tracker("T", ["A", "B", "C", "D", "P1", "P2", "P3"], frame, levelled=levelled)
    d.dist([("T", p) for p in ("P1", "P2", "P3")])
    assert d.err(approximate(d.network())) < TOL
    _same_minimum(d.network(np.random.default_rng(2)), d.truth)


def test_free_station_resection():
    """S unknown: a direction set with slope distances and zenith angles to two fixed points (2D
    resection), then its polar point P; U unknown: an unlevelled tracker fitted to three fixed points
    by its distances and angles, then its polar point Q."""
    truth = dict(CONTROL, S=[5.0, 5.0, 1.2], U=[10.0, 12.0, 2.0], P=[20.0, 14.0, 2.5], Q=[-2.0, 6.0, 4.0])
    d = Design(truth, fixed=["A", "B", "C", "D"])
    d.directions("S", ["A", "B", "P"], orientation=-2.0)
    d.dist([("S", "A"), ("S", "B"), ("S", "P")])
    d.zenith([("S", "A"), ("S", "B"), ("S", "P")])
    d.tracker("U", ["A", "B", "C", "Q"], (0.01, 0.02, 0.7), levelled=False)
    d.dist([("U", "A"), ("U", "B"), ("U", "C"), ("U", "Q")])
    assert d.err(approximate(d.network())) < TOL
    _same_minimum(d.network(np.random.default_rng(3)), d.truth)


def test_resection_from_directions_alone():
    """S unknown: directions to A, B, C, D (fixed) and zenith angles to two of them, no distance:
    the orientation grid and Gauss-Newton on the directions place it, then its polar point P."""
    truth = dict(CONTROL, S=[6.0, 7.0, 1.2], P=[20.0, 14.0, 2.5])
    d = Design(truth, fixed=["A", "B", "C", "D"])
    d.directions("S", ["A", "B", "C", "D", "P"], orientation=2.7)
    d.zenith([("S", "A"), ("S", "C"), ("S", "P")], from_dh=1.5)
    d.dist([("S", "P")], from_dh=1.5)
    out = approximate(d.network())
    assert d.err(out) < TOL and "(1 resection, 1 polar)" in out.notes[-1]
    _same_minimum(d.network(np.random.default_rng(10)), d.truth)


def test_intersection_of_rays_and_planes():
    """P: directions and zenith angles (rays) from fixed S1 and S2, no distance; Q: directions only
    from S1 and S2 (two vertical planes) and a height difference from A; both exact. R: sights from
    S1 and S2 within 0.3 degrees of parallel: placed, and flagged."""
    truth = dict(CONTROL, S1=[1.0, -3.0, 1.0], S2=[30.0, 0.0, 1.0], P=[14.0, 20.0, 3.0], Q=[8.0, 9.0, -1.0],
                 R=[59.0, 3.15, 1.0])
    d = Design(truth, fixed=["A", "B", "C", "D", "S1", "S2"])
    d.directions("S1", ["A", "B", "P", "Q", "R"], orientation=0.4)
    d.directions("S2", ["A", "C", "P", "Q", "R"], orientation=2.9)
    d.zenith([("S1", "P"), ("S2", "P"), ("S1", "R"), ("S2", "R")])
    d.pairs_kind("height_difference", [("A", "Q")])
    out = approximate(d.network())
    assert d.err(out) < 1e-7                 # R: the near-parallel pair amplifies rounding (1/sin 0.3 deg)
    assert np.abs(out.points.xyz_m[:-1] - d.truth[:-1]).max() < TOL
    assert any("'R': intersected by rays" in n and "(weak)" in n for n in out.notes)
    assert not any("'P'" in n or "'Q'" in n for n in out.notes)


@pytest.mark.parametrize("below", [False, True])
def test_multilateration_and_trilateration(below):
    """P: distances to four fixed points not in one plane (multilateration). Q: distances to three
    fixed points, above or below their plane: the mirror position is picked by a height difference
    from D (either side). R: three distances and nothing else: not placed, and named."""
    z = -4.0 if below else 6.0
    truth = dict(CONTROL, P=[10.0, 9.0, 5.0], Q=[11.0, 7.0, z], R=[5.0, 3.0, 2.0])
    d = Design(truth, fixed=["A", "B", "C", "D"])
    d.dist([(c, "P") for c in "ABCD"] + [(c, "Q") for c in "ABC"] + [(c, "R") for c in "ABC"])
    d.pairs_kind("height_difference", [("D", "Q")])
    net = d.network()
    why = reasons(net)
    assert list(why) == ["R"] and "distances to 3 placed point(s)" in why["R"] and "trilateration 3" in why["R"]
    with pytest.raises(MultilatError, match=r"^point 'R': no approximate coordinates can be computed"):
        approximate(net)
    out = approximate(net, partial=True)
    assert np.abs(out.points.xyz_m[:-1] - d.truth[:-1]).max() < TOL and np.isnan(out.points.xyz_m[-1]).all()


def test_distance_only_search_self_calibrating():
    """Four heads (additive constants estimated), 14 targets, no point known: the distance-only
    search of the distance path (``starts.initial_for``) places everything; the adjustment (free
    network) reaches the minimum it reaches from the truth."""
    rng = np.random.default_rng(20261127)
    st = {f"H{i}": [10 * np.cos(a), 10 * np.sin(a), 1.5 + 2 * (i % 2)] for i, a in enumerate([0.3, 1.9, 3.5, 5.0])}
    tg = {f"T{k:02d}": rng.uniform([-6, -6, -1], [6, 6, 4]).tolist() for k in range(14)}
    d = Design({**st, **tg})
    d.dist([(h, t) for h in st for t in tg])
    b = d.blocks[0]
    d.blocks[0] = Block(b.kind, b.value, b.sigma, None, {**b.index, "instrument": np.repeat(np.arange(4), 14)},
                        b.data, b.labels, {"instrument": tuple(st)}, {"estimate_offset": True})
    net = d.network(np.random.default_rng(4))
    out = approximate(net)
    assert any("distance-only search" in n for n in out.notes)
    _same_minimum(net, d.truth, datum="free")


def test_no_known_point_first_setup_is_origin():
    """Two levelled trackers, no coordinates at all: T1 is the origin with the world's axes, T2
    resected on the polar points of T1; the shape is the truth's (interpoint distances to 1e-9 m)."""
    rng = np.random.default_rng(5)
    tg = {f"P{k}": rng.uniform([-5, 2, -1], [5, 9, 2]).tolist() for k in range(8)}
    d = Design({"T1": [0.5, -1.0, 0.2], "T2": [7.0, 1.0, 0.4], **tg})
    for t, kap in (("T1", 0.7), ("T2", 2.2)):
        d.tracker(t, list(tg), (0.0, 0.0, kap))
        d.dist([(t, p) for p in tg])
    out = approximate(d.network())
    x = out.points.xyz_m
    assert np.all(x[0] == 0.0) and any("'T1' is the origin" in n for n in out.notes)
    da, db = (np.linalg.norm(v[:, None] - v[None], axis=-1) for v in (x, d.truth))
    assert np.abs(da - db).max() < TOL
    _same_minimum(d.network(np.random.default_rng(6)), d.truth, datum="free")


def test_vectors_horizontal_angles_and_height_of_a_polar_point():
    """V1, V2: coordinate differences off A and V1; H: a horizontal angle at fixed S (backsight A)
    with a horizontal distance and a height difference; L: a direction and a slope distance from S
    (no zenith angle), its height levelled from B."""
    truth = dict(CONTROL, S=[5.0, 5.0, 1.2], V1=[3.0, -4.0, 2.0], V2=[9.0, -9.0, 1.0], H=[18.0, 12.0, 0.5],
                 L=[-6.0, 9.0, 2.2])
    d = Design(truth, fixed=["A", "B", "C", "D", "S"])
    d.vector([("A", "V1"), ("V1", "V2")])
    d.add("horizontal_angle", 1, {"from": d.ix("S"), "bs": d.ix("A"), "fs": d.ix("H")}, sigma=SA)
    d.pairs_kind("horizontal_distance", [("S", "H")])
    d.pairs_kind("height_difference", [("S", "H"), ("B", "L")])
    d.directions("S", ["A", "L"], orientation=0.3)
    d.dist([("S", "L")])
    assert d.err(approximate(d.network())) < TOL
    _same_minimum(d.network(np.random.default_rng(7)), d.truth)


def test_unreachable_point_named_and_left_out():
    """LOST has one distance: named in one line saying what would reach it, left out by
    adjust_network with that reason; the rest adjusted."""
    truth = dict(CONTROL, P=[10.0, 9.0, 5.0], LOST=[4.0, 4.0, 4.0])
    d = Design(truth, fixed=["A", "B", "C", "D"])
    d.dist([(c, "P") for c in "ABCD"] + [("A", "LOST")])
    net = d.network(np.random.default_rng(8))
    assert unreachable(net) == ("LOST",)
    adj = adjust_network(net)
    (ex,) = adj.excluded
    assert ex["id"] == "LOST" and ex["n_obs"] == 1 and "distances to 1 placed point(s)" in ex["reason"]
    assert "LOST" not in adj.network.points.ids


# ----------------------------------------------------------------------------- random networks


def _random_design(seed: int):
    """Control (3-5 fixed), 3-5 stations of random kinds (direction set with slope distances and
    zenith angles; levelled or unlevelled tracker; distance-only head), some of them fixed, 8-16
    targets, each sight present with probability 0.45-0.9 (occlusions); stations near one plane
    (weak for multilateration); a few height differences and a vector."""
    rng = np.random.default_rng(seed)
    n_c, n_s, n_t = rng.integers(3, 6), rng.integers(3, 6), rng.integers(8, 17)
    ctrl = {f"C{k}": rng.uniform([-20, -20, -2], [20, 20, 6]) for k in range(n_c)}
    sta = {f"S{k}": np.r_[rng.uniform(-15, 15, 2), 1.5 + 0.01 * rng.standard_normal()] for k in range(n_s)}
    tg = {f"P{k:02d}": rng.uniform([-18, -18, -3], [18, 18, 8]) for k in range(n_t)}
    d = Design({**ctrl, **sta, **tg}, fixed=list(ctrl) + [s for s in sta if rng.random() < 0.3])
    p_see = rng.uniform(0.45, 0.9)
    for s in sta:
        seen = [p for p in list(ctrl) + list(tg) + [o for o in sta if o != s] if rng.random() < p_see]
        if len(seen) < 2:
            continue
        kind = rng.choice(["set", "levelled", "unlevelled", "head"])
        if kind == "set":
            d.directions(s, seen, orientation=rng.uniform(-np.pi, np.pi))
            ranged = [p for p in seen if rng.random() < 0.8]
            if ranged:
                d.dist([(s, p) for p in ranged])
                d.zenith([(s, p) for p in ranged])
        elif kind in ("levelled", "unlevelled"):
            tilt = (0.0, 0.0) if kind == "levelled" else tuple(rng.uniform(-0.05, 0.05, 2))
            d.tracker(s, seen, (*tilt, rng.uniform(-np.pi, np.pi)), levelled=kind == "levelled")
            d.dist([(s, p) for p in seen if rng.random() < 0.85] or [(s, seen[0])])
        else:
            d.dist([(s, p) for p in seen])
    lev = [p for p in tg if rng.random() < 0.2]
    if lev:
        d.pairs_kind("height_difference", [(next(iter(ctrl)), p) for p in lev])
    d.vector([(next(iter(ctrl)), list(tg)[0])])
    return d


@pytest.mark.parametrize("seed", range(40))
def test_random_networks(seed):
    """Noise-free: every point a closed-form method places is the truth (1e-7 m: trilateration on
    ends near one plane and weak intersections amplify rounding); a target the distance-only search
    places as the last resort may be the mirror image of the truth (three distances from stations
    near one plane cannot tell), so there the test is that the adjustment from the approximations
    fits the noise-free observations exactly (σ0 < 1e-6: an exact solution). With noise and no such
    target, adjust_network from the chain reaches the minimum the same network (its unreached points
    left out) reaches from the truth."""
    from multilat.network.adjust.approximate.general import chain

    d = _random_design(seed)
    exact = d.network()
    st = chain(exact)
    searched = [j for j, how in st.method.items() if how == "distance-only search"]
    closed = np.array([st.known[j] and j not in searched for j in range(len(d.ids))], bool)
    assert np.abs(st.xyz[closed] - d.truth[closed]).max() < 1e-7
    net = d.network(np.random.default_rng(seed))
    missing = unreachable(net)
    unreached = {d.ids[j] for j in np.flatnonzero(~st.known)}
    assert unreached <= set(missing) <= unreached | {d.ids[j] for j in searched}   # the search's depend on values
    try:
        adj = adjust_network(net)
    except MultilatError as e:                            # nothing determinable left: named in one line
        assert "\n" not in str(e)
        return
    gone = [e["id"] for e in adj.excluded]
    assert set(missing) <= set(gone)
    if searched:
        assert adjust_network(exact).result.sigma0 < 1e-6
        return
    ref, _ = without_points(_with_truth(net, d.truth), gone)
    res = adjust(ref)
    assert res.dof == adj.result.dof
    assert np.abs(adj.result.xyz_m - res.xyz_m).max() < 1e-7


def test_random_networks_use_every_method():
    """The 40 random networks above exercise every method of the chain, and leave some points
    unreached (occlusions): counted from the chain's record (measured: polar 398, resection 68,
    vector 40, multilateration 9, intersection 6, distance-only search 4 (targets, as the last
    resort), trilateration 3; 66 of 811 points unreached)."""
    from collections import Counter

    from multilat.network.adjust.approximate.general import chain

    used, missing = Counter(), 0
    for seed in range(40):
        st = chain(_random_design(seed).network())
        used.update(st.method.values())
        missing += int((~st.known).sum())
    assert set(used) >= {"polar", "resection", "vector", "multilateration", "trilateration", "intersection",
                         "distance-only search"}
    assert missing > 0


# ----------------------------------------------------------------------------- gama-local's networks

GAMA3D = Path(__file__).resolve().parent / "data" / "gama3d"
NETWORKS = ["two_trackers", "station_control", "partly_fixed", "heights", "traverse", "direction_sets",
            "angles_hdist", "height_differences", "vectors", "trilateration_fixed", "trilateration_free"]


@pytest.mark.parametrize("name", NETWORKS)
def test_gama3d_from_blanked_free_points(name):
    """The free coordinates of every gama3d network blanked: the chain computes them all, and the
    adjustment reaches the solution it reaches from the file's approximations (dof, σ0 to 1e-9;
    coordinates to 1e-8 m; for the two free networks, whose minimum-trace datum follows the
    approximations, the interpoint distances), hence gama-local's (tests/test_general_gama3d.py)."""
    from multilat.network.io.interop.gama_input import read_gama_input

    net = read_gama_input(GAMA3D / f"{name}.xml")
    p = net.points
    xyz = np.where(p.status == FREE, np.nan, p.xyz_m)
    blank = Network(PointSet(p.ids, xyz, p.status, p.sigma_m, p.constrained), net.blocks)
    assert unreachable(blank) == ()
    a, b = adjust(approximate(blank)), adjust(approximate(net))
    assert a.dof == b.dof and a.sigma0 == pytest.approx(b.sigma0, rel=1e-9)
    if p.constrained.any():
        da, db = (np.linalg.norm(x.xyz_m[:, None] - x.xyz_m[None], axis=-1) for x in (a, b))
        assert np.abs(da - db).max() < 1e-8
    else:
        assert np.abs(a.xyz_m - b.xyz_m).max() < 1e-8


# ----------------------------------------------------------------------------- multilat's tables


def test_tables_angles_without_sigma_serve_the_approximations():
    """``network_from_tables``: two unlevelled trackers whose azimuths and elevations have no σ (not
    observations: the blocks hold distances only) still give the chain its readings: T1 the origin,
    its polar points, T2 placed from them (multilateration comes first in the pass); noise-free, the
    shape is the truth's to 1e-9 m."""
    from multilat.network.model.angles import rotation_matrix
    from multilat.network.model.data import Observations
    from multilat.network.adjust.general.from_tables import network_from_tables

    rng = np.random.default_rng(9)
    st = np.array([[0.0, 0.0, 0.0], [8.0, 1.0, 0.5]])
    ori = np.array([[0.02, -0.01, 0.4], [-0.03, 0.02, 2.6]])
    tg = rng.uniform([-4, 3, -1], [12, 10, 3], (12, 3))
    s, t = np.repeat([0, 1], 12), np.tile(np.arange(12), 2)
    v = np.einsum("kji,kj->ki", rotation_matrix(ori[s]), tg[t] - st[s])          # R^T (T - H)
    obs = Observations.from_labels([f"T{i + 1}" for i in s], [f"P{j:02d}" for j in t], np.linalg.norm(v, axis=1),
                                   SD, azimuth_rad=np.arctan2(v[:, 1], v[:, 0]),
                                   elevation_rad=np.arctan2(v[:, 2], np.hypot(v[:, 0], v[:, 1])))
    net, _ = network_from_tables(obs)
    assert {b.kind for b in net.blocks} == {"slope_distance"}
    x = net.points.xyz_m
    truth = np.vstack([st, tg])
    da, db = (np.linalg.norm(p[:, None] - p[None], axis=-1) for p in (x, truth))
    assert np.abs(da - db).max() < TOL
    assert any("(1 origin, 12 polar, 1 multilateration)" in n for n in net.notes)   # T2 from its 12 distances
