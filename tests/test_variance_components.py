"""Variance component estimation (issue 15 item 3, on distance groups; angle groups join when angles
are in the adjustment).

Independent values: (1) with one group the estimate is σ0² of the first adjustment (closed form:
Σ r_k = dof); (2) at convergence Helmert's rigorous estimator, written here with the dense
``R = I - A (AᵀA)⁺ Aᵀ`` of the whitened design matrix (itself built here from the model, not taken from
multilat), gives θ = 1 for every group, and ``diag(R)`` equals multilat's redundancy numbers;
(3) a group whose a-priori σ is mis-set by a factor of 3 is recovered: the estimated variance factor 9
within its standard error ``9 √(2/r)`` (|z| < 3 on each of 8 fixed-seed networks; the slow test
checks the coverage of ±2 SE over 200 networks against 95 % ± 3 binomial standard errors).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.stats import chi2

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.synthetic.generator import synthetic_network
from multilat.network.adjust.distance.variance_components import estimate_variance_components


def _misset(k, factor=3.0):
    """A random network whose stations S1, S2 measure with `factor` times the σ their file states."""
    net = synthetic_network(np.random.default_rng([15, k]), n_stations=(6, 8), n_targets=(15, 25))
    o = net.obs
    g = (o.station_index <= 1).astype(int)
    extra = np.sqrt(factor ** 2 - 1.0) * o.sigma_m
    d = o.distance_m + np.where(g == 1, np.random.default_rng([99, k]).normal(0.0, 1.0, o.n_obs) * extra, 0.0)
    return net, o.with_distances(d), g


def _z(k):
    net, obs, g = _misset(k)
    vc = estimate_variance_components(obs, groups=g, names=("rest", "S1S2"), initial=net, snooping=False)
    c = vc.components[1]
    return (c.variance_factor - 9.0) / c.variance_factor_std, vc


def test_a_group_misset_by_three_is_recovered():
    zs = []
    for k in range(8):
        z, vc = _z(k)
        zs.append(z)
        rest = vc.components[0]      # right σ: factor ~ χ²_r / r (r small here): inside its 99.9 % interval
        lo, hi = chi2.ppf([0.0005, 0.9995], rest.redundancy) / rest.redundancy
        assert vc.converged and lo < rest.variance_factor < hi
    assert np.all(np.abs(zs) < 3), zs
    assert abs(np.mean(zs)) < 3 / np.sqrt(8)


@pytest.mark.slow
def test_coverage_over_200_networks():
    """Networks where a group has redundancy below 1 are refused by name (counted, at most 10 %)."""
    zs, refused = [], 0
    for k in range(200):
        try:
            zs.append(_z(k)[0])
        except MultilatError as exc:
            assert "has redundancy" in str(exc)
            refused += 1
    n = len(zs)
    inside = sum(abs(z) < 2 for z in zs)
    assert refused <= 20 and inside / n >= 0.95 - 3 * np.sqrt(0.95 * 0.05 / n), (inside, n, refused)


def test_one_group_gives_sigma0_squared():
    net, obs, _ = _misset(3)
    first = adjust(obs, initial=net, snooping=False)
    vc = estimate_variance_components(obs, groups=np.zeros(obs.n_obs, int), names=("all",), initial=net,
                                      snooping=False)
    assert vc.components[0].variance_factor == pytest.approx(first.sigma0 ** 2, rel=1e-3)
    assert vc.result.sigma0 == pytest.approx(1.0, abs=1e-3)
    # the solution does not depend on a common scale of the weights
    np.testing.assert_allclose(vc.result.target_xyz_m, first.target_xyz_m, atol=1e-9)


def _dense_redundancy(res):
    """R = I - A (AᵀA)⁺ Aᵀ of the whitened distances at the solution (free network: pseudo-inverse)."""
    o = res.obs
    s, t = o.n_stations, o.n_targets
    si, ti = o.station_index, o.target_index
    d = res.station_xyz_m[si] - res.target_xyz_m[ti]
    u = d / np.linalg.norm(d, axis=1)[:, None]
    A = np.zeros((o.n_obs, 4 * s + 3 * t))
    r = np.arange(o.n_obs)
    for c in range(3):
        A[r, 4 * si + c] = u[:, c]
        A[r, 4 * s + 3 * ti + c] = -u[:, c]
    A[r, 4 * si + 3] = 1.0
    A /= o.sigma_m[:, None]
    return np.eye(o.n_obs) - A @ np.linalg.pinv(A.T @ A, rcond=1e-10) @ A.T


def test_helmert_rigorous_estimator_agrees_at_convergence():
    net, obs, g = _misset(5)
    vc = estimate_variance_components(obs, groups=g, names=("rest", "S1S2"), initial=net, snooping=False,
                                      tol=1e-8, max_iter=200)
    res = vc.result
    R = _dense_redundancy(res)
    np.testing.assert_allclose(np.diag(R), res.redundancy, atol=1e-8)
    v = res.residuals_m / res.obs.sigma_m
    E = [np.diag((g == k).astype(float)) for k in range(2)]
    S = np.array([[np.trace(R @ E[a] @ R @ E[b]) for b in range(2)] for a in range(2)])
    q = np.array([v @ E[a] @ v for a in range(2)])
    theta = np.linalg.solve(S, q)
    np.testing.assert_allclose(theta, 1.0, atol=1e-6)
    # the reported standard errors are Helmert's D(θ) = 2 S⁻¹ (scaled to the original σ)
    se = np.sqrt(2 * np.diag(np.linalg.inv(S)))
    np.testing.assert_allclose([c.variance_factor_std / c.variance_factor for c in vc.components], se, rtol=1e-6)
    assert vc.std_method == "helmert"


def test_group_without_redundancy_is_named():
    net, obs, _ = _misset(1, factor=1.0)
    g = np.zeros(obs.n_obs, int)
    g[0] = 1                                        # one observation alone: r < 1
    with pytest.raises(MultilatError, match="group 'lonely' has redundancy"):
        estimate_variance_components(obs, groups=g, names=("rest", "lonely"), initial=net)


def test_cli_variance_components_by_head(tmp_path, capsys):
    from pathlib import Path

    ex = Path(__file__).resolve().parents[1] / "examples" / "network" / "sequential" / "obs.csv"
    assert main(["adjust", str(ex), "--variance-components", "head", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    vc = doc["variance_components"]
    assert vc["grouping"] == "head" and [c["group"] for c in vc["components"]] == ["T1", "T2"]
    for c in vc["components"]:       # the example's σ are right: factors within 3 SE of 1
        assert abs(c["variance_factor"] - 1) < 3 * c["variance_factor_std"]
        assert c["sigma_scale"] == pytest.approx(np.sqrt(c["variance_factor"]))
    assert sum(c["n"] for c in vc["components"]) == doc["n_obs"]
    assert main(["adjust", str(ex), "--variance-components", "instrument"]) == 2
    err = capsys.readouterr().err
    assert "--variance-components must be one of head, station, kind" in err and err.count("\n") == 1


def _mixed_misset(k, factor=3.0):
    """A mixed campaign (4 heads, 2 trackers) whose angles scatter `factor` times their stated σ."""
    from multilat.network.model.data import Observations
    from multilat.network.synthetic.generator import synthetic_network

    net = synthetic_network(np.random.default_rng([16, k]), population="mixed", n_targets=20)
    o = net.obs
    rng = np.random.default_rng([17, k])
    extra = np.sqrt(factor ** 2 - 1.0) * o.sigma_azimuth_rad
    az = o.azimuth_rad + np.where(np.isfinite(extra), rng.normal(0, 1, o.n_obs) * np.nan_to_num(extra), 0.0)
    el = o.elevation_rad + np.where(np.isfinite(extra), rng.normal(0, 1, o.n_obs) * np.nan_to_num(extra), 0.0)
    obs = Observations(o.station_ids, o.target_ids, o.station_index, o.target_index, o.distance_m, o.sigma_m,
                       az, el, None, o.sigma_azimuth_rad, o.sigma_elevation_rad)
    return net, obs


def test_angle_sigma_misset_by_three_is_recovered():
    """Issue 15's must-show: the angles' σ mis-set by a factor of 3 (variance factor 9) recovered within
    3 Helmert standard errors on 4 fixed mixed campaigns; the distances' factor stays near 1."""
    zs = []
    for k in range(4):
        net, obs = _mixed_misset(k)
        vc = estimate_variance_components(obs, grouping="kind", initial=net, snooping=False)
        d, a = vc.components
        assert (d.group, a.group) == ("distances", "angles") and vc.std_method == "helmert"
        zs.append((a.variance_factor - 9.0) / a.variance_factor_std)
        lo, hi = chi2.ppf([0.0005, 0.9995], d.redundancy) / d.redundancy
        assert lo < d.variance_factor < hi
        assert vc.result.sigma0 == pytest.approx(1.0, abs=0.02)
    assert np.all(np.abs(zs) < 3), zs


def test_helmert_matrix_with_angles_equals_a_dense_finite_difference_solution():
    """``S`` from multilat's hat matrix of distances and angles against ``R = I − J (JᵀJ)⁺ Jᵀ`` with
    ``J`` by central differences of the model written here (free network, orientations included)."""
    from multilat.network.model.angles import predicted_angles, wrap_angle
    from multilat.network.adjust.distance.variance_components import helmert_matrix, observation_groups

    net, obs = _mixed_misset(0, factor=1.0)
    res = adjust(obs, initial=net, snooping=False)
    s, t = obs.n_stations, obs.n_targets
    orient = [sid for sid in obs.station_ids if sid in res.orientations]
    oi = [obs.station_ids.index(sid) for sid in orient]
    x0 = np.concatenate([res.station_xyz_m.ravel(), res.target_xyz_m.ravel(), res.offset_m,
                         np.concatenate([res.orientations[sid]["orientation_rad"] for sid in orient])])
    ka, ke = np.isfinite(obs.sigma_azimuth_rad), np.isfinite(obs.sigma_elevation_rad)

    def f(x):
        H, T = x[:3 * s].reshape(s, 3), x[3 * s:3 * s + 3 * t].reshape(t, 3)
        off = x[3 * s + 3 * t:4 * s + 3 * t]
        O = np.zeros((s, 3))
        O[oi] = x[4 * s + 3 * t:].reshape(-1, 3)
        si, ti = obs.station_index, obs.target_index
        az, el = predicted_angles(H, O, T, si, ti)
        return np.concatenate([(np.linalg.norm(H[si] - T[ti], axis=1) + off[si]) / obs.sigma_m,
                               wrap_angle(az[ka]) / obs.sigma_azimuth_rad[ka], el[ke] / obs.sigma_elevation_rad[ke]])

    J = np.empty((f(x0).size, x0.size))
    for k in range(x0.size):
        e = np.zeros_like(x0)
        e[k] = 1e-7
        J[:, k] = (f(x0 + e) - f(x0 - e)) / 2e-7
    R = np.eye(J.shape[0]) - J @ np.linalg.pinv(J.T @ J, rcond=1e-12) @ J.T
    gi, names = observation_groups(obs, "kind")
    S_dense = np.array([[np.sum(R[np.ix_(gi == g, gi == k)] ** 2) for k in range(2)] for g in range(2)])
    np.testing.assert_allclose(helmert_matrix(res, gi, 2), S_dense, rtol=1e-6)
