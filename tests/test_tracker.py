"""Tracker uncertainty from an MPE specification (multilat.tracker) against hand-computed values."""

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.tracker import TrackerSpec

# Leica AT500 user manual §2.8.2: ADM ±(10 µm + 0.3 µm/m), transverse ±(15 µm + 6 µm/m)
AT500 = TrackerSpec(adm_a_um=10, adm_b_um_per_m=0.3, transverse_a_um=15, transverse_b_um_per_m=6)


def test_distance_sigma_is_half_the_mpe():
    # at 5 m: MPE = 10 + 1.5 = 11.5 µm -> 5.75 µm
    assert AT500.distance_sigma_m(5.0) == pytest.approx(5.75e-6, rel=1e-14)
    assert np.allclose(AT500.distance_sigma_m([0.0, 10.0]), [5e-6, 6.5e-6], rtol=1e-14)


def test_angle_sigma_is_the_transverse_length_over_the_range():
    # at 6 m the transverse MPE is 15 + 36 = 51 µm (the manual's "Pos. 10 to 18 (6 m distance): ±51 µm")
    assert AT500.angle_sigma_rad(6.0) * 6.0 == pytest.approx(0.5 * 51e-6, rel=1e-14)
    # far away the angular term tends to b (µrad) times std_per_mpe
    assert AT500.angle_sigma_rad(1e6) == pytest.approx(0.5 * 6e-6, rel=1e-5)
    spec = TrackerSpec(1, 0, 0, 0, angular_c_urad=2.0, std_per_mpe=1 / np.sqrt(3))
    assert spec.angle_sigma_rad(3.0) == pytest.approx(2e-6 / np.sqrt(3), rel=1e-14)


@pytest.mark.parametrize("kw, match", [
    (dict(adm_a_um=-1), "adm_a_um"),
    (dict(std_per_mpe=0), "std_per_mpe"),
    (dict(adm_a_um=0, adm_b_um_per_m=0), "distance MPE"),
    (dict(transverse_a_um=float("nan")), "transverse_a_um"),
])
def test_bad_specifications_are_one_line_errors(kw, match):
    base = dict(adm_a_um=10, adm_b_um_per_m=0.3, transverse_a_um=15, transverse_b_um_per_m=6)
    base.update(kw)
    with pytest.raises(MultilatError, match=match):
        TrackerSpec(**base)
