"""Scales need a datum of their own (issue 10 item 6): with every station's scale estimated the
network's scale is a 7th defect; a reference length fixes it (the scale datum), or a held scale."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import least_squares

from multilat.cli.app import main
from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.model.data import ReferenceLengths
from multilat.network.io.files import read_observations, read_reference_lengths

EX = Path(__file__).resolve().parents[1] / "examples" / "network"
OBS, REF = EX / "small_volume_obs.csv", EX / "small_volume_refs.csv"


def _bar(k=0):
    refs = read_reference_lengths(REF)
    return ReferenceLengths(refs.target_a[k:k + 1], refs.target_b[k:k + 1], refs.length_m[k:k + 1],
                            refs.u_m[k:k + 1])


def _independent(obs, bar, x0):
    """A second method: every parameter at once (stations, targets, offsets, scales), the bar as one
    more observation, the rigid defect fixed 3-2-1 on the first three stations; scipy's
    least_squares (Levenberg-Marquardt, MINPACK) and the covariance (J^T J)^-1 of the free
    parameters with J by central differences."""
    s, t = obs.n_stations, obs.n_targets
    si, ti = obs.station_index, obs.target_index
    ids = obs.station_ids + obs.target_ids
    ia, ib = ids.index(bar.target_a[0]), ids.index(bar.target_b[0])
    free = np.ones(3 * (s + t), bool)
    free[[0, 1, 2, 4, 5, 8]] = False            # 3-2-1 on stations 0, 1, 2 (their own frame)
    pts0 = x0[: 3 * (s + t)].copy()

    def unpack(p):
        pts = pts0.copy()
        pts[free] = p[: free.sum()]
        rest = p[free.sum():]
        return pts.reshape(-1, 3), rest[:s], rest[s:]

    def fun(p):
        pts, off, k = unpack(p)
        rho = np.linalg.norm(pts[si] - pts[s + ti], axis=1)
        r = ((1 + k[si]) * rho + off[si] - obs.distance_m) / obs.sigma_m
        L = np.linalg.norm(pts[ia] - pts[ib])
        return np.append(r, (L - bar.length_m[0]) / bar.u_m[0])

    p0 = np.concatenate([pts0[free], x0[3 * (s + t):]])
    sol = least_squares(fun, p0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=20000)
    # central differences at the solution (least_squares' own Jacobian is forward-difference, ~1e-7)
    J = np.empty((sol.fun.size, sol.x.size))
    for q in range(sol.x.size):
        h = 1e-6 if q < free.sum() else 1e-8
        e = np.zeros(sol.x.size)
        e[q] = h
        J[:, q] = (fun(sol.x + e) - fun(sol.x - e)) / (2 * h)
    cov = np.linalg.inv(J.T @ J)
    return unpack(sol.x), sol, cov, free


def test_scales_with_a_scale_bar_equal_an_independent_solution():
    obs = read_observations(OBS)
    bar = _bar(0)
    res = adjust(obs, scales=True, scale_bar=bar, snooping=False, datum="321:A,B,C")
    assert res.dof == 1                          # 56 distances, 42 + 12 - 6 + 4 offsets + 4 scales - 1
    assert res.scale_estimated.all() and res.initial["scale_datum"]["points"] == ["1", "2"]
    # start the second method near (1 mm) the solution
    s = obs.n_stations
    x0 = np.concatenate([res.station_xyz_m.ravel(), res.target_xyz_m.ravel(), res.offset_m, res.scale])
    x0 = x0 + np.random.default_rng(0).normal(0, 1e-3, x0.size) * np.r_[np.ones(x0.size - s), np.zeros(s)]
    (pts, off, k), sol, cov, free = _independent(obs, bar, x0)
    np.testing.assert_allclose(off, res.offset_m, atol=1e-10)
    np.testing.assert_allclose(k, res.scale, atol=1e-11)
    vtpv = float(np.sum(sol.fun ** 2))
    assert res.sigma0 ** 2 * res.dof == pytest.approx(vtpv, rel=1e-6)
    # datum-free: interpoint distances and their uncertainties (the bar's own u included)
    ids = obs.station_ids + obs.target_ids
    ours = np.vstack([res.station_xyz_m, res.target_xyz_m])
    nfree = int(free.sum())
    for a, b in [("1", "2"), ("3", "9"), ("A", "14"), ("5", "12")]:
        i, j = ids.index(a), ids.index(b)
        assert np.linalg.norm(pts[i] - pts[j]) == pytest.approx(np.linalg.norm(ours[i] - ours[j]), abs=1e-10)
        # gradient of the length in the second method's free parameters
        g = np.zeros(3 * len(ids))
        u = (pts[i] - pts[j]) / np.linalg.norm(pts[i] - pts[j])
        g[3 * i:3 * i + 3], g[3 * j:3 * j + 3] = u, -u
        gf = np.concatenate([g[free], np.zeros(cov.shape[0] - nfree)])
        u_indep = float(np.sqrt(gf @ cov @ gf))
        assert res.interpoint_distance(a, b).u_m == pytest.approx(u_indep, rel=1e-6)
    # the bar itself: its adjusted length is the reference and its uncertainty the reference's
    ip = res.interpoint_distance("1", "2")
    assert ip.length_m == pytest.approx(bar.length_m[0], abs=1e-12)
    assert ip.u_m == pytest.approx(bar.u_m[0], rel=1e-6)
    cov_scale = res.global_cov[4::5, 4::5]
    np.testing.assert_allclose(np.sqrt(np.diag(cov_scale)), res.scale_std)


def test_scales_without_a_scale_datum_are_refused_in_one_line(capsys):
    obs = read_observations(OBS)
    with pytest.raises(MultilatError, match="7th datum defect"):
        adjust(obs, scales=True)
    rc = main(["adjust", str(OBS), "--scales"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len([ln for ln in err if ln.startswith("error:")]) == 1
    assert "7th datum defect" in err[-1] and "--scale-bar" in err[-1]


def test_scale_bar_and_fixed_scale_from_the_cli(capsys, tmp_path):
    one = tmp_path / "bar.csv"
    lines = REF.read_text().splitlines()
    head = [ln for ln in lines if ln.startswith("target_a")][0]
    row = [ln for ln in lines if ln and not ln.startswith("#") and not ln.startswith("target_a")][0]
    one.write_text(head + "\n" + row + "\n")
    rc = main(["adjust", str(OBS), "--scales", "--references", str(one), "--scale-bar", "--json"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    doc = json.loads(out.out)
    assert all("scale" in v for v in doc["stations"].values())
    assert doc["initial"]["scale_datum"]["kind"] == "scale bars"
    assert doc["reference_lengths"][0]["difference_m"] == pytest.approx(0.0, abs=1e-12)
    assert doc["scale_bars"][0]["redundancy"] == pytest.approx(0.0, abs=1e-9)     # one bar: the datum
    # several reference lengths: all are scale-bar observations (issue 16), with redundancy
    rc = main(["adjust", str(OBS), "--scales", "--references", str(REF), "--scale-bars", "--json"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    doc = json.loads(out.out)
    assert len(doc["scale_bars"]) == 9 and doc["initial"]["scale_datum"]["n_bars"] == 9
    # a held scale on one station is the scale datum too; the others are estimated
    rc = main(["adjust", str(OBS), "--scales", "--fixed-scale", "A", "--json"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    doc = json.loads(out.out)
    assert "scale" not in doc["stations"]["A"] and all("scale" in doc["stations"][k] for k in "BCD")
    rc = main(["adjust", str(OBS), "--fixed-scale", "Z", "--scales"])
    assert rc == 2 and "--fixed-scale" in capsys.readouterr().err
