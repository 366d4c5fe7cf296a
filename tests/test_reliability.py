"""The test procedure (B-method, Pope's τ-test) and reliability (issue 16 items 3-4) against independent
values: scipy.stats distributions written out here, a re-adjustment with a planted bias, and false-alarm
and detection rates over simulated networks."""

import numpy as np
import pytest
from scipy import stats

from multilat.cli import main
from multilat.network.adjust import statistics as st
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.model.data import Observations
from multilat.network.synthetic.generator import synthetic_network
from multilat.network.adjust.distance.result import Start


def _obs(net, sigma_m=None):
    s, t = len(net.station_xyz_m), len(net.target_xyz_m)
    return Observations(tuple(f"S{i}" for i in range(s)), tuple(f"T{j}" for j in range(t)), net.station_index,
                        net.target_index, net.distance_m, net.sigma_m if sigma_m is None else
                        np.full(net.distance_m.shape, sigma_m))


def _start(net):
    return Start(net.station_xyz_m, net.target_xyz_m, net.offset_m)


# ------------------------------------------------------------------------------------ test values
@pytest.mark.parametrize("dof", [1, 3, 10, 63, 500, 5944])
def test_b_method_alpha_global_against_scipy_noncentral_chi2(dof):
    """Baarda's B-method: the global test detects the w-test's non-centrality λ0 (α0 = 0.001, power 80 %)
    with the same power. Written out with scipy.stats: λ0 from the normal quantiles, the critical
    value the 20 % quantile of χ'²(dof, λ0), α its central χ² tail."""
    lam0 = (stats.norm.isf(0.0005) + stats.norm.ppf(0.80)) ** 2        # 17.07 (Baarda's table: 17.075)
    assert st.noncentrality(0.001, 0.80) == pytest.approx(lam0, rel=1e-12)
    ref = stats.chi2.sf(stats.ncx2.ppf(0.20, dof, lam0), dof)
    assert st.b_method_alpha_global(dof) == pytest.approx(ref, rel=1e-9)
    # the global test at that alpha has the w-test's power against λ0 (the definition, checked back)
    assert st.test_power(st.b_method_alpha_global(dof), dof, lam0) == pytest.approx(0.80, abs=1e-9)
    if dof == 1:
        assert st.b_method_alpha_global(1) == pytest.approx(0.001, rel=1e-9)


@pytest.mark.parametrize("alpha, dof", [(0.001, 5), (0.001, 63), (0.05, 20)])
def test_tau_critical_is_popes_transform_of_student_t(alpha, dof):
    """Pope (1976): τ = sqrt(dof) t / sqrt(dof - 1 + t²), t the Student-t quantile with dof - 1; bounded by
    sqrt(dof); and equivalently P(|τ| > τc) = α with τ²/dof ~ Beta(1/2, (dof - 1)/2)."""
    t = stats.t.isf(alpha / 2, dof - 1)
    tc = st.tau_critical(alpha, dof)
    assert tc == pytest.approx(np.sqrt(dof) * t / np.sqrt(dof - 1 + t * t), rel=1e-12)
    assert tc < np.sqrt(dof)
    assert stats.beta.sf(tc ** 2 / dof, 0.5, (dof - 1) / 2) == pytest.approx(alpha, rel=1e-9)


# ------------------------------------------------------------------------------ unknown variance factor
def test_tau_test_with_a_wrong_a_priori_sigma_rejects_nothing():
    """The issue's case: 5 µm data weighted as 2 µm. Variance factor known: the global test fails and
    snooping rejects good distances. Unknown: σ0 ≈ 2.5 is estimated, Pope's τ-test rejects nothing and
    the covariances are scaled by σ0²."""
    net = synthetic_network(3, population="rings", n_stations=6, n_targets=60, per_target=5, size_m=5.0, sigma_m=5e-6)
    obs = _obs(net, sigma_m=2e-6)
    known = adjust(obs, initial=_start(net))
    assert known.global_test.passed is False
    unknown = adjust(obs, initial=_start(net), variance_factor="unknown")
    assert unknown.outliers == () and unknown.used.all()
    dof = unknown.dof
    # σ0 estimates 2.5 with relative standard error 1/sqrt(2 dof) (~0.06 here): 4 SE
    assert abs(unknown.sigma0 - 2.5) < 4 * 2.5 / np.sqrt(2 * dof)
    assert unknown.tests["variance_factor"] == "unknown" and unknown.tests["tau_critical"] > 0
    # covariances scaled by σ0² against the known-factor ones of a blunder-free run
    clean = adjust(obs, initial=_start(net), snooping=False)
    ratio = unknown.target_cov_m2[:, 0, 0] / clean.target_cov_m2[:, 0, 0]
    assert np.allclose(ratio, unknown.sigma0 ** 2, rtol=1e-6)


# ------------------------------------------------------------------------------ external reliability
def test_external_shift_equals_a_readjustment_with_the_mdb_added():
    """Δx_k = C Aᵀ P e_k MDB_k, checked by re-adjusting with MDB_k added to distance k (same start,
    same free datum): the largest point shift agrees to 1 % (the response is linear to ~MDB/L ~ 1e-5;
    1 % allows the iteration's stopping tolerance of 1e-9 σ on shifts of tens of µm)."""
    net = synthetic_network(8, population="rings", n_stations=6, n_targets=40, per_target=5, size_m=5.0)
    obs = _obs(net)
    base = adjust(obs, initial=_start(net), snooping=False)
    rel = base.reliability
    red = base.redundancy
    for k in (int(np.argmin(np.abs(red - 0.3))), int(np.argmin(np.abs(red - 0.7)))):
        d = obs.distance_m.copy()
        d[k] += rel.mdb_m[k]
        moved = adjust(obs.with_distances(d), initial=_start(net), snooping=False)
        pts0 = np.vstack([base.station_xyz_m, base.target_xyz_m])
        pts1 = np.vstack([moved.station_xyz_m, moved.target_xyz_m])
        shift = np.linalg.norm(pts1 - pts0, axis=1)
        assert rel.shift_max_m[k] == pytest.approx(shift.max(), rel=0.01), k
        ids = base.station_ids + base.target_ids
        assert rel.shift_point[k] == ids[int(np.argmax(shift))]
        # Baarda's bias-to-noise ratio from its definition
        lam0 = st.noncentrality(base.alpha, 0.80)
        assert rel.bnr[k] == pytest.approx(np.sqrt(lam0 * (1 - red[k]) / red[k]), rel=1e-12)


def test_a_poorly_controlled_target_is_named_where_a_blunder_goes_undetected(capsys, tmp_path):
    """The issue's case: a target seen by 4 heads has MDBs of tens of σ; a 12σ blunder there is not
    detected. The reliability summary names that target (MDB above --mdb-limit-sigma σ)."""
    net = synthetic_network(5, population="rings", n_stations=4, n_targets=30, per_target=4, size_m=5.0)
    obs = _obs(net)
    base = adjust(obs, initial=_start(net), snooping=False)
    rel = base.reliability
    k = int(np.argmax(rel.mdb_sigma))
    assert rel.mdb_sigma[k] > 12
    d = obs.distance_m.copy()
    d[k] += 12 * obs.sigma_m[k]
    res = adjust(obs.with_distances(d), initial=_start(net))
    assert not any(o.target == obs.target_ids[obs.target_index[k]] and o.station == obs.station_ids[
        obs.station_index[k]] for o in res.outliers)
    poor = {p["id"] for p in res.reliability.poor_targets}
    assert obs.target_ids[obs.target_index[k]] in poor
    # every named target really owns an observation beyond the limits, and none other is named
    r = res.reliability
    bad = res.used & ((r.redundancy < r.r_min) | (r.mdb_sigma > r.mdb_limit_sigma))
    assert poor == {obs.target_ids[j] for j in np.unique(obs.target_index[bad])}


# ------------------------------------------------------------------------- false alarms, detection
def _rates(n_networks, seed0):
    """Blunder-free networks: rejected / tested observations; the same networks with a 20σ blunder on
    a well-controlled distance: how often it is the first one rejected. Well controlled: redundancy
    ≥ 0.5 and identifiable, its w-test correlated below 0.8 with every other (ρ_kl = -h_kl /
    sqrt(r_k r_l)). On these ring networks a distance and the one from the opposite station to the
    same target are often correlated above 0.95: a blunder in either is then (rightly) not separable,
    and the larger |w| may be the other one's."""
    rejected = tested = caught = planted = 0
    for i in range(n_networks):
        net = synthetic_network(seed0 + i, population="rings", n_stations=6, n_targets=40, per_target=5, size_m=5.0)
        obs = _obs(net)
        res = adjust(obs, initial=_start(net), test_method="b-method")     # forced: the B-method's rates
        rejected += len(res.outliers)
        tested += obs.n_obs
        red = res.redundancy
        used = np.flatnonzero(res.used)            # the covariance's rows are the used observations

        def identifiable(pos):
            k = used[pos]
            rho = res.covariance.hat_row(int(pos)) / np.sqrt(red[k] * red[used])
            return red[k] >= 0.5 and np.max(np.abs(np.delete(rho, pos))) < 0.8
        pos = next((p for p in range(used.size) if identifiable(p)), None)
        if pos is None:          # no identifiable distance in this network: no blunder planted
            continue
        k = int(used[pos])
        planted += 1
        d = obs.distance_m.copy()
        d[k] += 20 * obs.sigma_m[k]
        bad = adjust(obs.with_distances(d), initial=_start(net), test_method="b-method")
        caught += bool(bad.outliers) and (bad.outliers[0].station, bad.outliers[0].target) == (
            obs.station_ids[obs.station_index[k]], obs.target_ids[obs.target_index[k]])
    return rejected, tested, caught, planted


def _check_rates(n, rejected, tested, caught, alpha0=0.001):
    # B-method: each w-test at α0, acted on only after the global test fails: the expected rate of
    # false rejections per observation is at most α0. Poisson bound at the 99.9 % level.
    mu = alpha0 * tested
    assert rejected <= mu + 3.1 * np.sqrt(mu) + 1, (rejected, tested)
    return caught


def test_false_alarm_rate_and_detection_b_method():
    n = 25
    rejected, tested, caught, planted = _rates(n, 100)
    _check_rates(n, rejected, tested, caught)
    assert planted >= 0.8 * n and caught >= planted - 1


@pytest.mark.slow
def test_false_alarm_rate_and_detection_b_method_200_networks():
    n = 200
    rejected, tested, caught, planted = _rates(n, 1000)
    _check_rates(n, rejected, tested, caught)
    assert planted >= 0.8 * n and caught >= 0.99 * planted


def test_cli_options_and_one_line_errors(capsys, tmp_path):
    net = synthetic_network(2, population="rings", n_stations=5, n_targets=20, per_target=4, size_m=4.0)
    obs = _obs(net)
    p = tmp_path / "obs.csv"
    with open(p, "w") as f:
        f.write("station,target,distance_m,sigma_m\n")
        for k in range(obs.n_obs):
            f.write(f"{obs.label(k).replace('->', ',')},{float(obs.distance_m[k])!r},{float(obs.sigma_m[k])!r}\n")
    assert main(["adjust", str(p), "--variance-factor", "unknown", "--json"]) == 0
    import json

    doc = json.loads(capsys.readouterr().out)
    assert doc["tests"]["variance_factor"] == "unknown" and doc["sigma_source"]["kind"] == "file column"
    for args, words in ((["--test-method", "bayes"], "--test-method"),
                        (["--variance-factor", "maybe"], "--variance-factor"),
                        (["--test-method", "b-method", "--alpha-global", "0.05"], "--alpha-global"),
                        (["--mdb-limit-sigma", "0"], "--mdb-limit-sigma")):
        assert main(["adjust", str(p), *args]) == 2
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1, err


def test_confidence_ellipsoid_closed_form_and_unlocated_points():
    # a covariance R diag(d) R^T has semi-axes sqrt(chi2_3(0.95) d) (ascending) along R's columns;
    # a point with a non-finite covariance gets NaN, the others are unchanged
    rng = np.random.default_rng(3)
    R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    d = np.array([4e-12, 1e-12, 9e-12])
    cov = np.stack([R @ np.diag(d) @ R.T, np.full((3, 3), np.nan), np.diag(d)])
    ax, V = st.confidence_ellipsoid(cov)
    k = stats.chi2.ppf(0.95, 3)
    for j in (0, 2):
        np.testing.assert_allclose(ax[j], np.sqrt(k * np.sort(d)), rtol=1e-9)
    np.testing.assert_allclose(np.abs(V[0][:, 2] @ R[:, 2]), 1.0, rtol=1e-9)   # the 9e-12 axis
    assert np.isnan(ax[1]).all() and np.isnan(V[1]).all()
    both, _ = st.confidence_ellipsoid(cov[[0, 2]])
    np.testing.assert_array_equal(both, ax[[0, 2]])


def test_result_ellipsoids_computed_once_per_level():
    net = synthetic_network(5, population="rings", n_stations=4, n_targets=12, per_target=4, size_m=5.0)
    res = adjust(_obs(net), initial=_start(net))
    assert res.ellipsoids() is res.ellipsoids()
    (sa, _), (ta, _) = res.ellipsoids(level=0.99)
    np.testing.assert_allclose(ta, st.confidence_ellipsoid(res.target_cov_m2, level=0.99)[0], rtol=0)
    assert (ta > res.ellipsoids()[1][0]).all()


def test_final_residuals_in_slices_are_the_whole_array_formula(monkeypatch):
    # build_result computes the residuals slice by slice (bounded memory at 10^6 distances): the same
    # bits as the formula over the whole arrays, whatever the slice
    from multilat.network.adjust.distance import result as R

    net = synthetic_network(10, population="rings", n_stations=5, n_targets=40, per_target=4,
                            size_m=5.0)  # (rng=9 has a target whose sight lines are
    obs = _obs(net)                                             # coplanar: it is left out, test_weak_targets)
    monkeypatch.setattr(R, "RESIDUAL_SLICE", 7)
    res = adjust(obs, initial=_start(net), snooping=False)
    assert res.excluded == ()
    si, ti = obs.station_index, obs.target_index
    want = obs.distance_m - ((1 + res.scale[si]) * np.linalg.norm(res.station_xyz_m[si] - res.target_xyz_m[ti], axis=1)
                             + res.offset_m[si])
    assert np.array_equal(res.residuals_m, want)


def test_correlated_with_is_the_ratio_formula():
    # |c_l| / sqrt(r_k r_l) > 1 - tol computed in place: the indices of the plain expression, with zero
    # redundancies, zero rows and NaN
    rng = np.random.default_rng(8)
    c = rng.normal(size=5000) * 0.4
    red = rng.uniform(0.0, 1.0, 5000)
    red[::97] = 0.0
    c[::89] = 0.0
    c[5], red[7] = np.nan, np.nan
    # a zero-redundancy observation (r <= R_ZERO: its exact hat row is e_l, any h_kl is rounding noise)
    # is never correlated (issue 25 item 6: a zero denominator used to count as perfect correlation)
    for k in (1, 3):
        with np.errstate(divide="ignore", invalid="ignore"):
            want = np.flatnonzero((np.abs(c) / np.sqrt(red[k] * red) > 1.0 - 1e-6) & (red > st.R_ZERO))
        got = st.correlated_with(c.copy(), red, k, 1e-6)
        assert np.array_equal(got, want) and got.size > 0
        assert not np.isin(got, np.flatnonzero(red == 0.0)).any()
    for k in (0, 97):                                                   # r_k = 0: no w-test, no group
        assert red[k] == 0.0 and st.correlated_with(c.copy(), red, k, 1e-6).size == 0


def test_w_statistics_in_place_are_the_plain_expression():
    rng = np.random.default_rng(12)
    v = rng.normal(size=3000) * 1e-5
    r = rng.uniform(0.0, 1.0, 3000)
    r[::50] = 0.0
    r[1::77] = 1e-10
    sigma = rng.uniform(1e-6, 1e-5, 3000)
    ok = r > 1e-9
    for s in (sigma, 5e-6, None):
        den = np.sqrt(np.where(ok, r, 1.0)) * (1.0 if s is None else np.asarray(s, float))
        want = np.where(ok, v / den, 0.0)
        got = st.w_statistics(v, s, r)
        assert np.array_equal(got, want) and got.shape == v.shape
    assert (st.w_statistics(v, None, r)[~ok] == 0.0).all() and (~ok).sum() > 50   # uncontrolled: w = 0
