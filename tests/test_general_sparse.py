"""The sparse back end of the general network (multilat.network.adjust.general.sparse) against the dense one
(an independent solution: SVD of the dense whitened Jacobian and the inverse of the bordered normal
matrix), and against the distance-only path on a large distance-only network.

Tolerances (both back ends solve the same least-squares problem in double precision; the difference
is rounding, amplified by the condition of the normal equations, ~1e-12 relative on these networks):
σ0 to 1e-9 relative, coordinates and other parameters to 1e-9 (metres, radians), point cofactors to
1e-8 of the largest point cofactor (cofactors are m², ~1e-10: an absolute 1e-8 would test nothing),
redundancy numbers to 1e-8 (dimensionless, in [0, 1]); the undetermined points named identically.

Networks: the 11 gama3d reference networks (tests/data/gama3d), the tracker networks of
tests/test_general_trackers.py (two levelled trackers, one tracker on control with polar points),
the small-volume tracker network of tests/general_tracker_network.py (trackers, distance-only heads,
scale bars, weighted control), free networks (inner constraints over all points), the random mixed
networks of tests/test_general_approximate.py (its Design generator), and 8 stations x 2 000 targets
of :func:`multilat.network.synthetic.generator.synthetic_network` ("rings") against :func:`multilat.network.adjust.distance.adjust.adjust`.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.adjust.general.adjust import AdjustOptions, System, UndeterminedError, adjust, backend_for
from multilat.network.adjust.approximate.general import approximate
from multilat.network.io.interop.gama_input import read_gama_input
from multilat.network.model.observations import Block, Network
from multilat.network.model.points import FIXED, FREE, PointSet

sys.path.insert(0, str(Path(__file__).parent))
from general_tracker_network import tracker_network  # noqa: E402
from test_general_approximate import _random_design, _with_truth  # noqa: E402
from test_general_trackers import SIG_D, _blocks, _simulate  # noqa: E402

GAMA = Path(__file__).resolve().parent / "data" / "gama3d"
NETWORKS = ["two_trackers", "station_control", "partly_fixed", "heights", "traverse", "direction_sets",
            "angles_hdist", "height_differences", "vectors", "trilateration_fixed", "trilateration_free"]
gadjust = importlib.import_module("multilat.network.adjust.general.adjust")


def _both(net: Network, datum: str = "auto"):
    dense = adjust(net, options=AdjustOptions(datum=datum, backend="dense"))
    sparse = adjust(net, options=AdjustOptions(datum=datum, backend="sparse"))
    assert dense.backend == "dense" and sparse.backend == "sparse"
    return dense, sparse


def _same(a, b):
    assert a.dof == b.dof and a.defect == b.defect
    if a.dof > 0:
        assert b.sigma0 == pytest.approx(a.sigma0, rel=1e-9)
    assert np.abs(a.xyz_m - b.xyz_m).max() < 1e-9
    assert np.abs(a.parameters - b.parameters).max() < 1e-9
    qa = np.stack([a.point_cofactor(p) for p in a.ids])
    qb = np.stack([b.point_cofactor(p) for p in b.ids])
    assert np.abs(qa - qb).max() <= 1e-8 * np.abs(qa).max()
    assert np.abs(a.redundancy - b.redundancy).max() < 1e-8
    assert b.redundancy.sum() == pytest.approx(b.dof, abs=1e-6)
    # the interface every consumer uses: diagonal, Q times columns, a block; the dense Q kept (small n)
    big = np.abs(a.cofactor).max()
    assert np.abs(a.cofactor_diagonal() - b.cofactor_diagonal()).max() <= 1e-8 * big
    assert np.abs(a.cofactor - b.cofactor).max() <= 1e-8 * big
    m = np.random.default_rng(0).standard_normal((len(a.free_names), 2))
    assert np.abs(a.cofactor_times(m) - b.cofactor_times(m)).max() <= 1e-8 * big * np.abs(m).sum(0).max()
    cols = [0, len(a.free_names) - 1]
    assert np.abs(a.cofactor_block(cols) - b.cofactor_block(cols)).max() <= 1e-8 * big


@pytest.mark.parametrize("name", NETWORKS)
def test_gama3d_networks(name):
    net = approximate(read_gama_input(GAMA / f"{name}.xml"))
    _same(*_both(net))


@pytest.mark.parametrize("name", NETWORKS)
def test_gama3d_networks_free_over_all_points(name):
    """Inner constraints over every point (the datum the file gives replaced): minimum trace."""
    net = approximate(read_gama_input(GAMA / f"{name}.xml"))
    pts = net.points
    free = PointSet(pts.ids, pts.xyz_m, np.where(pts.status == FIXED, FREE, pts.status), pts.sigma_m,
                    np.ones(pts.n, bool))
    a, b = _both(Network(free, net.blocks, net.notes), datum="free")
    assert a.defect > 0           # station_control: polar points only, dof 0; the reduced system is all null
    _same(a, b)


def _two_trackers(rng):
    stations = np.array([[0.0, 0.0, 0.0], [6.2, 0.4, 0.15]])
    kappas = np.array([0.3, 2.1])
    targets = np.column_stack([rng.uniform(0, 6, 15), rng.uniform(2, 8, 15), rng.uniform(-1, 2, 15)])
    pairs = (np.repeat([0, 1], 15), np.tile(np.arange(15), 2))
    obs = _simulate(rng, stations, kappas, targets, pairs)
    approx = np.vstack([stations, targets]) + 0.003 * rng.standard_normal((17, 3))
    pts = PointSet.build(["T1", "T2"] + [f"P{i:02d}" for i in range(15)], approx)
    return Network(pts, _blocks(pairs, obs, 2))


def _tracker_on_control(rng, lone=False):
    station, kappa = np.array([1.0, 2.0, 0.5]), np.array([-1.2])
    control = station + np.column_stack([rng.uniform(-8, 8, 5), rng.uniform(-8, 8, 5), rng.uniform(-1, 1, 5)])
    targets = station + np.column_stack([rng.uniform(-8, 8, 10), rng.uniform(-8, 8, 10), rng.uniform(-1, 2, 10)])
    pairs = (np.zeros(15, int), np.arange(15))
    obs = _simulate(rng, station[None], kappa, np.vstack([control, targets]), pairs)
    approx = np.vstack([station + 0.01, control, targets + 0.01 * rng.standard_normal((10, 3))])
    ids = ["T"] + [f"K{i}" for i in range(5)] + [f"Q{i}" for i in range(10)]
    status = [FREE] + [FIXED] * 5 + [FREE] * 10
    blocks = _blocks(pairs, obs, 1)
    if lone:                    # a target with one distance: undetermined
        ids, approx, status = ids + ["LONE"], np.vstack([approx, [3.0, 3.0, 0.0]]), status + [FREE]
        blocks += (Block("slope_distance", np.array([4.3]), np.array([SIG_D]), None,
                         {"from": np.array([0]), "to": np.array([16])}),)
    return Network(PointSet.build(ids, approx, status=status), blocks)


def test_two_levelled_trackers_free_network():
    a, b = _both(_two_trackers(np.random.default_rng(20261126)), datum="free")
    assert a.defect == 4
    _same(a, b)


def test_one_tracker_on_control_with_polar_points():
    a, b = _both(_tracker_on_control(np.random.default_rng(7)))
    assert np.abs(b.redundancy[5:15]).max() < 1e-9          # polar points: read once, zero redundancy
    _same(a, b)


@pytest.mark.parametrize("datum", ["auto", "free"])
def test_trackers_heads_bars_and_weighted_control(datum):
    a, b = _both(tracker_network(5)[0], datum=datum)
    _same(a, b)


def test_undetermined_point_named_the_same_way():
    net = _tracker_on_control(np.random.default_rng(3), lone=True)
    errors = []
    for backend in ("dense", "sparse"):
        with pytest.raises(UndeterminedError) as e:
            adjust(net, options=AdjustOptions(backend=backend))
        errors.append(e.value)
    assert str(errors[0]) == str(errors[1])
    assert "point 'LONE' not determined" in str(errors[1])
    assert errors[0].points == errors[1].points == {"LONE": "xyz"}


@pytest.mark.parametrize("seed", range(12))
def test_random_mixed_networks(seed):
    """The random mixed networks of test_general_approximate (directions, zenith angles, trackers
    levelled or not, distance-only heads, control, height differences, a vector; occlusions),
    with noise, from the truth: equal results, or the same undetermined points named."""
    d = _random_design(seed)
    net = _with_truth(d.network(np.random.default_rng(seed)), d.truth)
    out = []
    for backend in ("dense", "sparse"):
        try:
            out.append(adjust(net, options=AdjustOptions(backend=backend)))
        except UndeterminedError as e:
            out.append(e)
    if isinstance(out[0], UndeterminedError):
        assert isinstance(out[1], UndeterminedError) and out[0].points == out[1].points
        assert str(out[0]) == str(out[1])
    else:
        _same(*out)


def test_distance_only_8_stations_2000_targets_equals_the_distance_path():
    """8 stations x 2 000 targets, 7 distances each (13 998 rows): the general sparse back end equals
    the distance-only path (Schur on targets, its own code) in σ0 and in coordinates, both in the
    free datum (inner constraints over every point, from the same approximate coordinates), and the
    heads' additive constants."""
    from multilat.network.adjust.distance.adjust import Start
    from multilat.network.adjust.distance.adjust import adjust as distance_adjust
    from multilat.network.model.data import Observations, Points
    from multilat.network.adjust.general.from_tables import network_from_tables
    from multilat.network.synthetic.generator import synthetic_network

    s, t = 8, 2000
    syn = synthetic_network(3, population="rings", n_stations=s, n_targets=t, per_target=7)
    obs = Observations(tuple(f"S{i}" for i in range(s)), tuple(f"T{j}" for j in range(t)), syn.station_index,
                       syn.target_index, syn.distance_m, syn.sigma_m)
    old = distance_adjust(obs, snooping=False, initial=Start(syn.station_xyz_m, syn.target_xyz_m, syn.offset_m))
    pts = Points(obs.station_ids + obs.target_ids, np.vstack([syn.station_xyz_m, syn.target_xyz_m]))
    net, opt = network_from_tables(obs, points=pts)
    sysm = System(net)
    assert backend_for(sysm, opt) == "sparse"                # auto: above SPARSE_ABOVE
    res = adjust(net, options=opt)
    assert res.backend == "sparse" and res.cofactor is None  # no (n, n) matrix at 6 032 unknowns
    assert res.dof == old.dof
    assert res.sigma0 == pytest.approx(old.sigma0, rel=1e-9)
    ix = {p: k for k, p in enumerate(res.ids)}
    x_gen = np.array([res.xyz_m[ix[p]] for p in obs.station_ids + obs.target_ids])
    assert np.abs(x_gen - np.vstack([old.station_xyz_m, old.target_xyz_m])).max() < 1e-9
    for h, v in zip(obs.station_ids, old.offset_m):
        assert res.parameters[res.names.index(f"offset:{h}")] == pytest.approx(v, abs=1e-9)
    # redundancy numbers: the distance path's, row by row
    assert np.abs(res.redundancy - old.redundancy).max() < 1e-8


def _shifts(net, backend, datum="auto"):
    from multilat.network.adjust.general import quality

    res = adjust(net, options=AdjustOptions(backend=backend, datum=datum))
    st = quality.statistics(System(net), res)
    return res, st.shift_max_m, st.shift_point


def _same_shifts(net, datum="auto"):
    """External reliability of the sparse back end (the Schur blocks, reliability.SchurShifts) against
    the dense one (``Q J_wᵀ`` with the dense Q of the bordered inverse): every row's largest point
    shift to 1e-9 relative (the two back ends' Q agree to ~1e-12 relative, the shift is a linear
    function of it; measured <= 6e-11 on these networks), the same point, inf on the same rows.
    Returns the sparse result and the points' indices."""
    a, sa, pa = _shifts(net, "dense", datum)
    b, sb, pb = _shifts(net, "sparse", datum)
    assert b.blocks is not None and not b.not_computed
    fin = np.isfinite(sa)
    assert np.array_equal(fin, np.isfinite(sb)) and (fin.any() or a.dof == 0)   # dof 0: every row inf
    # plus 1e-15 of the largest: a row whose shift is zero (by structure) is 0.0 in one back end and
    # rounding (4e-22 m, seed 11) in the other, and its point is then any (compared where shifts are not 0)
    floor = 1e-15 * np.abs(sa[fin]).max(initial=0.0)
    assert np.all(np.abs(sb[fin] - sa[fin]) <= 1e-9 * np.abs(sa[fin]) + floor)
    moved = ~(np.abs(sa) <= floor)
    assert [p for p, k in zip(pa, moved) if k] == [p for p, k in zip(pb, moved) if k]
    return b, [b.ids.index(p) if p else -1 for p in pb]


def _winners(res, where) -> np.ndarray:
    """Per row: 0 the row's own eliminated point gave the largest shift, 1 a point of the reduced
    system K, 2 another eliminated point (the bounded search), -1 none (uncontrolled)."""
    from multilat.network.adjust.general import sparse

    parts = sparse.row_parts(res.blocks.lin)
    pts = res.blocks.lin.red.points
    w = np.asarray(where)
    own = parts.touched & (w == pts[parts.prow])
    return np.where(w < 0, -1, np.where(own, 0, np.where(np.isin(w, pts), 2, 1)))


@pytest.mark.parametrize("name", NETWORKS)
def test_external_reliability_equals_the_dense_back_end(name):
    """The gama3d networks in the datum of their files and free over every point (inner constraints:
    the datum terms W c1 + H c2 of every point's response)."""
    net = approximate(read_gama_input(GAMA / f"{name}.xml"))
    _same_shifts(net)
    pts = net.points
    free = PointSet(pts.ids, pts.xyz_m, np.where(pts.status == FIXED, FREE, pts.status), pts.sigma_m,
                    np.ones(pts.n, bool))
    _same_shifts(Network(free, net.blocks, net.notes), datum="free")


def test_external_reliability_of_random_mixed_networks_every_branch():
    """The random mixed networks that are determined (directions, zenith angles, trackers, heads,
    control, a vector): equal to the dense back end; and each of the three ways a row's largest shift
    is found (its own eliminated point, a point of K, another eliminated point by the bounded search)
    wins on some rows, so each is checked against the dense product."""
    seen = np.zeros(3, int)
    for seed in (1, 2, 3, 9, 10, 11):
        d = _random_design(seed)
        res, where = _same_shifts(_with_truth(d.network(np.random.default_rng(seed)), d.truth))
        seen += np.bincount(_winners(res, where)[np.asarray(where) >= 0], minlength=3)
    assert np.all(seen >= 20), seen


def test_external_reliability_large_distance_network_by_pruned_search(monkeypatch):
    """8 stations x 1 000 targets free (inner constraints over every point, 3 032 unknowns, 7 000 rows;
    the dense back end refuses it): every row's shift equals the one from ``Q J_wᵀ`` (``Q`` times the
    rows through the blocks, the former O(R n) way, an independent product: 1e-12 relative, rounding)
    and the same point; the bounded search evaluates the other points' shifts for almost no row (the
    bound is below the row's own target's shift: O(R k) work, the growth measured in the commit), and
    forced to evaluate every point (MARGIN inf) it gives the same answer."""
    from multilat.network.model.data import Observations, Points
    from multilat.network.adjust.general import reliability as rel
    from multilat.network.adjust.general.from_tables import network_from_tables
    from multilat.network.adjust.distance.reliability import largest_point_shift
    from multilat.network.synthetic.generator import synthetic_network

    s, t = 8, 1000
    syn = synthetic_network(3, population="rings", n_stations=s, n_targets=t, per_target=7)
    obs = Observations(tuple(f"S{i}" for i in range(s)), tuple(f"T{j}" for j in range(t)), syn.station_index,
                       syn.target_index, syn.distance_m, syn.sigma_m)
    pts = Points(obs.station_ids + obs.target_ids, np.vstack([syn.station_xyz_m, syn.target_xyz_m]))
    net, opt = network_from_tables(obs, points=pts)
    res = adjust(net, options=opt)
    assert res.cofactor is None and res.defect == 6 and not res.not_computed
    jw = rel.whitened_jacobian(System(net), res)
    bias = rel.mdb_whitened(res.redundancy, alpha=0.001, power=0.8)
    evaluated = []
    real = rel.SchurShifts._others

    def spy(self, y, c1, c2, zn, t, pr, limit, best, where):
        evaluated.append(int((((self.bound[:, 0] @ zn) * (1 + self.MARGIN)) > limit).sum()))
        return real(self, y, c1, c2, zn, t, pr, limit, best, where)

    monkeypatch.setattr(rel.SchurShifts, "_others", spy)
    shift, point = rel.external_shifts(res, jw, bias)
    assert sum(evaluated) <= 0.002 * len(shift)           # measured: 6 rows of 7 000 search one chunk
    cols = rel.point_columns(res)
    nf = len(res.free_names)
    for lo in range(0, jw.shape[0], 1000):
        hi = min(lo + 1000, jw.shape[0])
        D = np.zeros((nf + 1, hi - lo))
        D[:-1] = res.cofactor_times(jw[lo:hi].toarray().T) * bias[lo:hi]
        norm, where = largest_point_shift(D[cols])
        assert np.all(np.abs(shift[lo:hi] - norm) <= 1e-12 * norm)
        assert list(point[lo:hi]) == [res.ids[int(w)] for w in where]
    monkeypatch.setattr(rel.SchurShifts, "MARGIN", np.inf)
    monkeypatch.setattr(rel.SchurShifts, "CHUNK", 97)
    shift2, point2 = rel.external_shifts(res, jw, bias, batch=700)
    assert np.array_equal(shift2, shift) and point2 == point


def test_statistics_served_without_a_dense_cofactor(monkeypatch):
    """With the dense Q not formed (a large network: here forced by the bound), the statistics come
    from the blocks, equal to the dense back end's; the external reliability is computed through
    the Schur blocks, or marked not computed (NaN) when the back end leaves it out (EXTERNAL_MAX_WORK,
    no limit since issue 29: forced here), never silently wrong."""
    from multilat.network.adjust.general import quality

    net = tracker_network(5)[0]
    a = adjust(net, options=AdjustOptions(backend="dense"))
    monkeypatch.setattr(gadjust, "MAX_DENSE_UNKNOWNS", 0)
    b = adjust(net, options=AdjustOptions(backend="sparse"))
    assert b.cofactor is None and b.not_computed == ()
    sa, sb = quality.statistics(System(net), a), quality.statistics(System(net), b)
    assert np.abs(sa.w - sb.w).max() < 1e-6
    assert np.abs(sa.cov_m2 - sb.cov_m2).max() <= 1e-8 * np.abs(sa.cov_m2).max()
    assert np.abs(sa.shift_max_m - sb.shift_max_m).max() <= 1e-8 * np.abs(sa.shift_max_m).max()
    assert sa.shift_point == sb.shift_point
    monkeypatch.setattr(gadjust, "EXTERNAL_MAX_WORK", 0)
    c = adjust(net, options=AdjustOptions(backend="sparse"))
    assert c.not_computed == ("external reliability",)
    assert np.all(np.isnan(quality.statistics(System(net), c).shift_max_m))


def test_dispatch_and_one_line_refusals(monkeypatch):
    net = approximate(read_gama_input(GAMA / "two_trackers.xml"))
    n = System(net).n_free
    assert backend_for(System(net), AdjustOptions()) == "dense"
    monkeypatch.setattr(gadjust, "SPARSE_ABOVE", n - 1)
    assert adjust(net).backend == "sparse"
    monkeypatch.setattr(gadjust, "MAX_DENSE_UNKNOWNS", n - 1)
    with pytest.raises(MultilatError, match=rf"dense back end takes at most {n - 1} unknowns; this network has {n} "):
        adjust(net, options=AdjustOptions(backend="dense"))
    monkeypatch.setattr("multilat.network.adjust.general.sparse.MAX_REDUCED", 3)
    with pytest.raises(MultilatError, match=r"reduced system of at most 3 parameters; this network leaves \d+ "):
        adjust(net, options=AdjustOptions(backend="sparse"))
    with pytest.raises(MultilatError, match="backend='x' must be"):
        AdjustOptions(backend="x")
