"""Sparse back end (network.solve.sparse and its kernels): the same reduced system as the dense back
end, kernels compiled or plain Python alike, any observation order."""

from __future__ import annotations

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.adjust.solve import _sparse_kernels as K
from multilat.network.adjust.distance.adjust import Start, adjust
from multilat.network.model.data import Observations
from multilat.network.synthetic.generator import synthetic_network
from multilat.network.model.distance import Q
from multilat.network.model.parameter_layout import XYZ, ParameterLayout
from multilat.network.model.problem import Params, Problem
from multilat.network.adjust.solve.dense import DenseBackend
from multilat.network.adjust.solve.sparse import SparseBackend


def start(net, rng, scale=1e-3):
    rng = np.random.default_rng(rng)
    return (net.station_xyz_m + rng.normal(0, scale, net.station_xyz_m.shape),
            net.offset_m + rng.normal(0, scale, net.offset_m.shape),
            net.target_xyz_m + rng.normal(0, scale, net.target_xyz_m.shape))


def as_obs(net, order=None):
    k = np.arange(len(net.distance_m)) if order is None else order
    s, t = len(net.station_xyz_m), len(net.target_xyz_m)
    return Observations(tuple(f"S{i}" for i in range(s)), tuple(f"T{j}" for j in range(t)),
                        net.station_index[k], net.target_index[k], net.distance_m[k], net.sigma_m[k])


@pytest.mark.parametrize("damping", [0.0, 1e-3])
def test_sparse_and_dense_assemble_the_same_reduced_system(damping):
    """N, b, the target blocks and the back-substituted target steps of both back ends agree to
    1e-9 relative at a point 1 mm off the solution, damped or not, observations in any order."""
    net = synthetic_network(4, population="rings", n_stations=7, n_targets=50, per_target=5)
    h, o, tg = start(net, 5)
    p = Params(h, tg, o, np.zeros(7))
    perm = np.random.default_rng(1).permutation(len(net.distance_m))
    obs = as_obs(net, perm)
    free = np.ones((7, Q), bool)
    free[:, 4] = False
    pb = Problem(obs, "distance", free, np.ones(50, bool))
    a = DenseBackend(pb).assemble(p, damping)
    b = SparseBackend(pb).assemble(p, damping)
    idx = free.ravel()
    np.testing.assert_allclose(b.N[np.ix_(idx, idx)], a.N[np.ix_(idx, idx)], rtol=1e-9,
                               atol=1e-9 * np.abs(a.N).max())
    np.testing.assert_allclose(b.b[idx], a.b[idx], rtol=1e-9, atol=1e-9 * np.abs(a.b).max())
    np.testing.assert_allclose(b.Ntt_inv, a.Ntt_inv, rtol=1e-9, atol=1e-9 * np.abs(a.Ntt_inv).max())
    assert b.vtpv == pytest.approx(a.vtpv, rel=1e-12)
    dg = np.random.default_rng(2).normal(0, 1e-4, 5 * 7) * free.ravel()
    np.testing.assert_allclose(b.back_substitute(dg), a.back_substitute(dg), rtol=1e-8, atol=1e-15)


def test_sparse_refuses_what_it_does_not_model():
    net = synthetic_network(1, population="rings", n_stations=6, n_targets=20, per_target=4)
    obs = as_obs(net)
    free = np.ones((6, Q), bool)
    with pytest.raises(ValueError, match="scales"):
        SparseBackend(Problem(obs, "distance", free, np.ones(20, bool)))
    h, o, tg = start(net, 2)
    with pytest.raises(MultilatError, match="sparse solver does not handle estimated scales"):
        adjust(obs, initial=Start(h, tg, o), scales=["S0"], solver="sparse")


def test_python_and_numba_kernels_agree():
    """The kernels run as plain Python without numba: same numbers on a tiny network."""
    if not K.HAVE_NUMBA:
        pytest.skip("numba not installed: only the Python path exists")
    net = synthetic_network(3, population="rings", n_stations=5, n_targets=12, per_target=4)
    h, o, tg = start(net, 4)
    t = len(tg)
    tptr = np.zeros(t + 1, np.int64)
    np.cumsum(np.bincount(net.target_index, minlength=t), out=tptr[1:])
    w = 1 / net.sigma_m**2
    lay = ParameterLayout.adjustment(len(h))
    cols = np.ascontiguousarray(lay.station_block(XYZ + ("offset",)), np.int64)
    outs = []
    for f in (K.assemble, K.assemble.py_func):
        u = np.empty((len(w), 3))
        nblk = np.empty((t, 3, 3))
        ninv = np.empty((t, 3, 3))
        gt = np.empty((t, 3))
        sm, gp, vt, dmin = f(h, o, tg, net.distance_m, w, net.station_index, tptr, cols, lay.n, u, nblk, ninv, gt,
                             2, 4, 1e-3)
        outs.append((sm, gp, vt, nblk, ninv, gt))
    for a, b in zip(*outs):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())
    # the blocks: sum over the target's observations of w u u^T, the diagonal damped by 1 + 1e-3, from
    # the station -> target directions computed here; their inverses: the kernel's ninv
    d = h[net.station_index] - tg[net.target_index]
    uu = d / np.linalg.norm(d, axis=1)[:, None]
    want = np.zeros((t, 3, 3))
    np.add.at(want, net.target_index, w[:, None, None] * uu[:, :, None] * uu[:, None, :])
    want[:, np.arange(3), np.arange(3)] *= 1.0 + 1e-3
    np.testing.assert_allclose(outs[0][3], want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    np.testing.assert_allclose(np.einsum("tij,tjk->tik", outs[0][3], outs[0][4]), np.broadcast_to(np.eye(3), (t, 3, 3)),
                               atol=1e-9)


def test_kernels_write_the_layout_columns_they_are_given():
    """The kernels place each station's ``x, y, z, offset`` at the columns of the layout passed in: the
    loop's adjustment layout (5 per station, scale columns left zero) and the station system (4 per
    station, the old tiles) give the same numbers, bit for bit, on each other's columns."""
    net = synthetic_network(3, population="rings", n_stations=5, n_targets=12, per_target=4)
    h, o, tg = start(net, 4)
    t = len(tg)
    tptr = np.zeros(t + 1, np.int64)
    np.cumsum(np.bincount(net.target_index, minlength=t), out=tptr[1:])
    w = 1 / net.sigma_m**2
    dg = np.linspace(-1e-6, 1e-6, 5 * len(h))
    out = {}
    for name, lay in (("adjustment", ParameterLayout.adjustment(len(h))),
                      ("station_system", ParameterLayout.station_system(len(h)))):
        cols = np.ascontiguousarray(lay.station_block(XYZ + ("offset",)), np.int64)
        u, nblk, ninv, gt = np.empty((len(w), 3)), np.empty((t, 3, 3)), np.empty((t, 3, 3)), np.empty((t, 3))
        N, b, _, _ = K.assemble(h, o, tg, net.distance_m, w, net.station_index, tptr, cols, lay.n, u, nblk, ninv, gt,
                                2, 4, 0.0)
        step = np.zeros(lay.n)
        step[cols.ravel()] = dg.reshape(-1, 5)[:, :4].ravel()
        dt = np.empty((t, 3))
        K.back_substitute(step, cols, gt, ninv, u, w, net.station_index, tptr, dt)
        out[name] = (cols.ravel(), N, b, dt)
    ca, Na, ba, dta = out["adjustment"]
    cs, Ns, bs, dts = out["station_system"]
    assert Na.shape == (25, 25) and Ns.shape == (20, 20)
    assert np.array_equal(Na[np.ix_(ca, ca)], Ns) and np.array_equal(ba[ca], bs) and np.array_equal(dta, dts)
    scale = np.setdiff1d(np.arange(25), ca)                          # the scale columns: untouched
    assert not Na[scale].any() and not Na[:, scale].any() and not ba[scale].any()


def test_fast_reader_matches_the_strict_reader(tmp_path):
    from multilat.network.io.fastio import read_observations_fast
    from multilat.network.io.files import read_observations

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


def test_compiled_block_test_equals_eigvalsh():
    """The compiled closed-form test of the targets' 3x3 blocks (used from 2 000 free targets) against
    LAPACK's eigenvalues: the same verdict on random, nearly singular (1e-13 and 1e-8 relative) and
    non-finite blocks."""
    from multilat.network.adjust.solve._sparse_kernels import degenerate_blocks

    r = np.random.default_rng(0)
    A = r.normal(size=(3000, 3, 3))
    N = A @ A.transpose(0, 2, 1)
    v = r.normal(size=(100, 3))
    n2 = np.einsum("ni,ni->n", v, v)[:, None, None]
    N[:100] = v[:, :, None] * v[:, None, :] + 1e-13 * n2 * np.eye(3)
    N[100:200] = v[:, :, None] * v[:, None, :] + 1e-8 * n2 * np.eye(3)
    N[200, 0, 0] = np.nan
    bad = np.empty(len(N), bool)
    degenerate_blocks(N, 1e-10, bad)
    with np.errstate(invalid="ignore"):
        ev = np.linalg.eigvalsh(np.where(np.isfinite(N), N, 0.0))
    assert np.array_equal(bad, ~(ev[:, 0] > 1e-10 * ev[:, 2]))
    assert bad[:100].all() and not bad[100:200].any() and bad[200]


def test_distinct_pair_codes_equal_numpy_unique():
    from multilat.network.model.data import distinct_pair_codes

    r = np.random.default_rng(1)
    for n in (0, 1, 2, 50, 10_000):
        si, ti = r.integers(0, 5, n), r.integers(0, 7, n)
        assert np.array_equal(distinct_pair_codes(si, ti, 7), np.unique(si.astype(np.int64) * 7 + ti))
