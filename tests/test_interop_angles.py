"""Directions and zenith angles through GNU Gama (issue 15's outside check of the angle adjustment).

A mixed network (six stations, fifteen targets, distances from all, azimuths and elevations from two
*levelled* trackers at 20 µrad) is exported with ``gama_local_text`` (directions counter-clockwise
under ``angles="right-handed"``, zenith angles, slope distances; offsets fixed at zero in both
programs, distances rounded to the file's 1e-8 m before either sees them) and adjusted by gama-local
1.18b, a separate least-squares program with its own model of directions (one orientation unknown
per ``<obs>`` cluster) and zenith angles, and its own free-network datum (4 defects found by its SVD).

Against our adjustment (tolerance; seen): dof 79 and defect 4 exactly; σ0 (1e-7, Gama prints 8
digits; 2.9e-9); 105 interpoint distances and height differences of the targets (1e-11 m; 2.3e-13 m);
residuals of 84 distances (1e-12 m; 3.5e-14 m) and 56 angles (1e-12 rad; 1.1e-13 rad); redundancy
numbers from the adjusted observations' σ (1e-7; 3.9e-9); the difference of the two stations'
orientations (datum-free; 2e-8 rad as Gama prints 1e-6 gon; 5.5e-9 rad); their σ and the σ of all
interpoint distances from Gama's covariance (1e-6 relative, 8 digits printed; 2.1e-8); Gama's
standardised residuals against |w| (1e-3, 3 decimals printed; 4.9e-4).

The stored output (tests/data/interop/levelled_mixed_gama_out.xml) is gama-local's run on this
export; when ``gama-local`` is on PATH the export is adjusted again live.
"""

import itertools
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.model.angles import predicted_angles
from multilat.network.model.data import Observations, Points
from multilat.network.synthetic.generator import synthetic_network
from multilat.network.io.interop.gama import gama_local_text, write_gama_local
from multilat.network.io.interop.gama_adjusted import read_gama_adjustment

STORED = Path(__file__).resolve().parent / "data" / "interop" / "levelled_mixed_gama_out.xml"
SIG_ANGLE = 20e-6


def _levelled_mixed(levelled=("S1", "S2")):
    net = synthetic_network(np.random.default_rng([15, 11]), n_stations=(6, 6), n_targets=(15, 15))
    o = net.obs
    rng = np.random.default_rng(11)
    ori = np.zeros((o.n_stations, 3))
    ori[:, 2] = rng.uniform(-3, 3, o.n_stations)
    az, el = predicted_angles(net.station_xyz_m, ori, net.target_xyz_m, o.station_index, o.target_index)
    tr = np.isin(o.station_index, [0, 1])
    s = np.where(tr, SIG_ANGLE, np.nan)
    az = az + np.where(tr, rng.normal(0, SIG_ANGLE, az.size), 0.0)
    el = el + np.where(tr, rng.normal(0, SIG_ANGLE, el.size), 0.0)
    d = np.linalg.norm(net.station_xyz_m[o.station_index] - net.target_xyz_m[o.target_index], axis=1)
    d = np.round(d + rng.normal(0, 1, o.n_obs) * o.sigma_m, 8)          # as the file carries them
    obs = Observations(o.station_ids, o.target_ids, o.station_index, o.target_index, d, o.sigma_m, az, el,
                       None, s, s, levelled)
    zero = {sid: 0.0 for sid in o.station_ids}
    res = adjust(obs, initial=net, snooping=False, offsets=zero)
    pts = Points(res.station_ids + res.target_ids, np.vstack([res.station_xyz_m, res.target_xyz_m]))
    return obs, pts, res, zero


@pytest.fixture(scope="module")
def mixed():
    return _levelled_mixed()


def _compare(g, obs, res):
    assert g.dof == res.dof and g.defect == 4
    assert g.sigma_aposteriori == pytest.approx(res.sigma0, rel=1e-7)
    P = g.points().as_dict()
    for a, b in itertools.combinations(res.target_ids, 2):
        assert np.linalg.norm(P[a] - P[b]) == pytest.approx(np.linalg.norm(res.xyz(a) - res.xyz(b)), abs=1e-11)
        assert P[a][2] - P[b][2] == pytest.approx(res.xyz(a)[2] - res.xyz(b)[2], abs=1e-11)
    urel = max(abs(g.interpoint_distance_std_m(a, b) / res.interpoint_distance(a, b).u_m - 1)
               for a, b in itertools.combinations(res.target_ids, 2))
    assert urel < 1e-6, urel
    key = {res.obs.label(k): k for k in range(res.obs.n_obs)}
    idx = [key[f"{s}->{t}"] for s, t in zip(g.station, g.target)]
    assert np.abs(g.residual_m - res.residuals_m[idx]).max() < 1e-12
    np.testing.assert_allclose(g.redundancy_from_sigma(res.obs.sigma_m[idx]), res.redundancy[idx], atol=1e-7)
    # the angles: Gama's zenith angle is pi/2 minus our elevation (its residual the negative of ours)
    ours = {(a["station"], a["target"], a["kind"]): a for a in res.angles}
    ga = g.angles
    assert len(ga.kind) == len(ours) == 2 * int(np.isfinite(obs.sigma_azimuth_rad).sum())
    for q in range(len(ga.kind)):
        a = ours[(ga.station[q], ga.target[q], "azimuth" if ga.kind[q] == "azimuth" else "elevation")]
        sign = 1.0 if ga.kind[q] == "azimuth" else -1.0
        assert sign * ga.residual_rad[q] == pytest.approx(a["residual_rad"], abs=1e-12)
        assert ga.redundancy_from_sigma(a["sigma_rad"])[q] == pytest.approx(a["redundancy"], abs=1e-7)
        assert ga.std_residual[q] == pytest.approx(abs(a["w"]), abs=1e-3)
    # orientations: Gama's orientation of a direction set is our kappa (directions = bearing - it)
    k1, k2 = (res.orientations[s]["orientation_rad"][2] for s in ("S1", "S2"))
    dk = (g.orientation_rad["S1"] - g.orientation_rad["S2"]) - (k1 - k2)
    assert abs((dk + np.pi) % (2 * np.pi) - np.pi) < 2e-8      # 6 decimals of gon printed: ±7.9e-9 rad each
    for s in ("S1", "S2"):
        assert g.orientation_std_rad[s] == pytest.approx(res.orientations[s]["orientation_std_rad"][2], rel=1e-6)


def test_gama_adjustment_of_directions_and_zenith_angles_equals_ours(mixed):
    obs, _, res, _ = mixed
    _compare(read_gama_adjustment(STORED), obs, res)


@pytest.mark.skipif(shutil.which("gama-local") is None, reason="gama-local not installed "
                    "(no Debian package; build GNU Gama from source to run this)")
def test_gama_local_live_on_the_levelled_export(mixed, tmp_path):
    obs, pts, res, zero = mixed
    write_gama_local(tmp_path / "in.xml", obs, pts, offsets=zero)
    r = subprocess.run(["gama-local", str(tmp_path / "in.xml"), "--xml", str(tmp_path / "out.xml")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-500:]
    _compare(read_gama_adjustment(tmp_path / "out.xml"), obs, res)


def test_export_writes_directions_in_gons_and_sigma_in_cc(mixed):
    obs, pts, _, zero = mixed
    text = gama_local_text(obs, pts, offsets=zero)
    k = int(np.flatnonzero(np.isfinite(obs.sigma_azimuth_rad))[0])
    line = next(ln for ln in text.splitlines() if "<direction" in ln)
    assert f'to="{obs.target_ids[obs.target_index[k]]}"' in line
    val = float(line.split('val="')[1].split('"')[0])
    assert val == pytest.approx((obs.azimuth_rad[k] % (2 * np.pi)) * 200 / np.pi, abs=1e-11)
    assert float(line.split('stdev="')[1].split('"')[0]) == pytest.approx(SIG_ANGLE * 200 / np.pi * 1e4)
    zline = next(ln for ln in text.splitlines() if "<z-angle" in ln)
    assert float(zline.split('val="')[1].split('"')[0]) == pytest.approx(
        (np.pi / 2 - obs.elevation_rad[k]) * 200 / np.pi, abs=1e-11)


def test_export_refuses_angles_of_a_station_that_is_not_levelled(mixed):
    obs, pts, _, zero = mixed
    import dataclasses

    tilted = dataclasses.replace(obs, levelled=("S1",))
    with pytest.raises(MultilatError, match=r"station 'S2' reads angles .* not levelled.*--levelled S2"):
        gama_local_text(tilted, pts, offsets=zero)


# ------------------------------------------------------------------------------ through the CLI
def _csv(obs, tmp_path):
    from multilat.network.io.files import write_observations

    p = tmp_path / "mixed.csv"
    write_observations(p, obs)
    return p


def test_cli_round_trip_export_import_adjust_keeps_the_angles(mixed, tmp_path, capsys):
    """export gama --levelled -> import gama -> adjust: the same network and the same adjustment
    (angles as azimuths and elevations of the same rows, the stations levelled again)."""
    obs, pts, res, _ = mixed
    p = _csv(obs, tmp_path)
    pts_csv = tmp_path / "pts.csv"
    pts_csv.write_text("point,x_m,y_m,z_m\n" + "".join(f"{i},{x!r},{y!r},{z!r}\n" for i, (x, y, z)
                                                       in zip(pts.ids, pts.xyz_m.tolist())))
    assert main(["export", "gama", str(p), "--points", str(pts_csv), "--offsets-um", "0", "--levelled",
                 "S1,S2", "-o", str(tmp_path / "net.xml"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["n_angles"] == 2 * int(np.isfinite(obs.sigma_azimuth_rad).sum())
    assert main(["import", "gama", str(tmp_path / "net.xml"), "-o", str(tmp_path / "imp"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["levelled"] == ["S1", "S2"] and doc["n_angles"] > 0
    from multilat.network.io.files import read_observations

    back = read_observations(tmp_path / "imp" / "distances.csv")
    k = np.isfinite(obs.sigma_azimuth_rad)
    np.testing.assert_allclose(back.distance_m, obs.distance_m, atol=1e-8)
    np.testing.assert_allclose(np.isfinite(back.sigma_azimuth_rad), k)
    da = (back.azimuth_rad[k] - obs.azimuth_rad[k] + np.pi) % (2 * np.pi) - np.pi
    assert np.abs(da).max() < 1e-13                          # 12 decimals of gon
    np.testing.assert_allclose(back.elevation_rad[k], obs.elevation_rad[k], atol=1e-13)
    np.testing.assert_allclose(back.sigma_elevation_rad[k], SIG_ANGLE, rtol=1e-9)
    assert main(["adjust", str(tmp_path / "imp" / "distances.csv"), "--points", str(tmp_path / "imp" / "points.csv"),
                 "--levelled", "S1,S2", "--fix-offsets-um", "0", "--json"]) == 0
    adj = json.loads(capsys.readouterr().out)
    assert adj["dof"] == res.dof and adj["sigma0"] == pytest.approx(res.sigma0, rel=1e-7)


def test_cli_imports_gama_adjusted_angles(tmp_path, capsys):
    assert main(["import", "gama-adjusted", str(STORED), "-o", str(tmp_path / "g"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["n_angles"] == 56 and set(doc["stations"]) == {"S1", "S2"}
    rows = (tmp_path / "g" / "angle_residuals.csv").read_text().splitlines()
    assert rows[0] == "station,target,kind,value_rad,adjusted_rad,residual_rad,adjusted_std_rad,w_abs"
    assert len(rows) == 57


def test_left_handed_directions_read_as_the_same_azimuths(mixed, tmp_path):
    """Gama's default sense (clockwise seen from above) is read negated, whatever the axes: the
    same file with x/y swapped (axes-xy="ne"), directions negated and angles="left-handed" — which
    gama-local adjusts to the same σ0 — gives the same azimuths up to each station's constant."""
    import re

    from multilat.network.io.interop.gama import read_gama_local

    obs, pts, _, zero = mixed
    text = gama_local_text(obs, pts, offsets=zero)
    flipped = re.sub(r'(<direction [^>]*val=")([0-9.]+)"', lambda m: f'{m.group(1)}{(400 - float(m.group(2))) % 400:.12f}"',
                     text).replace('angles="right-handed"', 'angles="left-handed"').replace('axes-xy="en"', 'axes-xy="ne"')
    flipped = re.sub(r'x="([-0-9.]+)" y="([-0-9.]+)"', lambda m: f'x="{m.group(2)}" y="{m.group(1)}"', flipped)
    (tmp_path / "a.xml").write_text(text)
    (tmp_path / "b.xml").write_text(flipped)
    a, b = read_gama_local(tmp_path / "a.xml"), read_gama_local(tmp_path / "b.xml")
    np.testing.assert_allclose(a.points.xyz_m, b.points.xyz_m, atol=1e-12)
    k = np.isfinite(a.obs.sigma_azimuth_rad)
    d = (a.obs.azimuth_rad[k] - b.obs.azimuth_rad[k] + np.pi) % (2 * np.pi) - np.pi
    assert np.abs(d).max() < 1e-12
    if shutil.which("gama-local"):
        s0 = []
        for n in ("a", "b"):
            subprocess.run(["gama-local", str(tmp_path / f"{n}.xml"), "--xml", str(tmp_path / f"{n}.out")],
                           capture_output=True, timeout=120, check=True)
            s0.append(read_gama_adjustment(tmp_path / f"{n}.out").sigma_aposteriori)
        assert s0[0] == s0[1]


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace('<z-angle to="T1"', '<z-angle to="T1" from_dh="0.1"', 1),
     r"<z-angle> S1->T1 from_dh=0.1 is not supported"),
    (lambda t: t.replace('stdev="12.732395447" />', "/>", 1), r"<direction> S1->T1 has no stdev"),
    (lambda t: t.replace('<z-angle to="T1" val="', '<z-angle to="T1" val="2', 1), r"outside 0\.\.200 gon"),
    (lambda t: t.replace('<s-distance to="T1" val', '<s-distance to="T1" vol', 1)
     .replace('<s-distance to="T1" vol="', '<!-- ', 1).replace('" stdev="0.0050000" />', ' -->', 1),
     r"direction S1->T1 has no slope distance"),
    (lambda t: t.replace('  <direction to="T2"', '</obs>\n<obs from="S1">\n  <direction to="T2"', 1),
     r"station 'S1' has directions in a second <obs> set"),
    (lambda t: re.sub(r'(<direction [^>]*val=")[0-9.]+', r'\g<1>221-29-47.x', t, count=1), r"is not d-m-s"),
])
def test_bad_gama_angles_are_one_line_errors(mixed, tmp_path, edit, message):
    from multilat.network.io.interop.gama import read_gama_local

    obs, pts, _, zero = mixed
    text = edit(gama_local_text(obs, pts, offsets=zero))
    p = tmp_path / "bad.xml"
    p.write_text(text)
    with pytest.raises(MultilatError, match=r"bad\.xml:\d+: .*" + message):
        read_gama_local(p)


def test_dms_directions_take_their_sigma_in_arc_seconds(mixed, tmp_path):
    from multilat.network.io.interop.gama import read_gama_local

    obs, pts, _, zero = mixed
    text = gama_local_text(obs, pts, offsets=zero)
    line = next(ln for ln in text.splitlines() if "<direction" in ln)
    new = re.sub(r'val="[0-9.]+" stdev="[0-9.]+"', 'val="-10-30-36" stdev="4.125"', line)
    p = tmp_path / "dms.xml"
    p.write_text(text.replace(line, new).replace('angles="right-handed"', 'angles="right-handed"'))
    net = read_gama_local(p)
    k = int(np.flatnonzero(np.isfinite(net.obs.sigma_azimuth_rad))[0])
    assert net.obs.azimuth_rad[k] == pytest.approx(-np.radians(10 + 30 / 60 + 36 / 3600), abs=1e-15)
    assert net.obs.sigma_azimuth_rad[k] == pytest.approx(np.radians(4.125 / 3600), rel=1e-14)


def test_export_of_angles_to_a_format_without_them_is_one_line(mixed, tmp_path, capsys):
    obs, pts, _, _ = mixed
    p = _csv(obs, tmp_path)
    assert main(["export", "starnet", str(p), "-o", str(tmp_path / "x.dat"), "--offsets-um", "0"]) != 0
    err = capsys.readouterr().err.strip()
    assert "starnet: station 'S1' reads angles" in err and "not levelled" in err and len(err.splitlines()) == 1
    pts_csv = tmp_path / "pts.csv"
    pts_csv.write_text("point,x_m,y_m,z_m\n" + "".join(f"{i},{x!r},{y!r},{z!r}\n" for i, (x, y, z)
                                                       in zip(pts.ids, pts.xyz_m.tolist())))
    assert main(["export", "gama", str(p), "-o", str(tmp_path / "x.xml"), "--offsets-um", "0",
                 "--points", str(pts_csv)]) != 0
    err = capsys.readouterr().err.strip()
    assert "station 'S1' reads angles" in err and "--levelled S1" in err and len(err.splitlines()) == 1
