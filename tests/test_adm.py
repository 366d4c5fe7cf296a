"""ADM (seed eq. 1, Table I): published values, closed forms, round trips, bad input."""

import math

import numpy as np
import pytest

from multilat import adm
from multilat.errors import MultilatError
from multilat.instrument import load_instrument

F = 4895e6
NG = 1.00027  # a typical group index at 1550 nm; only the ~3e-4 relative size matters here


def test_synthetic_wavelength_paper_61_2_mm():
    # seed section 2: "c/f = 61.2 mm" at 4895 MHz (vacuum, exact c)
    lam = adm.synthetic_wavelength_m(F)
    assert round(lam * 1e3, 1) == 61.2
    assert lam == pytest.approx(299_792_458.0 / 4895e6, rel=1e-15)
    # the distance per cycle in air is half of it divided by n
    assert adm.ambiguity_m(F, NG) == pytest.approx(lam / (2 * NG), rel=1e-15)


def test_table_I_terms_from_physics():
    inst = load_instrument("seed2020")
    t = adm.telemetric_terms(inst.adm, NG)
    # 65 dB -> cyclic error amplitude 2.7 um (paper), arcsine std 1.9 um
    assert round(t.crosstalk_amplitude_m * 1e6, 1) == 2.7
    assert round(t.crosstalk_std_m * 1e6, 1) == 1.9
    # 0.17 mrad -> 0.8 um
    assert round(t.noise_std_m * 1e6, 1) == 0.8
    # -0.15 um/dB x 5 dB p-p uniform -> 0.2 um
    assert round(t.am_pm_std_m * 1e6, 1) == 0.2
    # 1.5e-9 per year, annual calibration -> 30 nm at 20 m (paper's example)
    assert t.clock_relative_std * 20.0 == pytest.approx(30e-9, rel=1e-12)
    # the combined std at 20 m rounds to the paper's telemetric 2.1 um (closed form, no MC)
    assert round(float(t.std_m(20.0)) * 1e6, 1) == 2.1


def test_crosstalk_phase_error_maximum_is_asin_r():
    # one spurious phasor of relative amplitude r: max phase error asin(r) at cos(psi) = -r
    for scr in (20.0, 40.0, 65.0):
        r = 10 ** (-scr / 20)
        psi = np.linspace(-math.pi, math.pi, 200_001)
        err = adm.crosstalk_phase_error_rad(scr, psi)
        assert err.max() == pytest.approx(math.asin(r), rel=1e-8)
        assert err.min() == pytest.approx(-math.asin(r), rel=1e-8)
    # amplitude in distance: asin(r)/(2 pi) * c/(2 n f)
    amp = adm.crosstalk_amplitude_m(65.0, F, NG)
    assert amp == pytest.approx(math.asin(10 ** (-65 / 20)) / (2 * math.pi) * adm.ambiguity_m(F, NG), rel=1e-14)


def test_crosstalk_std_is_amplitude_over_sqrt2_small_r():
    # the law of atan2(r sin psi, 1 + r cos psi) is arcsine to first order in r: std = asin(r)/sqrt(2)
    # (relative deviation O(r^2) ~ 3e-7 at 65 dB). Quadrature over a fine uniform psi grid.
    psi = np.linspace(-math.pi, math.pi, 400_000, endpoint=False)
    e = adm.crosstalk_phase_error_rad(65.0, psi)
    assert e.std() == pytest.approx(math.asin(10 ** (-65 / 20)) / math.sqrt(2), rel=1e-5)


def test_phase_distance_round_trip():
    d = np.array([0.0, 1e-6, 0.015, 0.2, 1.2345678, 20.2, 138.0])
    phase, k = adm.phase_from_distance(d, F, NG)
    assert np.all((phase >= 0) & (phase < 2 * math.pi))
    back = adm.distance_from_phase(phase, k, F, NG)
    np.testing.assert_allclose(back, d, rtol=0, atol=1e-13)
    # eq. (1) literally: L = 1/2 (Phi/2pi + k) c/(n f)
    assert adm.distance_from_phase(math.pi, 3, F, NG) == pytest.approx(
        0.5 * (0.5 + 3) * 299_792_458.0 / (NG * F), rel=1e-15)


def test_resolve_integer_from_coarse_distance():
    rng = np.random.default_rng(4)
    d = rng.uniform(0.2, 140.0, 1000)
    phase, k = adm.phase_from_distance(d, F, NG)
    amb = adm.ambiguity_m(F, NG)
    coarse = d + rng.uniform(-0.24, 0.24, d.size) * amb  # coarse errors within a quarter cycle
    np.testing.assert_array_equal(adm.resolve_integer(phase, coarse, F, NG), k)


def test_resolve_integer_vernier_two_frequencies():
    # second frequency 10 MHz below: beat ambiguity c/(2 n 10 MHz) = 15 m; noise-free phases
    f2 = F - 10e6
    d = np.linspace(0.2, 14.9, 500)
    p1, k1 = adm.phase_from_distance(d, F, NG)
    p2, _ = adm.phase_from_distance(d, f2, NG)
    np.testing.assert_array_equal(adm.resolve_integer_vernier(p1, p2, F, f2, NG), k1)
    # with 0.17 mrad phase noise the magnified error (x 490) stays below a quarter cycle
    rng = np.random.default_rng(5)
    n1 = p1 + rng.normal(0, 0.17e-3, d.size)
    n2 = p2 + rng.normal(0, 0.17e-3, d.size)
    np.testing.assert_array_equal(adm.resolve_integer_vernier(n1, n2, F, f2, NG), k1)


@pytest.mark.parametrize("kwargs, word", [
    (dict(phase_rad=float("nan"), k=1), "phase_rad"),
    (dict(phase_rad=1.0, k=-1), "k"),
    (dict(phase_rad=1.0, k=1.5), "k"),
])
def test_distance_from_phase_bad_input(kwargs, word):
    with pytest.raises(MultilatError, match=word):
        adm.distance_from_phase(frequency_hz=F, group_index=NG, **kwargs)


def test_bad_frequency_and_distance():
    with pytest.raises(MultilatError, match="frequency_hz"):
        adm.synthetic_wavelength_m(-1.0)
    with pytest.raises(MultilatError, match="group_index"):
        adm.synthetic_wavelength_m(F, float("nan"))
    with pytest.raises(MultilatError, match="distance_m"):
        adm.phase_from_distance(-0.1, F, NG)
    with pytest.raises(MultilatError, match="scr_db"):
        adm.crosstalk_amplitude_m(-3.0, F)
    with pytest.raises(MultilatError, match="frequency1_hz must exceed"):
        adm.resolve_integer_vernier(0.0, 0.0, F - 1e6, F, NG)
