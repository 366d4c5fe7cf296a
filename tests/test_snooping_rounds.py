"""Data snooping on large networks: the rounds between two adjustments as rank-one downdates
(:mod:`multilat.network.adjust.distance.snooping`) against the exact path, a full adjustment after every rejection.

Independent value: the exact path itself (a second method: every round a full Gauss-Newton
adjustment and its own covariance). Forcing the downdated rounds on smaller networks (the threshold
set to 0), the two must reject the same observations in the same order, end with the same
coordinates (1e-9 m; seen 1e-14: the last result is a full adjustment in both), σ0 (1e-10) and
record the same round statistics (1e-7 relative, seen 1.5e-8: the downdate is exact for the
linearised model and serves only marginal rejections, |w| <= 10, where the network's curvature is
second order in a move of about one σ; a gross error's rejection is followed by a full adjustment —
without that rule the planted 125-300 µm blunders put the later rounds' vᵀPv 1e-6 off).
"""

import numpy as np
import pytest

from multilat.network.adjust.distance import snooping
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.model.data import Observations
from multilat.network.synthetic.generator import synthetic_network


def _blundered(n_targets=150, n_blunders=6, seed=5, size_sigma=(25, 60)):
    """A 12-station network with planted blunders of ``size_sigma`` σ, and its truth as initial values
    (in the observations' station order)."""
    from types import SimpleNamespace

    net = synthetic_network(seed, population="rings", n_stations=12, n_targets=n_targets, per_target=8)
    si, ti, d = net.station_index, net.target_index, net.distance_m.copy()
    g = np.random.default_rng(seed)
    k = g.choice(d.size, n_blunders, replace=False)
    d[k] += g.choice([-1, 1], n_blunders) * g.uniform(*size_sigma, n_blunders) * 5e-6
    obs = Observations.from_labels([f"S{i}" for i in si], [f"T{j}" for j in ti], d, np.full(d.size, 5e-6))
    order = [int(sid[1:]) for sid in obs.station_ids]
    tord = [int(tid[1:]) for tid in obs.target_ids]
    truth = SimpleNamespace(station_xyz_m=net.station_xyz_m[order], offset_m=net.offset_m[order],
                            target_xyz_m=net.target_xyz_m[tord])
    return obs, k, truth


class _NoSearch:
    """The minimum search stood down (the planted blunders fail the first global test by far, which
    starts it; these tests are about the snooping rounds that follow)."""

    def __call__(self, obs, core, *args, **kw):
        return core, self

    def as_dict(self):
        return {"search_triggered": False}

    warning = None


@pytest.fixture(autouse=True)
def _no_search(monkeypatch):
    import multilat.network.adjust.distance.adjust as adjust_module

    monkeypatch.setattr(adjust_module, "_search_minimum", _NoSearch())


@pytest.fixture
def downdates(monkeypatch):
    """The positions every :meth:`LinearRounds.reject` downdated, in order."""
    seen = []
    orig = snooping.LinearRounds.reject

    def spy(self, k, c):
        seen.append(k)
        return orig(self, k, c)

    monkeypatch.setattr(snooping.LinearRounds, "reject", spy)
    return seen


def _both(obs, monkeypatch, downdates, **kw):
    """The downdated rounds forced on (threshold 0) and the exact path; asserts that downdates happened."""
    monkeypatch.setattr(snooping, "LINEAR_MIN_OBS", 0)
    lin = adjust(obs, **kw)
    assert downdates
    monkeypatch.setattr(snooping, "LINEAR_MIN_OBS", 10 ** 12)
    ref = adjust(obs, **kw)
    return lin, ref


def _same(lin, ref):
    assert [(o.station, o.target) for o in lin.outliers] == [(o.station, o.target) for o in ref.outliers]
    assert np.array_equal(lin.used, ref.used)
    np.testing.assert_allclose(lin.target_xyz_m, ref.target_xyz_m, atol=1e-9, rtol=0)
    np.testing.assert_allclose(lin.station_xyz_m, ref.station_xyz_m, atol=1e-9, rtol=0)
    assert lin.sigma0 == pytest.approx(ref.sigma0, rel=1e-10)
    sl, sr = lin.tests["steps"], ref.tests["steps"]
    assert len(sl) == len(sr)
    for a, b in zip(sl, sr):
        assert a["action"] == b["action"] and a.get("index") == b.get("index")
        assert a["statistic"] == pytest.approx(b["statistic"], rel=1e-7)
        assert a["statistic_k"] == pytest.approx(b["statistic_k"], rel=1e-7)


def test_downdated_rounds_equal_the_exact_rounds(monkeypatch, downdates):
    obs, planted, truth = _blundered()
    lin, ref = _both(obs, monkeypatch, downdates, initial=truth)
    _same(lin, ref)
    assert set(planted) <= {int(k) for k in np.flatnonzero(~np.asarray(ref.used, bool))}


def test_with_an_unknown_variance_factor_and_refits_every_few_rounds(monkeypatch, downdates):
    """Pope's τ-test (σ̂0 from the downdated vᵀPv), and a cap of 4 downdates (an adjustment after
    every 4 rejections)."""
    obs, _, truth = _blundered(n_blunders=9, seed=8, size_sigma=(4.5, 9))     # marginal: |w| <= 10
    monkeypatch.setattr(snooping, "MAX_DOWNDATES", 4)
    lin, ref = _both(obs, monkeypatch, downdates, variance_factor="unknown", initial=truth)
    assert len(ref.outliers) >= 5
    _same(lin, ref)


def test_large_networks_use_the_downdate_and_small_ones_do_not(monkeypatch, downdates):
    obs, _, truth = _blundered()
    adjust(obs, initial=truth)
    assert not downdates                               # 1 200 distances: below LINEAR_MIN_OBS
    monkeypatch.setattr(snooping, "LINEAR_MIN_OBS", 1000)
    res = adjust(obs, initial=truth)
    assert len(downdates) == len(res.outliers) > 0


@pytest.mark.parametrize("seed,kernels", [(s, False) for s in range(6)] + [(s, True) for s in (6, 7, 8)])
def test_random_networks_with_weak_targets_agree_with_the_exact_path(monkeypatch, downdates, seed, kernels):
    """Networks not designed for the check: 10 stations, 200 targets each seen by 4, 5 or 6 random
    stations (at 4 the w-tests of a target's distances are perfectly correlated: nothing may be
    rejected there), 5 blunders of 5-40 σ. The downdated and the exact path end alike: the same
    rejections, the same reason when they stop, coordinates to 1e-9 m. Three more seeds through the
    compiled kernels (hat rows, covariance and design products, residuals) on both paths."""
    from types import SimpleNamespace

    if kernels:
        from multilat.network.adjust import _covariance_kernels as K
        from multilat.network.adjust import covariance as C

        if not K.HAVE_NUMBA:
            pytest.skip("numba not installed")
        monkeypatch.setattr(C, "KERNELS_ABOVE_OBS", 0)

    net = synthetic_network(seed, population="rings", n_stations=10, n_targets=200, per_target=[4, 5, 6][seed % 3])
    d = net.distance_m.copy()
    g = np.random.default_rng(seed)
    k = g.choice(d.size, 5, replace=False)
    d[k] += g.choice([-1, 1], 5) * g.uniform(5, 40, 5) * 5e-6
    obs = Observations.from_labels([f"S{i}" for i in net.station_index], [f"T{j}" for j in net.target_index],
                                   d, np.full(d.size, 5e-6))
    order = [int(sid[1:]) for sid in obs.station_ids]
    truth = SimpleNamespace(station_xyz_m=net.station_xyz_m[order], offset_m=net.offset_m[order],
                            target_xyz_m=net.target_xyz_m[[int(t[1:]) for t in obs.target_ids]])
    monkeypatch.setattr(snooping, "LINEAR_MIN_OBS", 0)
    lin = adjust(obs, initial=truth)
    monkeypatch.setattr(snooping, "LINEAR_MIN_OBS", 10 ** 12)
    ref = adjust(obs, initial=truth)
    assert [(o.station, o.target) for o in lin.outliers] == [(o.station, o.target) for o in ref.outliers]
    assert lin.unlocated_reason == ref.unlocated_reason
    assert lin.unlocated == ref.unlocated
    np.testing.assert_allclose(lin.target_xyz_m, ref.target_xyz_m, atol=1e-9, rtol=0)
    if kernels and seed % 3:          # 5 and 6 stations per target: rejections, so downdates (4: none)
        assert downdates



def test_downdated_rounds_through_the_compiled_kernels(monkeypatch, downdates):
    """The same agreement with the hat rows, covariance products and residuals from the compiled
    kernels (what networks above 10 000 distances run), several downdates between adjustments."""
    from multilat.network.adjust import _covariance_kernels as K
    from multilat.network.adjust import covariance as C

    if not K.HAVE_NUMBA:
        pytest.skip("numba not installed")
    monkeypatch.setattr(C, "KERNELS_ABOVE_OBS", 0)
    obs, planted, truth = _blundered(n_blunders=9, seed=8, size_sigma=(4.5, 9))
    lin, ref = _both(obs, monkeypatch, downdates, variance_factor="unknown", initial=truth)
    assert len(downdates) >= 3
    _same(lin, ref)
