"""Scale bars and weighted control as observations (issue 16 item 2).

Independent check: a second, plain implementation written here — every unknown in one vector,
distances, scale bars ``(|X_a - X_b| - L) / u`` and control coordinates ``(X - x0) / s`` as rows,
scipy's MINPACK Levenberg-Marquardt with an analytic Jacobian, covariance ``(JᵀJ)⁻¹`` — against
``adjust``'s coupled path (all targets eliminated at once). Tolerances as in test_network_heads:
values 1e-9 m (both at the float64 floor, MINPACK's stopping rule), uncertainties 1e-6 relative.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.optimize import least_squares

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.model.data import Points, ReferenceLengths
from multilat.network.io.files import read_points, read_reference_lengths
from multilat.network.synthetic.generator import synthetic_network


def _independent(obs, start, *, bars=(), control=(), hard=(), scale_heads=(), fix_321=True):
    """Full-vector least squares. ``bars``: (a, b, L, u); ``control``: (id, xyz, std) weighted;
    ``hard``: (id, xyz) held. With ``fix_321`` the first three stations carry a 3-2-1 minimal
    constraint at their ``start`` values. Returns dict of per-head offsets, scales, points (id -> xyz),
    vtpv, the covariance and a function giving the gradient of a length in the free parameters."""
    s, t = obs.n_stations, obs.n_targets
    ids = list(obs.station_ids + obs.target_ids)
    heads = list(obs.head_ids)
    hi = obs.head_index
    X0 = np.vstack([start.station_xyz_m, start.target_xyz_m]).copy()
    held = np.zeros((s + t, 3), bool)
    if fix_321:
        held[0, :], held[1, 1:], held[2, 2] = True, True, True
    for pid, xyz in hard:
        X0[ids.index(pid)] = xyz
        held[ids.index(pid)] = True
    nx = int((~held).sum())
    hsc = [heads.index(h) for h in scale_heads]
    nh = len(heads)

    def unpack(x):
        X = X0.copy()
        X[~held] = x[:nx]
        off = x[nx:nx + nh]
        k = np.zeros(nh)
        k[hsc] = x[nx + nh:]
        return X, off, k

    si, ti = obs.station_index, obs.target_index
    bar_ij = [(ids.index(a), ids.index(b)) for a, b, _, _ in bars]
    ctrl_i = [ids.index(pid) for pid, _, _ in control]

    def fun(x):
        X, off, k = unpack(x)
        rho = np.linalg.norm(X[si] - X[s + ti], axis=1)
        r = [((1 + k[hi[si]]) * rho + off[hi[si]] - obs.distance_m) / obs.sigma_m]
        r.append(np.array([(np.linalg.norm(X[i] - X[j]) - L) / u for (i, j), (_, _, L, u) in zip(bar_ij, bars)]))
        r.append(np.concatenate([(X[i] - np.asarray(x0)) / np.asarray(sd) for i, (_, x0, sd) in
                                 zip(ctrl_i, control)]) if control else np.zeros(0))
        return np.concatenate(r)

    col = -np.ones((s + t, 3), int)
    col[~held] = np.arange(nx)

    def jac(x):
        X, off, k = unpack(x)
        m = obs.n_obs
        J = np.zeros((m + len(bars) + 3 * len(control), x.size))
        d = X[si] - X[s + ti]
        rho = np.linalg.norm(d, axis=1)
        u = d / rho[:, None]
        g = (1 + k[hi[si]])[:, None] * u / obs.sigma_m[:, None]
        for r in range(m):
            for c in range(3):
                if col[si[r], c] >= 0:
                    J[r, col[si[r], c]] += g[r, c]
                if col[s + ti[r], c] >= 0:
                    J[r, col[s + ti[r], c]] -= g[r, c]
            J[r, nx + hi[si[r]]] = 1 / obs.sigma_m[r]
            if hi[si[r]] in hsc:
                J[r, nx + nh + hsc.index(hi[si[r]])] = rho[r] / obs.sigma_m[r]
        for q, ((i, j), (_, _, L, uu)) in enumerate(zip(bar_ij, bars)):
            e = (X[i] - X[j]) / np.linalg.norm(X[i] - X[j])
            for c in range(3):
                if col[i, c] >= 0:
                    J[m + q, col[i, c]] += e[c] / uu
                if col[j, c] >= 0:
                    J[m + q, col[j, c]] -= e[c] / uu
        for q, (i, (_, _, sd)) in enumerate(zip(ctrl_i, control)):
            for c in range(3):
                if col[i, c] >= 0:
                    J[m + len(bars) + 3 * q + c, col[i, c]] = 1 / sd[c]
        return J

    x0 = np.concatenate([X0[~held] + np.random.default_rng(3).normal(0, 1e-4, nx), np.zeros(nh),
                         np.zeros(len(hsc))])
    sol = least_squares(fun, x0, jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=20000)
    X, off, k = unpack(sol.x)
    Jf = jac(sol.x)
    cov = np.linalg.inv(Jf.T @ Jf)

    def u_length(a, b):
        i, j = ids.index(a), ids.index(b)
        e = (X[i] - X[j]) / np.linalg.norm(X[i] - X[j])
        gv = np.zeros(sol.x.size)
        for c in range(3):
            if col[i, c] >= 0:
                gv[col[i, c]] += e[c]
            if col[j, c] >= 0:
                gv[col[j, c]] -= e[c]
        return float(np.sqrt(gv @ cov @ gv))

    def xyz_cov(pid):
        i = ids.index(pid)
        c = col[i]
        return cov[np.ix_(c, c)]

    return dict(off=off, k=k, X=dict(zip(ids, X)), vtpv=float(sol.fun @ sol.fun), u_length=u_length,
                xyz_cov=xyz_cov)


def _bars(pairs, net, u, rng):
    ids = list(net.obs.target_ids)
    L = [float(np.linalg.norm(net.target_xyz_m[ids.index(a)] - net.target_xyz_m[ids.index(b)]))
         + rng.normal(0, u) for a, b in pairs]
    return ReferenceLengths(tuple(a for a, _ in pairs), tuple(b for _, b in pairs), L, np.full(len(pairs), u))


def test_scales_per_head_with_scale_bars_as_the_scale_datum():
    """Two heads over 8 stations, both heads' scales estimated (the 7th defect), three scale bars
    (2 µm) as observations: equal to the independent full-vector solution."""
    net = synthetic_network(np.random.default_rng([16, 2]), population="sequential")
    rng = np.random.default_rng(7)
    pairs = [("P1", "P2"), ("P3", "P7"), ("P5", "P11")]
    bars = _bars(pairs, net, 2e-6, rng)
    with pytest.raises(MultilatError, match="7th"):
        adjust(net.obs, initial=net, scales=True)
    r = adjust(net.obs, initial=net, scales=True, scale_bars=bars, snooping=False)
    assert r.solver == "dense" and r.scale_estimated.all()
    ind = _independent(net.obs, net, bars=[(a, b, L, 2e-6) for (a, b), L in zip(pairs, bars.length_m)],
                       scale_heads=("T1", "T2"))
    h = r.heads()
    np.testing.assert_allclose([h["T1"]["offset_m"], h["T2"]["offset_m"]], ind["off"], atol=1e-9)
    np.testing.assert_allclose([h["T1"]["scale"], h["T2"]["scale"]], ind["k"], atol=1e-11)
    assert r.sigma0 ** 2 * r.dof == pytest.approx(ind["vtpv"], rel=1e-8)
    o = net.obs
    assert r.dof == o.n_obs + 3 - (3 * (o.n_stations + o.n_targets) - 6 + 2 + 2)
    for a, b in [("P1", "P2"), ("S1", "P9"), ("P4", "P14"), ("S2", "S7")]:
        ip = r.interpoint_distance(a, b)
        assert ip.length_m == pytest.approx(np.linalg.norm(ind["X"][a] - ind["X"][b]), abs=1e-9)
        assert ip.u_m == pytest.approx(ind["u_length"](a, b), rel=1e-6)
    # the bars' residuals and redundancy numbers; Σ redundancy over every observation = dof
    assert len(r.scale_bars) == 3
    for q, (a, b) in enumerate(pairs):
        adj = np.linalg.norm(ind["X"][a] - ind["X"][b])
        assert r.scale_bars[q]["adjusted_m"] == pytest.approx(adj, abs=1e-9)
    total = float(np.sum(r.redundancy)) + sum(x["redundancy"] for x in r.scale_bars)
    assert total == pytest.approx(r.dof, abs=1e-8)


def test_scale_bars_without_scales_are_extra_observations():
    """Bars also add to a network whose scale is known (no scales): dof + 2, vtpv as the independent."""
    net = synthetic_network(np.random.default_rng([2024, 5]))
    t = net.obs.target_ids
    pairs = [(t[0], t[1]), (t[2], t[3])]
    bars = _bars(pairs, net, 3e-6, np.random.default_rng(1))
    r0 = adjust(net.obs, initial=net, snooping=False)
    r = adjust(net.obs, initial=net, scale_bars=bars, snooping=False)
    assert r.dof == r0.dof + 2
    ind = _independent(net.obs, net, bars=[(a, b, L, 3e-6) for (a, b), L in zip(pairs, bars.length_m)])
    assert r.sigma0 ** 2 * r.dof == pytest.approx(ind["vtpv"], rel=1e-8)
    np.testing.assert_allclose(r.offset_m, ind["off"], atol=1e-9)
    # sparse cannot couple targets: refused in one line, auto takes dense
    with pytest.raises(MultilatError, match="sparse solver does not handle scale bars"):
        adjust(net.obs, initial=net, scale_bars=bars, solver="sparse")


def test_weighted_and_hard_control_match_the_independent_solution():
    """Control datum: 2 hard control targets and 3 weighted ones (sx, sy, sz = 20, 30, 10 µm): the
    coordinates themselves (the control fixes the frame) and their covariance."""
    net = synthetic_network(np.random.default_rng([2024, 8]))
    tid = net.obs.target_ids
    tj = lambda p: net.target_xyz_m[tid.index(p)]  # noqa: E731
    rng = np.random.default_rng(11)
    sd = np.array([20e-6, 30e-6, 10e-6])
    weighted = [(p, tj(p) + rng.normal(0, sd), sd) for p in tid[2:5]]
    hard = [(p, tj(p)) for p in tid[:2]]
    pts = Points(tuple(p for p, _ in hard) + tuple(p for p, _, _ in weighted),
                 np.vstack([x for _, x in hard] + [x for _, x, _ in weighted]),
                 np.vstack([np.full((2, 3), np.nan)] + [sd] * 3))
    r = adjust(net.obs, initial=net, points=pts, datum="control", snooping=False)
    ind = _independent(net.obs, net, control=weighted, hard=hard, fix_321=False)
    for p in (tid[3], tid[7], net.obs.station_ids[1]):
        assert np.max(np.abs(r.xyz(p) - ind["X"][p])) < 1e-9
    j = tid.index(tid[7])
    np.testing.assert_allclose(r.target_cov_m2[j], ind["xyz_cov"](tid[7]), rtol=1e-6, atol=1e-18)
    assert r.sigma0 ** 2 * r.dof == pytest.approx(ind["vtpv"], rel=1e-8)
    # hard ones held exactly, weighted ones adjusted, with residuals reported
    assert np.array_equal(r.xyz(tid[0]), hard[0][1])
    assert len(r.weighted_control) == 3 and r.weighted_control[0]["point"] == tid[2]
    np.testing.assert_allclose(r.weighted_control[0]["residual_m"], weighted[0][1] - r.xyz(tid[2]), atol=1e-15)
    total = float(np.sum(r.redundancy)) + sum(sum(c["redundancy"]) for c in r.weighted_control)
    assert total == pytest.approx(r.dof, abs=1e-8)


def test_only_weighted_control_gives_the_datum():
    net = synthetic_network(np.random.default_rng([2024, 9]))
    tid = net.obs.target_ids
    sd = np.full(3, 50e-6)
    rng = np.random.default_rng(2)
    ctrl = [(p, net.target_xyz_m[tid.index(p)] + rng.normal(0, sd), sd) for p in tid[:4]]
    pts = Points(tuple(p for p, _, _ in ctrl), np.vstack([x for _, x, _ in ctrl]), np.vstack([sd] * 4))
    r = adjust(net.obs, initial=net, points=pts, datum="control", snooping=False)
    ind = _independent(net.obs, net, control=ctrl, fix_321=False)
    assert np.max(np.abs(r.station_xyz_m - np.array([ind["X"][s] for s in r.station_ids]))) < 1e-9


# ------------------------------------------------------------------ files and CLI
def test_bad_input_names_the_row(tmp_path, capsys):
    p = tmp_path / "pts.csv"
    p.write_text("point,x_m,y_m,z_m,sx_m,sy_m,sz_m\nA,0,0,0,,,\nB,1,0,0,1e-5,0,1e-5\n")
    with pytest.raises(MultilatError, match=r"pts\.csv:3: column 'sy_m': a control point's standard uncertainty "
                                            r"must be > 0, got 0\.0"):
        read_points(p)
    p.write_text("point,x_m,y_m,z_m,sx_m,sy_m,sz_m\nA,0,0,0,1e-5,,\n")
    with pytest.raises(MultilatError, match=r"pts\.csv:2: point 'A': give sx_m, sy_m and sz_m"):
        read_points(p)
    from pathlib import Path

    ex = Path(__file__).resolve().parents[1] / "examples" / "network" / "sequential"
    bars = tmp_path / "bars.csv"
    bars.write_text("target_a,target_b,length_m,u_m\nP1,P2,0.5,2e-6\nP3,Q9,0.4,2e-6\n")
    rc = main(["adjust", str(ex / "obs.csv"), "--references", str(bars), "--scale-bars"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc != 0 and err[-1].endswith("bars.csv:3: unknown point id 'Q9'") and len(err) == 1
    bars.write_text("target_a,target_b,length_m,u_m\nP1,P2,0.5,2e-6\nP3,P4,0.4,\n")
    rc = main(["adjust", str(ex / "obs.csv"), "--references", str(bars), "--scale-bars"])
    err = capsys.readouterr().err
    assert rc != 0 and "bars.csv:3: a scale bar needs its standard uncertainty u_m > 0" in err
    refs = read_reference_lengths(bars)
    assert len(refs) == 2


def test_cli_scale_bars_with_scales_on_the_sequential_example(tmp_path, capsys):
    from pathlib import Path

    ex = Path(__file__).resolve().parents[1] / "examples" / "network" / "sequential"
    truth = read_points(ex / "truth.csv")
    bars = tmp_path / "bars.csv"
    L = np.linalg.norm(truth.get("P1") - truth.get("P2"))
    bars.write_text(f"target_a,target_b,length_m,u_m\nP1,P2,{L:.9f},2e-6\n")
    rc = main(["adjust", str(ex / "obs.csv"), "--scales", "--references", str(bars), "--scale-bars", "--json"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    doc = json.loads(out.out)
    assert doc["heads"]["T1"]["scale_estimated"] and doc["heads"]["T2"]["scale_estimated"]
    assert doc["scale_bars"][0]["residual_m"] == pytest.approx(0.0, abs=1e-12)     # one bar: zero redundancy
    assert doc["initial"]["scale_datum"]["kind"] == "scale bars"


def test_weighted_control_on_stations_with_shared_heads():
    """Weighted control on three stations (each 30 µm) of a sequential network whose heads occupy
    several stations: the stations' coordinates, the head offsets and vᵀPv as the independent."""
    net = synthetic_network(np.random.default_rng([16, 4]), population="sequential")
    sid = net.obs.station_ids
    sd = np.full(3, 30e-6)
    rng = np.random.default_rng(4)
    ctrl = [(p, net.station_xyz_m[sid.index(p)] + rng.normal(0, sd), sd) for p in ("S1", "S4", "S6")]
    pts = Points(tuple(p for p, _, _ in ctrl), np.vstack([x for _, x, _ in ctrl]), np.vstack([sd] * 3))
    r = adjust(net.obs, initial=net, points=pts, datum="control", snooping=False)
    ind = _independent(net.obs, net, control=ctrl, fix_321=False)
    assert np.max(np.abs(r.station_xyz_m - np.array([ind["X"][s] for s in sid]))) < 1e-9
    h = r.heads()
    np.testing.assert_allclose([h["T1"]["offset_m"], h["T2"]["offset_m"]], ind["off"], atol=1e-9)
    assert r.sigma0 ** 2 * r.dof == pytest.approx(ind["vtpv"], rel=1e-8)
