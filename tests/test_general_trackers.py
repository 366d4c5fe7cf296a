"""Laser-tracker networks in the general network, against independent solutions written here
(scipy.optimize.least_squares on closed-form residuals, parametrised without the kinds, the layout
or the datum machinery):

- two levelled trackers (distance, azimuth, elevation each) on 15 common targets, a free network:
  datum defect 4 found from the observations (3 shifts and a turn about the vertical), the
  residuals, σ0, dof and every datum-invariant distance between adjusted points equal the
  independent solution's (which holds tracker 1 and its heading instead);
- one levelled tracker of unknown position and heading on 5 fixed control points and 10 polar
  targets (zero redundancy each): coordinates and their covariance equal the independent ones.

Tolerances: both solvers converge to ~1e-12 m on these 10 m networks; the coordinates are
compared to 1e-9 m, σ0 to 1e-9 relative; the covariance to 1e-6 of its largest element (the
independent one is ``(J^T J)^-1`` from least_squares' 3-point finite-difference Jacobian, good to
~1e-8 relative; measured agreement ~1e-7).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from multilat.errors import MultilatError
from multilat.network.adjust.general.adjust import AdjustOptions, adjust
from multilat.network.model.observations import Block, Network
from multilat.network.model.points import FIXED, FREE, WEIGHTED, PointSet

SIG_D, SIG_A = 20e-6, 5e-6          # metres, radians


def _polar(station, kappa, target):
    d = target - station
    return (np.linalg.norm(d, axis=-1), np.arctan2(d[..., 1], d[..., 0]) - kappa,
            np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1])))


def _simulate(rng, stations, kappas, targets, pairs):
    """Noisy distance, azimuth, elevation for each (station, target) pair."""
    s, t = pairs
    d, az, el = _polar(stations[s], kappas[s], targets[t])
    m = len(s)
    return (d + SIG_D * rng.standard_normal(m), np.angle(np.exp(1j * (az + SIG_A * rng.standard_normal(m)))),
            el + SIG_A * rng.standard_normal(m))


def _blocks(pairs, obs, n_st, offset=False):
    """Distances (of one instrument "I", its additive constant estimated when ``offset``) and
    tracker angles of levelled set-ups T1, T2, ..."""
    s, t = pairs
    m = len(s)
    idx = {"from": s, "to": t + n_st}
    if offset:
        idx["instrument"] = np.zeros(m, int)
    names = {"setup": tuple(f"T{i + 1}" for i in range(n_st))}
    return (Block("slope_distance", obs[0], np.full(m, SIG_D), None, idx, names={"instrument": ("I",)},
                  options={"estimate_offset": offset}),
            Block("tracker_angles", np.concatenate(obs[1:]), np.full(2 * m, SIG_A), None,
                  {"from": np.tile(s, 2), "to": np.tile(t + n_st, 2), "setup": np.tile(s, 2),
                   "component": np.repeat([0, 1], m)}, names=names, options={"levelled": True}))


def _residual(stations, kappas, targets, pairs, obs):
    s, t = pairs
    d, az, el = _polar(stations[s], kappas[s], targets[t])
    return np.concatenate([(obs[0] - d) / SIG_D, np.angle(np.exp(1j * (obs[1] - az))) / SIG_A,
                           (obs[2] - el) / SIG_A])


def test_two_levelled_trackers_free_network():
    rng = np.random.default_rng(20261126)
    stations = np.array([[0.0, 0.0, 0.0], [6.2, 0.4, 0.15]])
    kappas = np.array([0.3, 2.1])
    targets = np.column_stack([rng.uniform(0, 6, 15), rng.uniform(2, 8, 15), rng.uniform(-1, 2, 15)])
    pairs = (np.repeat([0, 1], 15), np.tile(np.arange(15), 2))
    obs = _simulate(rng, stations, kappas, targets, pairs)
    approx = np.vstack([stations, targets]) + 0.003 * rng.standard_normal((17, 3))
    pts = PointSet.build(["T1", "T2"] + [f"P{i:02d}" for i in range(15)], approx)
    res = adjust(Network(pts, _blocks(pairs, obs, 2)), options=AdjustOptions(datum="free"))
    assert res.defect == 4 and res.dof == 90 - (51 + 2) + 4

    def fun(p):          # independent: T1 and its heading held at the truth (another datum)
        st = np.vstack([stations[0], p[:3]])
        return _residual(st, np.array([kappas[0], p[3]]), p[4:].reshape(15, 3), pairs, obs)

    p0 = np.concatenate([approx[1], [kappas[1]], approx[2:].ravel()])
    ind = least_squares(fun, p0, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    xyz_ind = np.vstack([stations[0], ind.x[:3], ind.x[4:].reshape(15, 3)])
    assert res.sigma0 == pytest.approx(np.sqrt(2 * ind.cost / res.dof), rel=1e-9)
    assert np.abs(res.residuals[:30] - fun(ind.x)[:30] * SIG_D).max() < 1e-9
    dist = lambda xyz: np.linalg.norm(xyz[:, None] - xyz[None], axis=-1)   # noqa: E731
    assert np.abs(dist(res.xyz_m) - dist(xyz_ind)).max() < 1e-9
    assert np.abs(res.xyz_m[:, 2] - res.xyz_m[0, 2] - (xyz_ind[:, 2] - xyz_ind[0, 2])).max() < 1e-9  # levelled
    # minimum trace over all points: the sum of the corrections' shifts is zero
    assert np.abs((res.xyz_m - approx).mean(0)).max() < 1e-9


def test_one_tracker_on_control_points():
    rng = np.random.default_rng(7)
    station, kappa = np.array([1.0, 2.0, 0.5]), np.array([-1.2])
    control = station + np.column_stack([rng.uniform(-8, 8, 5), rng.uniform(-8, 8, 5), rng.uniform(-1, 1, 5)])
    targets = station + np.column_stack([rng.uniform(-8, 8, 10), rng.uniform(-8, 8, 10), rng.uniform(-1, 2, 10)])
    allp = np.vstack([control, targets])
    pairs = (np.zeros(15, int), np.arange(15))
    obs = _simulate(rng, station[None], kappa, allp, pairs)
    approx = np.vstack([station + 0.01, control, targets + 0.01 * rng.standard_normal((10, 3))])
    status = [FREE] + [FIXED] * 5 + [FREE] * 10
    pts = PointSet.build(["T"] + [f"K{i}" for i in range(5)] + [f"Q{i}" for i in range(10)], approx, status=status)
    res = adjust(Network(pts, _blocks((pairs[0], pairs[1]), obs, 1)))
    assert res.defect == 0 and res.dof == 45 - (3 + 1 + 30)

    def fun(p):
        return _residual(p[None, :3], p[3:4], np.vstack([control, p[4:].reshape(10, 3)]), pairs, obs)

    ind = least_squares(fun, np.concatenate([approx[0], [0.0], approx[6:].ravel()]), xtol=1e-15, ftol=1e-15,
                        gtol=1e-15, jac="3-point")
    assert np.abs(res.xyz_m[0] - ind.x[:3]).max() < 1e-9
    assert np.abs(res.xyz_m[6:] - ind.x[4:].reshape(10, 3)).max() < 1e-9
    assert res.sigma0 == pytest.approx(np.sqrt(2 * ind.cost / res.dof), rel=1e-9)
    cov_ind = np.linalg.inv(ind.jac.T @ ind.jac)
    order = [res.free_names.index(f"{c}:T") for c in "xyz"] + [res.free_names.index("kappa:T1")] + \
        [res.free_names.index(f"{c}:Q{i}") for i in range(10) for c in "xyz"]
    q = res.cofactor[np.ix_(order, order)]
    assert np.abs(q - cov_ind).max() < 1e-6 * np.abs(cov_ind).max()
    # a polar point is read once: zero redundancy, kept
    assert np.abs(res.redundancy[5:15]).max() < 1e-9


def test_a_target_seen_by_one_distance_is_named():
    """A target with one distance only: undetermined, named in one line (never counted)."""
    rng = np.random.default_rng(3)
    station, kappa = np.array([0.0, 0.0, 0.0]), np.array([0.0])
    control = np.column_stack([rng.uniform(-8, 8, 5), rng.uniform(-8, 8, 5), rng.uniform(-1, 1, 5)])
    pairs = (np.zeros(5, int), np.arange(5))
    obs = _simulate(rng, station[None], kappa, control, pairs)
    pts = PointSet.build(["T"] + [f"K{i}" for i in range(5)] + ["LONE"],
                         np.vstack([station, control, [3.0, 3.0, 0.0]]), status=[FREE] + [FIXED] * 5 + [FREE])
    lone = Block("slope_distance", np.array([4.3]), np.array([SIG_D]), None, {"from": np.array([0]), "to": np.array([6])})
    with pytest.raises(MultilatError, match=r"point 'LONE' not determined by the observations \(datum defect 2"):
        adjust(Network(pts, _blocks(pairs, obs, 1) + (lone,)))


def test_instrument_constant_and_weighted_control():
    """One tracker with an additive constant (0.4 mm, estimated) on weighted control points
    (σ 0.05 mm each coordinate, status WEIGHTED): against least_squares with the constant and the
    control's coordinates as parameters and the control's given values as observations."""
    rng = np.random.default_rng(11)
    station, kappa, c_true = np.array([1.0, 2.0, 0.5]), np.array([0.7]), 0.4e-3
    control = station + np.column_stack([rng.uniform(-8, 8, 6), rng.uniform(-8, 8, 6), rng.uniform(-1, 1, 6)])
    targets = station + np.column_stack([rng.uniform(-8, 8, 8), rng.uniform(-8, 8, 8), rng.uniform(-1, 2, 8)])
    allp = np.vstack([control, targets])
    pairs = (np.zeros(14, int), np.arange(14))
    obs = list(_simulate(rng, station[None], kappa, allp, pairs))
    obs[0] = obs[0] + c_true
    sig_c = 5e-5
    given = control + sig_c * rng.standard_normal(control.shape)
    approx = np.vstack([station + 0.01, given, targets + 0.01 * rng.standard_normal((8, 3))])
    status = [FREE] + [WEIGHTED] * 6 + [FREE] * 8
    sigma = np.where(np.array(status)[:, None] == WEIGHTED, sig_c, np.nan) * np.ones((15, 3))
    pts = PointSet.build(["T"] + [f"K{i}" for i in range(6)] + [f"Q{i}" for i in range(8)], approx, status=status,
                         sigma_m=sigma)
    res = adjust(Network(pts, _blocks(pairs, obs, 1, offset=True)))
    assert res.dof == 14 * 3 + 18 - (3 + 1 + 1 + 18 + 24)

    def fun(p):
        xyz = np.vstack([p[:3], p[5:].reshape(14, 3)])
        r = _residual(xyz[None, 0], p[3:4], xyz[1:], pairs, [obs[0] - p[4], obs[1], obs[2]])
        return np.concatenate([r, ((given - xyz[1:7]) / sig_c).ravel()])

    p0 = np.concatenate([approx[0], [0.0, 0.0], approx[1:].ravel()])
    ind = least_squares(fun, p0, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert res.parameters[res.names.index("offset:I")] == pytest.approx(ind.x[4], abs=1e-10)
    assert np.abs(res.xyz_m - np.vstack([ind.x[:3], ind.x[5:].reshape(14, 3)])).max() < 1e-9
    assert res.sigma0 == pytest.approx(np.sqrt(2 * ind.cost / res.dof), rel=1e-9)
