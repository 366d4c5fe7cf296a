"""The covariance without its whitened Jacobian (issue 29, memory at 1.6 M distances).

At :data:`multilat.network.adjust.covariance.JACOBIAN_ON_DEMAND_OBS` observations and more the adjustment's
covariance drops the whitened Jacobian blocks and the gains ``P`` (88 bytes per distance, 135 MiB at
1.6 M) once the fit's own statistics are computed, and recomputes them per product from the adjusted
parameters. The recomputation is the same function of the same inputs, so every number must be the
same bits as with the blocks held: checked here with the threshold moved to 0 (every network releases)
against the threshold out of reach (none does), on the numpy and on the compiled path, with data
snooping's downdated rounds (which call the covariance products after the release) and without.
"""

from __future__ import annotations

import numpy as np
import pytest

from multilat.network.adjust import covariance as C
from multilat.network.adjust.distance import snooping
from multilat.network.adjust.distance.adjust import Start, adjust
from multilat.network.model.data import Observations
from multilat.network.adjust.distance.result import result_to_json
from multilat.network.synthetic.generator import synthetic_network


def _network(t=60, s=8, seed=3, blunders=0):
    net = synthetic_network(seed, population="rings", n_stations=s, n_targets=t, per_target=6, size_m=6.0)
    d = net.distance_m.copy()
    g = np.random.default_rng(seed)
    k = g.choice(d.size, blunders, replace=False)
    d[k] += g.choice([-1, 1], blunders) * g.uniform(30, 60, blunders) * 5e-6
    obs = Observations(tuple(f"S{i}" for i in range(s)), tuple(f"T{j}" for j in range(t)),
                       net.station_index, net.target_index, d, np.full(d.size, 5e-6))
    return obs, Start(net.station_xyz_m, net.target_xyz_m, net.offset_m)


def _kernels(monkeypatch, on: bool):
    if on:
        from multilat.network.adjust import _covariance_kernels as K

        if not K.HAVE_NUMBA:
            pytest.skip("numba not installed: the numpy path is the only one")
    monkeypatch.setattr(C, "KERNELS_ABOVE_OBS", 0 if on else 10 ** 12)


def _per_observation_arrays(cov, m: int) -> list[str]:
    """Attributes of ``cov`` that are arrays with a row per observation and more than one column."""
    return [k for k, v in vars(cov).items() if isinstance(v, np.ndarray) and v.ndim >= 2 and v.shape[0] == m]


@pytest.mark.parametrize("kernels", [False, True])
def test_released_covariance_gives_the_same_bits(monkeypatch, kernels):
    """Every product of the covariance after :meth:`release_jacobian` equals the held one's, bit for
    bit, and the released one keeps no (m, k) array."""
    _kernels(monkeypatch, kernels)
    obs, start = _network()
    res = adjust(obs, initial=start, snooping=False, solver="sparse")
    cov = res.covariance
    m = obs.n_obs
    assert cov._held is not None                     # 480 distances: below the threshold, held
    g = 0.7 * cov.design_row(3) - 1.3 * cov.design_row(50)
    V = np.random.default_rng(0).normal(size=(cov.n, 2))
    held = (cov.hat_diagonal(), cov.target_blocks(), cov.hat_row(7), cov.internal_times(g),
            cov.design_times(g), cov.target_coupling(), cov.times(V), cov.design_row(11), cov.P.copy())
    assert cov.release_jacobian()
    assert cov._held is None and _per_observation_arrays(cov, m) == []
    again = (cov.hat_diagonal(), cov.target_blocks(), cov.hat_row(7), cov.internal_times(g),
             cov.design_times(g), cov.target_coupling(), cov.times(V), cov.design_row(11), cov.P)
    for a, b in zip(held, again):
        assert np.array_equal(a, b)
    assert cov._held is None                         # the products did not keep what they recomputed


def test_a_covariance_without_a_recipe_keeps_its_blocks():
    """Built from arrays alone (the design's blocked covariance, the tests): nothing to recompute
    from, so :meth:`release_jacobian` refuses and the blocks stay."""
    obs, start = _network(t=20, s=6)
    res = adjust(obs, initial=start, snooping=False)
    cov = res.covariance
    bare = C.NetworkCovariance(cov.Qgg, cov.Minv, cov.Js_w, cov.Jt_w, cov.si, cov.ti)
    assert not bare.release_jacobian()
    assert bare._held is not None


@pytest.mark.parametrize("kernels", [False, True])
def test_adjustment_with_released_jacobian_equals_the_held_one(monkeypatch, kernels):
    """The whole adjustment with data snooping through the downdated rounds (covariance products
    after the release), the threshold at 0 against out of reach: the same rejections and the same
    document, bit for bit; the released result's covariance keeps no (m, k) array."""
    _kernels(monkeypatch, kernels)
    monkeypatch.setattr(snooping, "LINEAR_MIN_OBS", 0)
    obs, start = _network(t=80, blunders=3, seed=5)
    import multilat.network.adjust.distance.fit as fit_module

    monkeypatch.setattr(fit_module, "JACOBIAN_ON_DEMAND_OBS", 10 ** 12)
    ref = adjust(obs, initial=start, solver="sparse")
    monkeypatch.setattr(fit_module, "JACOBIAN_ON_DEMAND_OBS", 0)
    got = adjust(obs, initial=start, solver="sparse")
    assert len(ref.outliers) >= 1                    # the rounds ran
    assert ref.covariance._held is not None and got.covariance._held is None
    assert _per_observation_arrays(got.covariance, got.covariance.si.size) == []
    assert np.array_equal(ref.used, got.used)
    for name in ("redundancy", "w", "mdb_m", "residuals_m", "target_cov_m2", "station_cov_m2"):
        assert np.array_equal(getattr(ref, name), getattr(got, name)), name
    assert ref.w_failure_groups == got.w_failure_groups
    assert np.array_equal(ref.reliability.shift_max_m, got.reliability.shift_max_m, equal_nan=True)
    from multilat.io import dumps_json

    assert dumps_json(result_to_json(ref, observations="all")) == dumps_json(result_to_json(got, observations="all"))


def test_released_covariance_pickles_and_recomputes_the_same_bits():
    """Process pools pickle results: the recipe is an object, not a closure; the copy released and
    unpickled recomputes the held blocks' hat diagonal bit for bit."""
    import pickle

    obs, start = _network(t=30, s=6)
    cov = adjust(obs, initial=start, snooping=False).covariance
    h = cov.hat_diagonal()
    assert cov.release_jacobian()
    back = pickle.loads(pickle.dumps(cov))
    assert back._held is None and np.array_equal(back.hat_diagonal(), h)
