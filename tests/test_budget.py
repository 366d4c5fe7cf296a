"""Distance budget: reproduces the seed's 2.1 / 1.4 / 3.9 / 4.7 um by its own Monte Carlo; closed-form
checks of each group; shapes of the distributions; helpers for other modules; the CLI."""

import json
import math

import numpy as np
import pytest

from multilat import adm, budget
from multilat.cli import main
from multilat.errors import MultilatError
from multilat.instrument import load_instrument

PAPER_UM = {"telemetric": 2.1, "head": 1.4, "target": 3.9}
ROUND_HALF_WIDTH = 0.05e-6  # the paper's values are rounded to 0.1 um
TRIALS = 20_000  # per distance: 26 x 20 000 = 520 000 pooled trials, ~1 s


@pytest.fixture(scope="module")
def inst():
    return load_instrument("seed2020")


@pytest.fixture(scope="module")
def res(inst):
    return budget.distance_budget(inst, head="A", trials=TRIALS, rng=2020, keep_samples=True)


def _rms_se(x):
    """Monte Carlo standard error of sqrt(mean(x^2)) (delta method on the mean of x^2)."""
    m2 = np.mean(x * x)
    return np.std(x * x, ddof=1) / math.sqrt(x.size) / (2 * math.sqrt(m2))


def test_reproduces_paper_components(res):
    s = res.samples
    for j, g in enumerate(("telemetric", "head", "target")):
        u = res.components[g]
        assert u == pytest.approx(math.sqrt(np.mean(s[:, j] ** 2)), rel=1e-9)
        tol = ROUND_HALF_WIDTH + 3 * _rms_se(s[:, j])
        assert abs(u - PAPER_UM[g] * 1e-6) <= tol, (g, u, tol)


def test_reproduces_paper_combined(res):
    tot = res.samples[:, :3].sum(axis=1)
    assert res.error_rms_m == pytest.approx(math.sqrt(np.mean(tot ** 2)), rel=1e-9)
    tol = ROUND_HALF_WIDTH + 3 * _rms_se(tot)
    assert abs(res.error_rms_m - 4.7e-6) <= tol, (res.error_rms_m, tol)
    # additive groups: the combined mean square is the sum of the group mean squares plus the
    # cross terms of the means (groups independent); Monte Carlo covariance noise ~ 3/sqrt(N) relative
    ms = sum(res.components[g] ** 2 for g in PAPER_UM)
    means = [res.means[g] for g in PAPER_UM]
    cross = 2 * (means[0] * means[1] + means[0] * means[2] + means[1] * means[2])
    assert res.error_rms_m ** 2 == pytest.approx(ms + cross, rel=3 * 4 / math.sqrt(res.trials))
    lo, hi = res.coverage_95_m
    assert lo < 0 < hi and res.trials == 26 * TRIALS


def test_telemetric_against_closed_form(res, inst):
    n_g, _ = budget._air_cached(inst)
    t = adm.telemetric_terms(inst.adm, n_g)
    u2 = float(np.mean(t.std_m(res.distances_m) ** 2))  # pooled over the grid
    s = res.samples[:, 0]
    assert res.components["telemetric"] == pytest.approx(math.sqrt(u2), abs=3 * _rms_se(s))


def test_head_against_linearised_model(res, inst):
    # e_head ~ dToh cos(phi) - (a sin(alpha) + c sin(gamma)) + (a^2 + c^2)/(2R): independent terms, so
    # u^2 = sigma_Toh^2 E[cos^2 phi] + E[a^2] E[sin^2 alpha] + E[c^2] E[sin^2 gamma] + E[(a^2+c^2)^2]/(4R^2)
    h, w = inst.heads["A"], inst.head_common.beam_offset_m[1]

    def e_sin2(lo_deg, hi_deg):  # E[sin^2 x], x uniform, by quadrature
        x = np.radians(np.linspace(lo_deg, hi_deg, 100_001))
        return float(np.mean(np.sin(x) ** 2))

    u2 = (h.toh_std_m ** 2 * 0.5 + w ** 2 / 3 * e_sin2(*h.alpha_deg) + w ** 2 / 3 * e_sin2(*h.gamma_deg)
          + float(np.mean((2 * w ** 4 / 5 + 2 * w ** 4 / 9) / (4 * res.distances_m ** 2))))
    # neglected: third-order terms, < 1e-3 relative; MC: 3 standard errors
    tol = 3 * _rms_se(res.samples[:, 1]) + 1e-3 * math.sqrt(u2)
    assert res.components["head"] == pytest.approx(math.sqrt(u2), abs=tol)


def test_air_group_linear(res, inst):
    _, s = budget._air_cached(inst)
    e = inst.environment
    rel2 = ((s["temperature_c"] * e.u_temperature_c) ** 2 + (s["pressure_hpa"] * e.u_pressure_hpa) ** 2
            + (s["humidity_pct"] * e.u_humidity_pct) ** 2 + (s["co2_ppm"] * e.u_co2_ppm) ** 2)
    u = math.sqrt(rel2 * float(np.mean(res.distances_m ** 2)))
    assert res.components["air"] == pytest.approx(u, abs=3 * _rms_se(res.samples[:, 3]))
    assert not res.include_air  # the seed's 4.7 um excludes the air


def _excess_kurtosis(x):
    x = x - x.mean()
    return float(np.mean(x ** 4) / np.mean(x ** 2) ** 2 - 3)


def test_distribution_shapes(res):
    # standard error of the excess kurtosis of ~5e5 samples: sqrt(24/N) ~ 0.007 for a gaussian,
    # a few times more for heavy tails; the bounds below are 10+ standard errors from the values
    k_tel, k_head, k_tgt = (_excess_kurtosis(res.samples[:, j]) for j in range(3))
    # telemetric: arcsine-dominated (arcsine excess kurtosis -1.5), bimodal
    assert k_tel < -0.5
    # head "Lorentzian-like": dToh cos(phi) alone has excess kurtosis 3 E[cos^4]/E[cos^2]^2 - 3 = 1.5
    assert 1.0 < k_head < 1.7
    # target "near-gaussian"
    assert abs(k_tgt) < 0.5
    # combined close to a gaussian (Fig. 10)
    assert abs(_excess_kurtosis(res.samples[:, :3].sum(axis=1))) < 0.3


def test_other_readings_give_larger_target(inst):
    # the documented alternatives: correcting Tot with phi' only, or the brief's +-30 deg misalignment
    base = budget.distance_budget(inst, trials=5000, rng=3).components["target"]
    d = inst.model_dump()
    d["target"]["transit_correction"] = "target_axis"
    axis = budget.distance_budget(type(inst).model_validate(d), trials=5000, rng=3).components["target"]
    d["target"]["transit_correction"] = "model"
    d["target"]["misalignment_half_angle_deg"] = 30.0
    wide = budget.distance_budget(type(inst).model_validate(d), trials=5000, rng=3).components["target"]
    assert axis > base + 0.08e-6 and wide > 1.5 * base


def test_seeded_reproducible(inst):
    a = budget.distance_budget(inst, distance_m=[1.0, 5.0], trials=3000, rng=7)
    b = budget.distance_budget(inst, distance_m=[1.0, 5.0], trials=3000, rng=7)
    assert a.components == b.components and a.coverage_95_m == b.coverage_95_m


def test_sample_distance_errors_shapes_and_statistics(inst):
    d = np.array([0.5, 2.0, 10.0])
    e1 = budget.sample_distance_errors(inst, d, rng=1)
    assert e1.shape == (3,)
    many = budget.sample_distance_errors(inst, d, rng=1, trials=100_000)
    assert many.shape == (100_000, 3)
    # the RMS of the draws at each distance against distance_std_m (which uses its own cached MC,
    # relative precision ~0.3 %, and neglects the weak length dependence of the head's a^2/(2R) term)
    u = budget.distance_std_m(inst, d)
    for j in range(3):
        tol = 3 * _rms_se(many[:, j]) + 0.01 * u[j]
        assert math.sqrt(np.mean(many[:, j] ** 2)) == pytest.approx(u[j], abs=tol)
    mixed = budget.sample_distance_errors(inst, d, rng=1, head=None, trials=10)
    assert mixed.shape == (10, 3) and np.all(np.isfinite(mixed))
    # deterministic for a seed
    np.testing.assert_array_equal(budget.sample_distance_errors(inst, d, rng=9),
                                  budget.sample_distance_errors(inst, d, rng=9))


def test_distance_std_grows_with_length(inst):
    u = budget.distance_std_m(inst, np.array([1.0, 100.0, 1000.0]))
    assert u[0] < u[1] < u[2]
    # at 1000 m the clock term 1.5e-9 x 1000 = 1.5 um adds in quadrature
    assert u[2] ** 2 - u[0] ** 2 == pytest.approx((1.5e-9 * 1000) ** 2 - (1.5e-9) ** 2, rel=1e-9)


@pytest.mark.parametrize("call, word", [
    (lambda i: budget.distance_budget(i, head="Z", trials=10), "unknown head"),
    (lambda i: budget.distance_budget(i, distance_m=[-1.0], trials=10), "distance_m"),
    (lambda i: budget.distance_budget(i, distance_m=[1.0], trials=1), "trials"),
    (lambda i: budget.sample_distance_errors(i, [float("nan")], rng=1), "distance_m"),
    (lambda i: budget.distance_std_m(i, [1.0], head="Q"), "unknown head"),
])
def test_bad_input(inst, call, word):
    with pytest.raises(MultilatError, match=word):
        call(inst)


@pytest.mark.slow
def test_full_paper_run_rounds_to_paper():
    r = budget.distance_budget("seed2020", rng=1)  # 5.2 million trials as in the paper
    got = {g: round(r.components[g] * 1e6, 1) for g in PAPER_UM}
    assert got == PAPER_UM and round(r.error_rms_m * 1e6, 1) == 4.7


# ------------------------------------------------------------------ CLI
def test_cli_json(capsys):
    rc = main(["budget", "--trials", "4000", "--seed", "5", "--json"])
    out = capsys.readouterr().out
    assert rc == 0
    d = json.loads(out)
    assert set(d["components"]) >= {"telemetric", "head", "target"}
    assert d["trials"] == 26 * 4000
    assert len(d["coverage_95_m"]) == 2 and d["coverage_95_m"][0] < 0 < d["coverage_95_m"][1]
    # ~104 000 trials: well within 10 % of the paper
    assert d["error_rms_m"] == pytest.approx(4.7e-6, rel=0.1)
    assert d["components"]["target"] == pytest.approx(3.9e-6, rel=0.1)


def test_cli_table_and_plot(capsys, tmp_path):
    png = tmp_path / "fig.png"
    rc = main(["budget", "--trials", "2000", "--seed", "5", "--head", "B", "--plot", str(png)])
    out = capsys.readouterr().out
    assert rc == 0 and "paper" in out and "combined" in out and "head B" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _one_line_error(capsys, argv, word):
    rc = main(argv)
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert err.startswith("error:") and "\n" not in err and word in err, err


def test_cli_unknown_preset(capsys):
    _one_line_error(capsys, ["budget", "--instrument", "seed1999", "--trials", "10"], "seed2020")


def test_cli_bad_files(capsys, tmp_path):
    from importlib import resources

    text = resources.files("multilat").joinpath("presets", "seed2020.toml").read_text()
    cases = [
        ("[adm\nx = 1\n", "malformed TOML"),
        (text.replace("phase_noise_rad", "phase_noise_mrad"), "phase_noise_mrad"),
        (text.replace("toh_std_m = 2e-6", "toh_std_m = nan", 1), "toh_std_m"),
        (text.replace("tot_std_m = 2e-6", "tot_std_m = -2e-6"), "tot_std_m"),
    ]
    for i, (body, word) in enumerate(cases):
        p = tmp_path / f"bad{i}.toml"
        p.write_text(body)
        _one_line_error(capsys, ["budget", "--instrument", str(p), "--trials", "10"], word)


def test_cli_bad_head_trials_seed_plot(capsys):
    _one_line_error(capsys, ["budget", "--head", "Z", "--trials", "10"], "unknown head")
    _one_line_error(capsys, ["budget", "--trials", "1"], "trials")
    _one_line_error(capsys, ["budget", "--trials", "10", "--seed", "-3"], "seed")
    _one_line_error(capsys, ["budget", "--trials", "10", "--plot", "/proc/no/such/dir/x.png"], "--plot")


def test_cli_air_is_labelled(capsys):
    assert main(["budget", "--trials", "500", "--seed", "2", "--air", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["include_air"] is True and d["components"]["air"] > 0
    # air adds in quadrature (independent group): combined^2 ~ sum of squares + mean cross terms
    assert d["error_rms_m"] > 4.7e-6


def test_demo_section_quick():
    from multilat.report.distance_demo import section
    from multilat.report.html import render

    sec = section(seed=1, quick=True)
    html = render("t", [sec])
    assert "Table I" in html and "Table II" in html and "61.24 mm" in html and "<img" in html
    assert html.count("<table>") == 6           # Tables I-II, 2 group tables, the per-input budget and its sums


def test_streamed_mode_matches_stratified(inst, res, monkeypatch):
    # beyond STRATIFIED_LIMIT the engine streams (distance drawn from the grid, histogram quantiles):
    # same budget within Monte Carlo noise (two independent runs: sqrt(2) x 3 standard errors)
    monkeypatch.setattr(budget, "STRATIFIED_LIMIT", 1000)
    s = budget.distance_budget(inst, head="A", trials=TRIALS, rng=99)
    assert s.samples is None and s.trials == res.trials
    for j, g in enumerate(("telemetric", "head", "target")):
        tol = math.sqrt(2) * 3 * _rms_se(res.samples[:, j])
        assert s.components[g] == pytest.approx(res.components[g], abs=tol)
    assert s.error_rms_m == pytest.approx(res.error_rms_m, abs=math.sqrt(2) * 3 * _rms_se(
        res.samples[:, :3].sum(axis=1)))
    with pytest.raises(MultilatError, match="keep_samples"):
        budget.distance_budget(inst, trials=100, keep_samples=True)


def test_mechanical_sigma_disk_cache_is_bit_identical(tmp_path, monkeypatch):
    """The head's mechanical σ² read back from the on-disk cache is the very float computed; a corrupt
    entry is recomputed; ``MULTILAT_CACHE_DIR=off`` writes nothing; another head type is another key."""
    from multilat import budget
    from multilat import instrument as instr

    monkeypatch.setenv("MULTILAT_CACHE_DIR", str(tmp_path))
    inst = instr.load_instrument("seed2020")
    budget._MECH_CACHE.clear()
    first = budget._mechanical_u2(inst, "A")
    files = list((tmp_path / "budget").iterdir())
    assert len(files) == 1
    budget._MECH_CACHE.clear()

    def boom(*a, **k):
        raise AssertionError("recomputed although cached")

    monkeypatch.setattr(budget, "distance_budget", boom)
    assert budget._mechanical_u2(inst, "A") == first          # bit-identical, not recomputed
    monkeypatch.undo()
    monkeypatch.setenv("MULTILAT_CACHE_DIR", str(tmp_path))
    files[0].write_text("not a number")
    budget._MECH_CACHE.clear()
    assert budget._mechanical_u2(inst, "A") == first          # corrupt entry: recomputed, same value
    budget._MECH_CACHE.clear()
    budget._mechanical_u2(inst, "B")
    assert len(list((tmp_path / "budget").iterdir())) == 2    # heads B and A differ in the preset
    monkeypatch.setenv("MULTILAT_CACHE_DIR", "off")
    budget._MECH_CACHE.clear()
    assert budget._mechanical_u2(inst, "A") == first
    assert len(list((tmp_path / "budget").iterdir())) == 2
    budget._MECH_CACHE.clear()


def test_cli_without_seed_reports_one_that_reproduces_the_run(capsys):
    """Issue 25 item 9: a reported seed always reproduces the run it reports. Without --seed the
    JSON said "seed": null (the run could not be repeated); now the fresh entropy drawn is reported
    and re-running with it gives the same numbers, bit for bit."""
    assert main(["budget", "--trials", "500", "--json"]) == 0
    first = json.loads(capsys.readouterr().out)
    assert isinstance(first["seed"], int) and first["seed"] >= 0
    assert main(["budget", "--trials", "500", "--seed", str(first["seed"]), "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again == first
