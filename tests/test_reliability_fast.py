"""External reliability by block algebra (issue 29, "a quadratic step") against the per-observation
covariance product it replaces: the old path is kept here as the reference, ``S C a_k`` from one
product of the whole covariance per design row. The largest point shift must agree to 1e-9 relative
(both are the same linear algebra in a different order; rounding is ~1e-13) and name the same point.
"""

import numpy as np
import pytest

from multilat.network.adjust import covariance as cv
from multilat.network.adjust.distance import reliability as rl
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.model.data import Observations, ReferenceLengths
from multilat.network.synthetic.generator import synthetic_network
from multilat.network.model.distance import Q
from multilat.network.adjust.distance.result import Start


def _reference_shifts(cov, sx_ids, tx_ids, bias_m, batch=64):
    """The pre-issue-29 path: one covariance product per observation (``cov._rot_times``)."""
    s, t, n = cov.s, cov.t, cov.n
    mu = cov.Js_w.shape[0]
    ids = list(sx_ids) + list(tx_ids)
    out, where = np.empty(mu), np.empty(mu, dtype=np.intp)
    R = cov.R
    for lo in range(0, mu, batch):
        ks = np.arange(lo, min(lo + batch, mu))
        V = np.zeros((n, ks.size))
        c = np.arange(ks.size)
        si, ti = cov.si[ks], cov.ti[ks]
        a_s = cov.Js_w[ks].copy()
        a_s[:, :3] = a_s[:, :3] @ R.T
        for q in range(Q):
            V[Q * si + q, c] = a_s[:, q]
        a_t = cov.Jt_w[ks] @ R.T
        for q in range(3):
            V[Q * s + 3 * ti + q, c] = a_t[:, q]
        D = cov._rot_times(V)
        if cov.G is not None:
            D = D - cov.G @ (cov.H @ D)
        D /= cov.factor
        pts = np.concatenate([D[:Q * s].reshape(s, Q, -1)[:, :3], D[Q * s:].reshape(t, 3, -1)], axis=0)
        norm = np.linalg.norm(pts, axis=1)
        j = np.argmax(norm, axis=0)
        out[ks] = norm[j, c] * bias_m[ks]
        where[ks] = j
    return out, tuple(ids[j] for j in where)


def _spy(monkeypatch):
    """Record every call of ``external_shifts`` made by ``adjust`` (its arguments and answer)."""
    calls = []
    real = rl.external_shifts

    def spy(cov, obs, used, sx, tx, bias, **kw):
        got = real(cov, obs, used, sx, tx, bias, **kw)
        calls.append((cov, sx, tx, np.array(bias), got))
        return got

    monkeypatch.setattr(rl, "external_shifts", spy)
    return calls


def _obs(net, repeat=0, rng=None):
    s, t = len(net.station_xyz_m), len(net.target_xyz_m)
    si, ti, d, sig = net.station_index, net.target_index, net.distance_m, net.sigma_m
    if repeat:              # the first pair read ``repeat`` more times (the hostile case, small)
        rng = np.random.default_rng(rng)
        si = np.concatenate([si, np.full(repeat, si[0])])
        ti = np.concatenate([ti, np.full(repeat, ti[0])])
        d = np.concatenate([d, d[0] + rng.normal(0, sig[0], repeat)])
        sig = np.concatenate([sig, np.full(repeat, sig[0])])
    return Observations(tuple(f"S{i}" for i in range(s)), tuple(f"T{j}" for j in range(t)), si, ti, d, sig)


def _check(calls, min_calls=1):
    assert len(calls) >= min_calls
    for cov, sx, tx, bias, (sh, pt) in calls:
        ref, rpt = _reference_shifts(cov, sx, tx, bias)
        assert np.all(np.isfinite(sh)) and sh.max() > 0
        np.testing.assert_allclose(sh, ref, rtol=1e-9, atol=0)
        assert pt == rpt


@pytest.mark.parametrize("solver", ["dense", "sparse"])
@pytest.mark.parametrize("kernels", [False, True])
@pytest.mark.parametrize("datum", ["free", "321:T0,T1,T2", "free:T0,T1,T2,T3,T4"])
def test_block_shifts_equal_the_per_observation_product(monkeypatch, solver, kernels, datum):
    """Free, 3-2-1 and inner constraints on a subset (different ``G``/``E``), numpy and compiled
    covariance kernels (forced below their size), dense and sparse solvers; a blunder planted so
    that snooping rejects it (the used subset differs from the observations)."""
    if kernels:
        monkeypatch.setattr(cv, "KERNELS_ABOVE_OBS", 50)
    calls = _spy(monkeypatch)
    net = synthetic_network(11, population="rings", n_stations=6, n_targets=60, per_target=5, size_m=5.0)
    obs = _obs(net)
    d = obs.distance_m.copy()
    d[7] += 2e-3
    res = adjust(obs.with_distances(d), initial=Start(net.station_xyz_m, net.target_xyz_m, net.offset_m),
                 datum=datum, solver=solver)
    assert not res.used[7]
    _check(calls)


@pytest.mark.parametrize("kernels", [False, True])
def test_repeated_readings_and_estimated_variance(monkeypatch, kernels):
    """200 repeated readings of one pair (the hostile case, small) with σ0 estimated (the
    MDBs scaled by σ̂0): the per-target coupling sums the repeats like the product."""
    if kernels:
        monkeypatch.setattr(cv, "KERNELS_ABOVE_OBS", 50)
    calls = _spy(monkeypatch)
    net = synthetic_network(5, population="rings", n_stations=6, n_targets=40, per_target=5, size_m=4.0)
    obs = _obs(net, repeat=200, rng=2)
    res = adjust(obs, initial=Start(net.station_xyz_m, net.target_xyz_m, net.offset_m),
                 variance_factor="unknown", snooping=False)
    assert res.reliability.shifts_computed
    _check(calls)


def test_scale_bars_take_the_coupled_path(monkeypatch):
    """Scale bars couple targets (CoupledCovariance): the dense product in batches, same numbers."""
    calls = _spy(monkeypatch)
    net = synthetic_network(3, population="rings", n_stations=6, n_targets=30, per_target=5, size_m=4.0)
    obs = _obs(net)
    x = net.target_xyz_m
    pairs = [(0, 1), (2, 9), (5, 17)]
    L = np.array([np.linalg.norm(x[a] - x[b]) for a, b in pairs])
    bars = ReferenceLengths(tuple(f"T{a}" for a, _ in pairs), tuple(f"T{b}" for _, b in pairs), L,
                            np.full(3, 2e-6))
    adjust(obs, initial=Start(net.station_xyz_m, net.target_xyz_m, net.offset_m), scales=True,
           scale_bars=bars, snooping=False)
    assert isinstance(calls[0][0], cv.CoupledCovariance)
    _check(calls)


def test_ties_go_to_the_first_point_as_argmax():
    """The search's tie rule is argmax's: among equal largest shifts the first point (stations, then
    targets). Checked on the bounded search alone with a context whose targets all shift equally."""
    ctx = rl._BlockContext.__new__(rl._BlockContext)
    ctx.s, ctx.t = 2, 4
    T = np.tile(np.eye(3, 4), (4, 1, 1))                     # every target: |T z| = |z[:3]|
    ctx.order = np.array([3, 1, 0, 2])
    ctx.bound = np.ones(4)
    ctx.Ts = T[ctx.order].reshape(-1, 4)
    ctx.CHUNK = 2
    z = np.array([[1.0, 0, 0, 0], [0, 2.0, 0, 0]])
    best, where = ctx._others(z, np.array([0, 3]), np.array([0.5, 2.0]), np.array([1, 5]))
    # obs 0 (own target 0): targets 1..3 all shift 1 > 0.5 -> the first of them, point 2 + 1 = 3
    # obs 1 (own target 3, point 5, 2.0): targets 0..2 tie at 2.0 -> target 0, point 2
    assert best.tolist() == [1.0, 2.0] and where.tolist() == [3, 2]
