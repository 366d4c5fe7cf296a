"""Monte Carlo of a real campaign (issue 16 item 6): raw readings with shared environment sensors,
repeated readings kept or averaged, through ``multilat propagate``.

The independent value for the coordinates' covariance is ``adjust RAW``'s ``G C Gᵀ``
(:func:`multilat.campaign.correlated.correlated_covariance`: ``G`` by central differences of the
adjustment itself, ``C`` the corrected distances' full covariance). Monte Carlo standard error of a
covariance element from ``n`` gaussian trials: ``sqrt((c_ii c_jj + c_ij²) / (n - 1))``, i.e.
``c_ii sqrt(2 / (n - 1))`` for a variance (1.4 % at n = 10 000). Tolerance: 4.5 standard errors on
each of the 52 variances and 1378 covariance elements (the chance that one of ~1400 correlated
gaussian z-scores exceeds 4.5 is below 1 %; the seed is fixed, so the test is deterministic).
"""

from __future__ import annotations

import csv
import json
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError

EX = Path(__file__).resolve().parents[1] / "examples" / "campaign"
RAW, ENV, HTS = EX / "raw.csv", EX / "environment.csv", EX / "heights.csv"
KW = dict(environment=ENV, heights=HTS)
N = 10_000


def _order(s, t):
    """Indices of the Monte Carlo layout [station xyz, offsets, target xyz] in the correlated
    covariance's layout [x, y, z, offset per station, then target xyz]."""
    idx = []
    for i in range(s):
        idx += [3 * i, 3 * i + 1, 3 * i + 2, 3 * s + i]
    return np.array(idx + list(range(4 * s, 4 * s + 3 * t)))


def _z_scores(samples, ref):
    n = samples.shape[0]
    c = np.cov(samples.T)
    d = np.diag(ref)
    se = np.sqrt((np.outer(d, d) + ref**2) / (n - 1))
    return (c - ref) / se, c


def _campaign(instrument="seed2020"):
    from multilat.campaign.correlated import correlated_covariance
    from multilat.campaign.propagation import campaign_problem
    from multilat.network.adjust.distance.adjust import adjust

    prob, corr = campaign_problem(RAW, instrument=instrument, **KW)
    res = adjust(corr.to_observations(), snooping=False)        # what `adjust RAW` does
    return prob, corr, res, correlated_covariance(res, corr.covariance_m2)


@pytest.fixture(scope="module")
def shipped():
    return _campaign()


def test_linear_sensor_sensitivity_matches_the_full_correction(shipped):
    """Each trial applies J e (linearised); the correction chain redone with every sensor log shifted
    by e gives the same distances to 1e-9 m (5e-10 relative at 2-6 m: far below the ppm asked),
    for errors of 1 and 5 standard uncertainties."""
    from multilat.campaign.propagation import shifted_sensor_distances

    _, corr, _, _ = shipped
    rng = np.random.default_rng(11)
    for k in (1.0, 1.0, 5.0):
        e = k * rng.standard_normal(corr.air_parameter_std.size) * corr.air_parameter_std
        full = shifted_sensor_distances(RAW, dict(zip(corr.air_parameters, e)), **KW) - corr.distance_m
        lin = corr.air_jacobian_m @ e
        assert np.abs(lin).max() > 1e-7                    # the sensors do move the distances
        assert np.abs(full - lin).max() < 1e-9 + 1e-3 * np.abs(lin).max() * (k > 1)


def test_mc_covariance_of_the_shipped_campaign_agrees_with_adjust_raw(shipped):
    """Must-show: `propagate` on examples/campaign (raw readings + environment log) — the Monte Carlo
    covariance of all 52 parameters agrees with adjust RAW's G C Gᵀ within 4.5 MC standard errors."""
    from multilat.network.montecarlo.propagate import propagate

    prob, corr, res, cc = shipped
    assert prob.readings.n_sensor_errors == 16
    r = propagate(prob, trials=N, rng=2026, noise="gaussian")
    assert r.n_failed == 0 and r.trials == N
    dev = r.samples[:, :prob.network.n_params].astype(float)[:, _order(4, 14)]
    z, c = _z_scores(dev, cc.cov_m2)
    zd = np.diag(z)
    assert np.abs(zd).max() < 4.5, np.abs(zd).max()
    assert np.abs(z).max() < 4.5, np.abs(z).max()
    # the engine's own linear covariance (batched Jacobian, full C) is the same G C Gᵀ to 1e-3
    lin = r.lin_std[:prob.network.n_params][_order(4, 14)]
    assert np.allclose(lin, np.sqrt(np.diag(cc.cov_m2)), rtol=1e-3)


def test_sensor_correlations_are_what_the_monte_carlo_sees():
    """With 1 °C / 1 hPa sensors the correlations matter (diagonal-only C gives variances 25-90 %
    too large): the Monte Carlo agrees with G C Gᵀ (4.5 SE) and is > 10 SE away from the diagonal
    model for every quantity that differs by more than 20 % — so the comparison above can fail."""
    from multilat import instrument as _inst
    from multilat.campaign.correlated import correlated_covariance
    from multilat.network.montecarlo.propagate import propagate

    base = _inst.load_instrument("seed2020")
    inst = base.model_copy(update={"environment": base.environment.model_copy(
        update=dict(u_temperature_c=1.0, u_pressure_hpa=1.0))})
    prob, corr, res, cc = _campaign(inst)
    diag_only = np.diag(correlated_covariance(res, np.diag(np.diag(corr.covariance_m2))).cov_m2)
    r = propagate(prob, trials=N, rng=5, noise="gaussian")
    dev = r.samples[:, :prob.network.n_params].astype(float)[:, _order(4, 14)]
    z, c = _z_scores(dev, cc.cov_m2)
    assert np.abs(np.diag(z)).max() < 4.5
    v = np.diag(c)
    differs = diag_only / np.diag(cc.cov_m2) > 1.2
    assert differs.sum() >= 20
    z_diag = (v - diag_only) / (diag_only * np.sqrt(2 / (N - 1)))
    assert np.all(z_diag[differs] < -10)


def test_model_noise_with_sensors(shipped):
    """Non-gaussian per-reading errors (distance model) plus gaussian sensor errors: each variance
    agrees with G C Gᵀ within 4.5 standard errors of a variance for that output's kurtosis
    (sqrt((k - 1) / n) relative)."""
    from multilat.network.montecarlo.propagate import propagate

    prob, corr, res, cc = shipped
    r = propagate(prob, trials=N, rng=9, noise="model")
    dev = r.samples[:, :prob.network.n_params].astype(float)[:, _order(4, 14)]
    c = dev - dev.mean(axis=0)
    m2 = np.mean(c**2, axis=0)
    kurt = np.mean(c**4, axis=0) / m2**2
    ref = np.diag(cc.cov_m2)
    assert np.all(np.abs(m2 / ref - 1) < 4.5 * np.sqrt((kurt - 1) / N) + 0.01)   # + model std vs sampler
    assert abs(r.input_std_ratio - 1) < 0.02


def test_identical_whatever_the_chunks_or_map(shipped):
    """Fixed-block seeding: the campaign draws (readings, sensors) are bit-identical for any chunk
    size and any map."""
    from multilat.network.montecarlo.propagate import propagate

    prob = shipped[0]
    a = propagate(prob, trials=2500, rng=4, noise="model", chunk_size=1000)
    b = propagate(prob, trials=2500, rng=4, noise="model", chunk_size=3000)
    with ThreadPoolExecutor(2) as ex:
        c = propagate(prob, trials=2500, rng=4, noise="model", chunk_size=1000, map=ex)
    assert np.array_equal(a.samples, b.samples) and np.array_equal(a.samples, c.samples)
    d = propagate(prob, trials=2500, rng=5, noise="model", chunk_size=1000)
    assert not np.array_equal(a.samples, d.samples)


# ------------------------------------------------------------------------------------- repeats
def _write_repeats(path, k=9, scatter_m=3e-6, seed=1):
    """The shipped raw file with every reading repeated ``k`` times (optical paths scattered)."""
    rows = list(csv.reader(open(RAW)))
    rng = np.random.default_rng(seed)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(rows[0])
        col = rows[0].index("optical_path_m")
        for row in rows[1:]:
            for _ in range(k):
                r = list(row)
                r[col] = repr(float(row[col]) + scatter_m * rng.standard_normal())
                w.writerow(r)
    return path


@pytest.fixture(scope="module")
def raw9(tmp_path_factory):
    return _write_repeats(tmp_path_factory.mktemp("rep") / "raw9.csv")


@pytest.mark.filterwarnings("ignore:possible false minimum")   # 9x the weight, same systematic misfit
def test_nine_readings_kept_or_averaged_give_the_same_result(raw9):
    """Table V style: 9 readings of each pair. Kept as 504 observations or averaged into 56 weighted
    means, the adjustment gives the same coordinates (to 1e-9 m, 3-2-1 datum) and covariance; the
    Monte Carlo with the same seed draws the same readings and gives the same trials (to 1e-9 m,
    float32 storage) and standard deviations; both solvers agree on the repeats."""
    from multilat.campaign.propagation import campaign_problem
    from multilat.network.adjust.distance.adjust import adjust
    from multilat.network.montecarlo.propagate import propagate
    from multilat.network.model.repeats import average_repeats

    kw = dict(KW, datum="321:A,B,C")
    sep, corr = campaign_problem(raw9, **kw)
    avg, _ = campaign_problem(raw9, average=True, **kw)
    assert sep.network.n_obs == 504 and avg.network.n_obs == 56

    obs = corr.to_observations()
    r_sep = adjust(obs, datum="321:A,B,C", snooping=False)
    r_avg = adjust(average_repeats(obs).obs, datum="321:A,B,C", snooping=False)
    r_sp = adjust(obs, datum="321:A,B,C", snooping=False, solver="sparse")
    for r in (r_avg, r_sp):
        assert np.abs(r.target_xyz_m - r_sep.target_xyz_m).max() < 1e-9
        assert np.abs(r.station_xyz_m - r_sep.station_xyz_m).max() < 1e-9
        assert np.abs(r.offset_m - r_sep.offset_m).max() < 1e-9
        assert np.allclose(r.target_cov_m2, r_sep.target_cov_m2, rtol=1e-6, atol=1e-9 * r_sep.target_cov_m2.max())
    assert r_sep.dof == 504 - (4 * 4 + 14 * 3 - 6) and abs(r_sep.redundancy.sum() - r_sep.dof) < 1e-6
    assert abs(r_sp.redundancy.sum() - r_sep.dof) < 1e-6

    a = propagate(sep, trials=3000, rng=3, noise="model")
    b = propagate(avg, trials=3000, rng=3, noise="model")
    assert np.abs(a.samples - b.samples).max() < 1e-9
    keep = ~b.fixed
    assert np.allclose(a.mc_std[keep], b.mc_std[keep], rtol=1e-6)
    assert np.allclose(a.lin_std[keep], b.lin_std[keep], rtol=1e-6)


@pytest.mark.filterwarnings("ignore:possible false minimum")
def test_averaged_scatter_is_reported(raw9):
    """The scatter per pair (sample std, n) equals numpy's std (ddof=1) of the corrected readings."""
    from multilat.campaign.propagation import campaign_problem

    avg, corr = campaign_problem(raw9, average=True, **KW)
    rep = avg.readings.scatter
    assert len(rep) == 56 and all(r["n"] == 9 for r in rep)
    d = corr.distance_m.reshape(56, 9)      # the file holds the 9 readings of a pair together
    assert np.allclose([r["std_m"] for r in rep], d.std(axis=1, ddof=1), rtol=1e-9)
    assert 2e-6 < np.median([r["std_m"] for r in rep]) < 4e-6          # the 3 µm written in
    w = 1 / corr.sigma_m.reshape(56, 9) ** 2
    assert np.allclose([r["mean_m"] for r in rep], (w * d).sum(1) / w.sum(1), rtol=0, atol=1e-12)


def test_plain_observation_file_with_repeats(tmp_path, capsys):
    """An observations CSV with repeated rows: `adjust` keeps them (dof counts every reading) and
    `propagate --average-repeats` reports the scatter, writing repeats.csv."""
    src = Path(__file__).resolve().parents[1] / "examples" / "network" / "small_volume_obs.csv"
    rows = [r for r in csv.reader(open(src)) if r and not r[0].startswith("#")]
    p = tmp_path / "rep.csv"
    rng = np.random.default_rng(0)
    col = rows[0].index("distance_m")
    with open(p, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(rows[0])
        for row in rows[1:]:
            for _ in range(3):
                r = list(row)
                r[col] = repr(float(row[col]) + 1e-6 * rng.standard_normal())
                w.writerow(r)
    pairs = len(rows) - 1
    m = 3 * pairs
    dof_single = json.loads(_adjust_json(src, capsys))["dof"]
    assert json.loads(_adjust_json(p, capsys))["dof"] == dof_single + 2 * pairs   # every reading counts
    out = tmp_path / "out"
    assert main(["propagate", str(p), "--trials", "2000", "--average-repeats", "--json", "--out", str(out)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["readings"]["n_readings"] == m and doc["readings"]["averaged"]
    assert all(r["n"] == 3 for r in doc["readings"]["repeats"])
    assert (out / "repeats.csv").exists()


def _adjust_json(path, capsys):
    assert main(["adjust", str(path), "--json", "--no-snooping"]) == 0
    return capsys.readouterr().out


def test_cli_raw_campaign_json(capsys):
    assert main(["propagate", str(RAW), "-e", str(ENV), "--heights", str(HTS), "--trials", "2000",
                 "--noise", "gaussian", "--instrument", "seed2020", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    rd = doc["readings"]
    assert rd["n_readings"] == 56 and rd["n_sensor_errors"] == 16 and rd["sensors"] == ["S1", "S2", "S3", "S4"]
    assert "linearised" in rd["air_sensitivity"]
    assert main(["propagate", str(RAW), "-e", str(ENV), "--heights", str(HTS), "--trials", "2000",
                 "--instrument", "seed2020"]) == 0
    assert "16 sensor errors" in capsys.readouterr().out
    # raw readings take their σ from an instrument: never a quiet default (issue 28)
    assert main(["propagate", str(RAW), "-e", str(ENV), "--heights", str(HTS), "--trials", "200"]) == 2
    assert "--instrument" in capsys.readouterr().err


@pytest.mark.parametrize("args, msg", [
    ([str(RAW)], "no environment: give an environment log"),
    ([str(RAW), "-e", str(EX / "missing.csv")], "missing.csv"),
    ([str(RAW), "-e", str(ENV), "--sigma-um", "3"], "--sigma-um does not apply to raw readings"),
    ([str(RAW), "-e", str(ENV), "--formula", "foo"], "--formula must be ciddor or edlen"),
    (["small-volume", "-e", str(ENV)], "apply to a campaign file, not to the built-in"),
    ([str(EX.parent / "network" / "small_volume_obs.csv"), "-e", str(ENV)], "apply to raw readings"),
    (["nofile.csv"], "no such file"),
])
def test_cli_bad_input_one_line(capsys, args, msg):
    rc = main(["propagate", *args, "--trials", "100"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc != 0 and len(err) == 1 and err[0].startswith("error:") and msg in err[0], err


def test_repeated_reading_with_a_slipped_digit_is_one_line_error(tmp_path, capsys):
    """Repeats are accepted, a malformed one is not: a reading 1 m off its pair's others is named."""
    p = tmp_path / "bad.csv"
    p.write_text("station,target,distance_m,sigma_m\n" + "".join(
        f"{s},{t},{2.0 + 0.1 * i + 0.01 * j},4e-6\n" for i, s in enumerate("ABCD") for j, t in enumerate("1234"))
        + "A,1,12.0,4e-6\n")
    rc = main(["adjust", str(p)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc != 0 and len(err) == 1 and "A->1" in err[0], err


def test_readings_validation():
    from multilat.network.montecarlo.readings import Readings

    with pytest.raises(MultilatError, match="one value per reading"):
        Readings(np.zeros(3, int), np.ones(3), np.ones(2))
    with pytest.raises(MultilatError, match="together"):
        Readings(np.zeros(3, int), np.ones(3), np.ones(3), air_jacobian_m=np.ones((3, 2)))


@pytest.mark.filterwarnings("ignore:possible false minimum")
def test_adjust_average_repeats_cli(raw9, capsys):
    """`adjust RAW --average-repeats`: the scatter per pair in the JSON, offsets (datum-free) equal to
    those of the separate readings to 1e-9 m, and the correlated block computed on A C Aᵀ."""
    base = [str(raw9), "-e", str(ENV), "--heights", str(HTS), "--json", "--no-snooping"]
    assert main(["adjust", *base, "--average-repeats"]) == 0
    avg = json.loads(capsys.readouterr().out)
    assert len(avg["repeats"]) == 56 and avg["repeats"][0]["n"] == 9 and avg["dof"] == 4
    assert "with_correlations" in avg
    from multilat.campaign.correct import correct_file
    from multilat.network.adjust.distance.adjust import adjust

    sep = adjust(correct_file(raw9, **KW).to_observations(), snooping=False)
    off = {k: v["offset_m"] for k, v in avg["stations"].items()}
    for i, sid in enumerate(sep.station_ids):
        assert abs(off[sid] - sep.offset_m[i]) < 1e-9


def test_redundancy_of_repeated_readings_against_a_dense_hat_matrix(tmp_path):
    """The pair table scaled for repeats (normal_equations.slot_gain, covariance.hat_diagonal) against the plain
    hat matrix ``A (AᵀA)⁺ Aᵀ`` of the whole whitened Jacobian (an independent computation), with
    2-4 readings per pair of unequal sigma: redundancy numbers equal to 1e-8."""
    from multilat.network.adjust.distance.adjust import adjust
    from multilat.network.model.data import Observations
    from multilat.network.model.distance import dense_jacobian, residuals_and_jacobian

    p = _write_repeats(tmp_path / "r.csv", k=1)
    from multilat.campaign.correct import correct_file

    o = correct_file(p, **KW).to_observations()
    rng = np.random.default_rng(4)
    k = rng.integers(1, 5, o.n_obs)                         # 1-4 readings per pair
    rows = np.repeat(np.arange(o.n_obs), k)
    sig = o.sigma_m[rows] * rng.uniform(0.7, 1.4, rows.size)
    d = o.distance_m[rows] + 0.5 * sig * rng.standard_normal(rows.size)
    rep = Observations(o.station_ids, o.target_ids, o.station_index[rows], o.target_index[rows], d, sig)
    res = adjust(rep, snooping=False)
    _, js, jt = residuals_and_jacobian(rep.distance_m, res.station_xyz_m, res.target_xyz_m, res.offset_m,
                                       np.zeros(rep.n_stations), rep.station_index, rep.target_index,
                                       cost="distance")
    js = js.copy()
    js[:, 4] = 0.0                                          # scales not estimated
    a = dense_jacobian(js, jt, rep.station_index, rep.target_index, rep.n_stations, rep.n_targets) / sig[:, None]
    hat = np.einsum("ij,ji->i", a, np.linalg.pinv(a.T @ a, rcond=1e-12) @ a.T)
    assert np.allclose(res.redundancy, 1.0 - hat, atol=1e-8)
