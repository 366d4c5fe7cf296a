"""G C Gᵀ: the coordinates' covariance with correlated distances (campaign.correlated).

Checks: (1) with C = diag(sigma²) and exact distances (zero residuals) it equals the adjustment's
analytic covariance (the Gauss-Newton (AᵀWA)⁻ is then the exact derivative): 1e-6 relative; with
noisy distances the two differ by the residual-curvature term GN neglects (≤ 1e-3 relative here);
(2) against a Monte Carlo of correlated distance errors re-adjusted per trial: every offset's std
within 4 Monte Carlo standard errors; (3) a common scale error (one sensor serving every beam) moves
the interpoint-distance uncertainty of a long pair by the closed form L·u_scale in quadrature.
"""

import numpy as np
import pytest

from multilat.campaign.correlated import adjustment_gain, correlated_covariance
from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.synthetic.configs import small_volume
from multilat.network.model.data import Observations

SIGMA = 4.7e-6


def _network(noise_rng=None):
    cfg = small_volume()
    d = cfg.geometric_distances_m() + cfg.offset_m[:, None]
    s, t = d.shape
    si, ti = np.repeat(np.arange(s), t), np.tile(np.arange(t), s)
    dist = d.ravel().copy()
    if noise_rng is not None:
        dist += noise_rng.normal(0.0, SIGMA, dist.size)
    obs = Observations(cfg.station_ids, cfg.target_ids, si, ti, dist, np.full(dist.size, SIGMA))
    return cfg, obs


@pytest.fixture(scope="module")
def exact():
    cfg, obs = _network()
    res = adjust(obs, snooping=False)
    return cfg, obs, res, adjustment_gain(res)


def test_diagonal_covariance_reproduces_the_adjustment(exact):
    cfg, obs, res, g = exact
    cc = correlated_covariance(res, np.diag(obs.sigma_m**2), gain=g)
    np.testing.assert_allclose(cc.offset_std_m, res.offset_std_m, rtol=1e-6)
    scale = np.abs(res.target_cov_m2).max()
    assert np.abs(cc.target_cov_m2 - res.target_cov_m2).max() < 1e-6 * scale
    assert np.abs(cc.station_cov_m2 - res.station_cov_m2).max() < 1e-6 * np.abs(res.station_cov_m2).max()


def test_noisy_data_differ_only_by_the_residual_curvature():
    cfg, obs = _network(np.random.default_rng(5))
    res = adjust(obs, snooping=False)
    cc = correlated_covariance(res, np.diag(obs.sigma_m**2))
    np.testing.assert_allclose(cc.offset_std_m, res.offset_std_m, rtol=1e-3)


def test_monte_carlo_with_a_shared_sensor_error(exact):
    """Distances with a common relative error (u = 5 µm/m: exaggerated, as from a 5 °C sensor error
    shared by every beam, so that the correlation stands out of the Monte Carlo noise) plus independent
    4.7 µm, 300 re-adjustments. The std of the offsets and of the longest target-target distance vs
    sqrt of G C Gᵀ: within 4 standard errors of a std estimate (s.e. ≈ std/sqrt(2(n-1))); and for that
    distance the diagonal-only covariance is off by more than 4 s.e. (the correlation matters)."""
    cfg, obs, res, g = exact
    u_rel = 5e-6
    d0 = obs.distance_m
    geo = d0 - res.offset_m[obs.station_index]
    c = np.diag(obs.sigma_m**2) + u_rel**2 * np.outer(geo, geo)
    cc = correlated_covariance(res, c, gain=g)
    ids = list(res.target_ids)
    tx = res.target_xyz_m
    far = max(((a, b) for a in range(len(ids)) for b in range(a)), key=lambda p: np.linalg.norm(tx[p[0]] - tx[p[1]]))
    pair = [(ids[far[0]], ids[far[1]])]
    xyz = dict(zip(ids, tx))
    rng = np.random.default_rng(11)
    n = 300
    offs = np.empty((n, len(cfg.station_ids)))
    lengths = np.empty(n)
    for k in range(n):
        e = rng.normal(0.0, SIGMA, d0.size) + geo * rng.normal(0.0, u_rel)
        r = adjust(Observations(obs.station_ids, obs.target_ids, obs.station_index, obs.target_index,
                                d0 + e, obs.sigma_m), snooping=False, initial=res)
        offs[k] = r.offset_m
        lengths[k] = np.linalg.norm(r.target_xyz_m[far[0]] - r.target_xyz_m[far[1]])
    mc = offs.std(axis=0, ddof=1)
    se = mc / np.sqrt(2 * (n - 1))
    assert np.all(np.abs(mc - cc.offset_std_m) < 4 * se), (mc, cc.offset_std_m)
    mc_l = lengths.std(ddof=1)
    se_l = mc_l / np.sqrt(2 * (n - 1))
    assert abs(mc_l - cc.interpoint_std_m(pair, xyz)[0]) < 4 * se_l
    diag_only = correlated_covariance(res, np.diag(np.diag(c)), gain=g).interpoint_std_m(pair, xyz)[0]
    assert abs(mc_l - diag_only) > 4 * se_l


def test_common_scale_adds_in_quadrature_on_interpoint_distances(exact):
    """A pure common scale error s on every distance scales the whole network (offsets aside): a
    length L between targets gets L·u_s added in quadrature, to first order."""
    cfg, obs, res, g = exact
    u_rel = 1e-6
    d0 = obs.distance_m
    xyz = dict(zip(res.target_ids, res.target_xyz_m))
    pairs = [("1", "11"), ("2", "3")]
    base = correlated_covariance(res, np.diag(obs.sigma_m**2), gain=g).interpoint_std_m(pairs, xyz)
    # the scale acts on the geometric part |H - T| = d - offset
    geo = d0 - res.offset_m[obs.station_index]
    both = correlated_covariance(res, np.diag(obs.sigma_m**2) + u_rel**2 * np.outer(geo, geo),
                                 gain=g).interpoint_std_m(pairs, xyz)
    length = np.array([np.linalg.norm(xyz[a] - xyz[b]) for a, b in pairs])
    np.testing.assert_allclose(both, np.sqrt(base**2 + (length * u_rel) ** 2), rtol=2e-3)


def test_bad_covariance_shapes(exact):
    cfg, obs, res, g = exact
    with pytest.raises(MultilatError, match="must be \\(56, 56\\)"):
        correlated_covariance(res, np.eye(3), gain=g)
    bad = np.diag(obs.sigma_m**2)
    bad[0, 1] = 1e-12
    with pytest.raises(MultilatError, match="symmetric"):
        correlated_covariance(res, bad, gain=g)
