"""Raw readings -> corrected distances: round trip, uncertainty (χ²), interpolation, CLI and bad input."""

import json
from dataclasses import replace

import numpy as np
import pytest

from multilat import air, gimbal, instrument
from multilat.campaign.correct import correct_file, correct_raw, is_raw_file, observations_from_raw
from multilat.campaign.worked import (CampaignConditions, simulate_campaign, write_environment_csv,
                                      write_heights_csv, write_raw_csv)
from multilat.cli import main

# a small fixed geometry: the paper's large-volume heads and 6 targets (metres, network frame)
STATIONS = ("A", "B", "C", "D")
SXYZ = np.array([[0, 0, 0], [2.736, 0.056, 1.406], [5.289, 0, 0], [2.692, 6.236, 0.793]])
TARGETS = tuple(f"P{i}" for i in range(1, 7))
TXYZ = np.array([[1.0, 2.0, 0.2], [4.0, 3.0, -0.4], [2.5, 9.0, 0.5], [6.5, 5.0, 0.1],
                 [-0.8, 4.0, 0.3], [3.0, 1.5, 1.2]])
LINEAR = CampaignConditions(profile="linear", gradient_c_per_m=0.6)
INST = instrument.load_instrument("seed2020")


def _camp(**kw):
    kw.setdefault("conditions", LINEAR)
    return simulate_campaign(STATIONS, SXYZ, TARGETS, TXYZ, offset_m=[1e-4, -2e-4, 3e-4, 0.0],
                             instrument=INST, **kw)


@pytest.mark.parametrize("phase", [False, True])
@pytest.mark.parametrize("formula", ["ciddor", "edlen"])
def test_round_trip_exact_environment(phase, formula):
    # truth -> raw readings (air, transit offsets, head constants) -> correct: back to the truth.
    # 1 nm bound: the chain is algebraically exact, float64 rounding is ~1e-15 m.
    camp = _camp(phase=phase, formula=formula)
    res = correct_raw(camp.raw, environment=camp.log, instrument=INST, formula=formula)
    np.testing.assert_allclose(res.distance_m, camp.observed_true_m, rtol=0, atol=1e-9)
    # the beam air the pipeline used is the true beam-averaged air (linear profile: exact)
    np.testing.assert_allclose(res.environment["temperature_c"], camp.true_environment["temperature_c"],
                               atol=1e-10)
    np.testing.assert_allclose(res.gradient_c_per_m, 0.6, atol=1e-10)
    # the transit corrections are eq. (2)'s: -Toh cos(phi) to first order (Toh/R ~ 1e-6)
    toh = np.array([INST.heads[s].toh_m for s in res.station_ids])
    np.testing.assert_allclose(res.head_transit_correction_m, -toh * np.cos(camp.raw.elevation_rad),
                               atol=1e-11)
    np.testing.assert_allclose(res.target_transit_correction_m, INST.target.tot_m * np.cos(camp.raw.elevation_rad),
                               atol=1e-11)


def test_index_along_integrated_path_differs_by_nanometres():
    # the pipeline uses the index of the beam-averaged air; the physical optical path integrates the
    # index along the beam. Their difference is the index's curvature in T: well below 10 nm here.
    camp = _camp(exact_path=False)
    res = correct_raw(camp.raw, environment=camp.log, instrument=INST)
    err = res.distance_m - camp.observed_true_m
    assert np.max(np.abs(err)) < 1e-8


def test_interpolated_index_between_readings():
    camp = _camp()
    res = correct_raw(camp.raw, environment=camp.log, instrument=INST)
    # by hand: reading 7 lies between two log readings of each sensor; interpolate, fit the line, evaluate
    i = 7
    t = camp.raw.time_s[i]
    log = camp.log
    temps = []
    for ts, rd in zip(log.times_s, log.readings):
        k = np.searchsorted(ts, t) - 1
        f = (t - ts[k]) / (ts[k + 1] - ts[k])
        assert 0 < f < 1
        temps.append(rd["temperature_c"][k] * (1 - f) + rd["temperature_c"][k + 1] * f)
    slope, icpt = np.polyfit(log.height_m, temps, 1)
    zmid = 0.5 * (camp.raw.station_height_m[i] + camp.raw.target_height_m[i])
    ts0, rd0 = log.times_s[0], log.readings[0]
    p = np.interp(t, ts0, rd0["pressure_hpa"])
    n = air.group_index(icpt + slope * zmid, p * 100, humidity_pct=45.0, co2_ppm=450.0)
    assert res.group_index[i] == pytest.approx(float(n), abs=1e-14)


def test_jacobian_against_finite_difference():
    camp = _camp()
    res = correct_raw(camp.raw, environment=camp.log, instrument=INST)
    j = res.air_parameters.index("S2:temperature_c")
    h = 0.01
    bumped = replace(camp.log, readings=tuple(
        {**rd, "temperature_c": rd["temperature_c"] + (h if k == 1 else 0.0)} for k, rd in enumerate(camp.log.readings)))
    res2 = correct_raw(camp.raw, environment=bumped, instrument=INST)
    np.testing.assert_allclose((res2.distance_m - res.distance_m) / h, res.air_jacobian_m[:, j], rtol=1e-4, atol=1e-12)


def test_chi2_over_simulated_campaigns():
    # Many campaigns with fresh sensor calibration errors and distance-model errors: the corrected
    # distances' errors r must follow the reported covariance C: E[r' C^-1 r] = m. The tolerance is
    # 4 standard errors of the mean, from the empirical spread of chi2 (the model errors are not
    # gaussian). Sensor errors alone (gaussian, rank-deficient C_air): chi2 ~ chi2(rank) exactly.
    rng = np.random.default_rng(2020)
    n_camp = 300
    chi_full, chi_air = [], []
    for _ in range(n_camp):
        camp = _camp(rng=rng, sensor_errors=True, model_errors=True)
        res = correct_raw(camp.raw, environment=camp.log, instrument=INST)
        r = res.distance_m - camp.observed_true_m
        chi_full.append(r @ np.linalg.solve(res.covariance_m2, r))
        r_air = r - camp.model_error_m        # the sensor part alone (model error known in simulation)
        cov_air = res.air_jacobian_m @ np.diag(res.air_parameter_std ** 2) @ res.air_jacobian_m.T
        w, v = np.linalg.eigh(cov_air)
        keep = w > w.max() * 1e-9
        z = (v[:, keep].T @ r_air) / np.sqrt(w[keep])
        chi_air.append(z @ z)
        rank = int(keep.sum())
    m = camp.raw.size
    chi_full, chi_air = np.array(chi_full), np.array(chi_air)
    assert abs(chi_full.mean() - m) < 4 * chi_full.std(ddof=1) / np.sqrt(n_camp)
    assert abs(chi_air.mean() - rank) < 4 * np.sqrt(2 * rank / n_camp)
    # every distance is ~ proportional to its length times a common sensitivity, and P, RH, CO2 are
    # sensor means: the air part has a handful of independent directions (T offset and gradient...)
    assert 2 <= rank <= 5


def test_sensor_errors_are_correlated_between_observations():
    camp = _camp()
    res = correct_raw(camp.raw, environment=camp.log, instrument=INST)
    corr = res.correlation - np.diag(np.diag(res.correlation))
    cov_air = res.covariance_m2 - np.diag(res.sigma_model_m ** 2)
    assert np.all(cov_air[np.triu_indices(res.distance_m.size, 1)] > 0)   # all sensors serve all beams
    assert corr.max() < 1.0
    np.testing.assert_allclose(np.sqrt(np.diag(cov_air)), res.sigma_air_m, rtol=1e-12)


def _files(tmp_path, camp, *, heights=True):
    raw, env = tmp_path / "raw.csv", tmp_path / "env.csv"
    write_raw_csv(raw, camp, heights_in_file=heights)
    write_environment_csv(env, camp.log)
    return raw, env


def test_files_and_library_entry_points(tmp_path):
    camp = _camp()
    raw, env = _files(tmp_path, camp, heights=False)
    hts = tmp_path / "heights.csv"
    write_heights_csv(hts, camp.heights)
    assert is_raw_file(raw)
    res = correct_file(raw, environment=env, instrument=INST, heights=hts)
    np.testing.assert_allclose(res.distance_m, camp.observed_true_m, atol=1e-9)
    obs = observations_from_raw(raw, environment=env, instrument=INST, heights=hts)
    assert obs.station_ids == STATIONS and obs.target_ids == TARGETS
    np.testing.assert_allclose(obs.distance_m, res.distance_m)
    np.testing.assert_allclose(obs.sigma_m, res.sigma_m)


def test_cli_correct_writes_observation_file(tmp_path, capsys):
    camp = _camp(phase=True)
    raw, env = _files(tmp_path, camp)
    out, png = tmp_path / "obs.csv", tmp_path / "fig.png"
    assert main(["correct", str(raw), "--environment", str(env), "--out", str(out), "--plot", str(png),
                 "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(js["distance_m"], camp.observed_true_m, atol=1e-9)
    assert len(js["covariance_m2"]) == camp.raw.size
    assert png.stat().st_size > 10_000
    from multilat.io import read_csv_table
    t = read_csv_table(out, required=("station", "target", "distance_m", "sigma_m"))
    np.testing.assert_allclose(t.floats("distance_m"), camp.observed_true_m, atol=1e-9)
    np.testing.assert_allclose(t.floats("sigma_m"), js["sigma_m"], rtol=1e-12)
    assert not is_raw_file(out)
    from multilat.network.io.files import read_observations   # the file `multilat adjust` reads
    obs = read_observations(out)
    np.testing.assert_allclose(obs.sigma_m, js["sigma_m"], rtol=1e-12)
    assert main(["correct", str(raw), "-e", str(env), "--formula", "edlen"]) == 0
    assert "corrected distances" in capsys.readouterr().out
    cov = tmp_path / "cov.csv"
    assert main(["correct", str(raw), "-e", str(env), "--cov", str(cov), "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    ct = read_csv_table(cov, required=("row",), warn_unknown=False)
    got = np.array([ct.floats(c) for c in ct.columns[1:]]).T
    np.testing.assert_allclose(got, js["covariance_m2"], rtol=1e-15)
    np.testing.assert_allclose(np.sqrt(np.diag(got)), js["sigma_m"], rtol=1e-12)


def _expect_error(capsys, argv, match, out):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:"), err
    assert match in err[0], err[0]
    assert not out.exists()
    assert not [p for p in out.parent.iterdir() if p.name.endswith(".part")]


def test_cli_outside_span_refused_or_extrapolated(tmp_path, capsys):
    camp = _camp()
    raw, env = _files(tmp_path, camp)
    lines = env.read_text().splitlines()
    # drop the last two log times (8 rows): the last readings fall outside the log
    env.write_text("\n".join(lines[:-8]) + "\n")
    out = tmp_path / "obs.csv"
    _expect_error(capsys, ["correct", str(raw), "-e", str(env), "--out", str(out)],
                  f"raw.csv:{camp.raw.size + 1}: time", out)
    assert main(["correct", str(raw), "-e", str(env), "--out", str(out), "--extrapolate"]) == 0
    assert "extrapolated" in capsys.readouterr().err
    assert out.exists()


@pytest.mark.parametrize("edit,match", [
    (lambda h, r: (h, r.replace(r.split(",")[3], "6.3", 1)), "raw.csv:3: column 'phase_rad'"),
    (lambda h, r: (h, r.replace(r.split(",")[4], "0", 1)), "raw.csv:3: column 'frequency_hz'"),
    (lambda h, r: (h, r.replace(r.split(",")[2], "yesterday", 1)), "raw.csv:3: column 'time'"),
])
def test_cli_bad_raw_rows(tmp_path, capsys, edit, match):
    camp = _camp(phase=True)
    raw, env = _files(tmp_path, camp)
    lines = raw.read_text().splitlines()
    lines[0], lines[2] = edit(lines[0], lines[2])
    raw.write_text("\n".join(lines) + "\n")
    out = tmp_path / "obs.csv"
    _expect_error(capsys, ["correct", str(raw), "-e", str(env), "--out", str(out)], match, out)


def test_cli_bad_environment(tmp_path, capsys):
    camp = _camp()
    raw, env = _files(tmp_path, camp)
    out = tmp_path / "obs.csv"
    text = env.read_text().splitlines()
    # humidity over 100 %
    cells = text[5].split(",")
    cells[5] = "100.2"
    env.write_text("\n".join(text[:5] + [",".join(cells)] + text[6:]) + "\n")
    _expect_error(capsys, ["correct", str(raw), "-e", str(env), "--out", str(out)],
                  "env.csv:6: column 'humidity_pct'", out)
    # a sensor with no reading for the first observations (its first readings removed)
    kept = [ln for k, ln in enumerate(text) if not (",S3," in ln and k < 40)]
    env.write_text("\n".join(kept) + "\n")
    _expect_error(capsys, ["correct", str(raw), "-e", str(env), "--out", str(out)],
                  "raw.csv:2: time 2020-03-10T09:00:00Z has no reading of sensor 'S3'", out)
    # heights missing with several sensors
    env.write_text("\n".join(text) + "\n")
    raw2 = tmp_path / "raw2.csv"
    write_raw_csv(raw2, camp, heights_in_file=False)
    _expect_error(capsys, ["correct", str(raw2), "-e", str(env), "--out", str(out)],
                  "raw2.csv:2: station or target height missing", out)
    # one target height unknown in a heights file
    hts = tmp_path / "h.csv"
    write_heights_csv(hts, {k: v for k, v in camp.heights.items() if k != "P3"})
    _expect_error(capsys, ["correct", str(raw2), "-e", str(env), "--heights", str(hts), "--out", str(out)],
                  f"raw2.csv:{2 + 2 * 4}: station or target height missing", out)
    # no environment at all
    _expect_error(capsys, ["correct", str(raw2), "--out", str(out)], "no environment", out)


def test_per_row_environment_and_unknown_head(tmp_path, capsys):
    p = tmp_path / "raw.csv"
    p.write_text("station,target,optical_path_m,elevation_rad,temperature_c,pressure_hpa,humidity_pct\n"
                 "A,P1,3.0008,0.1,20,1013.25,50\nB,P1,4.0011,0.0,20.5,1013.0,50\n")
    res = correct_file(p, instrument=INST)
    n = air.group_index([20, 20.5], [101325.0, 101300.0], humidity_pct=50, co2_ppm=450)
    d_air = np.array([3.0008, 4.0011]) / n
    expect = gimbal.transit_offset_correction(d_air, [INST.heads["A"].toh_m, INST.heads["B"].toh_m], [0.1, 0.0])
    expect = gimbal.target_transit_offset_correction(expect, INST.target.tot_m, [-0.1, 0.0])
    np.testing.assert_allclose(res.distance_m, expect, atol=1e-12)
    # Tot = 11 µm is corrected with the line of sight when the target's angle is not recorded
    np.testing.assert_allclose(res.target_transit_correction_m, INST.target.tot_m * np.cos([0.1, 0.0]), rtol=1e-6)
    assert any("corrected with the line of sight" in s for s in res.notes)
    # one sensor for all rows: its errors are common, the air part almost fully correlated (not
    # exactly: the four quantities' sensitivities differ slightly between the two states' air)
    c_air = res.covariance_m2 - np.diag(res.sigma_model_m ** 2)
    assert c_air[0, 1] / np.sqrt(c_air[0, 0] * c_air[1, 1]) == pytest.approx(1.0, abs=1e-4)
    # azimuth and elevation are passed through to the observation file (for initial values, eq. 7)
    q = tmp_path / "rawaz.csv"
    q.write_text(p.read_text().replace("elevation_rad,", "elevation_rad,azimuth_rad,").replace(",0.1,", ",0.1,1.5,")
                 .replace(",0.0,", ",0.0,-0.5,"))
    out = tmp_path / "obs_az.csv"
    assert main(["correct", str(q), "--out", str(out)]) == 0
    from multilat.network.io.files import read_observations
    obs = read_observations(out)
    np.testing.assert_allclose(obs.azimuth_rad, [1.5, -0.5])
    np.testing.assert_allclose(obs.elevation_rad, [0.1, 0.0])
    p.write_text(p.read_text().replace("B,P1", "X,P1"))
    out = tmp_path / "o.csv"
    _expect_error(capsys, ["correct", str(p), "--out", str(out)], "raw.csv:3: station 'X' is not a head", out)
