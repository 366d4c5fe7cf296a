"""Adjustment against networks with a known truth: exact recovery without noise, and with noise
errors consistent with the reported covariance (χ² statistics), σ0 ≈ 1, data snooping."""

import warnings

import numpy as np
import pytest
from scipy import stats

from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import Start, adjust
from multilat.network.model.datum import rigid_fit
from multilat.network.model.distance import Q, dense_jacobian, residuals_and_jacobian
from multilat.network.synthetic.generator import synthetic_network

from network_truth import noise_free, perturbed_start


def _net(seed, s, t, gap_fraction=0.0, **options):
    """``s`` stations around ``t`` targets (the package's generator, population "shell")."""
    return synthetic_network(seed, population="shell", n_stations=s, n_targets=t,
                             gap_fraction=gap_fraction, **options)


def _rigid_errors(res, truth):
    """Coordinate errors after the least-squares rigid fit of the truth onto the estimate (errors in
    the estimate's frame, where its covariance is expressed)."""
    est = np.vstack([res.station_xyz_m, res.target_xyz_m])
    true = np.vstack([truth.station_xyz_m, truth.target_xyz_m])
    R, t = rigid_fit(true, est)
    return est - (true @ R.T + t)


def test_noise_free_network_is_recovered_exactly():
    tr = _net(7, 6, 25, 0.2)
    res = adjust(noise_free(tr), initial=perturbed_start(tr, 8, scale_m=2e-2))
    # nothing but rounding: coordinates of metres to 1e-10 m
    assert np.abs(_rigid_errors(res, tr)).max() < 1e-10
    np.testing.assert_allclose(res.offset_m, tr.offset_m, atol=1e-10)
    assert res.outliers == ()


def test_errors_consistent_with_covariance_chi2():
    """Σ over runs of eᵀ C⁺ e (coordinates after a rigid fit to the truth, and offsets) against its
    χ² distribution with Σ rank degrees of freedom; two-sided test with false-alarm rate 0.2 %."""
    rng = np.random.default_rng(2024)
    chi2_total, dof_total = 0.0, 0
    vtpv_total, red_total = 0.0, 0
    z_off = []
    for run in range(24):
        s = int(rng.integers(4, 13))
        t = int(rng.integers(10, 201)) if s > 4 else int(rng.integers(14, 201))
        tr = _net(rng, s, t, 0.15 if s > 5 else 0.0, sigma_m=float(rng.uniform(2e-6, 8e-6)))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = adjust(tr.obs, initial=perturbed_start(tr, rng), snooping=False)
        e = _rigid_errors(res, tr)
        # parameter vector [station xyz, offsets, target xyz] and its covariance (free datum)
        rows = np.concatenate([(Q * np.arange(s)[:, None] + np.arange(3)).ravel(), Q * np.arange(s) + 3,
                               Q * s + np.arange(3 * t)])
        C = res.covariance.block(rows)
        vec = np.concatenate([e[:s].ravel(), res.offset_m - tr.offset_m, e[s:].ravel()])
        w, V = np.linalg.eigh(C)
        keep = w > 1e-10 * w[-1]
        assert keep.sum() == rows.size - 6          # datum defect exactly 6
        proj = V[:, keep].T @ vec
        chi2_total += float(np.sum(proj ** 2 / w[keep]))
        dof_total += int(keep.sum())
        vtpv_total += res.global_test.statistic
        red_total += res.dof
        z_off.append((res.offset_m - tr.offset_m) / res.offset_std_m)
    lo, hi = stats.chi2.ppf([0.001, 0.999], dof_total)
    assert lo < chi2_total < hi, (chi2_total, dof_total)
    lo, hi = stats.chi2.ppf([0.001, 0.999], red_total)
    assert lo < vtpv_total < hi, (vtpv_total, red_total)   # pooled σ0² = 1 within MC error
    z = np.concatenate(z_off)
    lo, hi = stats.chi2.ppf([0.001, 0.999], z.size)
    assert lo < np.sum(z ** 2) < hi                        # offsets within their uncertainty


def test_covariance_is_pseudo_inverse_and_redundancies_sum_to_dof():
    tr = _net(3, 5, 15, 0.2)
    res = adjust(tr.obs, initial=perturbed_start(tr, 4))
    o = tr.obs
    _, Js, Jt = residuals_and_jacobian(o.distance_m, res.station_xyz_m, res.target_xyz_m, res.offset_m,
                                       res.scale, o.station_index, o.target_index)
    J = dense_jacobian(Js, Jt, o.station_index, o.target_index, o.n_stations, o.n_targets) / o.sigma_m[:, None]
    keep = np.ones(J.shape[1], bool)
    keep[4:Q * o.n_stations:Q] = False
    N = J[:, keep].T @ J[:, keep]
    P = np.linalg.pinv(N, rcond=1e-12, hermitian=True)
    C = res.covariance.full()[np.ix_(keep, keep)]
    # inner constraints over all points = minimum-norm (pseudo-inverse); agreement limited by
    # cond(N) * eps ~ 1e-9 relative
    np.testing.assert_allclose(C, P, atol=1e-8 * np.abs(P).max())
    H = J[:, keep] @ P @ J[:, keep].T
    np.testing.assert_allclose(res.redundancy, 1 - np.diag(H), atol=1e-8)
    assert res.redundancy.sum() == pytest.approx(res.dof, abs=1e-6)


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_single_20_sigma_blunder_is_found_and_nothing_else(seed):
    rng = np.random.default_rng(100 + seed)
    tr = _net(rng, 6, 30, 0.1, sigma_m=5e-6)
    # a redundant place: a target seen by >= 5 stations (with 4, its 4 w-tests are perfectly
    # correlated and the faulty one cannot be told from the others; see docs/network.md)
    per_target = np.bincount(tr.obs.target_index)
    cand = np.flatnonzero(per_target[tr.obs.target_index] >= 5)
    k = int(rng.choice(cand))
    d = tr.obs.distance_m.copy()
    d[k] += 20 * tr.obs.sigma_m[k] * rng.choice([-1, 1])
    obs = tr.obs.with_distances(d)
    # alpha 1e-5 per observation: family-wise false-alarm rate ~ m * alpha = 0.2 % over ~170 obs
    res = adjust(obs, initial=perturbed_start(tr, rng), alpha=1e-5)
    assert [(o.station, o.target) for o in res.outliers] == [(obs.station_ids[obs.station_index[k]],
                                                             obs.target_ids[obs.target_index[k]])]
    assert res.used.sum() == obs.n_obs - 1 and not res.used[k]
    # the rejected residual shows the blunder (20 sigma), the rest passes the global test
    assert abs(res.residuals_m[k]) > 15 * obs.sigma_m[k]
    assert res.global_test.passed


def test_squared_cost_and_fixed_offsets_and_scales():
    tr = _net(21, 6, 30)
    exact = noise_free(tr)
    st = perturbed_start(tr, 22)
    res = adjust(exact, initial=st, cost="squared")
    assert np.abs(_rigid_errors(res, tr)).max() < 1e-9
    np.testing.assert_allclose(res.offset_m, tr.offset_m, atol=1e-9)
    assert res.global_test.passed is None and res.outliers == ()
    # offsets fixed at their true values: same solution, offsets reported as fixed, 6 more dof
    free = adjust(exact, initial=st)
    fixed = adjust(exact, initial=st, offsets=dict(zip(exact.station_ids, tr.offset_m)))
    assert not fixed.offset_estimated.any() and fixed.dof == free.dof + 6
    assert np.all(fixed.offset_std_m == 0)
    # a true scale of 20 ppm on one station is recovered when scales are estimated
    d = exact.distance_m.copy()
    m0 = exact.station_index == 2
    d[m0] = (d[m0] - tr.offset_m[2]) * (1 + 2e-5) + tr.offset_m[2]
    sc = adjust(exact.with_distances(d), initial=st, scales=["S3"])
    assert sc.scale[2] == pytest.approx(2e-5, abs=1e-12)
    assert sc.scale_estimated.tolist() == [False, False, True, False, False, False]


def test_large_network_runs_linear_in_targets():
    tr = _net(5, 8, 2000, 0.2)
    res = adjust(tr.obs, initial=perturbed_start(tr, 6, scale_m=1e-3), snooping=False)
    assert res.target_cov_m2.shape == (2000, 3, 3)
    assert 0.9 < res.sigma0 < 1.1     # dof ~ 6000: sd of sigma0 ~ 0.01


def test_bad_options_raise():
    tr = _net(1, 4, 14)
    st = perturbed_start(tr, 1)
    with pytest.raises(MultilatError, match="cost"):
        adjust(tr.obs, initial=st, cost="cubic")
    with pytest.raises(MultilatError, match="alpha"):
        adjust(tr.obs, initial=st, alpha=2)
    with pytest.raises(MultilatError, match="unknown station"):
        adjust(tr.obs, initial=st, offsets={"nope": 0.0})
    with pytest.raises(MultilatError, match="initial values"):
        adjust(tr.obs, initial=Start(np.zeros((3, 3)), np.zeros((14, 3)), np.zeros(4)))


def test_fault_at_a_minimally_observed_station_is_reported_not_misplaced():
    # station S1 sees exactly 5 targets (its minimum: 3 coordinates + offset + 1 for redundancy):
    # its 5 w-tests are perfectly correlated, so a 200-sigma fault on S1->T3 is detected but cannot
    # be located; nothing is rejected and the group is reported, and the global test fails
    tr = _net(31, 6, 25)
    keep = (tr.obs.station_index != 0) | (tr.obs.target_index < 5)
    obs = tr.obs.subset(keep)
    k = int(np.flatnonzero((obs.station_index == 0) & (obs.target_index == 2))[0])
    d = obs.distance_m.copy()
    d[k] += 200 * obs.sigma_m[k]
    res = adjust(obs.with_distances(d), initial=perturbed_start(tr, 32))
    assert res.outliers == ()
    assert sorted(o.target for o in res.unlocated) == ["T1", "T2", "T3", "T4", "T5"]
    assert {o.station for o in res.unlocated} == {"S1"}
    assert len({round(abs(o.w), 6) for o in res.unlocated}) == 1 and abs(res.unlocated[0].w) > 3.29
    # detected: by the largest |w| (Šidák, the default above 10 observations: the χ² test is then the
    # variance factor's, at 0.01, and passes here), by the global test under the B-method
    assert res.tests["method"] == "sidak" and res.tests["steps"][-1]["detection_passed"] is False
    assert abs(res.unlocated[0].w) > res.tests["w_critical"]
    assert res.used.all()
    b = adjust(obs.with_distances(d), initial=perturbed_start(tr, 32), test_method="b-method")
    assert not b.global_test.passed and b.outliers == () and len(b.unlocated) == 5


def test_snooping_keeps_a_targets_last_redundancy():
    """A 30-sigma fault on a target seen by only 4 of 6 stations: rejecting any of its 4 distances
    would leave it with 3 (determined, no redundancy). Its 4 w-tests are perfectly correlated even
    with 6 stations (the target's 3 coordinates absorb 3 of the 4 residual directions), so the
    fault is reported as not locatable and nothing is removed (the rule 'keep >= 4 distances per
    free target' in snooping._last_redundancy is the safety net behind this)."""
    tr = _net(41, 6, 20)
    keep = (tr.obs.target_index != 0) | (tr.obs.station_index < 4)
    obs = tr.obs.subset(keep)
    k = int(np.flatnonzero((obs.station_index == 1) & (obs.target_index == 0))[0])
    d = obs.distance_m.copy()
    d[k] += 30 * obs.sigma_m[k]
    res = adjust(obs.with_distances(d), initial=perturbed_start(tr, 42))
    assert res.outliers == () and res.used.all()
    assert {o.target for o in res.unlocated} == {"T1"}
    assert len(res.unlocated) == 4 and "perfectly correlated" in res.unlocated_reason


def test_control_blunder_is_snooped_and_bad_control_is_named():
    """Under a control datum (true coordinates of 6 targets) a 20-sigma distance blunder is still
    found by snooping (the control test separates the two: Omega_c - Omega_f ~ chi2); a control
    point moved by 2 mm is refused as inconsistent, naming it."""
    from multilat.network.model.data import Points

    tr = _net(51, 6, 25)
    ctrl = [f"T{j + 1}" for j in range(6)]
    pts = Points(tuple(ctrl), tr.target_xyz_m[:6])
    st = perturbed_start(tr, 52)
    per_target = np.bincount(tr.obs.target_index)
    k = int(np.flatnonzero((tr.obs.target_index == 10) & (per_target[tr.obs.target_index] >= 5))[0])
    d = tr.obs.distance_m.copy()
    d[k] += 20 * tr.obs.sigma_m[k]
    res = adjust(tr.obs.with_distances(d), initial=st, points=pts, datum="control", alpha=1e-5)
    assert [(o.station, o.target) for o in res.outliers] == [(tr.obs.label(k).split("->")[0], "T11")]
    moved = tr.target_xyz_m[:6].copy()
    moved[3] += [2e-3, 0.0, 0.0]
    with pytest.raises(MultilatError, match=r"control coordinates inconsistent .*largest misfit 'T4'"):
        adjust(tr.obs, initial=st, points=Points(tuple(ctrl), moved), datum="control")


def test_control_point_keeps_its_last_observation():
    """A control target seen by a single station with a fault on that distance: snooping flags it
    but does not remove the control point's only observation (it used to, then failed with
    'data snooping removed every observation of ...')."""
    from multilat.network.model.data import Points

    tr = _net(61, 6, 25)
    keep = (tr.obs.target_index != 0) | (tr.obs.station_index == 2)
    obs = tr.obs.subset(keep)
    k = int(np.flatnonzero(obs.target_index == 0)[0])
    d = obs.distance_m.copy()
    d[k] += 50 * obs.sigma_m[k]
    pts = Points(tuple(f"T{j + 1}" for j in range(5)), tr.target_xyz_m[:5])
    res = adjust(obs.with_distances(d), initial=perturbed_start(tr, 62), points=pts, datum="control")
    assert res.outliers == () and res.used.all()
    assert [(o.station, o.target) for o in res.unlocated] == [("S3", "T1")]
    assert "control point 'T1'" in res.unlocated_reason
