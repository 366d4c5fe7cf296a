"""Angles as observations in the adjustment (issue 15, item 1 for unlevelled stations).

Independent values, written here without multilat's solver, rotations or Jacobians:

* a second implementation: every unknown in one vector (station and target coordinates, offsets, three
  orientation angles per station with angles), whitened residuals of distances, azimuths (wrapped) and
  elevations written out from their definitions, the exact Jacobian by complex steps (``Im f(x + ih)/h``,
  h = 1e-30: no truncation and no cancellation), scipy's MINPACK Levenberg-Marquardt, a 3-2-1 hold on
  three stations. Datum-free quantities must agree: vᵀPv (1e-9 relative; seen: 8e-12), offsets and
  interpoint distances (1e-9 m), the relative orientation of two stations ``R_aᵀ R_b`` (1e-9);
* the statistics: at multilat's solution the test takes that Jacobian, the null space of the datum
  defects from its SVD (so the orientations' share of a rigid rotation is not taken from multilat), and
  the inner-constraint covariance ``S J⁺ J⁺ᵀ Sᵀ`` over all points; targets' 3x3 blocks, orientations'
  standard uncertainties and the redundancy numbers (``diag R``) of distances and angles must agree to
  1e-9 relative (issue 15's must-show; seen: better than 1e-12);
* noise-free angles and distances: vᵀPv at the rounding floor and the true relative orientations.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.optimize import least_squares

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.model.angles import predicted_angles
from multilat.network.model.data import Observations
from multilat.network.model.datum import helmert_basis
from multilat.network.io.files import write_observations

from angle_networks import SIG_ANGLE, mixed_with_angles as _mixed

def _rot(o):
    """Rz(kappa) Ry(phi) Rx(omega) for one orientation (omega, phi, kappa), written out (complex-safe)."""
    cw, sw, cp, sp, ck, sk = np.cos(o[0]), np.sin(o[0]), np.cos(o[1]), np.sin(o[1]), np.cos(o[2]), np.sin(o[2])
    rx = np.array([[1, 0, 0], [0, cw, -sw], [0, sw, cw]], dtype=o.dtype)
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]], dtype=o.dtype)
    rz = np.array([[ck, -sk, 0], [sk, ck, 0], [0, 0, 1]], dtype=o.dtype)
    return rz @ ry @ rx


def _atan2(y, x):
    """atan2 carried through a complex step: the real angle and, in the imaginary part, its exact
    first-order change (x dy - y dx) / (x² + y²)."""
    a = np.arctan2(y.real, x.real)
    if not np.iscomplexobj(y) and not np.iscomplexobj(x):
        return a
    return a + 1j * (x.real * np.imag(y) - y.real * np.imag(x)) / (x.real ** 2 + y.real ** 2)


def _model(obs, x, oriented):
    """Whitened residuals of the full vector x = [H (3s), T (3t), offsets (s), orientations (3 per
    oriented)]: distances, azimuths (wrapped), elevations — written here from the definitions, not
    with multilat's functions, and safe under a complex step."""
    s, t = obs.n_stations, obs.n_targets
    H = x[:3 * s].reshape(s, 3)
    T = x[3 * s:3 * s + 3 * t].reshape(t, 3)
    off = x[3 * s + 3 * t:4 * s + 3 * t]
    O = np.zeros((s, 3), dtype=x.dtype)
    O[oriented] = x[4 * s + 3 * t:].reshape(-1, 3)
    si, ti = obs.station_index, obs.target_index
    dv = T[ti] - H[si]
    rd = (obs.distance_m - np.sqrt(np.sum(dv * dv, axis=1)) - off[si]) / obs.sigma_m
    R = np.array([_rot(O[i]) for i in range(s)])
    v = np.einsum("mji,mj->mi", R[si], dv)                   # R^T (T - H)
    az = _atan2(v[:, 1], v[:, 0])
    el = _atan2(v[:, 2], np.sqrt(v[:, 0] ** 2 + v[:, 1] ** 2))
    ka = np.isfinite(obs.sigma_azimuth_rad)
    ke = np.isfinite(obs.sigma_elevation_rad)
    da = obs.azimuth_rad[ka] - az[ka]
    da = da - 2 * np.pi * np.round(da.real / (2 * np.pi))    # wrapped to (-pi, pi]
    ra = da / obs.sigma_azimuth_rad[ka]
    re = (obs.elevation_rad[ke] - el[ke]) / obs.sigma_elevation_rad[ke]
    return np.concatenate([rd, ra, re])


def _jac(obs, x, oriented, h=1e-30):
    """The exact Jacobian by complex steps (no subtraction, so no truncation or cancellation error)."""
    J = np.empty((_model(obs, x, oriented).size, x.size))
    for k in range(x.size):
        e = x.astype(complex)
        e[k] += 1j * h
        J[:, k] = _model(obs, e, oriented).imag / h
    return J


def _inner_cov(J, G, E):
    """The inner-constraint covariance ``S J⁺ J⁺ᵀ Sᵀ`` with ``S = I - G (Eᵀ G)⁻¹ Eᵀ`` and the hat
    redundancies ``diag(I - U Uᵀ)``, from J's SVD (not from the squared normal matrix)."""
    U, sv, Vt = np.linalg.svd(J, full_matrices=False)
    r = int(np.sum(sv > sv[0] * 1e-10))
    Jp = Vt[:r].T / sv[:r]
    S = np.eye(J.shape[1]) - G @ np.linalg.solve(E.T @ G, E.T)
    A = S @ Jp
    return A @ A.T, 1.0 - np.sum(U[:, :r] ** 2, axis=1)


def _write_csv(obs, p):
    write_observations(p, obs)


def _pack(H, T, off, O, oriented):
    return np.concatenate([H.ravel(), T.ravel(), off, O[oriented].ravel()])


def _rel(Oa, Ob):
    return _rot(np.asarray(Oa, float)).T @ _rot(np.asarray(Ob, float))


def test_mixed_network_equals_the_independent_solution():
    net, obs, ori = _mixed()
    res = adjust(obs, initial=net, snooping=False)
    oriented = np.zeros(obs.n_stations, bool)
    oriented[[0, 1]] = True
    s, t = obs.n_stations, obs.n_targets
    x0 = _pack(net.station_xyz_m, net.target_xyz_m, net.offset_m, ori, oriented)
    held = np.zeros(x0.size, bool)
    held[[0, 1, 2, 4, 5, 8]] = True               # 3-2-1 on stations 0, 1, 2 (a minimal constraint)

    def fun(y):
        x = x0.copy()
        x[~held] = y
        return _model(obs, x, oriented)

    def jac(y):
        x = x0.copy()
        x[~held] = y
        return _jac(obs, x, oriented)[:, ~held]

    sol = least_squares(fun, x0[~held], jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200)
    x = x0.copy()
    x[~held] = sol.x
    vtpv = float(sol.fun @ sol.fun)
    assert res.sigma0 ** 2 * res.dof == pytest.approx(vtpv, rel=1e-9)
    assert res.dof == obs.n_obs + 2 * int(np.isfinite(obs.sigma_azimuth_rad).sum()) - (4 * s + 3 * t + 6 - 6)
    np.testing.assert_allclose(res.offset_m, x[3 * s + 3 * t:4 * s + 3 * t], atol=1e-9)
    H, T = x[:3 * s].reshape(s, 3), x[3 * s:3 * s + 3 * t].reshape(t, 3)
    for a, b in [(0, 5), (3, 9), (12, 14)]:
        assert np.linalg.norm(res.target_xyz_m[a] - res.target_xyz_m[b]) == pytest.approx(
            np.linalg.norm(T[a] - T[b]), abs=1e-9)
    assert np.linalg.norm(res.station_xyz_m[0] - res.target_xyz_m[4]) == pytest.approx(
        np.linalg.norm(H[0] - T[4]), abs=1e-9)
    Om = np.array([res.orientations[sid]["orientation_rad"] for sid in ("S1", "S2")])
    Oi = x[4 * s + 3 * t:].reshape(-1, 3)
    np.testing.assert_allclose(_rel(Om[0], Om[1]), _rel(Oi[0], Oi[1]), atol=1e-9)


def test_covariance_and_redundancy_equal_the_dense_inner_constraint_solution():
    net, obs, _ = _mixed(seed=5)
    res = adjust(obs, initial=net, snooping=False)
    oriented = np.zeros(obs.n_stations, bool)
    oriented[[0, 1]] = True
    s, t = obs.n_stations, obs.n_targets
    O = np.zeros((s, 3))
    O[oriented] = [res.orientations[sid]["orientation_rad"] for sid in ("S1", "S2")]
    x = _pack(res.station_xyz_m, res.target_xyz_m, res.offset_m, O, oriented)
    J = _jac(obs, x, oriented)
    # the datum defects from the Jacobian itself: its 6 smallest right singular vectors
    _, sv, Vt = np.linalg.svd(J)
    assert sv[-6] < 1e-6 * sv[0] < sv[-7]
    G = Vt[-6:].T
    E = np.zeros((x.size, 6))                      # inner constraints over all points' coordinates
    E[:3 * (s + t)] = helmert_basis(np.vstack([res.station_xyz_m, res.target_xyz_m]))
    C, r = _inner_cov(J, G, E)
    for j in (0, 7, 14):
        blk = C[3 * s + 3 * j:3 * s + 3 * j + 3, 3 * s + 3 * j:3 * s + 3 * j + 3]
        np.testing.assert_allclose(res.target_cov_m2[j], blk, rtol=1e-9, atol=1e-9 * np.abs(blk).max())
    std_o = np.sqrt(np.diag(C)[4 * s + 3 * t:])
    got = np.concatenate([res.orientations[sid]["orientation_std_rad"] for sid in ("S1", "S2")])
    np.testing.assert_allclose(got, std_o, rtol=1e-9)
    np.testing.assert_allclose(res.redundancy, r[:obs.n_obs], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose([a["redundancy"] for a in res.angles], r[obs.n_obs:], rtol=1e-9, atol=1e-12)
    assert float(np.sum(r)) == pytest.approx(res.dof, rel=1e-12)


def test_noise_free_angles_and_distances_fit_exactly():
    net, obs, ori = _mixed(seed=7, noise=False)
    res = adjust(obs, snooping=False)                 # initial values from the distances alone
    assert res.sigma0 < 1e-4
    Om = np.array([res.orientations[sid]["orientation_rad"] for sid in ("S1", "S2")])
    np.testing.assert_allclose(_rel(Om[0], Om[1]), _rel(ori[0], ori[1]), atol=1e-9)
    assert max(abs(a["residual_rad"]) for a in res.angles) < 1e-10


def test_angles_shrink_the_uncertainty_and_the_json_carries_them(tmp_path, capsys):
    net, obs, _ = _mixed(seed=3)
    plain = adjust(Observations(obs.station_ids, obs.target_ids, obs.station_index, obs.target_index,
                                obs.distance_m, obs.sigma_m), initial=net, snooping=False)
    mixed = adjust(obs, initial=net, snooping=False)
    tr_plain = np.trace(plain.target_cov_m2, axis1=1, axis2=2)
    tr_mixed = np.trace(mixed.target_cov_m2, axis1=1, axis2=2)
    assert np.all(tr_mixed <= tr_plain * (1 + 1e-9))          # more observations never hurt
    # the CLI: angle columns with their sigma
    p = tmp_path / "mixed.csv"
    _write_csv(obs, p)
    assert main(["adjust", str(p), "--json", "--no-snooping"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["angles"]) == 2 * int(np.isfinite(obs.sigma_azimuth_rad).sum())
    assert "orientation_std_rad" in doc["stations"]["S1"] and "orientation_rad" not in doc["stations"]["S3"]
    assert doc["sigma0"] == pytest.approx(mixed.sigma0, rel=1e-6)


def test_bad_angle_input_is_one_line(tmp_path, capsys):
    net, obs, _ = _mixed(seed=3)
    with pytest.raises(MultilatError, match="sigma_azimuth_rad of observation S1->T1 must be > 0"):
        Observations(obs.station_ids, obs.target_ids, obs.station_index, obs.target_index, obs.distance_m,
                     obs.sigma_m, obs.azimuth_rad, obs.elevation_rad, None,
                     np.where(np.arange(obs.n_obs) == 0, -1.0, obs.sigma_azimuth_rad), None)
    one = np.full(obs.n_obs, np.nan)
    one[0] = SIG_ANGLE
    bad = Observations(obs.station_ids, obs.target_ids, obs.station_index, obs.target_index, obs.distance_m,
                       obs.sigma_m, obs.azimuth_rad, obs.elevation_rad, None, one, None)
    with pytest.raises(MultilatError, match="station 'S1' has 1 angle observation.* needs at least 3, to 2 targets"):
        adjust(bad, initial=net, snooping=False)
    elev_only = Observations(obs.station_ids, obs.target_ids, obs.station_index, obs.target_index, obs.distance_m,
                             obs.sigma_m, obs.azimuth_rad, obs.elevation_rad, None, None, obs.sigma_elevation_rad,
                             ("S1", "S2"))
    with pytest.raises(MultilatError, match="levelled station 'S1' has no azimuth observation"):
        adjust(elev_only, initial=net, snooping=False)
    with pytest.raises(MultilatError, match="levelled: 'T1' is not a station"):
        Observations(obs.station_ids, obs.target_ids, obs.station_index, obs.target_index, obs.distance_m,
                     obs.sigma_m, levelled=("T1",))
    with pytest.raises(MultilatError, match="datum 321 would tilt"):
        adjust(Observations(obs.station_ids, obs.target_ids, obs.station_index, obs.target_index, obs.distance_m,
                            obs.sigma_m, obs.azimuth_rad, obs.elevation_rad, None, obs.sigma_azimuth_rad,
                            obs.sigma_elevation_rad, ("S1",)), initial=net, datum="321:S3,S4,S5", snooping=False)
    p = tmp_path / "bad.csv"
    p.write_text("station,target,distance_m,sigma_m,azimuth_rad,elevation_rad,sigma_azimuth_rad\n"
                 "A,1,1.0,1e-5,0.1,2.0,1e-5\n")
    assert main(["adjust", str(p)]) == 2
    err = capsys.readouterr().err
    assert "bad.csv:2" in err and "elevation_rad" in err and err.count("\n") == 1


def test_shipped_mixed_example_is_the_generator_output_and_recovers_the_truth(tmp_path, capsys):
    from pathlib import Path
    import importlib.util

    ex = Path(__file__).resolve().parents[1] / "examples" / "network" / "mixed"
    spec = importlib.util.spec_from_file_location("gen_mixed", ex / "generate.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main(tmp_path)
    for f in ("obs.csv", "truth.csv", "offsets_truth.csv", "orientation_truth.csv"):
        assert (tmp_path / f).read_text() == (ex / f).read_text(), f
    from multilat.network.io.files import read_observations

    obs = read_observations(ex / "obs.csv")
    res = adjust(obs)
    assert res.global_test.passed and not res.outliers
    truth_off = dict(ln.split(",") for ln in (ex / "offsets_truth.csv").read_text().splitlines()[1:])
    z = [(res.offset_m[i] - float(truth_off[sid])) / res.offset_std_m[i] for i, sid in enumerate(res.station_ids)]
    assert np.max(np.abs(z)) < 4, z
    rows = [ln.split(",") for ln in (ex / "orientation_truth.csv").read_text().splitlines()[1:]]
    tru = {r[0]: np.array([float(v) for v in r[1:]]) for r in rows}
    est = {k: np.array(v["orientation_rad"]) for k, v in res.orientations.items()}
    D = _rel(est["AT1"], est["AT2"]).T @ _rel(tru["AT1"], tru["AT2"])
    angle = np.arccos(np.clip((np.trace(D) - 1) / 2, -1, 1))
    u = max(max(v["orientation_std_rad"]) for v in res.orientations.values())
    assert angle < 6 * u, (angle, u)
    # the Monte Carlo draws the angles too (tests/test_propagate_general.py checks it against this covariance)
    assert main(["propagate", str(ex / "obs.csv"), "--trials", "500", "--noise", "gaussian", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["solver"] == "batched-coupled"


def test_encoder_angles_on_the_small_volume_predicted_and_by_monte_carlo():
    """Issue 15's must-show: the seed's small volume with the heads' angles at encoder-level σ — the
    first-order uncertainty with angles is below the distances-only one, and the Monte Carlo (angles
    drawn in every trial) agrees with the first order within 4 standard errors in every column."""
    from multilat.report.angles_demo import encoder_angle_study

    st = encoder_angle_study(trials=1000, seed=3)
    se = st["mc_relative_se"]
    for case in ("distances", "distances_and_angles"):
        c = st[case]
        for q in ("target", "interpoint"):
            assert abs(c[f"{q}_std_mc_rms_m"] / c[f"{q}_std_lin_rms_m"] - 1) < 4 * se, (case, q)
    d, a = st["distances"], st["distances_and_angles"]
    assert a["solver"] == "CoupledBatchedNetwork" and d["solver"] == "BatchedNetwork"
    assert a["target_std_lin_rms_m"] < d["target_std_lin_rms_m"]
    assert a["interpoint_std_lin_rms_m"] < d["interpoint_std_lin_rms_m"]


def test_levelled_station_equals_the_independent_solution():
    """Station S1 levelled (its vertical = the world's z: κ only) and S2 with three angles: 4 datum
    defects. Against the full-vector solution (S1's ω, φ held at 0; a's xyz and b's y held): vᵀPv,
    dof, offsets, interpoint distances and — datum-free now that the vertical is observed — height
    differences, to 1e-9 m; the dense inner-constraint covariance (4-vector null space from the SVD)
    for the targets' blocks and the orientations' σ."""
    net, obs0, ori = _mixed(seed=11, noise=False)
    ori = ori.copy()
    ori[0, :2] = 0.0                                   # S1 stands on its level
    o = obs0
    az, el = predicted_angles(net.station_xyz_m, ori, net.target_xyz_m, o.station_index, o.target_index)
    rng = np.random.default_rng(4)
    tr = np.isfinite(o.sigma_azimuth_rad)
    az = az + np.where(tr, rng.normal(0, SIG_ANGLE, az.size), 0.0)
    el = el + np.where(tr, rng.normal(0, SIG_ANGLE, el.size), 0.0)
    d = o.distance_m + rng.normal(0, 1, o.n_obs) * o.sigma_m
    obs = Observations(o.station_ids, o.target_ids, o.station_index, o.target_index, d, o.sigma_m, az, el, None,
                       o.sigma_azimuth_rad, o.sigma_elevation_rad, ("S1",))
    res = adjust(obs, initial=net, snooping=False)
    s, t = obs.n_stations, obs.n_targets
    n_ang = int(np.isfinite(obs.sigma_azimuth_rad).sum()) * 2
    assert res.dof == obs.n_obs + n_ang - (4 * s + 3 * t + 1 + 3) + 4
    oriented = np.zeros(s, bool)
    oriented[[0, 1]] = True
    x0 = _pack(net.station_xyz_m, net.target_xyz_m, net.offset_m, ori, oriented)
    held = np.zeros(x0.size, bool)
    held[[0, 1, 2, 4]] = True                          # station 0 xyz, station 1 y
    e = 4 * s + 3 * t
    held[[e, e + 1]] = True                            # S1's omega, phi
    sol = least_squares(lambda y: _model(obs, np.where(held, x0, 0) + _scatter(y, held), oriented), x0[~held],
                        jac=lambda y: _jac(obs, np.where(held, x0, 0) + _scatter(y, held), oriented)[:, ~held],
                        method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200)
    x = np.where(held, x0, 0) + _scatter(sol.x, held)
    assert res.sigma0 ** 2 * res.dof == pytest.approx(float(sol.fun @ sol.fun), rel=1e-9)
    np.testing.assert_allclose(res.offset_m, x[3 * s + 3 * t:4 * s + 3 * t], atol=1e-9)
    T = x[3 * s:3 * s + 3 * t].reshape(t, 3)
    for a, b in [(0, 5), (3, 9), (12, 14)]:
        assert res.target_xyz_m[a, 2] - res.target_xyz_m[b, 2] == pytest.approx(T[a, 2] - T[b, 2], abs=1e-9)
        assert np.linalg.norm(res.target_xyz_m[a] - res.target_xyz_m[b]) == pytest.approx(
            np.linalg.norm(T[a] - T[b]), abs=1e-9)
    assert res.orientations["S1"]["orientation_rad"][:2] == [0.0, 0.0]
    assert res.orientations["S1"]["orientation_std_rad"][:2] == [0.0, 0.0]
    # covariance: dense inner constraints over all points with the 4 defects
    O = np.zeros((s, 3))
    O[oriented] = [res.orientations[sid]["orientation_rad"] for sid in ("S1", "S2")]
    xm = _pack(res.station_xyz_m, res.target_xyz_m, res.offset_m, O, oriented)
    keep = np.ones(xm.size, bool)
    keep[[e, e + 1]] = False                           # S1's held omega, phi are not unknowns
    J = _jac(obs, xm, oriented)[:, keep]
    _, sv, Vt = np.linalg.svd(J)
    assert sv[-4] < 1e-6 * sv[0] < sv[-5]
    G = Vt[-4:].T
    E = np.zeros((keep.sum(), 4))
    E[:3 * (s + t)] = helmert_basis(np.vstack([res.station_xyz_m, res.target_xyz_m]))[:, [0, 1, 2, 5]]
    C, r = _inner_cov(J, G, E)
    for j in (0, 7, 14):
        blk = C[3 * s + 3 * j:3 * s + 3 * j + 3, 3 * s + 3 * j:3 * s + 3 * j + 3]
        np.testing.assert_allclose(res.target_cov_m2[j], blk, rtol=1e-9, atol=1e-9 * np.abs(blk).max())
    std_o = np.sqrt(np.diag(C)[e:])                    # S1's kappa, S2's omega, phi, kappa
    got = [res.orientations["S1"]["orientation_std_rad"][2], *res.orientations["S2"]["orientation_std_rad"]]
    np.testing.assert_allclose(got, std_o, rtol=1e-9)
    np.testing.assert_allclose(res.redundancy, r[:obs.n_obs], rtol=1e-9, atol=1e-12)


def _scatter(y, held):
    out = np.zeros(held.size)
    out[~held] = y
    return out


def test_cli_levelled_option(tmp_path, capsys):
    net, obs, _ = _mixed(seed=3)
    p = tmp_path / "mixed.csv"
    _write_csv(obs, p)
    assert main(["adjust", str(p), "--json", "--no-snooping"]) == 0
    free = json.loads(capsys.readouterr().out)
    # one levelled station only defines which way is up (its vertical = the frame's z): same fit, same dof
    assert main(["adjust", str(p), "--json", "--no-snooping", "--levelled", "S1"]) == 0
    one = json.loads(capsys.readouterr().out)
    assert one["dof"] == free["dof"] and one["sigma0"] == pytest.approx(free["sigma0"], rel=1e-8)
    assert one["stations"]["S1"]["orientation_rad"][:2] == [0.0, 0.0]
    # S1 and S2 are tilted differently (up to 0.2 rad): both levelled is a wrong model (their verticals
    # disagree), which the global test must show
    assert main(["adjust", str(p), "--json", "--no-snooping", "--levelled", "S1,S2"]) == 0
    lev = json.loads(capsys.readouterr().out)
    assert lev["dof"] == free["dof"] + 2               # 4 orientation unknowns fewer, 2 defects fewer
    assert lev["sigma0"] > 10 * free["sigma0"] and not lev["global_test"]["passed"]
    assert main(["adjust", str(p), "--levelled", "NOPE"]) == 2
    assert "--levelled: unknown station 'NOPE'" in capsys.readouterr().err


def test_angles_on_a_station_declared_distance_only_is_one_line(capsys):
    from pathlib import Path

    ex = Path(__file__).resolve().parents[1] / "examples" / "network" / "mixed" / "obs.csv"
    assert main(["adjust", str(ex), "--distance-only", "H1,H2,AT1"]) == 2
    err = capsys.readouterr().err
    assert "station 'AT1' is declared distance-only" in err and "obs.csv" in err and err.count("\n") == 1
    assert main(["adjust", str(ex), "--distance-only", "H1,H2", "--json"]) == 0
    capsys.readouterr()
