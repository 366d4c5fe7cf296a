"""LBB HTM length model (seed 003, §3-4): sag vs closed forms, HTMs, DL model, eq. 6, config."""

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from multilat.errors import MultilatError
from multilat.lbb import htm
from multilat.lbb.config import DEFAULT_CONFIG, load_config
from multilat.lbb.model import (MECH_SOURCES, BarModel, cs3_to_cs1, fixture_length, length_for_reading,
                                pose_distributions, retroreflector_x_cs1, sag_offsets, section_lengths,
                                true_length_change)
from multilat.lbb.sag import stepped_beam

CFG = load_config()
BAR = BarModel.from_config(CFG)


# ----------------------------------------------------------------------------- sag
def test_sag_equal_steps_matches_uniform_beam_closed_form():
    L, w, ei = 0.62, 11.3, 737.0
    breaks = [0.0, 0.1, 0.37, L]              # three "steps" with equal properties
    v, th = stepped_beam(breaks, [ei] * 3, [w] * 3, [0.0, L / 2, L, 0.37, 0.1])
    assert v[1] == pytest.approx(5 * w * L**4 / (384 * ei), rel=1e-12)
    assert th[0] == pytest.approx(w * L**3 / (24 * ei), rel=1e-12)       # Castigliano slope at supports
    assert th[2] == pytest.approx(-w * L**3 / (24 * ei), rel=1e-12)
    assert abs(th[1]) < 1e-15 and abs(v[0]) < 1e-18 and abs(v[2]) < 1e-18
    for x, vx, tx in ((0.37, v[3], th[3]), (0.1, v[4], th[4])):   # elastic curve of a uniform beam
        assert vx == pytest.approx(w * x * (L**3 - 2 * L * x**2 + x**3) / (24 * ei), rel=1e-12)
        assert tx == pytest.approx(w * (L**3 - 6 * L * x**2 + 4 * x**3) / (24 * ei), rel=1e-12)


def test_stepped_beam_matches_direct_integration_of_the_elastic_curve():
    # independent method: integrate v'' = -M/EI twice on a fine grid, fix the constants by v(0)=v(L)=0
    breaks = np.array([0.0, 0.1, 0.33, 0.58])
    ei = np.array([4100.0, 1860.0, 420.0])
    w = np.array([62.0, 18.0, 6.9])
    x = np.linspace(0, breaks[-1], 400_001)
    seg = np.clip(np.searchsorted(breaks, x, side="right") - 1, 0, 2)
    q = w[seg]
    shear = cumulative_trapezoid(q, x, initial=0.0)
    moment_load = cumulative_trapezoid(shear, x, initial=0.0)            # moment of the load left of x
    r_a = moment_load[-1] / x[-1]
    m = r_a * x - moment_load
    curv = -m / ei[seg]
    slope0 = cumulative_trapezoid(curv, x, initial=0.0)
    v0 = cumulative_trapezoid(slope0, x, initial=0.0)
    c = -v0[-1] / x[-1]
    v_num = v0 + c * x
    slope_num = slope0 + c
    at = np.array([0.0, 0.1, 0.21, 0.33, 0.58])
    v, th = stepped_beam(breaks, ei, w, at)
    idx = np.searchsorted(x, at)
    # the reference's own error: the trapezoid rule across the load steps (grid 1.5 um) leaves ~1e-5
    # relative; a wrong segment stiffness or load would be off by tens of per cent
    np.testing.assert_allclose(v, v_num[idx], rtol=0, atol=2e-5 * np.max(np.abs(v_num)))
    np.testing.assert_allclose(th, slope_num[idx], rtol=0, atol=2e-5 * np.max(np.abs(slope_num)))


def test_sag_offsets_chain_puts_right_ball_on_the_support_line():
    # in the gravity frame the right ball is a support (v = 0): in CS1 (turned by the slope at the
    # left ball) its y must be theta0 * L, and the sag vanishes for a vertical bar
    lb, lc = section_lengths(BAR, 0.55, 0.3)
    dy2, ez2, dy3, ez3 = sag_offsets(BAR, lb, lc, 0.0)
    t = cs3_to_cs1(BAR, 0.55, 0.0, u_mid=0.3)
    _, th = stepped_beam([0, BAR.la_m, BAR.la_m + lb, 0.55], BAR.ei_n_m2, BAR.weight_n_per_m, [0.0])
    # compliance also rotates CS3; remove it to isolate sag
    bar0 = BarModel(**{**BAR.__dict__, "compliance_rad": 0.0})
    t0 = cs3_to_cs1(bar0, 0.55, 0.0, u_mid=0.3)
    assert htm.origin(t0)[1] == pytest.approx(th[0] * 0.55, rel=1e-6)
    assert htm.origin(t)[1] < htm.origin(t0)[1]          # compliance lowers the free end
    assert np.allclose(sag_offsets(BAR, lb, lc, np.pi / 2), 0.0, atol=1e-18)   # cos(pi/2) = 6e-17
    tv = cs3_to_cs1(BAR, 0.55, np.pi / 2, u_mid=0.3)
    np.testing.assert_allclose(htm.origin(tv), [0.55, 0, 0], atol=1e-15)   # vertical: no sag, no compliance


# ----------------------------------------------------------------------------- HTMs
def test_htm_building_blocks():
    np.testing.assert_allclose(htm.cs2_to_cs1_nominal(0.1, 0.2) @ htm.cs3_to_cs2_nominal(0.3),
                               htm.translation(0.6), atol=1e-15)                       # eq. 2
    r = htm.rot_z(0.3) @ htm.rot_y(-0.2) @ htm.rot_x(0.1)
    np.testing.assert_allclose(r[:3, :3] @ r[:3, :3].T, np.eye(3), atol=1e-15)
    assert np.linalg.det(r[:3, :3]) == pytest.approx(1.0)
    e = 1e-4
    for exact, small in ((htm.rot_x(e), htm.small_angle_htm(ex_rad=e)), (htm.rot_y(e), htm.small_angle_htm(ey_rad=e)),
                         (htm.rot_z(e), htm.small_angle_htm(ez_rad=e))):
        assert np.max(np.abs(exact - small)) < e**2      # first-order agreement
    batch = htm.rot_z(np.zeros((5, 2)))
    assert batch.shape == (5, 2, 4, 4)
    # the middle tube's tilt ez moves CS2 by ez*Lb (Table 1's "+ ez Lb")
    t = htm.cs2_to_cs1(0.1, 0.25, ez_rad=123e-6)
    assert htm.origin(t)[1] == pytest.approx(123e-6 * 0.25, rel=1e-6)


# ----------------------------------------------------------------------------- length change
def test_reading_solver_and_error_free_length_change():
    bar_ideal = BarModel(**{**BAR.__dict__, "compliance_rad": 0.0})
    dl = true_length_change(bar_ideal, from_length_m=0.3, from_elevation_rad=0.0, from_pose={"sag": False},
                            to_length_m=np.array([0.25, 0.45, 0.69]), to_elevation_rad=0.7,
                            to_pose={"sag": False}, thermal_m=0.0, dmi_m=0.0)
    np.testing.assert_allclose(dl, [-0.05, 0.15, 0.39], atol=1e-15)   # a perfect bar reads true
    # the solver puts the apex where asked
    rng = np.random.default_rng(3)
    d = pose_distributions(CFG)
    pose = {k: d[k].sample(rng, 100) for k in MECH_SOURCES}
    target = 0.4 + rng.normal(0, 1e-6, 100)
    _, t = length_for_reading(BAR, target, 0.4, start_length_m=0.42, thermal_m=1e-7, **pose)
    np.testing.assert_allclose(retroreflector_x_cs1(BAR, t, 1e-7), target, atol=1e-13)


def test_length_change_error_is_dmi_plus_thermal_and_mechanics_is_second_order():
    # std of (true - reading) from MC against the root-sum-square of the two first-order terms
    rng = np.random.default_rng(11)
    n = 20_000
    d = pose_distributions(CFG)
    pf = {k: d[k].sample(rng, n) for k in MECH_SOURCES}
    pt = {k: d[k].sample(rng, n) for k in MECH_SOURCES}
    th = d["thermal_m"].sample(rng, n)
    dmi = d["dmi_m"].sample(rng, n)
    assert d["thermal_m"].std == pytest.approx(0.147e-6, abs=0.0005e-6)    # the paper's sigma
    err = true_length_change(BAR, from_length_m=0.3, from_elevation_rad=0.0, from_pose=pf,
                             to_length_m=0.6, to_elevation_rad=0.5, to_pose=pt, thermal_m=th, dmi_m=dmi) - 0.3
    expected = np.hypot(0.125e-6, 0.147e-6)
    # relative standard error of a std from n draws ~ 1/sqrt(2n) = 0.5 %; 4 SE tolerance
    assert np.std(err) == pytest.approx(expected, rel=4 / np.sqrt(2 * n))
    mech = true_length_change(BAR, from_length_m=0.3, from_elevation_rad=0.0, from_pose=pf,
                              to_length_m=0.6, to_elevation_rad=0.5, to_pose=pt, thermal_m=0.0, dmi_m=0.0) - 0.3
    assert np.std(mech) < 0.02e-6 and abs(np.mean(mech)) < 0.1e-6     # cosine-type: nm level


def test_fixture_equation_6():
    assert fixture_length(0.22, 0.3, 0.0) == pytest.approx(0.3, abs=1e-15)
    # second-order expansion: L23 - dL = dy^2 L12 / (2 dL (L12 + dL))
    dy = 0.25e-3
    exact = fixture_length(0.22, 0.3, dy) - 0.3
    assert exact == pytest.approx(dy**2 * 0.22 / (2 * 0.3 * 0.52), rel=1e-5)
    # geometric check: socket 3 at distance L12 + dL from socket 1 and dy off the line
    x3 = np.sqrt(0.52**2 - dy**2)
    assert fixture_length(0.22, 0.3, dy) == pytest.approx(np.hypot(x3 - 0.22, dy), abs=1e-15)


# ----------------------------------------------------------------------------- config
def test_config_errors_are_one_line_and_name_the_key(tmp_path):
    text = DEFAULT_CONFIG.read_text()
    p = tmp_path / "c.toml"
    p.write_text(text.replace("interferometer_std_m =", "interferometer_sdt_m ="))
    with pytest.raises(MultilatError) as e:
        load_config(p)
    msg = str(e.value)
    assert "\n" not in msg and "errors" in msg and ("missing" in msg or "unknown" in msg)
    p.write_text(text.replace("la_m = 0.100", ""))
    with pytest.raises(MultilatError, match=r"bar\.la_m: missing required key"):
        load_config(p)
    p.write_text(text.replace("nx = 9", 'nx = "nine"'))
    with pytest.raises(MultilatError, match=r"volume\.nx"):
        load_config(p)
    p.write_text(text.replace("interferometer_std_m = 0.125e-6", "interferometer_std_m = -1.0"))
    with pytest.raises(MultilatError, match=r"errors\.interferometer_std_m: must be >= 0"):
        load_config(p)
    p.write_text(text + "\n[extra]\nfoo = 1\n")
    with pytest.raises(MultilatError, match=r"extra: unknown key"):
        load_config(p)
    with pytest.raises(MultilatError, match="not found"):
        load_config(tmp_path / "nope.toml")


def test_distribution_options_follow_the_documented_sigmas():
    d = pose_distributions(CFG)
    assert d["ez2"].std == pytest.approx(123e-6 / 2) and d["sy3"].std == pytest.approx(2.5e-6 / 2)
    assert d["dmi_m"].std == pytest.approx(0.125e-6)
    u = pose_distributions(CFG.replace(errors__thermal_model="uniform", errors__axis_distribution="uniform"))
    assert u["thermal_m"].std == pytest.approx(0.0196 * 15e-6 / np.sqrt(3))       # 0.170 um
    assert u["ez2"].low == -123e-6 and u["ez2"].high == 123e-6
    z = pose_distributions(CFG.replace(errors__inner_angle_bound_rad=0.0))
    assert z["ey3"].std == 0.0


def test_example_configs_load():
    from pathlib import Path

    ex = Path(__file__).resolve().parents[1] / "examples" / "lbb" / "controlled_room.toml"
    c = load_config(ex)
    assert c.base.thermal_bound_c == 0.01 and c.model_dump(exclude={"base"}) == CFG.model_dump(exclude={"base"})


def test_sag_fast_path_at_segment_ends_equals_explicit_stations():
    rng = np.random.default_rng(2)
    br = np.cumsum(np.c_[np.zeros(50), rng.uniform(0.05, 0.3, (50, 3))], axis=1)
    ei = rng.uniform(300, 5000, (50, 3))
    w = rng.uniform(5, 60, (50, 3))
    v1, t1 = stepped_beam(br, ei, w)
    v2, t2 = stepped_beam(br, ei, w, br)
    np.testing.assert_allclose(v1, v2, rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(t1, t2, rtol=1e-12, atol=1e-20)
