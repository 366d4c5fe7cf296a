"""Batched Gauss-Newton (network.batched): methods and engines agree, and agree with independent solvers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from multilat.errors import MultilatError
from multilat.network.montecarlo.batched import BatchedNetwork, TrialDatum as Datum, flatten, numba_available
from multilat.network.model.distance import inv3 as inv3_sym

H = np.array([[504, 938, 491], [0, 0, 0], [524, -7, 909], [1050, 0, 0]]) / 1000.0   # seed 000 §4.1


def small_network(seed=1, datum=None, sigma=4.7e-6):
    rng = np.random.default_rng(seed)
    tg = rng.uniform([0.05, 0.05, 0.05], [1.0, 0.9, 0.8], (14, 3))
    off = rng.normal(0, 3e-3, 4)
    si, ti = (a.ravel() for a in np.meshgrid(np.arange(4), np.arange(14), indexing="ij"))
    net = BatchedNetwork(si, ti, np.full(56, sigma), H, off, tg, datum=datum or Datum.inner())
    return net


def noisy(net, n, seed=2, sigma=4.7e-6):
    rng = np.random.default_rng(seed)
    return net.nominal_distance_m() + rng.normal(0, sigma, (n, net.n_obs))


def test_inv3_closed_form_matches_numpy():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(50, 3, 3))
    a = a @ a.transpose(0, 2, 1) + 0.1 * np.eye(3)
    np.testing.assert_allclose(inv3_sym(a), np.linalg.inv(a), rtol=1e-10, atol=1e-12)


def test_noise_free_trials_return_the_nominal_solution():
    net = small_network()
    sol = net.solve(np.tile(net.nominal_distance_m(), (3, 1)), engine="numpy")
    assert sol.converged.all()
    x = flatten(sol.station_xyz_m, sol.offset_m, sol.target_xyz_m)
    x0 = flatten(net.station_xyz_m, net.offset_m, net.target_xyz_m)
    assert np.abs(x - x0).max() < 1e-13


@pytest.mark.parametrize("engine", ["numpy"] + (["numba"] if numba_available() else []))
def test_frozen_equals_full_gauss_newton(engine):
    """Both methods have the same fixed point: solutions agree far below the step tolerance."""
    net = small_network()
    d = noisy(net, 200)
    a = net.solve(d, method="gauss-newton", engine="numpy", tol_m=1e-13, max_iter=20)
    b = net.solve(d, method="frozen", engine=engine, tol_m=1e-13, max_iter=30)
    assert a.converged.all() and b.converged.all()
    xa = flatten(a.station_xyz_m, a.offset_m, a.target_xyz_m)
    xb = flatten(b.station_xyz_m, b.offset_m, b.target_xyz_m)
    assert np.abs(xa - xb).max() < 1e-12          # 1 pm, vs 10-100 um parameter scatter
    np.testing.assert_allclose(a.sigma0, b.sigma0, rtol=1e-9)


def test_against_scipy_least_squares_per_trial():
    """Independent solver: scipy LM with a minimal 3-2-1 parametrisation, moved into the same datum."""
    net = small_network()
    d = noisy(net, 3)
    sol = net.solve(d, method="frozen", tol_m=1e-13, max_iter=30)
    s, t = net.n_stations, net.n_targets
    x0 = flatten(net.station_xyz_m, net.offset_m, net.target_xyz_m)
    fixed = np.zeros(len(x0), bool)
    # B xyz, D y z, C y (C lies near the z axis seen from the B-D line: its y sets the rotation)
    fixed[[3, 4, 5, 3 * 3 + 1, 3 * 3 + 2, 3 * 2 + 1]] = True
    w = 1 / net.sigma_m

    def unpack(p):
        x = x0.copy()
        x[~fixed] = p
        return x[: 3 * s].reshape(s, 3), x[3 * s: 4 * s], x[4 * s:].reshape(t, 3)

    for r in range(3):
        def fun(p):
            h, o, tg = unpack(p)
            return w * (d[r] - np.linalg.norm(h[net.station_index] - tg[net.target_index], axis=1)
                        - o[net.station_index])
        ls = least_squares(fun, x0[~fixed], method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
        h, o, tg = unpack(ls.x)
        hd, td = net.datum.apply(h[None], tg[None], net.station_xyz_m, net.target_xyz_m)
        assert np.abs(hd[0] - sol.station_xyz_m[r]).max() < 1e-9
        assert np.abs(td[0] - sol.target_xyz_m[r]).max() < 1e-9
        assert np.abs(o - sol.offset_m[r]).max() < 1e-9


def test_against_network_adjust_solution_and_covariance():
    """Same solution (< 1 nm) and same linear covariance as the general adjustment, free datum."""
    from multilat.network.adjust.distance.adjust import adjust
    from multilat.network.model.data import Observations

    net = small_network()
    d = noisy(net, 1)[0]
    sol = net.solve(d[None], tol_m=1e-13, max_iter=30)
    ids_s = tuple("ABCD")
    ids_t = tuple(f"T{j}" for j in range(14))
    obs = Observations(ids_s, ids_t, net.station_index, net.target_index, d, net.sigma_m)

    class Start:
        station_xyz_m = net.station_xyz_m
        target_xyz_m = net.target_xyz_m
        offset_m = net.offset_m

    res = adjust(obs, datum="free", initial=Start(), snooping=False)
    assert np.abs(res.station_xyz_m - sol.station_xyz_m[0]).max() < 1e-9
    assert np.abs(res.target_xyz_m - sol.target_xyz_m[0]).max() < 1e-9
    assert np.abs(res.offset_m - sol.offset_m[0]).max() < 1e-9
    # covariance at the adjusted point, a-priori variance factor
    net2 = BatchedNetwork(net.station_index, net.target_index, net.sigma_m, res.station_xyz_m,
                          res.offset_m, res.target_xyz_m)
    q = net2.linear_covariance()
    tcov = np.array([q[16 + 3 * j: 19 + 3 * j, 16 + 3 * j: 19 + 3 * j] for j in range(14)])
    ref = np.asarray(res.target_cov_m2) / res.sigma0**2 if getattr(res, "cost", "distance") == "distance" \
        else None
    # adjust may or may not scale by sigma0^2: accept either convention, exactly one must match
    ok_apriori = np.allclose(tcov, res.target_cov_m2, rtol=1e-5, atol=1e-18)
    ok_post = np.allclose(tcov, ref, rtol=1e-5, atol=1e-18)
    assert ok_apriori or ok_post
    np.testing.assert_allclose(np.sqrt(np.diag(q)[12:16]),
                               res.offset_std_m / (1.0 if ok_apriori else res.sigma0), rtol=1e-5)


def test_datum_321_fixes_the_three_points():
    net = small_network(datum=Datum.three_two_one(1, 3, 2))     # B origin, D on the axis, C plane
    sol = net.solve(noisy(net, 20))
    h = sol.station_xyz_m
    b0, d0, c0 = net.station_xyz_m[1], net.station_xyz_m[3], net.station_xyz_m[2]
    assert np.abs(h[:, 1] - b0).max() < 1e-15
    ex = (d0 - b0) / np.linalg.norm(d0 - b0)
    dd = h[:, 3] - b0
    assert np.abs(dd - (dd @ ex)[:, None] * ex).max() < 1e-14        # D stays on the nominal axis
    nz = np.cross(ex, c0 - b0)
    nz /= np.linalg.norm(nz)
    assert np.abs((h[:, 2] - b0) @ nz).max() < 1e-14                  # C stays in the nominal plane
    # linear covariance: those 6 coordinates have zero variance
    q = net.linear_covariance()
    assert np.abs(q[3:6, 3:6]).max() < 1e-25


def test_interpoint_distances_do_not_depend_on_the_datum():
    d = noisy(small_network(), 30)
    a = small_network().solve(d)
    b = small_network(datum=Datum.three_two_one(1, 3, 2)).solve(d)
    c = small_network(datum=Datum.inner("stations")).solve(d)
    for other in (b, c):
        la = np.linalg.norm(a.target_xyz_m[:, :, None] - a.target_xyz_m[:, None], axis=-1)
        lo = np.linalg.norm(other.target_xyz_m[:, :, None] - other.target_xyz_m[:, None], axis=-1)
        assert np.abs(la - lo).max() < 1e-12
        assert np.abs(a.offset_m - other.offset_m).max() < 1e-12


def test_nonconverged_trials_are_flagged():
    net = small_network()
    d = noisy(net, 50)
    d[7] += np.random.default_rng(5).normal(0, 0.02, net.n_obs)   # 2 cm noise: far from the nominal
    d[3, 0] = np.nan                                                # a broken trial
    sol = net.solve(d, max_iter=10, fallback=False)
    assert not sol.converged[7] and not sol.converged[3]
    assert sol.n_failed == 2
    sol = net.solve(d, max_iter=10)                 # frozen, then full Gauss-Newton for the stragglers
    assert sol.retried[7] and sol.retried[3] and sol.retried.sum() == 2
    assert not sol.converged[3] and not sol.converged[7]    # NaN / 2 cm noise: still flagged
    good = net.solve(noisy(net, 50), max_iter=10)
    assert good.n_failed == 0 and not good.retried.any()


def test_bad_input():
    net = small_network()
    with pytest.raises(MultilatError):
        net.solve(np.zeros((3, 5)))
    with pytest.raises(MultilatError):
        net.solve(noisy(net, 2), method="newton")
    with pytest.raises(MultilatError):
        BatchedNetwork([0, 1], [0, 0], [1e-6, -1e-6], H, np.zeros(4), np.zeros((1, 3)))
    with pytest.raises(MultilatError, match="target 0"):   # seen by 2 stations only
        BatchedNetwork([0, 1, 0, 1, 2], [0, 0, 1, 1, 1], np.full(5, 1e-6), H[:3], np.zeros(3),
                       np.array([[0.3, 0.3, 0.3], [0.5, 0.2, 0.1]]))
    with pytest.raises(MultilatError):
        Datum.three_two_one(0, 0, 1)


def _frozen_by_hand(net, d, tol_m=1e-10, max_iter=10):
    """The frozen iteration of one trial written out in plain Python floats, in the numba kernel's
    order of operations: every station's and target's sums over its observations in observation order
    (from 0.0), each row of the frozen inverse summed over its columns in order, no fused multiply-add.
    Returns (h, o, t, iterations, last step, vtpv)."""
    import math

    p = net._pre
    si, ti = net.station_index.tolist(), net.target_index.tolist()
    w, u0, ninv0, s0inv = p["w"].tolist(), p["u0"].tolist(), p["ninv0"].tolist(), p["s0inv"].tolist()
    s, t, d = net.n_stations, net.n_targets, d.tolist()
    h, o, tg = net.station_xyz_m.tolist(), net.offset_m.tolist(), net.target_xyz_m.tolist()
    iters, last = max_iter, math.inf
    for it in range(max_iter):
        gh = [[0.0] * 4 for _ in range(s)]
        gt = [[0.0] * 3 for _ in range(t)]
        for k, (i, j) in enumerate(zip(si, ti)):
            dx, dy, dz = (h[i][c] - tg[j][c] for c in range(3))
            rho = math.sqrt(dx * dx + dy * dy + dz * dz)
            e = w[k] * (d[k] - rho - o[i]) / rho
            for c, v in enumerate((dx, dy, dz, rho)):
                gh[i][c] += e * v
            for c, v in enumerate((dx, dy, dz)):
                gt[j][c] -= e * v
        yt = [[ninv0[j][a][0] * gt[j][0] + ninv0[j][a][1] * gt[j][1] + ninv0[j][a][2] * gt[j][2]
               for a in range(3)] for j in range(t)]
        for k, (i, j) in enumerate(zip(si, ti)):
            sk = w[k] * (u0[k][0] * yt[j][0] + u0[k][1] * yt[j][1] + u0[k][2] * yt[j][2])
            for c in range(3):
                gh[i][c] += sk * u0[k][c]
            gh[i][3] += sk
        g = [gh[b // 4][b % 4] for b in range(4 * s)]
        dxp = []
        for a in range(4 * s):
            acc = 0.0
            for b in range(4 * s):
                acc += s0inv[a][b] * g[b]
            dxp.append(acc)
        step = 0.0
        for i in range(s):
            for a in range(3):
                h[i][a] += dxp[4 * i + a]
                step = max(step, abs(dxp[4 * i + a]))
            o[i] += dxp[4 * i + 3]
            step = max(step, abs(dxp[4 * i + 3]))
        for k, (i, j) in enumerate(zip(si, ti)):
            q = w[k] * (u0[k][0] * dxp[4 * i] + u0[k][1] * dxp[4 * i + 1] + u0[k][2] * dxp[4 * i + 2]
                        + dxp[4 * i + 3])
            for c in range(3):
                gt[j][c] += q * u0[k][c]
        for j in range(t):
            for a in range(3):
                v = ninv0[j][a][0] * gt[j][0] + ninv0[j][a][1] * gt[j][1] + ninv0[j][a][2] * gt[j][2]
                tg[j][a] += v
                step = max(step, abs(v))
        last = step
        if step < tol_m:
            iters = it + 1
            break
    acc = 0.0
    for k, (i, j) in enumerate(zip(si, ti)):
        dx, dy, dz = (h[i][c] - tg[j][c] for c in range(3))
        res = d[k] - math.sqrt(dx * dx + dy * dy + dz * dz) - o[i]
        acc += w[k] * res * res
    return h, o, tg, iters, last, acc


@pytest.mark.skipif(not numba_available(), reason="numba not installed")
def test_numba_frozen_kernel_gives_the_bits_of_the_iteration_written_out():
    """The compiled frozen kernel (sums kept in registers, rows of the inverse four at a time) performs
    exactly the additions of the iteration written out: equal bits, not merely close values; also with
    the observations shuffled (a station's observations not consecutive)."""
    base = small_network()
    perm = np.random.default_rng(3).permutation(base.n_obs)
    shuffled = BatchedNetwork(base.station_index[perm], base.target_index[perm], base.sigma_m[perm],
                              base.station_xyz_m, base.offset_m, base.target_xyz_m)
    for net in (base, shuffled):
        d = noisy(net, 4)
        d[1] = net.nominal_distance_m() + np.random.default_rng(9).normal(0, 2e-4, net.n_obs)   # more iterations
        h, o, tg, iters, last, vtpv = net._iterate(d, "frozen", "numba", 1e-10, 10)
        for r in range(len(d)):
            hh, oo, tt, it, ls, v = _frozen_by_hand(net, d[r])
            assert np.array_equal(h[r], hh) and np.array_equal(o[r], oo) and np.array_equal(tg[r], tt)
            assert (iters[r], last[r], vtpv[r]) == (it, ls, v)
        assert iters.max() > iters.min()


@pytest.mark.skipif(not numba_available(), reason="numba not installed")
def test_numba_frozen_kernel_trial_independent_of_lanes_and_threads():
    """The kernel iterates LANES trials side by side and refills a lane when its trial is done: each
    trial gives the bits of its iteration written out whatever its lane, its neighbours (trials taking
    3 to 10 iterations, one failing with a NaN distance) and the threads (whole batch with numba's
    threads, one thread, each trial alone)."""
    import numba

    from multilat.network.montecarlo import _batched_numba as nb

    net = small_network()
    n = 3 * nb.LANES + 5
    d = noisy(net, n)
    rng = np.random.default_rng(11)
    for r in (1, 40, 41, 77):     # far trials: more iterations, in several lanes
        d[r] = net.nominal_distance_m() + rng.normal(0, 3e-4, net.n_obs)
    d[50, 3] = np.nan
    whole = net._iterate(d, "frozen", "numba", 1e-10, 10)
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        serial = net._iterate(d, "frozen", "numba", 1e-10, 10)
    finally:
        numba.set_num_threads(before)
    for a, b in zip(whole, serial):
        assert np.array_equal(a, b, equal_nan=True)
    assert whole[3].max() == 10 and whole[3].min() <= 4 and not np.isfinite(whole[4][50])
    for r in range(0, n, 7):
        alone = net._iterate(d[r:r + 1], "frozen", "numba", 1e-10, 10)
        for a, b in zip(whole, alone):
            assert np.array_equal(a[r:r + 1], b, equal_nan=True)
        if r != 50:
            hh, oo, tt, it, ls, v = _frozen_by_hand(net, d[r])
            assert np.array_equal(whole[0][r], hh) and np.array_equal(whole[1][r], oo)
            assert np.array_equal(whole[2][r], tt) and (whole[3][r], whole[4][r], whole[5][r]) == (it, ls, v)
