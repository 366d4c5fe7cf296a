"""Initial values: from distances alone and from a head's angles (seed 000 eq. 7), checked against a
known truth; convergence of the adjustment from them on the paper's configurations and on >= 99 %
of 200 random well-conditioned networks."""

from types import SimpleNamespace

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.synthetic.configs import large_volume, small_volume
from multilat.network.model.data import Observations
from multilat.network.adjust.approximate.initial import initial_values, multilaterate, rigid_fit
from multilat.network.synthetic.generator import synthetic_network


def _obs_of(cfg, rng, sigma=4.7e-6, **angles):
    s, t = cfg.n_stations, cfg.n_targets
    si, ti = np.meshgrid(np.arange(s), np.arange(t), indexing="ij")
    si, ti = si.ravel(), ti.ravel()
    d = cfg.geometric_distances_m()[si, ti] + cfg.offset_m[si] + rng.normal(0, sigma, si.size)
    return Observations(cfg.station_ids, cfg.target_ids, si, ti, d, np.full(si.size, sigma), **angles)


def _aligned_error(P, Q, *, reflection=True):
    R, t = rigid_fit(P, Q, allow_reflection=reflection)
    return np.abs(P @ R.T + t - Q).max()


def _datum_free_gap(r1, r0):
    """Largest difference of all interpoint distances and offsets between two adjustments."""
    P1 = np.vstack([r1.station_xyz_m, r1.target_xyz_m])
    P0 = np.vstack([r0.station_xyz_m, r0.target_xyz_m])
    D1 = np.linalg.norm(P1[:, None] - P1[None], axis=2)
    D0 = np.linalg.norm(P0[:, None] - P0[None], axis=2)
    return max(np.abs(D1 - D0).max(), np.abs(r1.offset_m - r0.offset_m).max())


def _truth(net):
    return SimpleNamespace(station_xyz_m=net.station_xyz_m, target_xyz_m=net.target_xyz_m,
                           offset_m=net.offset_m)


# ------------------------------------------------------------------------------- building blocks


def test_multilaterate_recovers_point_and_offset_exactly():
    rng = np.random.default_rng(3)
    a = rng.uniform(-2, 2, (8, 3))
    p = np.array([0.3, -0.4, 0.9])
    d = np.linalg.norm(a - p, axis=1) + 0.0031
    xyz, off = multilaterate(a, d, with_offset=True)
    np.testing.assert_allclose(xyz, p, atol=1e-10)     # noise-free: exact up to rounding
    assert abs(off - 0.0031) < 1e-10
    xyz0, off0 = multilaterate(a, d - 0.0031)
    np.testing.assert_allclose(xyz0, p, atol=1e-10)
    assert off0 == 0.0


def test_rigid_fit_rotation_and_reflection():
    rng = np.random.default_rng(4)
    P = rng.normal(size=(10, 3))
    Rt, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    Rt *= np.sign(np.linalg.det(Rt))                   # a proper rotation
    Q = P @ Rt.T + [1.0, 2.0, 3.0]
    R, t = rigid_fit(P, Q)
    np.testing.assert_allclose(R, Rt, atol=1e-12)
    np.testing.assert_allclose(t, [1, 2, 3], atol=1e-12)
    M = Q * [1, 1, -1]                                  # a mirror image: only with reflection
    assert _aligned_error(P, M, reflection=False) > 0.1
    assert _aligned_error(P, M, reflection=True) < 1e-12


def test_closed_form_block_is_exact_without_offsets():
    """The bipartite factorisation + linear solve for G recovers an offset-free, noise-free block
    exactly (up to a rigid motion and a mirror): the derivation checked against a known truth."""
    from multilat.network.adjust.approximate.initial import _algebraic_block

    rng = np.random.default_rng(12)
    H = rng.uniform(-1, 1, (5, 3))
    T = rng.uniform(-1.5, 1.5, (12, 3))
    D2 = ((H[:, None] - T[None]) ** 2).sum(2)
    Hc, Tc = _algebraic_block(D2)
    assert _aligned_error(np.vstack([Hc, Tc]), np.vstack([H, T])) < 1e-9


def test_affine_fit_jacobian_against_finite_differences():
    from multilat.network.adjust.approximate import initial as ini

    rng = np.random.default_rng(0)
    H = rng.normal(size=(5, 3))
    T = rng.normal(size=(12, 3))
    D = np.linalg.norm(H[:, None] - T[None], axis=2) + 0.01
    Ut, Vv = ini._factorise(D ** 2)
    captured = {}

    def spy(fun, jac, x, **kw):
        captured.update(fun=fun, jac=jac, x=x)
        return x, None

    orig = ini.levenberg_marquardt
    ini.levenberg_marquardt = spy
    try:
        ini._affine_fit(D, Ut, Vv, rng.normal(size=(3, 3)), rng.normal(size=3), 0.01 * rng.normal(size=5))
    finally:
        ini.levenberg_marquardt = orig
    f, x = captured["fun"], captured["x"]
    J = captured["jac"](x)
    h = 1e-7
    Jn = np.column_stack([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(len(x))])
    # central differences: truncation ~h^2 and rounding ~1e-16/h relative: 1e-6 of max |J|
    assert np.abs(J - Jn).max() < 1e-6 * np.abs(J).max()


@pytest.mark.parametrize("n_targets", [12, 60])   # dense and sparse (> 150 unknowns) Jacobians
def test_refinement_jacobian_against_finite_differences(n_targets):
    import scipy.sparse

    from multilat.network.adjust.approximate import initial as ini
    from multilat.network.adjust.approximate import initial_refine as ir

    net = synthetic_network(np.random.default_rng(3), population="well-conditioned", n_stations=(5, 5),
                            n_targets=(n_targets, n_targets), gap_fraction=0.0)
    D, W = ini.distance_matrix(net.obs)
    captured = {}

    def spy(fun, jac, x, **kw):
        captured.update(fun=fun, jac=jac, x=x)
        return x, None

    orig = ir.levenberg_marquardt
    ir.levenberg_marquardt = spy
    try:
        H, T = ir.to_frame(net.station_xyz_m, net.target_xyz_m, (0, 1, 2))
        ir.refine(D, W, H, T, net.offset_m, (0, 1, 2), robust=False)
    finally:
        ir.levenberg_marquardt = orig
    f, x = captured["fun"], captured["x"] + 1e-3
    J = captured["jac"](x)
    assert scipy.sparse.issparse(J) == (len(x) > ir.SPARSE_FROM)
    J = J.toarray() if scipy.sparse.issparse(J) else J
    h = 1e-7
    Jn = np.column_stack([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(len(x))])
    assert np.abs(J - Jn).max() < 1e-6 * np.abs(J).max()


# ------------------------------------------------------------------------------- the paper's configurations


@pytest.mark.parametrize("make", [small_volume, large_volume])
def test_distances_alone_on_paper_configs(make):
    """No angles, no coordinates: the initial values are within the noise of the truth (after a
    rigid fit, mirror allowed) and the adjustment from them reaches the same minimum as from the
    truth (datum-free quantities equal to 1e-9 m)."""
    cfg = make()
    rng = np.random.default_rng(11)
    for _ in range(3):
        obs = _obs_of(cfg, rng)
        iv = initial_values(obs, rng=1)
        assert iv.method == "algebraic"
        P = np.vstack([iv.station_xyz_m, iv.target_xyz_m])
        Q = np.vstack([cfg.station_xyz_m, cfg.target_xyz_m])
        # the noise (4.7 um) moves the least-squares solution by up to ~1 mm along the weak
        # offset/geometry direction (offsets are determined to ~0.1 mm): 2 mm is far inside the
        # adjustment's basin (~10 mm, seed 000 §4.3)
        assert _aligned_error(P, Q) < 2e-3
        assert np.abs(iv.offset_m - cfg.offset_m).max() < 2e-3
        r1 = adjust(obs, initial=iv, snooping=False)
        r0 = adjust(obs, initial=_truth(cfg), snooping=False)
        assert _datum_free_gap(r1, r0) < 1e-9


def test_output_frame_and_mirror_convention():
    cfg = small_volume()
    iv = initial_values(_obs_of(cfg, np.random.default_rng(2)), rng=0)
    H = iv.station_xyz_m
    # frame stations A, B, C (first well-shaped triple in id order): A at origin, B on +x,
    # C in the xy-plane with y > 0, the mirror chosen so that D has z > 0
    np.testing.assert_allclose(H[0], 0.0, atol=1e-15)
    assert H[1, 0] > 0 and abs(H[1, 1]) < 1e-12 and abs(H[1, 2]) < 1e-12
    assert H[2, 1] > 0 and abs(H[2, 2]) < 1e-12
    assert H[3, 2] > 0


def test_mirrored_truth_gives_the_same_values():
    """Distances cannot tell a network from its mirror image: the output is the same for both."""
    cfg = small_volume()
    rng = np.random.default_rng(5)
    obs = _obs_of(cfg, rng)
    iv1 = initial_values(obs, rng=0)
    iv2 = initial_values(obs, rng=0)
    np.testing.assert_array_equal(iv1.target_xyz_m, iv2.target_xyz_m)   # deterministic
    # and the output keeps the truth's handedness or mirrors it, never anything else
    P = np.vstack([iv1.station_xyz_m, iv1.target_xyz_m])
    Q = np.vstack([cfg.station_xyz_m, cfg.target_xyz_m])
    assert min(_aligned_error(P, Q, reflection=False), _aligned_error(P, Q * [1, 1, -1], reflection=False)) < 2e-3


def _angles_from(cfg, obs, head=0, sigma_rad=0.0, rng=None):
    """Azimuth/elevation of head ``head`` (world axes), NaN for the other heads."""
    diff = cfg.target_xyz_m[obs.target_index] - cfg.station_xyz_m[obs.station_index]
    az = np.arctan2(diff[:, 1], diff[:, 0])
    el = np.arctan2(diff[:, 2], np.hypot(diff[:, 0], diff[:, 1]))
    if sigma_rad:
        az = az + rng.normal(0, sigma_rad, az.size)
        el = el + rng.normal(0, sigma_rad, el.size)
    other = obs.station_index != head
    az[other] = np.nan
    el[other] = np.nan
    return az, el


@pytest.mark.parametrize("make", [small_volume, large_volume])
def test_angles_eq7_without_refinement_within_basin(make):
    """Eq. 7 from head A's angles (0.5 mrad noise), then multilateration, no refinement: in head A's
    frame within the paper's ~10 mm of the truth (the offsets, a few mm, are not yet known)."""
    cfg = make()
    rng = np.random.default_rng(8)
    obs0 = _obs_of(cfg, rng)
    az, el = _angles_from(cfg, obs0, sigma_rad=0.5e-3, rng=rng)
    obs = Observations(obs0.station_ids, obs0.target_ids, obs0.station_index, obs0.target_index,
                       obs0.distance_m, obs0.sigma_m, azimuth_rad=az, elevation_rad=el)
    iv = initial_values(obs, refine=False)
    assert iv.method == "angles"
    shift = cfg.station_xyz_m[0]             # head A at the origin, world axes
    assert np.abs(iv.target_xyz_m - (cfg.target_xyz_m - shift)).max() < 10e-3
    assert np.abs(iv.station_xyz_m - (cfg.station_xyz_m - shift)).max() < 10e-3
    ivr = initial_values(obs)                  # refined: same frame, noise level
    r1 = adjust(obs, initial=ivr, snooping=False)
    r0 = adjust(obs, initial=_truth(cfg), snooping=False)
    assert _datum_free_gap(r1, r0) < 1e-9
    # the angles fix the mirror: no reflection needed
    P = np.vstack([ivr.station_xyz_m, ivr.target_xyz_m])
    Q = np.vstack([cfg.station_xyz_m, cfg.target_xyz_m])
    assert _aligned_error(P, Q, reflection=False) < 2e-3


# ------------------------------------------------------------------------------- random networks


def _convergence_failures(n):
    children = np.random.SeedSequence(20200808).spawn(n)
    failures = []
    for k, child in enumerate(children):
        net = synthetic_network(np.random.default_rng(child), population="well-conditioned", n_stations=(4, 6),
                                n_targets=(10, 20))
        iv = initial_values(net.obs, rng=k)
        r1 = adjust(net.obs, initial=iv, snooping=False)
        r0 = adjust(net.obs, initial=_truth(net), snooping=False)
        if _datum_free_gap(r1, r0) > 1e-8:
            failures.append(k)
    return failures


def test_convergence_rate_on_60_random_networks():
    """The first 60 of the 200 networks below: at most one fails to reach the minimum."""
    failures = _convergence_failures(60)
    assert len(failures) <= 1, failures


@pytest.mark.slow
def test_convergence_rate_on_200_random_networks():
    """>= 99 % of 200 random well-conditioned networks (4-6 stations x 10-20 targets, gaps, offsets
    ±5 mm, 5 um noise; definition in multilat.network.synthetic.generator, population "well-conditioned") converge from
    distances alone to the minimum the adjustment reaches from the truth (1e-8 m)."""
    failures = _convergence_failures(200)
    assert len(failures) <= 2, failures


def test_adjust_calls_initial_values_by_default():
    net = synthetic_network(np.random.default_rng(99), population="well-conditioned", n_stations=(5, 5),
                            n_targets=(15, 15))
    r1 = adjust(net.obs, snooping=False, rng=0)
    r0 = adjust(net.obs, initial=_truth(net), snooping=False)
    assert _datum_free_gap(r1, r0) < 1e-8


@pytest.mark.slow
def test_convergence_rate_large_study():
    """1000 networks, 4-8 stations x 10-30 targets: >= 99 %."""
    children = np.random.SeedSequence(7).spawn(1000)
    fails = 0
    for k, child in enumerate(children):
        net = synthetic_network(np.random.default_rng(child), population="well-conditioned")
        iv = initial_values(net.obs, rng=k)
        r1 = adjust(net.obs, initial=iv, snooping=False)
        r0 = adjust(net.obs, initial=_truth(net), snooping=False)
        fails += _datum_free_gap(r1, r0) > 1e-8
    assert fails <= 10


# ------------------------------------------------------------------------------- bad input


def test_too_few_stations_and_under_observed_target():
    rng = np.random.default_rng(0)
    H = rng.normal(size=(3, 3))
    T = rng.normal(size=(10, 3))
    si, ti = np.meshgrid(np.arange(3), np.arange(10), indexing="ij")
    si, ti = si.ravel(), ti.ravel()
    d = np.linalg.norm(H[si] - T[ti], axis=1)
    obs = Observations(("A", "B", "C"), tuple(str(j) for j in range(10)), si, ti, d, np.full(d.size, 1e-6))
    with pytest.raises(MultilatError, match="at least 4 stations"):
        initial_values(obs)
    net = synthetic_network(np.random.default_rng(1), population="well-conditioned", n_stations=(5, 5),
                            n_targets=(12, 12))
    keep = ~((net.obs.target_index == 0) & (net.obs.station_index >= 3))
    with pytest.raises(MultilatError, match=r"target .T1. is seen by [0-3] station"):
        initial_values(net.obs.subset(keep))


def test_gross_error_does_not_derail_the_initial_values():
    """A 2 mm blunder (400 sigma) in one distance: the initial values still lead the adjustment to the
    minimum reached from the truth (data snooping, in adjust, then deals with the blunder)."""
    cfg = small_volume()
    obs = _obs_of(cfg, np.random.default_rng(21))
    d = obs.distance_m.copy()
    d[17] += 2e-3
    bad = obs.with_distances(d)
    iv = initial_values(bad, rng=0)
    r1 = adjust(bad, initial=iv, snooping=False)
    r0 = adjust(bad, initial=_truth(cfg), snooping=False)
    # 10 nm: the adjustment's own stopping tolerance on this stretched problem (a wrong minimum is >= um)
    assert _datum_free_gap(r1, r0) < 1e-8


def test_larger_gappy_networks():
    """8-12 stations x 50-200 targets with 30 % of the distances missing (the adjustment tests'
    range): the same minimum as from the truth."""
    for k in range(4):
        net = synthetic_network(np.random.default_rng(1000 + k), population="well-conditioned",
                                n_stations=(8, 12), n_targets=(50, 200), gap_fraction=0.3)
        iv = initial_values(net.obs, rng=k)
        r1 = adjust(net.obs, initial=iv, snooping=False)
        r0 = adjust(net.obs, initial=_truth(net), snooping=False)
        assert _datum_free_gap(r1, r0) < 1e-8
