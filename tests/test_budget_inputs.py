"""Per-input budget of one distance (issue 28): every input quantity of the distance model with its
distribution, sensitivity, first-order and one-at-a-time Monte Carlo contributions and its share of
the group; the rows of a group add up to the group (and to the seed's 2.1 / 1.4 / 3.9 / 4.7 um)."""

import json
import math

import numpy as np
import pytest

from multilat import adm, budget
from multilat.budget_inputs import QUANTITIES, input_budget
from multilat.cli import main
from multilat.errors import MultilatError
from multilat.instrument import load_instrument

PAPER_UM = {"telemetric": 2.1, "head": 1.4, "target": 3.9}
ROUND_HALF_WIDTH = 0.05e-6      # the paper's values are rounded to 0.1 um
N_IN = 2000                     # per distance, 26 distances: 52 000 trials per run (~10 s)


@pytest.fixture(scope="module")
def inst():
    return load_instrument("seed2020")


@pytest.fixture(scope="module")
def ib(inst):
    return input_budget(inst, head="A", trials=N_IN, rng=28, include_air=False)


@pytest.fixture(scope="module")
def main_run(inst):
    return budget.distance_budget(inst, head="A", trials=20_000, rng=2020, keep_samples=True)


def _rows(ib, group=None):
    return {r["quantity"]: r for r in ib.rows if group is None or r["group"] == group}


def _rms_se(x):
    m2 = np.mean(x * x)
    return np.std(x * x, ddof=1) / math.sqrt(x.size) / (2 * math.sqrt(m2))


def test_every_random_input_of_the_model_has_a_row(inst, ib):
    raw = set(budget.group_inputs(inst, "A"))
    assert {nm for q in QUANTITIES for nm in q[4]} == raw            # nothing left out, nothing invented
    for g in budget.GROUPS:
        rows = _rows(ib, g)
        assert "bias" in rows and len(rows) == 1 + sum(q[1] == g for q in QUANTITIES)
    r = _rows(ib)["toh"]
    assert r["distribution"] == {"type": "normal", "mean": -1e-6, "std": 2e-6}
    assert r["source"] == "heads.A.toh_m, heads.A.toh_std_m" and r["unit"] == "m"
    a = _rows(ib)["a"]
    assert a["distribution"] == {"type": "uniform", "low": -320e-6, "high": 320e-6}
    assert a["estimate_std"] == pytest.approx(320e-6 / math.sqrt(3))


def test_rows_add_up_to_their_group_and_to_the_main_run(ib, main_run):
    """The shares of a group's rows add up to its u^2 (by construction of Shapley values plus the
    bias row: checked to rounding), and that u equals the group of the independent main Monte Carlo
    within 4 combined standard errors."""
    s = main_run.samples
    for j, g in enumerate(budget.GROUPS):
        tot = sum(r["share_var_m2"] for r in _rows(ib, g).values())
        u = ib.groups[g]["error_rms_m"]
        assert tot == pytest.approx(u * u, rel=1e-9)
        se = math.hypot(ib.groups[g]["error_rms_se_m"], _rms_se(s[:, j]))
        assert abs(u - main_run.components[g]) <= 4 * se, (g, u, main_run.components[g], se)


def test_rows_reproduce_the_seed(ib):
    """2.1 / 1.4 / 3.9 / 4.7 um (rounded to 0.1 um) from the sums of the rows, within the rounding
    half-width plus 3 Monte Carlo standard errors (batch means)."""
    for g, paper in PAPER_UM.items():
        u, se = ib.groups[g]["error_rms_m"], ib.groups[g]["error_rms_se_m"]
        assert abs(u - paper * 1e-6) <= ROUND_HALF_WIDTH + 3 * se, (g, u, se)
    assert abs(ib.error_rms_m - 4.7e-6) <= ROUND_HALF_WIDTH + 3 * ib.error_rms_se_m
    # the combined is the union of the groups' rows (disjoint inputs) and the square of the summed means
    shares = sum(r["share_var_m2"] for r in ib.rows if r["group"] != "air" and r["quantity"] != "bias")
    means = sum(ib.groups[g]["error_mean_m"] for g in PAPER_UM)
    assert ib.error_rms_m ** 2 == pytest.approx(shares + means ** 2, abs=0.02e-12)


def _five_point(f, x0, h):
    return (-f(x0 + 2 * h) + 8 * f(x0 + h) - 8 * f(x0 - h) + f(x0 - 2 * h)) / (12 * h)


def test_sensitivities_against_finite_differences(inst, ib):
    """Each sensitivity against a five-point difference of group_errors at the nominal point (step
    0.05 u, not gum_linear's two-point 1e-3 u), distance by distance, pooled as the signed RMS.
    The misalignment (joint) is checked against its closed form below."""
    from multilat.budget_inputs import _nominal

    p = budget._params(inst, "A")
    dists = budget.group_inputs(inst, "A")
    nom = _nominal(dists, p)
    L = inst.budget.distances_m
    for key, g, _, _, raw, _ in QUANTITIES:
        if key == "misalignment":
            continue
        col = budget.GROUPS.index(g)
        h = 0.05 * dists[raw[0]].std

        def f(x, L1):
            return budget.group_errors(p, L1, **dict(nom, **{raw[0]: x}))[..., col]

        c = np.array([_five_point(lambda x: f(x, L1), nom[raw[0]], h) for L1 in L])
        want = math.copysign(math.sqrt(np.mean(c * c)), np.mean(c))
        got = _rows(ib)[key]["sensitivity"]
        # relative 1e-5, or a contribution |dc| u(x) below 1e-11 m (rounding of L - L at 20 m over the step)
        assert abs(got - want) <= 1e-5 * abs(want) + 1e-11 / dists[raw[0]].std, (key, got, want)


def test_sensitivities_against_closed_forms(inst, ib):
    rows = _rows(ib)
    L = inst.budget.distances_m
    n_g, s = budget._air_cached(inst)
    amb = adm.ambiguity_m(inst.adm.modulation_frequency_hz, n_g)
    r = 10 ** (-inst.adm.signal_to_crosstalk_db / 20)
    assert rows["clock"]["sensitivity"] == pytest.approx(-math.sqrt(np.mean(L * L)), rel=1e-9)   # -L
    assert rows["phase_noise"]["sensitivity"] == pytest.approx(amb / (2 * math.pi), rel=1e-9)
    assert rows["power_db"]["sensitivity"] == pytest.approx(inst.adm.am_pm_m_per_db, rel=1e-9)
    # d/dpsi atan2(r sin psi, 1 + r cos psi) at psi = 0 is r / (1 + r)
    assert rows["xt_phase"]["sensitivity"] == pytest.approx(amb / (2 * math.pi) * r / (1 + r), rel=1e-6)
    al, ga = (sum(inst.head("A").alpha_deg) / 2, sum(inst.head("A").gamma_deg) / 2)
    assert rows["toh"]["sensitivity"] == pytest.approx(math.cos(math.radians(al)) * math.cos(math.radians(ga)),
                                                       abs=1e-5)
    assert rows["tb"]["sensitivity"] == pytest.approx(-1.0, abs=1e-5)      # the apex comes closer
    assert rows["tot"]["sensitivity"] == pytest.approx(-1.0, abs=1e-5)
    # the misalignment: 2 a' L sin(theta'') and 2 c' L sin(phi'') in eq. (5): (a', c') m/rad
    c_th, c_ph = rows["misalignment"]["sensitivity"]
    assert c_th == pytest.approx(inst.target.a_m, rel=1e-3) and c_ph == pytest.approx(inst.target.c_m, rel=1e-3)
    rms_L = math.sqrt(np.mean(L * L))
    for k, key in (("d_t", "temperature_c"), ("d_p", "pressure_hpa"), ("d_rh", "humidity_pct"),
                   ("d_co2", "co2_ppm")):
        assert rows[k]["sensitivity"] == pytest.approx(-math.copysign(rms_L, s[key]) * abs(s[key]), rel=1e-6)


@pytest.mark.parametrize("key,kurtosis", [("clock", 3.0), ("phase_noise", 3.0), ("power_db", 1.8), ("toh", 3.0),
                                          ("tb", 3.0), ("tot", 3.0), ("d_t", 3.0), ("d_p", 3.0)])
def test_one_at_a_time_equals_first_order_where_linear(ib, key, kurtosis):
    """Inputs that enter (nearly) linearly: the Monte Carlo std with the input alone equals |c| u(x)
    within 4 standard errors of a std, u sqrt((kurtosis - 1) / (4 N)), N the pooled trials."""
    r = _rows(ib)[key]
    n = 26 * ib.trials_per_distance
    se = r["contribution_std_lin_m"] * math.sqrt((kurtosis - 1) / (4 * n))
    assert abs(r["contribution_std_mc_m"] - r["contribution_std_lin_m"]) <= 4 * se + 1e-15, key


def test_where_the_first_order_fails_the_monte_carlo_says_so(inst, ib):
    """The crosstalk is cyclic over the whole phase circle: first order at psi = 0 gives amb/(2 pi)
    r/(1+r) x pi/sqrt(3) = 4.97 um; the Monte Carlo alone gives the arcsine's amb/(2 pi) r/sqrt(2)
    (closed form, to O(r^2)). The elevations have no first-order effect (derivative 0 at the
    expectation) but a share through dToh cos(phi): Shapley with v(Toh) = s^2 (2/pi)^2,
    v(Toh, phi) = s^2 / 2 gives Toh s^2 (1/4 + 2/pi^2) and phi s^2 (1/4 - 2/pi^2)."""
    rows = _rows(ib)
    n_g, _ = budget._air_cached(inst)
    amb = adm.ambiguity_m(inst.adm.modulation_frequency_hz, n_g)
    r = 10 ** (-inst.adm.signal_to_crosstalk_db / 20)
    xt = rows["xt_phase"]
    assert xt["contribution_std_lin_m"] == pytest.approx(amb / (2 * math.pi) * r / (1 + r) * math.pi / math.sqrt(3),
                                                         rel=1e-6)
    n = 26 * ib.trials_per_distance
    assert xt["contribution_std_mc_m"] == pytest.approx(amb / (2 * math.pi) * r / math.sqrt(2),
                                                        rel=4 * math.sqrt(0.5 / (4 * n)) + 1e-3)
    s2 = 2e-6 ** 2
    for key, want in (("toh", s2 * (0.25 + 2 / math.pi ** 2)), ("head_el", s2 * (0.25 - 2 / math.pi ** 2))):
        got, se = rows[key]["share_var_m2"], rows[key]["share_var_se_m2"]
        assert abs(got - want) <= 4 * se + 0.01 * s2, (key, got, want, se)
    assert rows["head_el"]["contribution_std_lin_m"] < 1e-9 and rows["head_el"]["share_std_m"] > 0.3e-6


def test_seeded_and_reproducible(inst):
    a = input_budget(inst, trials=32, rng=7, distance_m=[1.0, 5.0])
    b = input_budget(inst, trials=32, rng=7, distance_m=[1.0, 5.0])
    assert a.to_dict() == b.to_dict()
    c = input_budget(inst, trials=32, rng=8, distance_m=[1.0, 5.0])
    assert c.to_dict() != a.to_dict()


def test_bad_input(inst):
    with pytest.raises(MultilatError, match="trials"):
        input_budget(inst, trials=3)
    with pytest.raises(MultilatError, match="distance_m"):
        input_budget(inst, trials=32, distance_m=[-1.0])
    with pytest.raises(MultilatError, match="head"):
        input_budget(inst, head="Z", trials=32)


def test_cli_json_table_and_report(capsys, tmp_path):
    rep = tmp_path / "b.html"
    assert main(["budget", "--trials", "200", "--seed", "3", "--json", "--report", str(rep)]) == 0
    d = json.loads(capsys.readouterr().out)
    ibd = d["input_budget"]
    assert ibd["trials_per_distance"] == 200 and len(ibd["rows"]) == len(QUANTITIES) + 4
    for g, v in ibd["groups"].items():
        tot = sum(r["share_var_m2"] for r in ibd["rows"] if r["group"] == g)
        assert tot == pytest.approx(v["error_rms_m"] ** 2, rel=1e-9)
    html = rep.read_text()
    assert "Per input quantity" in html and "heads.A.toh_m" in html
    assert f"{ibd['groups']['target']['error_rms_m'] * 1e6:.2f}" in html
    assert main(["budget", "--trials", "200", "--seed", "3"]) == 0
    out = capsys.readouterr().out
    assert "per input" in out and "head transit Toh" in out and "rows summed" in out
    first = next(line for line in out.splitlines() if line.startswith("target misalign"))
    assert first                                        # the largest share leads the table


def test_cli_bad_input_trials(capsys):
    assert main(["budget", "--trials", "100", "--input-trials", "5"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and "--input-trials" in err and "\n" not in err


def test_other_readings_of_the_instrument(inst):
    """Per-head beam offsets, a square misalignment and an exact received power: the rows follow the
    file (sources, laws, u(theta'') = h / sqrt(3) for the square) and still add up to their groups."""
    d = inst.model_dump()
    d["budget"]["beam_offset_model"] = "per_head"
    d["target"]["misalignment_shape"] = "square"
    d["adm"]["power_variation_db"] = 0.0
    other = type(inst).model_validate(d)
    ib2 = input_budget(other, head="B", trials=64, rng=3, distance_m=[1.0, 10.0])
    rows = _rows(ib2)
    assert rows["a"]["source"] == "heads.B.a_limit_m"
    assert rows["a"]["distribution"] == {"type": "uniform", "low": -310e-6, "high": 310e-6}
    h = math.radians(inst.target.misalignment_half_angle_deg)
    assert rows["misalignment"]["estimate_std"] == pytest.approx([h / math.sqrt(3)] * 2, rel=1e-12)
    assert rows["misalignment"]["distribution"]["type"] == "independent uniforms"
    p = rows["power_db"]
    assert p["distribution"]["type"] == "constant" and p["sensitivity"] is None
    assert p["contribution_std_lin_m"] == 0.0 and p["contribution_std_mc_m"] == 0.0
    assert abs(p["share_var_m2"]) < 1e-20
    for g, v in ib2.groups.items():
        tot = sum(r["share_var_m2"] for r in _rows(ib2, g).values())
        assert tot == pytest.approx(v["error_rms_m"] ** 2, rel=1e-9)


def test_cone_misalignment_std_against_sampling(inst):
    """u(theta''), u(phi'') of the cone by quadrature against 10^6 draws (SE ~0.07 %)."""
    from multilat.budget_inputs import _Misalignment

    m = _Misalignment(True, math.radians(15.0))
    x = m.sample(np.random.default_rng(5), 1_000_000)
    assert np.allclose(m.stds(), x.std(axis=0), rtol=3e-3)
    assert abs(np.corrcoef(x.T)[0, 1]) < 3e-3                     # uncorrelated


@pytest.mark.parametrize("key,kurtosis", [("xt_phase", 1.5), ("phase_noise", 3.0), ("power_db", 1.8),
                                          ("d_t", 3.0), ("d_p", 3.0)])
def test_shares_of_an_additive_group_are_the_one_at_a_time_variances(ib, key, kurtosis):
    """Telemetric and air errors are sums of one term per input: the Shapley share of each input is then
    its own variance, the one-at-a-time Monte Carlo's (two estimators on independent draws: within 4
    combined standard errors; the std's variance has SE var sqrt((kurtosis - 1) / N))."""
    r = _rows(ib)[key]
    var = r["contribution_std_mc_m"] ** 2
    se = math.hypot(r["share_var_se_m2"], var * math.sqrt((kurtosis - 1) / (26 * ib.trials_per_distance)))
    assert abs(r["share_var_m2"] - var) <= 4 * se, (key, r["share_var_m2"], var, se)
