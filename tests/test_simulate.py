"""The §4.4 simulation study: the paper's statistic on its own tables, Monte Carlo against the
first-order prediction, seeding, configuration files and the ``multilat simulate`` command."""

import json

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.synthetic.configs import large_volume, small_volume
from multilat.network.montecarlo.simulate import (PAPER_STUDY, interpoint_error_std, linear_prediction,
                                       load_config_file, simulate)

# seed 000 Tables V and VI: multilateration minus reference, um
TABLE_V_UM = [-2.7, 2.0, -2.4, -9.8, 16.0, 4.5, -7.0, 8.7, 0.0]
TABLE_VI_UM = [24.2, 8.6, -4.9, -9.8, -3.9, 11.3]


def test_statistic_reproduces_tables_v_and_vi():
    """The paper's 'standard deviation on these differences': 8.0 um (Table V) and 12.8 um (Table VI)
    are the sample std (ddof=1) of the printed differences: 7.94 and 12.76 um. Table VI agrees to
    the printed digit; Table V is 0.06 um short, more than the rounding of the printed values can
    explain (~0.01 um), so the paper probably used unrounded differences: tolerance 0.1 um. The
    alternatives are further off: ddof=0 gives 7.49 / 11.65 um, an uncentred RMS (n-1) 8.02 / 13.58 um."""
    assert interpoint_error_std(TABLE_V_UM) == pytest.approx(8.0, abs=0.1)
    assert interpoint_error_std(TABLE_VI_UM) == pytest.approx(12.8, abs=0.05)
    assert abs(np.std(TABLE_V_UM) - 8.0) > 0.4          # ddof=0 would give 7.5 um: not the paper's
    with pytest.raises(MultilatError, match="at least 2"):
        interpoint_error_std([1.0])


def test_monte_carlo_matches_first_order_prediction():
    """Mean over simulations of s^2 against tr(C Sigma_L)/(k-1) from the adjustment's covariance:
    agreement within 4 Monte Carlo standard errors (the linearisation error at 4.7 um is ~1e-5
    relative, far below the MC error)."""
    cfg = small_volume()
    res = simulate(cfg, trials=80, rng=3, initial="truth")
    s2 = res.interpoint_std_m ** 2
    se = s2.std(ddof=1) / np.sqrt(len(s2))
    assert abs(s2.mean() - res.predicted_rms_std_m ** 2) < 4 * se
    assert res.n_failed == 0 and res.errors_m.shape == (80, 9) and res.offset_error_m.shape == (80, 4)


def test_prediction_scales_with_sigma():
    cfg = large_volume()
    p1 = linear_prediction(cfg, 4.7e-6)
    assert linear_prediction(cfg, 9.4e-6) == pytest.approx(2 * p1, rel=1e-9)   # linear in sigma
    assert 2e-6 < p1 < 20e-6


def test_seeding_and_initial_values_do_not_change_results():
    cfg = large_volume()
    a = simulate(cfg, trials=4, rng=7)
    b = simulate(cfg, trials=6, rng=7)
    # simulation i uses SeedSequence child i: the first 4 are the same whatever the total
    np.testing.assert_array_equal(a.interpoint_std_m, b.interpoint_std_m[:4])
    c = simulate(cfg, trials=4, rng=7, initial="truth")
    # from distances alone or from the truth, the adjustment reaches the same minimum
    np.testing.assert_allclose(a.errors_m, c.errors_m, rtol=0, atol=1e-9)


def test_distance_model_noise():
    """Non-gaussian errors from the distance model: the weights are the model's standard
    uncertainties (~4.7 um); the per-simulation std stays within a factor 2 of the first-order value
    (constant parts of the head errors are absorbed by the offsets, so it is not equal)."""
    cfg = small_volume()
    m = simulate(cfg, trials=4, rng=1, noise="model")
    g = simulate(cfg, trials=4, rng=1)
    assert np.isnan(m.sigma_m) and m.noise == "model"
    assert not np.allclose(m.errors_m, g.errors_m)
    assert 0.5 < m.interpoint_std_m.mean() / m.predicted_rms_std_m < 2.0
    assert 3e-6 < m.predicted_rms_std_m < 15e-6


def test_bad_arguments():
    cfg = small_volume()
    with pytest.raises(MultilatError, match="noise must be one of"):
        simulate(cfg, trials=2, noise="uniform")
    with pytest.raises(MultilatError, match="trials must be >= 1"):
        simulate(cfg, trials=0)
    with pytest.raises(MultilatError, match="sigma_m"):
        simulate(cfg, trials=1, sigma_m=-1.0)
    with pytest.raises(MultilatError, match="unknown target '99'"):
        simulate(cfg, trials=1, pairs=[("1", "99"), ("1", "2")])


# ---------------------------------------------------------------------------- configuration files


def _toml_of(cfg, pairs=True):
    lines = [f'name = "{cfg.name}-file"', f"vertical_axis = {cfg.vertical_axis}"]
    if pairs:
        lines.append("pairs = [" + ", ".join(f'["{a}", "{b}"]' for a, b in
                                             zip(cfg.reference_lengths.target_a, cfg.reference_lengths.target_b)) + "]")
    lines.append("[stations]")
    lines += [f'{s} = [{x!r}, {y!r}, {z!r}]' for s, (x, y, z) in zip(cfg.station_ids, cfg.station_xyz_m.tolist())]
    lines.append("[targets]")
    lines += [f'"{t}" = [{x!r}, {y!r}, {z!r}]' for t, (x, y, z) in zip(cfg.target_ids, cfg.target_xyz_m.tolist())]
    lines.append("[offsets_m]")
    lines += [f"{s} = {o!r}" for s, o in zip(cfg.station_ids, cfg.offset_m.tolist())]
    return "\n".join(lines) + "\n"


def test_toml_file_equals_builtin(tmp_path):
    cfg = small_volume()
    p = tmp_path / "net.toml"
    p.write_text(_toml_of(cfg))
    fc = load_config_file(p)
    assert fc.name == "small-volume-file" and fc.vertical_axis == 1
    np.testing.assert_array_equal(fc.target_xyz_m, cfg.target_xyz_m)
    a = simulate(cfg, trials=3, rng=5)
    b = simulate(fc, trials=3, rng=5)
    np.testing.assert_array_equal(a.interpoint_std_m, b.interpoint_std_m)
    p.write_text(_toml_of(cfg, pairs=False))
    assert len(load_config_file(p).reference_lengths) == 14 * 13 // 2      # default: all target pairs


def test_csv_file_and_file_errors(tmp_path):
    cfg = large_volume()
    rows = ["point,kind,x_m,y_m,z_m,offset_m"]
    rows += [f"{s},station,{x!r},{y!r},{z!r},{o!r}" for s, (x, y, z), o in
             zip(cfg.station_ids, cfg.station_xyz_m.tolist(), cfg.offset_m.tolist())]
    rows += [f"{t},target,{x!r},{y!r},{z!r}," for t, (x, y, z) in zip(cfg.target_ids, cfg.target_xyz_m.tolist())]
    p = tmp_path / "net.csv"
    p.write_text("\n".join(rows) + "\n")
    fc = load_config_file(p)
    np.testing.assert_array_equal(fc.offset_m, cfg.offset_m)
    p.write_text("\n".join(rows[:3] + ["X,tripod,0,0,0,"] + rows[3:]) + "\n")
    with pytest.raises(MultilatError, match=r"net.csv:4: kind must be 'station' or 'target'"):
        load_config_file(p)
    t = tmp_path / "bad.toml"
    t.write_text(_toml_of(small_volume()).replace("vertical_axis", "vertikal_axis"))
    with pytest.raises(MultilatError, match="unknown key 'vertikal_axis'"):
        load_config_file(t)
    t.write_text("[stations\nA = 1\n")
    with pytest.raises(MultilatError, match="malformed TOML"):
        load_config_file(t)
    t.write_text(_toml_of(small_volume()).replace("A = [0.504", "A = [0.504, 1.0"))
    with pytest.raises(MultilatError, match=r"stations.A: expected \[x, y, z\]"):
        load_config_file(t)
    (tmp_path / "x.txt").write_text("")
    with pytest.raises(MultilatError, match="expected a .toml or .csv"):
        load_config_file(tmp_path / "x.txt")


# ---------------------------------------------------------------------------- CLI


def test_cli_json(capsys):
    assert main(["simulate", "small-volume", "--trials", "3", "--seed", "4", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["trials"] == 3 and doc["converged"] == 3 and doc["config"] == "small-volume"
    s = doc["interpoint_std_m"]
    assert set(s) == {"min", "mean", "max"} and s["min"] <= s["mean"] <= s["max"]
    assert doc["paper_m"] == {"min": 2.0e-6, "mean": 6.6e-6, "max": 10.7e-6, "trials": 50}
    assert len(doc["per_simulation_std_m"]) == 3 and len(doc["pairs"]) == 9
    assert s["mean"] == pytest.approx(np.mean(doc["per_simulation_std_m"]), rel=1e-12)
    assert PAPER_STUDY["large-volume"].mean_m == 5.4e-6


def test_cli_human_and_file(capsys, tmp_path):
    assert main(["simulate", "large-volume", "--trials", "2", "--noise", "gaussian", "--sigma-um", "2"]) == 0
    out = capsys.readouterr().out
    assert "paper (50 sims)" in out and "2.2" in out and "9.2" in out
    p = tmp_path / "n.toml"
    p.write_text(_toml_of(small_volume()))
    assert main(["simulate", str(p), "--trials", "2", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["paper_m"] is None and doc["config"] == "small-volume-file"


@pytest.mark.parametrize("args,msg", [
    (["simulate", "small-volume", "--noise", "uniform"], "--noise must be one of"),
    (["simulate", "small-volume", "--sigma-um", "0"], "--sigma-um must be > 0"),
    (["simulate", "small-volume", "--trials", "0"], "--trials must be >= 1"),
    (["simulate", "medium-volume"], "no such file"),
])
def test_cli_errors_are_one_line(capsys, args, msg):
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and msg in err[0]


def test_demo_section_quick():
    from multilat.report.html import render
    from multilat.report.network_demo import section

    sec = section(seed=1, quick=True)
    html = render("t", [sec])
    assert "Table V" in html and "Table VI" in html and "6.6" in html and "5.4" in html
    assert html.count("<img") == 2


def test_cli_model_noise_json(capsys):
    assert main(["simulate", "large-volume", "--trials", "2", "--noise", "model", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["noise"] == "model" and doc["sigma_m"] is None
    assert set(doc["offset_error_rms_m"]) == {"A", "B", "C", "D"}
    assert main(["simulate", "large-volume", "--trials", "1", "--noise", "model", "--instrument", "nope"]) == 2
    assert "unknown instrument preset" in capsys.readouterr().err


def test_perturbed_config_keeps_groups_rigid():
    from multilat.network.montecarlo.simulate import perturbed_config

    cfg = large_volume()
    p = perturbed_config(cfg, 0.5, rng=0, fixed=("3",))
    np.testing.assert_allclose(p.true_lengths_m(), cfg.true_lengths_m(), rtol=0, atol=1e-12)
    ix = [cfg.target_ids.index(k) for k in ("3", "7", "12")]
    np.testing.assert_array_equal(p.target_xyz_m[ix], cfg.target_xyz_m[ix])      # pillars held
    moved = np.abs(p.target_xyz_m - cfg.target_xyz_m).max(1)
    assert np.all(moved[[i for i in range(14) if i not in ix]] > 0)
    assert np.all(moved <= 0.5)


@pytest.mark.slow
def test_large_volume_layout_sensitivity():
    """docs/network-simulation.md: 100 re-placements (±0.5 m, pillars held) of the large volume give
    first-order rms values whose 5th percentile is above what the paper's 5.4 um mean implies."""
    from multilat.network.montecarlo.simulate import perturbed_config

    vals = [linear_prediction(perturbed_config(large_volume(), 0.5, rng=k, fixed=("3",)), 4.7e-6)
            for k in range(100)]
    assert np.percentile(vals, 5) > 6.0e-6


def test_cli_degenerate_network_is_one_line(capsys, tmp_path):
    """Four coplanar stations: every adjustment is refused; the command says why, exit 2."""
    lines = ["[stations]", "A = [0.0, 0.0, 0.0]", "B = [1.0, 0.0, 0.0]", "C = [0.0, 1.0, 0.0]",
             "D = [1.0, 1.0, 0.0]", "[targets]"]
    rng = np.random.default_rng(0)
    lines += [f'"{k}" = [{x!r}, {y!r}, {z!r}]' for k, (x, y, z) in
              enumerate(rng.uniform([0, 0, 0.3], [1, 1, 1.2], (12, 3)).tolist(), start=1)]
    p = tmp_path / "flat.toml"
    p.write_text("\n".join(lines) + "\n")
    assert main(["simulate", str(p), "--trials", "2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no simulation converged (2 failed; first:" in err[0]


def test_shipped_example_configuration(capsys):
    """examples/network/small_volume_config.csv (the truth of small_volume_obs.csv) simulates; its
    per-simulation std agrees with the first-order prediction (16 trials: the per-simulation std
    scatters by ~29 % (measured), so the mean has a relative standard error of ~7 %; bounds +-30 %,
    over 4 standard errors). The truth
    points file (no kind column) is refused with a hint to the example."""
    from pathlib import Path

    ex = Path(__file__).resolve().parents[1] / "examples" / "network"
    assert main(["simulate", str(ex / "small_volume_config.csv"), "--trials", "16", "--seed", "3",
                 "--start", "truth", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["converged"] == 16 and len(doc["pairs"]) == 14 * 13 // 2
    assert set(doc["offset_error_rms_m"]) == {"A", "B", "C", "D"}
    assert 0.7 < doc["interpoint_std_m"]["mean"] / doc["interpoint_std_lin_rms_m"] < 1.3
    assert main(["simulate", str(ex / "small_volume_truth.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "small_volume_truth.csv:2: header lacks column kind" in err[0]
    assert "small_volume_config.csv" in err[0]
