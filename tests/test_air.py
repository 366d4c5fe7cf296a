"""Refractive index of air: NIST check values, IAPWS check values, seed 000 Table II, group index
against a finite-difference derivative, humidity inputs, validation, and the ``multilat air`` CLI."""

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

from multilat import air
from multilat.cli import main
from multilat.errors import MultilatError
from multilat.io import read_csv_table

DATA = Path(__file__).parent / "data" / "nist_air_check_values.csv"


def _nist_rows():
    t = read_csv_table(DATA, required=["temperature_c", "humidity_pct", "pressure_kpa", "wavelength_nm",
                                       "co2_ppm", "n_ciddor", "n_edlen_nist"])
    return {c: t.floats(c) for c in t.columns}


# ---------------------------------------------------------------------------------------------
# Published reference values
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("formula, column", [("ciddor", "n_ciddor"), ("edlen-nist", "n_edlen_nist")])
def test_phase_index_matches_nist_check_values(formula, column):
    # NIST prints n to 9 decimals (rounding error <= 5e-10); the brief asks for 1e-9.
    r = _nist_rows()
    assert len(r[column]) == 14
    n = air.phase_index(r["temperature_c"], r["pressure_kpa"] * 1e3, humidity_pct=r["humidity_pct"],
                        co2_ppm=r["co2_ppm"], wavelength_m=r["wavelength_nm"] * 1e-9, formula=formula)
    assert n.shape == (14,)
    np.testing.assert_allclose(n, r[column], rtol=0, atol=1e-9)


def test_saturation_vapour_pressure_matches_iapws_if97_check_values():
    # IAPWS-IF97 (the NIST notes' saturation equation), Table 35 verification values:
    # p_s(300 K) = 3.53658941e-3 MPa, p_s(500 K) = 2.63889776 MPa, p_s(600 K) = 12.3443146 MPa.
    t_c = np.array([300.0, 500.0, 600.0]) - 273.15
    np.testing.assert_allclose(air.saturation_vapour_pressure_pa(t_c),
                               [3.53658941e3, 2.63889776e6, 1.23443146e7], rtol=1e-8)


def test_saturation_vapour_pressure_over_ice_is_continuous_at_zero():
    # water and ice curves meet at the triple point (611.657 Pa at 0.01 °C); at 0 °C they differ by
    # ~0.01 % — a wrong branch (or a sign slip in theta^-1.5) would be off by orders of magnitude.
    below = air.saturation_vapour_pressure_pa(-1e-9)
    above = air.saturation_vapour_pressure_pa(0.0)
    assert abs(below / above - 1) < 2e-4
    assert 259.0 < air.saturation_vapour_pressure_pa(-10.0) < 261.0  # 259.9 Pa over ice (IAPWS 1993)


def test_edlen_bonsch_potulski_reduces_to_its_standard_air_dispersion():
    # Bönsch & Potulski eq. (6) is the refractivity of standard air (20 °C, 100 kPa, 400 ppm, dry);
    # their eqs. (7)-(8) must give a factor of 1 there, up to the rounding of their constants
    # (93214.60 has 7 significant digits: 1e-7 relative, 3e-11 in n).
    lam_um = np.array([0.4, 0.633, 1.0, 1.55])
    s2 = lam_um**-2
    ref = 1e-8 * (8091.37 + 2333983 / (130 - s2) + 15518 / (38.9 - s2))
    n = air.phase_index(20.0, 100000.0, humidity_pct=0.0, co2_ppm=400.0, wavelength_m=lam_um * 1e-6,
                        formula="edlen")
    np.testing.assert_allclose(n - 1.0, ref, rtol=1e-7, atol=0)


def test_edlen_bonsch_potulski_agrees_with_nist_edlen_in_dry_air():
    # Two updates of Edlén's formula fitted to different data sets; the NIST notes give the Edlén
    # equation an intrinsic expanded uncertainty of ~2e-8 near room conditions. Dry-air rows between
    # 0 and 50 °C at 633 nm must agree within that (humid rows differ by design: NIST's 292.75/T term).
    r = _nist_rows()
    dry = (r["humidity_pct"] == 0) & (r["temperature_c"] >= 0) & (r["wavelength_nm"] == 633)
    assert dry.sum() == 5
    n = air.phase_index(r["temperature_c"][dry], r["pressure_kpa"][dry] * 1e3, humidity_pct=0.0,
                        co2_ppm=450.0, wavelength_m=633e-9, formula="edlen")
    np.testing.assert_allclose(n, r["n_edlen_nist"][dry], rtol=0, atol=2e-8)


# ---------------------------------------------------------------------------------------------
# Seed 000, Table II
# ---------------------------------------------------------------------------------------------

TABLE_II = dict(temperature_c=20.0, pressure_pa=101325.0, humidity_pct=50.0, co2_ppm=450.0,
                wavelength_m=1550e-9)


@pytest.mark.parametrize("formula", ["edlen", "ciddor"])
def test_table_ii_group_index_sensitivities(formula):
    # Paper (Bönsch-Potulski Edlén, group index): -0.95 µm/m/°C, 0.27 µm/m/hPa, -0.09 µm/m for
    # +10 %RH, 0.03 µm/m for +200 ppm. Reproduced to the paper's rounding (2 decimals).
    s = air.sensitivities(**TABLE_II, formula=formula)
    assert round(float(s["temperature_c"]) * 1e6, 2) == -0.95
    assert round(float(s["pressure_hpa"]) * 1e6, 2) == 0.27
    assert round(float(s["humidity_pct"]) * 10e6, 2) == -0.09
    assert round(float(s["co2_ppm"]) * 200e6, 2) == 0.03


def test_table_ii_temperature_value_needs_relative_humidity_held_fixed():
    # Interpretation check (docs/air.md): holding the water-vapour *pressure* fixed gives -0.92,
    # not the paper's -0.95; holding RH fixed (what an RH sensor reports) gives -0.95.
    pv = float(air.water_vapour_pressure_pa(20.0, humidity_pct=50.0))
    kw = {k: v for k, v in TABLE_II.items() if k != "humidity_pct"}
    s_pv = air.sensitivities(**kw, water_vapour_pa=pv, formula="edlen")
    assert round(float(s_pv["temperature_c"]) * 1e6, 2) == -0.92
    s_rh = air.sensitivities(**TABLE_II, formula="edlen")
    np.testing.assert_allclose(s_pv["pressure_hpa"], s_rh["pressure_hpa"], rtol=1e-6)


def test_sensitivity_sign_is_the_distance_change_when_the_air_changes():
    # D_reported = L / n_assumed with L = n_true D: warm the air by dT with the index not updated.
    ng0 = float(air.group_index(**TABLE_II, formula="edlen"))
    kw = dict(TABLE_II, temperature_c=TABLE_II["temperature_c"] + 0.1)
    ng1 = float(air.group_index(**kw, formula="edlen"))
    reported_rel_change = ng1 / ng0 - 1.0  # (L_new / ng0) / D - 1
    s = air.sensitivities(**TABLE_II, formula="edlen")
    np.testing.assert_allclose(reported_rel_change, 0.1 * float(s["temperature_c"]), rtol=1e-3)
    assert reported_rel_change < 0


def test_pressure_sensitivity_matches_closed_form():
    # Bönsch-Potulski, dry air: n-1 = K p (1 + 1e-8 (0.5953 - 0.009876 t) p) with K independent of p,
    # so d(n-1)/dp = (n-1)/p * (1 + 1e-8 a p) / (1 + 1e-8 a p) ... exactly:
    t, p = 20.0, 101325.0
    a = 1e-8 * (0.5953 - 0.009876 * t)
    ng = float(air.group_index(t, p, humidity_pct=0.0, formula="edlen"))
    d_dp = (ng - 1.0) / p * (1 + 2 * a * p) / (1 + a * p)
    s = air.sensitivities(t, p, humidity_pct=0.0, formula="edlen")
    np.testing.assert_allclose(float(s["pressure_hpa"]), 100.0 * d_dp / ng, rtol=1e-8)


# ---------------------------------------------------------------------------------------------
# Group index, humidity inputs, broadcasting
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("formula", ["ciddor", "edlen", "edlen-nist"])
def test_group_index_equals_finite_difference_of_phase_index(formula):
    # n_g = n - λ dn/dλ with dn/dλ from a Richardson-extrapolated central difference (h = 0.5 nm
    # and 0.25 nm): truncation O(h^4) ~ 1e-15 (a plain central difference is off by 8e-11 at 400 nm),
    # round-off ~ 1e-16 λ / h ~ 2e-13; tolerance 1e-12.
    lam = np.array([400e-9, 633e-9, 1064e-9, 1550e-9])
    kw = dict(temperature_c=22.0, pressure_pa=99000.0, humidity_pct=40.0, co2_ppm=450.0, formula=formula)
    n = air.phase_index(**kw, wavelength_m=lam)

    def central(h):
        return (air.phase_index(**kw, wavelength_m=lam + h) - air.phase_index(**kw, wavelength_m=lam - h)) / (2 * h)

    dn = (4.0 * central(0.25e-9) - central(0.5e-9)) / 3.0
    ng = air.group_index(**kw, wavelength_m=lam)
    np.testing.assert_allclose(ng, n - lam * dn, rtol=0, atol=1e-12)
    assert np.all(ng > n)  # normal dispersion


@pytest.mark.parametrize("formula", ["ciddor", "edlen", "edlen-nist"])
def test_relative_humidity_partial_pressure_and_dew_point_agree(formula):
    t, p = 20.0, 101325.0
    pv = float(air.water_vapour_pressure_pa(t, humidity_pct=50.0))
    td = brentq(lambda x: float(air.saturation_vapour_pressure_pa(x)) - pv, -20.0, 20.0, xtol=1e-12)
    a = air.phase_index(t, p, humidity_pct=50.0, formula=formula)
    b = air.phase_index(t, p, water_vapour_pa=pv, formula=formula)
    c = air.phase_index(t, p, dew_point_c=td, formula=formula)
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-14)
    # Ciddor evaluates the enhancement factor at the dew point (NIST A-II): f(t)/f(t_d) - 1 =
    # 5.6e-7 (t^2 - t_d^2) = 1.8e-4 of the water term (~ -4e-7): 8e-11; the Edlén forms use p_v only.
    np.testing.assert_allclose(c, a, rtol=0, atol=1e-10 if formula == "ciddor" else 1e-14)


def test_broadcasting_matches_scalar_calls():
    t = np.array([[10.0], [20.0], [30.0]])
    lam = np.array([500e-9, 633e-9, 1000e-9, 1550e-9])
    ng = air.group_index(t, 100000.0, humidity_pct=30.0, wavelength_m=lam)
    assert ng.shape == (3, 4)
    for i in range(3):
        for j in range(4):
            assert ng[i, j] == float(air.group_index(float(t[i, 0]), 100000.0, humidity_pct=30.0,
                                                     wavelength_m=float(lam[j])))
    s = air.sensitivities(t, 100000.0, humidity_pct=30.0, wavelength_m=lam)
    assert set(s) == {"temperature_c", "pressure_hpa", "humidity_pct", "co2_ppm"}
    assert all(v.shape == (3, 4) for v in s.values())


def test_defaults_are_table_ii_conditions():
    a = air.group_index(humidity_pct=50.0)
    b = air.group_index(**TABLE_II)
    assert float(a) == float(b)


# ---------------------------------------------------------------------------------------------
# Validation at the boundary
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, name", [
    (dict(temperature_c=np.nan, humidity_pct=50.0), "temperature_c"),
    (dict(temperature_c=150.0, humidity_pct=50.0), "temperature_c"),
    (dict(humidity_pct=120.0), "humidity_pct"),
    (dict(humidity_pct=-1.0), "humidity_pct"),
    (dict(humidity_pct=[20.0, np.nan]), "humidity_pct"),
    (dict(pressure_pa=-5.0, humidity_pct=50.0), "pressure_pa"),
    (dict(pressure_pa=500e3, humidity_pct=50.0), "pressure_pa"),
    (dict(co2_ppm=-1.0, humidity_pct=50.0), "co2_ppm"),
    (dict(wavelength_m=-1550e-9, humidity_pct=50.0), "wavelength_m"),
    (dict(wavelength_m=2000e-9, humidity_pct=50.0), "wavelength_m"),
    (dict(wavelength_m=200e-9, humidity_pct=50.0), "wavelength_m"),
    (dict(dew_point_c=25.0), "dew_point_c"),
    (dict(water_vapour_pa=5000.0), "water_vapour_pa"),
    (dict(water_vapour_pa=-1.0), "water_vapour_pa"),
    (dict(humidity_pct=50.0, dew_point_c=5.0), "humidity_pct, dew_point_c"),
    (dict(), "exactly one of"),
    (dict(humidity_pct=50.0, formula="edlen1966"), "formula"),
    (dict(humidity_pct=50.0, co2_ppm=400.0, formula="edlen-nist"), "co2_ppm"),
])
@pytest.mark.parametrize("fn", [air.phase_index, air.group_index, air.sensitivities])
def test_bad_input_raises_naming_the_parameter(fn, kwargs, name):
    with pytest.raises(MultilatError, match=name) as exc:
        fn(**kwargs)
    assert "\n" not in str(exc.value)


# ---------------------------------------------------------------------------------------------
# CLI
# ---------------------------------------------------------------------------------------------

def test_cli_json_reproduces_table_ii(capsys):
    rc = main(["air", "--temperature-c", "20", "--pressure-hpa", "1013.25", "--humidity-pct", "50",
               "--co2-ppm", "450", "--wavelength-nm", "1550", "--formula", "edlen", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["phase_index"] == pytest.approx(float(air.phase_index(**TABLE_II, formula="edlen")), abs=1e-15)
    assert out["group_index"] == pytest.approx(float(air.group_index(**TABLE_II, formula="edlen")), abs=1e-15)
    s = out["sensitivity_um_per_m"]
    assert set(s) == {"temperature_c", "pressure_hpa", "humidity_pct", "co2_ppm"}
    assert round(s["temperature_c"], 2) == -0.95
    assert round(s["pressure_hpa"], 2) == 0.27
    assert round(10 * s["humidity_pct"], 2) == -0.09
    assert round(200 * s["co2_ppm"], 2) == 0.03


def test_cli_defaults_and_human_table(capsys):
    assert main(["air"]) == 0
    out = capsys.readouterr().out
    assert "group index" in out and "-0.95" in out and "+0.27" in out
    assert main(["air", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["inputs"]["humidity_pct"] == 50.0 and out["inputs"]["co2_ppm"] == 450.0
    assert out["formula"] == "ciddor"


def test_cli_dew_point_alternative(capsys):
    assert main(["air", "--dew-point-c", "9.27", "--json"]) == 0
    a = json.loads(capsys.readouterr().out)
    assert main(["air", "--json"]) == 0
    b = json.loads(capsys.readouterr().out)
    assert a["inputs"]["humidity_pct"] is None
    assert a["group_index"] == pytest.approx(b["group_index"], abs=1e-9)  # 9.27 °C ≈ 50 %RH at 20 °C


@pytest.mark.parametrize("argv, name", [
    (["air", "--humidity-pct", "120"], "humidity"),
    (["air", "--humidity-pct", "50", "--dew-point-c", "5"], "only one"),
    (["air", "--pressure-hpa", "nan"], "pressure"),
    (["air", "--wavelength-nm", "3000"], "wavelength"),
    (["air", "--formula", "foo"], "formula"),
    (["air", "--temperature-c", "abc"], "temperature"),
    (["air", "--water-vapour-pa", "5000"], "water_vapour_pa"),  # a message longer than 80 columns
])
def test_cli_bad_input_is_one_line_exit_2(capsys, argv, name):
    assert main(argv) == 2
    cap = capsys.readouterr()
    err = cap.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and name in err[0]
    assert cap.out == ""


def test_cli_help(capsys):
    assert main(["air", "--help"]) == 0
    assert "--dew-point-c" in capsys.readouterr().out
