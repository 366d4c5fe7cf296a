"""Gimbal models (seed eqs. 2, 4, 5) against explicit 3D geometry; the Tot sign; the elevation convention."""

import math

import numpy as np
import pytest

from multilat import gimbal
from multilat.errors import MultilatError

DEG = math.pi / 180
RNG = np.random.default_rng(11)
N = 20_000


def _head_kw(n=N, tilt_deg=0.3, offset=320e-6, toh=5e-6):
    return dict(a_m=RNG.uniform(-offset, offset, n), c_m=RNG.uniform(-offset, offset, n),
                alpha_rad=RNG.uniform(-tilt_deg, tilt_deg, n) * DEG, gamma_rad=RNG.uniform(-tilt_deg, tilt_deg, n) * DEG,
                toh_m=RNG.normal(0, toh, n), elevation_rad=RNG.uniform(-math.pi / 2, math.pi / 2, n))


def _target_kw(n=N, mis_deg=15.0):
    return dict(a_m=RNG.normal(-6e-6, 2e-6, n), b_m=RNG.normal(34e-6, 2e-6, n), c_m=RNG.normal(-22e-6, 2e-6, n),
                tot_m=RNG.normal(11e-6, 2e-6, n), elevation_rad=RNG.uniform(-math.pi / 2, math.pi / 2, n),
                theta_rad=RNG.uniform(-mis_deg, mis_deg, n) * DEG, phi_rad=RNG.uniform(-mis_deg, mis_deg, n) * DEG)


def test_head_eq4_forward_inverse_round_trip():
    rt = RNG.uniform(0.2, 140.0, N)
    kw = _head_kw()
    rm = gimbal.head_measured_distance(rt, **kw)
    np.testing.assert_allclose(gimbal.head_true_distance(rm, **kw), rt, rtol=0, atol=1e-12)
    # the first line of eq. 4 alone, both ways
    ri = gimbal.head_intermediate_from_true(rt, **{k: kw[k] for k in ("a_m", "c_m", "alpha_rad", "gamma_rad")})
    back = gimbal.head_true_from_intermediate(ri, **{k: kw[k] for k in ("a_m", "c_m", "alpha_rad", "gamma_rad")})
    np.testing.assert_allclose(back, rt, rtol=0, atol=1e-12)


def test_head_eq4_against_3d_geometry():
    # eq. (4) composes planar steps; the explicit 3D vector model differs only at second order:
    # offset x tilt x offset / R and Toh x offset / R cross terms (Toh c sin(phi) / R <= 15 um x 320 um
    # / 0.2 m = 2.4e-8 m for |Toh| < 3 sigma); bound 5e-8 m
    rt = RNG.uniform(0.2, 20.0, N)
    kw = _head_kw()
    diff = gimbal.head_measured_distance(rt, **kw) - gimbal.head_measured_distance_3d(rt, **kw)
    assert np.abs(diff).max() < 5e-8
    # offsets without tilts or Toh: both exact
    kw0 = dict(kw, alpha_rad=0.0, gamma_rad=0.0, toh_m=0.0)
    d0 = gimbal.head_measured_distance(rt, **kw0) - gimbal.head_measured_distance_3d(rt, **kw0)
    assert np.abs(d0).max() < 1e-12
    # Toh alone: eq. (2)'s phi is the elevation seen from O, the 3D model's the beam's; they differ by
    # at most Toh^2 / R
    kw1 = dict(kw, a_m=0.0, c_m=0.0, alpha_rad=0.0, gamma_rad=0.0)
    d1 = gimbal.head_measured_distance(rt, **kw1) - gimbal.head_measured_distance_3d(rt, **kw1)
    assert np.all(np.abs(d1) <= kw1["toh_m"] ** 2 / rt + 1e-13)  # + rounding of 20 m (ulp 3.6e-15)


def test_eq2_is_eq4_without_beam_errors():
    rt = RNG.uniform(0.2, 20.0, N)
    toh = RNG.normal(0, 5e-6, N)
    el = RNG.uniform(-math.pi / 2, math.pi / 2, N)
    rm4 = gimbal.head_measured_distance(rt, a_m=0, c_m=0, alpha_rad=0, gamma_rad=0, toh_m=toh, elevation_rad=el)
    np.testing.assert_allclose(gimbal.transit_offset_effect(rt, toh, el), rm4, rtol=0, atol=1e-13)
    np.testing.assert_allclose(gimbal.transit_offset_correction(rm4, toh, el), rt, rtol=0, atol=1e-13)


def test_elevation_is_from_the_horizontal():
    # 3D geometry: a horizontal transit offset changes a horizontal sight's distance by its full length
    # and a vertical sight's by ~Toh^2/(2R) only. Eq. (2) with phi measured from the horizontal says
    # the same (cos 0 = 1, cos 90 deg = 0); read from the zenith, its cosine would be the wrong way round.
    toh, r = 10e-6, 5.0
    for el, expected in ((0.0, toh), (math.pi / 2, 0.0), (math.pi / 3, toh / 2)):
        rm3 = gimbal.head_measured_distance_3d(r, a_m=0, c_m=0, alpha_rad=0, gamma_rad=0, toh_m=toh, elevation_rad=el)
        assert rm3 - r == pytest.approx(expected, abs=1e-10)
        assert gimbal.transit_offset_effect(r, toh, el) - r == pytest.approx(expected, abs=1e-10)
    zenith_reading = gimbal.transit_offset_effect(r, toh, math.pi / 2 - 0.0) - r  # horizontal sight as 90 deg
    assert abs(zenith_reading) < 1e-10  # would predict no effect at horizontal sight: contradicts 3D (= toh)


def test_target_eq5_against_3d_geometry():
    rt = RNG.uniform(0.2, 20.0, N)
    kw = _target_kw()
    az = RNG.uniform(-math.pi, math.pi, N)  # the world azimuth must not matter
    d = gimbal.target_measured_distance(rt, **kw) - gimbal.target_measured_distance_3d(rt, azimuth_rad=az, **kw)
    # eq. 5 writes a' sin(th'') where the unit vector gives a' sin(th'') cos(ph''): difference
    # |a'| |sin th''| (1 - cos ph'') <= 12 um * 0.26 * 0.034 = 1.1e-7 m (a' within 3 sigma)
    assert np.abs(d).max() < 1.2e-7
    # with phi'' = 0 eq. 5 is the exact vector norm
    kw0 = dict(kw, phi_rad=0.0)
    d0 = gimbal.target_measured_distance(rt, **kw0) - gimbal.target_measured_distance_3d(rt, azimuth_rad=az, **kw0)
    assert np.abs(d0).max() < 1e-12


def test_tot_sign_eq5_is_the_geometric_one():
    # Build the target in 3D with its transit axis displaced by +x TOWARDS the head (no other error).
    x, rt = 11e-6, 3.0
    el = np.linspace(-math.pi / 2, math.pi / 2, 181)
    rm = gimbal.target_measured_distance_3d(rt, a_m=0, b_m=0, c_m=0, tot_m=x, elevation_rad=el, theta_rad=0,
                                            phi_rad=0)
    # eq. (5) with Tot = +x reproduces it exactly ...
    rm5 = gimbal.target_measured_distance(rt, a_m=0, b_m=0, c_m=0, tot_m=x, elevation_rad=el, theta_rad=0, phi_rad=0)
    np.testing.assert_allclose(rm5, rm, rtol=0, atol=1e-14)
    # ... eq. (2) as printed for the target reproduces it only with Tot = -x,
    np.testing.assert_allclose(gimbal.transit_offset_effect(rt, -x, el), rm, rtol=0, atol=1e-14)
    # and with Tot = +x it is off by ~2 x cos(phi') (22 um at horizontal sight)
    np.testing.assert_allclose(gimbal.transit_offset_effect(rt, x, el) - rm, 2 * x * np.cos(el), rtol=0, atol=1e-10)
    # eq. (5)'s own cross terms force its sign: b' and Tot are parallel at phi' = 0 (the +2 b' Tot
    # term), b' towards the head shortens the distance (-2 b' Rt), so Tot towards the head must too.
    rm_b = gimbal.target_measured_distance_3d(rt, a_m=0, b_m=x, c_m=0, tot_m=0, elevation_rad=0.0, theta_rad=0,
                                              phi_rad=0)
    assert float(rm_b) == pytest.approx(float(rm[90]), abs=1e-15)  # same displacement, same distance
    assert float(rm[90]) - rt == pytest.approx(-x, abs=1e-12)


def test_target_correction_removes_tot_both_readings():
    rt = RNG.uniform(0.2, 20.0, N)
    kw = _target_kw()
    kw0 = dict(kw, a_m=0.0, b_m=0.0, c_m=0.0)
    rm = gimbal.target_measured_distance(rt, **kw0)
    # eq. 5 convention with the sighting's angles: exact removal
    back = gimbal.target_transit_offset_correction(rm, kw["tot_m"], kw["elevation_rad"], theta_rad=kw["theta_rad"],
                                                   phi_rad=kw["phi_rad"])
    np.testing.assert_allclose(back, rt, rtol=0, atol=1e-12)
    # aligned target: the correction with phi' only is exact too, and equals eq. 2's with -Tot
    kwa = dict(kw0, theta_rad=0.0, phi_rad=0.0)
    rma = gimbal.target_measured_distance(rt, **kwa)
    a = gimbal.target_transit_offset_correction(rma, kw["tot_m"], kw["elevation_rad"])
    np.testing.assert_allclose(a, rt, rtol=0, atol=1e-12)
    np.testing.assert_allclose(gimbal.transit_offset_correction(rma, -kw["tot_m"], kw["elevation_rad"]), a,
                               rtol=0, atol=1e-15)


def test_line_of_sight_elevation():
    el = RNG.uniform(-1.3, 1.3, N)  # |el - ph| < pi/2: no wrap of the elevation
    ph = RNG.uniform(-0.2, 0.2, N)
    np.testing.assert_allclose(gimbal.line_of_sight_elevation(el, 0.0, ph), el - ph, atol=1e-12)
    # against the 3D unit vector: z component of w
    th = RNG.uniform(-0.2, 0.2, N)
    w_z = np.cos(th) * np.cos(ph) * np.sin(el) - np.sin(ph) * np.cos(el)
    np.testing.assert_allclose(np.sin(gimbal.line_of_sight_elevation(el, th, ph)), w_z, atol=1e-14)


def test_broadcasting_shapes():
    rt = np.linspace(1, 2, 5)[:, None]
    el = np.linspace(-1, 1, 3)[None, :]
    out = gimbal.head_measured_distance(rt, a_m=1e-4, c_m=0.0, alpha_rad=1e-3, gamma_rad=0.0, toh_m=2e-6,
                                        elevation_rad=el)
    assert out.shape == (5, 3)
    out5 = gimbal.target_measured_distance(rt, a_m=0, b_m=1e-5, c_m=0, tot_m=1e-5, elevation_rad=el, theta_rad=0,
                                           phi_rad=0)
    assert out5.shape == (5, 3)


def test_forward_bad_input():
    with pytest.raises(MultilatError, match="true_distance_m"):
        gimbal.head_measured_distance(-1.0, a_m=0, c_m=0, alpha_rad=0, gamma_rad=0, toh_m=0, elevation_rad=0)
    with pytest.raises(MultilatError, match="true_distance_m"):
        gimbal.target_measured_distance(float("nan"), a_m=0, b_m=0, c_m=0, tot_m=0, elevation_rad=0, theta_rad=0,
                                        phi_rad=0)
    with pytest.raises(MultilatError, match="measured_m"):
        gimbal.head_true_distance(0.0, a_m=0, c_m=0, alpha_rad=0, gamma_rad=0, toh_m=0, elevation_rad=0)


def test_correction_bad_input():
    with pytest.raises(MultilatError, match="measured_m"):
        gimbal.transit_offset_correction(-1.0, 1e-6, 0.0)
    with pytest.raises(MultilatError, match="measured_m"):
        gimbal.transit_offset_correction(float("nan"), 1e-6, 0.0)
    with pytest.raises(MultilatError, match="finite"):
        gimbal.transit_offset_correction(1.0, float("nan"), 0.0)
    with pytest.raises(MultilatError, match="shorter"):
        gimbal.transit_offset_correction(1e-6, 1e-3, 1.0)


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


@settings(max_examples=200, deadline=None)
@given(rt=st.floats(0.05, 500.0), a=st.floats(-1e-3, 1e-3), c=st.floats(-1e-3, 1e-3),
       al=st.floats(-0.02, 0.02), ga=st.floats(-0.02, 0.02), toh=st.floats(-1e-4, 1e-4),
       el=st.floats(-math.pi, math.pi))
def test_head_round_trip_property(rt, a, c, al, ga, toh, el):
    kw = dict(a_m=a, c_m=c, alpha_rad=al, gamma_rad=ga, toh_m=toh, elevation_rad=el)
    rm = gimbal.head_measured_distance(rt, **kw)
    assert float(gimbal.head_true_distance(rm, **kw)) == pytest.approx(rt, rel=1e-13, abs=1e-13)
    # first order: Rm - Rt = Toh cos(alpha) cos(phi - gamma) + a sin(alpha) + c sin(gamma), up to O(offset^2 / R)
    lin = toh * math.cos(al) * math.cos(el - ga) + a * math.sin(al) + c * math.sin(ga)
    assert float(rm) - rt == pytest.approx(lin, abs=2 * (a * a + c * c + toh * toh) / rt + 1e-12)
