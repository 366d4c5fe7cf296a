"""Large-network solver (network.sparse): same answer as the dense and general solvers, honest covariances."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from multilat.errors import MultilatError
from multilat.network import _sparse_kernels as K
from multilat.network.batched import BatchedNetwork, Datum
from multilat.network.sparse import solve_large, synthetic_network


def start(net, rng, scale=1e-3):
    rng = np.random.default_rng(rng)
    return (net.station_xyz_m + rng.normal(0, scale, net.station_xyz_m.shape),
            net.offset_m + rng.normal(0, scale, net.offset_m.shape),
            net.target_xyz_m + rng.normal(0, scale, net.target_xyz_m.shape))


def solve(net, init, **kw):
    return solve_large(net.station_index, net.target_index, net.distance_m, net.sigma_m, *init, **kw)


@pytest.fixture(scope="module")
def medium():
    net = synthetic_network(12, 150, 6, rng=11)
    return net, solve(net, start(net, 12))


def test_same_solution_and_covariance_as_dense_batched(medium):
    net, res = medium
    assert res.converged
    dense = BatchedNetwork(net.station_index, net.target_index, net.sigma_m, res.station_xyz_m, res.offset_m,
                           res.target_xyz_m, datum=Datum.inner("stations"))
    # the dense full Gauss-Newton from this solution does not move it
    sol = dense.solve(net.distance_m[None], method="gauss-newton", tol_m=1e-13, max_iter=5)
    assert np.abs(sol.target_xyz_m[0] - res.target_xyz_m).max() < 1e-11
    assert np.abs(sol.offset_m[0] - res.offset_m).max() < 1e-11
    q = dense.linear_covariance()
    s = 12
    scale = np.abs(q).max()
    assert np.abs(q[: 4 * s, : 4 * s] - res.station_cov_m2).max() < 1e-8 * scale
    tc = np.array([q[4 * s + 3 * j: 4 * s + 3 * j + 3, 4 * s + 3 * j: 4 * s + 3 * j + 3] for j in range(150)])
    assert np.abs(tc - res.target_cov_m2).max() < 1e-8 * scale


def test_same_solution_as_general_adjust(medium):
    """vs network.adjust (free datum over the stations, referenced to the same start): < 1 nm."""
    from multilat.network.adjust import adjust
    from multilat.network.data import Observations

    net, res = medium
    s_ids = tuple(f"S{i}" for i in range(12))
    t_ids = tuple(f"T{j}" for j in range(150))
    obs = Observations(s_ids, t_ids, net.station_index, net.target_index, net.distance_m, net.sigma_m)
    h0, o0, t0 = start(net, 12)

    class Start:
        station_xyz_m, offset_m, target_xyz_m = h0, o0, t0

    ref = adjust(obs, datum="free:" + ",".join(s_ids), initial=Start(), snooping=False)
    assert np.abs(ref.station_xyz_m - res.station_xyz_m).max() < 1e-9
    assert np.abs(ref.target_xyz_m - res.target_xyz_m).max() < 1e-9
    assert np.abs(ref.offset_m - res.offset_m).max() < 1e-9
    assert abs(ref.sigma0 - res.sigma0) < 1e-9


def test_errors_against_truth_are_consistent_with_the_covariance():
    """Offsets (datum-free) vs truth: chi2 with s dof below its 99.9 % quantile, over 5 networks;
    and sigma0 within its 99.9 % band."""
    chi = []
    for seed in range(5):
        net = synthetic_network(10, 300, 6, rng=100 + seed)
        res = solve(net, start(net, 200 + seed))
        c = res.station_cov_m2[30:, 30:]
        e = res.offset_m - net.offset_m
        chi.append(float(e @ np.linalg.solve(c, e)))
        lo, hi = stats.chi2.ppf([0.0005, 0.9995], res.dof)
        assert lo <= res.sigma0**2 * res.dof <= hi
    total = sum(chi)
    assert total < stats.chi2.ppf(0.999, 50)
    assert total > stats.chi2.ppf(0.001, 50)


def test_python_and_numba_kernels_agree():
    """The kernels run as plain Python without numba: same numbers on a tiny network."""
    if not K.HAVE_NUMBA:
        pytest.skip("numba not installed: only the Python path exists")
    net = synthetic_network(5, 12, 4, rng=3)
    h, o, tg = start(net, 4)
    t = len(tg)
    tptr = np.zeros(t + 1, np.int64)
    np.cumsum(np.bincount(net.target_index, minlength=t), out=tptr[1:])
    w = 1 / net.sigma_m**2
    outs = []
    for f in (K.assemble, K.assemble.py_func):
        u = np.empty((len(w), 3))
        ninv = np.empty((t, 3, 3))
        gt = np.empty((t, 3))
        sm, gp, vt, dmin = f(h, o, tg, net.distance_m, w, net.station_index, tptr, u, ninv, gt, 2, 4)
        outs.append((sm, gp, vt, ninv, gt))
    for a, b in zip(*outs):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())


def test_observations_in_any_order():
    net = synthetic_network(8, 60, 5, rng=5)
    init = start(net, 6)
    a = solve(net, init, covariance=False)
    perm = np.random.default_rng(0).permutation(len(net.distance_m))
    b = solve_large(net.station_index[perm], net.target_index[perm], net.distance_m[perm], net.sigma_m[perm],
                    *init, covariance=False)
    assert np.abs(a.target_xyz_m - b.target_xyz_m).max() < 1e-12


def test_bad_input():
    net = synthetic_network(6, 20, 4, rng=1)
    init = start(net, 2)
    with pytest.raises(MultilatError, match="target 0"):
        keep = ~((net.target_index == 0) & (np.arange(len(net.target_index)) % 4 != 0))
        solve_large(net.station_index[keep], net.target_index[keep], net.distance_m[keep], net.sigma_m[keep],
                    *init)
    d = net.distance_m.copy()
    d[3] = np.nan
    with pytest.raises(MultilatError):
        solve_large(net.station_index, net.target_index, d, net.sigma_m, *init)
    with pytest.raises(MultilatError):
        solve_large(net.station_index, net.target_index, net.distance_m, -net.sigma_m, *init)
    with pytest.raises(MultilatError):
        synthetic_network(5, 10, 2)


def test_fast_reader_matches_the_strict_reader(tmp_path):
    from multilat.network.fastio import read_observations_fast
    from multilat.network.files import read_observations

    p = tmp_path / "obs.csv"
    p.write_text("# comment\nstation,target,distance_m,sigma_m\nA,P10,1.25,5e-6\nB,P10,2.5,4e-6\n"
                 "A,P2,0.75,5e-6\nC,P2,1.0e0,5e-6\n")
    fast = read_observations_fast(p)
    ref = read_observations(p)
    assert fast.station_ids == tuple(ref.station_ids) and fast.target_ids == tuple(ref.target_ids)
    np.testing.assert_array_equal(fast.station_index, ref.station_index)
    np.testing.assert_array_equal(fast.target_index, ref.target_index)
    np.testing.assert_array_equal(fast.distance_m, ref.distance_m)
    np.testing.assert_array_equal(fast.sigma_m, ref.sigma_m)
    bad = tmp_path / "bad.csv"
    bad.write_text("station,target,distance_m,sigma_m\nA,P1,1.0,5e-6\nA,P2,x1,5e-6\n")
    with pytest.raises(MultilatError, match=r"bad.csv:3: column 'distance_m'"):
        read_observations_fast(bad)
    bad.write_text("station,target,distance_m,sigma_m\nA,P1,1.0,5e-6\nA,P2,1.0\n")
    with pytest.raises(MultilatError, match=r"bad.csv:3: expected 4 cells"):
        read_observations_fast(bad)
    bad.write_text("station,target,distance_m,sigma_m\nA,P1,-1.0,5e-6\n")
    with pytest.raises(MultilatError, match=r"bad.csv:2: .*> 0"):
        read_observations_fast(bad)
