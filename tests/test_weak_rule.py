"""One rule for a weak point on both adjustments (issue 27, "each concept once"; issue 26's network 717).

:func:`multilat.network.model.weak_points.weak_points` decides; the distance path
(:func:`multilat.network.adjust.distance.exclusion.undetermined_targets`) and the general layer
(:mod:`multilat.network.adjust.general.weak`, :func:`~multilat.network.adjust.general.run.adjust_network`)
both call it. Independent values: the closed-form information of a point's sights and of a
tracker's angles (below), the general system's dense whitened Jacobian (a second computation of a
point's normal block), and the other path's result on the same network.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.adjust.general.adjust import System
from multilat.network.adjust.general.from_tables import network_from_tables
from multilat.network.adjust.general.run import adjust_network
from multilat.network.adjust.general.weak import _other_information, weak_points_of
from multilat.network.model.weak_points import K_PLANE, weak_points
from p403_network import SIGMA, SIGMA_ANGLE, p403_network



def _quiet(f, *a, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return f(*a, **kw)


# --- the rule itself, against closed forms ---------------------------------------------------------

def _three_sights(h_m: float):
    """A point ``h_m`` above the plane z = 0 of 3 stations at 2 m around it: its sights (3, 3)."""
    a = np.deg2rad([0.0, 120.0, 240.0])
    H = np.c_[2 * np.cos(a), 2 * np.sin(a), np.zeros(3)]
    return np.array([0.0, 0.0, h_m]) - H, H


def test_rule_on_three_stations_matches_the_closed_form():
    """σ_z of a point h above 3 stations at radius R: N_zz = 3 (h/L)² / σ², L = sqrt(R² + h²);
    weak exactly when h < K_PLANE σ_z (h² < K_PLANE σ L / sqrt(3): h below 7.6 mm here)."""
    for h, expect in ((1e-4, True), (7e-3, True), (8e-3, False), (2e-2, False)):
        d, _ = _three_sights(h)
        L = np.hypot(2.0, h)
        sz = SIGMA * L / (np.sqrt(3) * h)
        assert bool(h < K_PLANE * sz) is expect
        got = weak_points(np.zeros(3, int), d, np.full(3, SIGMA), 1, tested=np.array([True]))
        assert (0 in got) is expect, got
        if expect:       # the reason's numbers: spread h (mm) and σ_z (mm) to its 2 and 3 digits
            assert f"spread {h * 1e3:.3g} mm" in got[0] and f"uncertainty {sz * 1e3:.2g} mm" in got[0]


def _angle_information(H, P, sigma_rad):
    """A tracker's azimuth and elevation at H fix P across the sight: (I - u uᵀ) / (L σ)² (closed form)."""
    d = P - H
    L = np.linalg.norm(d)
    u = d / L
    return (np.eye(3) - np.outer(u, u)) / (L * sigma_rad) ** 2


def test_angles_from_a_tracker_keep_a_point_its_coplanar_sights_leave_weak():
    """The rule respects what else observes the point: with one tracker's angles (1 arcsecond) the
    point is fixed along the plane's normal to ~ L σ = 10 µm, linearly: not weak; angles 10⁴ times
    worse give less information along the normal than the distances: weak again."""
    d, H = _three_sights(1e-4)
    P = d[0] + H[0]
    tested = np.array([True])
    assert 0 in weak_points(np.zeros(3, int), d, np.full(3, SIGMA), 1, tested=tested)
    other = _angle_information(H[0], P, SIGMA_ANGLE)[None]
    assert weak_points(np.zeros(3, int), d, np.full(3, SIGMA), 1, tested=tested, other=other) == {}
    poor = _angle_information(H[0], P, 1e4 * SIGMA_ANGLE)[None]
    assert 0 in weak_points(np.zeros(3, int), d, np.full(3, SIGMA), 1, tested=tested, other=poor)
    # no other information at all (zeros) is the distance-only rule, to the bit
    zero = np.zeros((1, 3, 3))
    assert (weak_points(np.zeros(3, int), d, np.full(3, SIGMA), 1, tested=tested, other=zero)
            == weak_points(np.zeros(3, int), d, np.full(3, SIGMA), 1, tested=tested))


# --- the general layer: the point's other information, and the verdict end to end ----------------

def _weak_network(angles: bool):
    """6 stations, 40 targets seen by all, plus P403 2 mm above the centroid of stations 1, 2, 3,
    seen by those 3 only (tests/test_weak_targets.py's network, the point lifted off the plane:
    exactly in it, neither path's distance-only initial values place it). By its distances it is
    weak: adjusted, spread 1.7 mm, σ along the normal ≈ σ L / (h sqrt 3) ≈ 2.9 mm. ``angles``:
    station 1 is a tracker reading azimuth and elevation (σ 1 arcsecond) of every target it sees,
    P403 too."""
    return p403_network(angles, lift_m=2e-3)


def test_other_information_equals_the_dense_whitened_jacobian():
    """Each point's block of the non-distance rows' normal matrix, accumulated row by row, equals
    Jᵀ J of the dense whitened Jacobian (System.evaluate, System.whiten) restricted to those rows:
    two computations of one sum, to 1e-9 of its largest entry (rounding of 10⁹-10¹¹ m⁻² sums)."""
    net, opts = network_from_tables(_weak_network(angles=True), rng=0)
    adj = _quiet(adjust_network, net, options=opts)
    system = System(adj.network)
    x = adj.result.parameters
    other = _other_information(system, x, system.layout.points.n)
    _, jac = system.evaluate(x)
    jw = system.whiten(jac)
    keep = np.zeros(system.n_rows, bool)
    for b, sl in zip(system.blocks, system.rows):
        keep[sl] = b.kind != "slope_distance"
    red = system.reduced
    n_checked = 0
    for p in range(system.layout.points.n):
        cols = red[system.layout.point_cols[p]]
        if np.any(cols < 0):
            continue
        ref = jw[keep][:, cols].T @ jw[keep][:, cols]
        np.testing.assert_allclose(other[p], ref, rtol=0, atol=1e-9 * max(np.abs(ref).max(), 1.0))
        n_checked += 1
    assert n_checked >= 40 and np.abs(other).max() > 1e9     # the tracker's targets carry angle information


def test_general_keeps_a_coplanar_point_its_tracker_angles_fix_and_leaves_it_out_without():
    net, opts = network_from_tables(_weak_network(angles=False), rng=0)
    adj = _quiet(adjust_network, net, options=opts)
    assert [(e["id"], e["kind"], e["n_obs"]) for e in adj.excluded] == [("P403", "point", 3)]
    d = _quiet(adjust, _weak_network(angles=False), rng=0, snooping=False)
    assert [e.id for e in d.excluded] == ["P403"]           # the same verdict, in the same words
    assert adj.excluded[0]["reason"] == d.excluded[0].reason
    assert "lines of sight are coplanar within their uncertainty" in d.excluded[0].reason
    assert adj.result.dof == d.dof and abs(adj.result.sigma0 - d.sigma0) <= 1e-9 * d.sigma0
    with pytest.raises(MultilatError, match=r"point 'P403' is undetermined: its lines of sight are coplanar.*--strict"):
        _quiet(adjust_network, net, options=opts, strict=True)

    net, opts = network_from_tables(_weak_network(angles=True), rng=0)
    adj = _quiet(adjust_network, net, options=opts)
    assert adj.excluded == ()
    found, n_tested = weak_points_of(System(adj.network), adj.result.parameters)
    assert found == {} and n_tested == 41
    # the angles fix P403 linearly: its largest σ ~ L σ_angle (L ≈ 2-4 m: 10-20 µm), not the mm of
    # the distances along the plane's normal
    s = np.sqrt(np.diag(adj.result.point_cofactor("P403"))) * adj.result.sigma0
    assert s.max() < 1e-4, s


def test_distance_path_agrees_on_the_tracker_network():
    """The distance path keeps P403 too (a target with angle observations is placed by them) and
    reaches the same minimum (σ0 to 1e-9 relative: both converged to ~1e-12)."""
    obs = _weak_network(angles=True)
    d = _quiet(adjust, obs, rng=0, snooping=False)
    net, opts = network_from_tables(obs, rng=0)
    g = _quiet(adjust_network, net, options=opts)
    assert [e.id for e in d.excluded] == [] and g.excluded == ()
    assert d.dof == g.result.dof
    assert abs(g.result.sigma0 - d.sigma0) <= 1e-9 * d.sigma0


# --- network 717 of the acceptance study: one verdict on both paths ---------------------------------

def _study():
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import study_general_acceptance

    return study_general_acceptance


def test_network_717_same_points_sigma0_and_dof_on_both_paths():
    """Before: the distance path left T12 out (spread 6.5 σ), the general layer kept it (its rank
    test finds it determined): σ0 5.7 % apart, dof 8 vs 9. Now both leave it out with the same
    reason and reach the same minimum: σ0 equal to 1e-9 relative (both solvers converge to ~1e-12;
    the study's SIGMA_REL), the same dof."""
    net = _study().network(717)
    d = _quiet(adjust, net.obs, snooping=False, rng=0)
    gnet, opts = network_from_tables(net.obs, rng=0)
    g = _quiet(adjust_network, gnet, options=opts)
    assert [e.id for e in d.excluded] == ["T12"]
    assert [e["id"] for e in g.excluded] == ["T12"]
    assert g.excluded[0]["reason"] == d.excluded[0].reason
    assert "6.5 times" in g.excluded[0]["reason"]
    assert g.result.dof == d.dof == 8
    assert abs(g.result.sigma0 - d.sigma0) <= 1e-9 * d.sigma0
