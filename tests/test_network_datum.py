"""Datum choices: datum-independent quantities (interpoint distances and their uncertainty,
offsets, σ0) agree to 1 nm across free, 3-2-1 and control datums; each datum does what it says."""

import itertools

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.model.data import Points
from multilat.network.model.datum import Datum, frame_321, helmert_basis, parse_datum

from multilat.network.synthetic.generator import synthetic_network

from network_truth import perturbed_start


@pytest.fixture(scope="module")
def net():
    tr = synthetic_network(42, population="shell", n_stations=5, n_targets=20, gap_fraction=0.15)
    return tr, perturbed_start(tr, 43)


def _all_distances(res, ids):
    return np.array([res.interpoint_distance(a, b).length_m for a, b in itertools.combinations(ids, 2)])


def test_three_datums_same_distances_offsets_sigma0(net):
    tr, st = net
    free = adjust(tr.obs, initial=st)
    d321 = adjust(tr.obs, initial=st, datum="321:S2,S4,S1")
    # control: three stations held at the free solution's coordinates moved by an arbitrary rigid
    # motion (control consistent with the distances, so the shape is not forced)
    ang = 0.7
    R = np.array([[np.cos(ang), -np.sin(ang), 0], [np.sin(ang), np.cos(ang), 0], [0, 0, 1]])
    ids = ["S1", "S3", "T6"]
    pts = Points(tuple(ids), np.array([free.xyz(i) for i in ids]) @ R.T + [10.0, -3.0, 1.0])
    ctrl = adjust(tr.obs, initial=st, datum="control", points=pts)
    ids_all = tr.obs.station_ids + tr.obs.target_ids
    ref = _all_distances(free, ids_all)
    for other in (d321, ctrl):
        np.testing.assert_allclose(_all_distances(other, ids_all), ref, rtol=0, atol=1e-9)
        np.testing.assert_allclose(other.offset_m, free.offset_m, rtol=0, atol=1e-9)
        assert other.global_test.statistic == pytest.approx(free.global_test.statistic, rel=1e-9)
    assert d321.sigma0 == pytest.approx(free.sigma0, abs=1e-9) and d321.dof == free.dof
    # 3 control points fix 9 coordinates, 3 more than the 6 of the datum: 3 more dof (same vᵀPv)
    assert ctrl.dof == free.dof + 3
    # uncertainties of distances: identical between minimal-constraint datums (1e-9 relative is
    # far below 1 nm for micrometre uncertainties)
    for a, b in [("T1", "T8"), ("S2", "T4"), ("S1", "S5"), ("T12", "T20")]:
        u_f = free.interpoint_distance(a, b).u_m
        assert d321.interpoint_distance(a, b).u_m == pytest.approx(u_f, abs=1e-12)
        assert adjust(tr.obs, initial=st, datum="free:T1,T2,T3,S5").interpoint_distance(a, b).u_m \
            == pytest.approx(u_f, abs=1e-12)
    np.testing.assert_allclose(d321.offset_std_m, free.offset_std_m, rtol=1e-9)
    # the control points are where they were put, with zero variance
    for i, p in zip(ids, pts.xyz_m):
        np.testing.assert_allclose(ctrl.xyz(i), p, atol=1e-12)
    assert np.all(ctrl.station_cov_m2[0] == 0)


def test_321_frame_and_zero_variance(net):
    tr, st = net
    r = adjust(tr.obs, initial=st, datum=Datum.three_two_one("S2", "S4", "S1"))
    a, b, c = r.xyz("S2"), r.xyz("S4"), r.xyz("S1")
    np.testing.assert_allclose(a, 0, atol=1e-12)
    assert abs(b[1]) < 1e-12 and abs(b[2]) < 1e-12 and b[0] > 0
    assert abs(c[2]) < 1e-12 and c[1] > 0
    C = r.points_covariance(["S2", "S4", "S1"])
    fixed = [0, 1, 2, 4, 5, 8]
    assert np.abs(C[np.ix_(fixed, fixed)]).max() < 1e-24
    assert np.all(np.diag(C)[[3, 6, 7]] > 0)


def test_inner_constraints_minimise_the_trace(net):
    tr, st = net
    ids = ["T1", "T2", "T3", "T4", "S5"]
    inner = adjust(tr.obs, initial=st, datum="free:" + ",".join(ids))
    tr_inner = np.trace(inner.points_covariance(ids))
    for d in ("321:S2,S4,S1", "free", "321:T1,T2,T3"):
        other = adjust(tr.obs, initial=st, datum=d)
        assert tr_inner <= np.trace(other.points_covariance(ids)) * (1 + 1e-12)
    # and its datum points fit the initial values best: their mean correction is zero
    xyz = np.array([inner.xyz(i) for i in ids])
    ref = np.array([np.vstack([st.station_xyz_m, st.target_xyz_m])[(tr.obs.station_ids + tr.obs.target_ids).index(i)]
                    for i in ids])
    np.testing.assert_allclose((xyz - ref).mean(axis=0), 0, atol=1e-12)


def test_helmert_basis_is_the_null_space_of_distances():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(6, 3))
    G = helmert_basis(x)
    # d/dx of every pairwise distance is orthogonal to the 6 rigid motions
    for i, j in itertools.combinations(range(6), 2):
        g = np.zeros(18)
        u = (x[i] - x[j]) / np.linalg.norm(x[i] - x[j])
        g[3 * i:3 * i + 3], g[3 * j:3 * j + 3] = u, -u
        np.testing.assert_allclose(g @ G, 0, atol=1e-12)
    assert np.linalg.matrix_rank(G) == 6


def test_parse_and_bad_datums(net):
    tr, st = net
    assert parse_datum("321:B,D,C") == Datum("321", ("B", "D", "C"))
    assert parse_datum("free") == Datum()
    for bad, msg in (("321:A,B", "exactly three"), ("polar", "datum must be"), ("free:A,,B", "empty")):
        with pytest.raises(MultilatError, match=msg):
            parse_datum(bad)
    with pytest.raises(MultilatError, match="unknown point id 'X'"):
        adjust(tr.obs, initial=st, datum="321:S1,S2,X")
    with pytest.raises(MultilatError, match="control"):
        adjust(tr.obs, initial=st, datum="control")
    with pytest.raises(MultilatError, match="collinear"):
        frame_321([0, 0, 0], [1, 0, 0], [2, 0, 0])
