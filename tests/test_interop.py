"""``multilat export`` / ``multilat import``: GNU Gama (gama-local XML in, adjusted XML out),
JAG3D flat files, Star*Net .dat.

Independent values: the round trips compare with the CSV inputs themselves (to the printed
precision, 1e-8 m for distances and coordinates, 1e-10 m for σ); the Gama output is gama-local's
own adjustment (GNU Gama 1.18b and 2.24, a separate least-squares program) of our export, compared
with our adjustment; when ``gama-local`` is on PATH the export is adjusted again live. The export
against Gama's schema: tests/test_interop_gama_schema.py.
"""

import itertools
import re
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.model.data import Points
from multilat.network.io.files import read_observations, read_points
from multilat.network.io.interop.gama_adjusted import read_gama_adjustment
from multilat.network.io.interop.gama import (gama_local_text, read_gama_local,
                                           write_gama_local)
from multilat.network.io.interop.jag3d import read_jag3d, write_jag3d
from multilat.network.io.interop.starnet import read_starnet, starnet_text, write_starnet

EX = Path(__file__).resolve().parents[1] / "examples" / "network"
OBS = EX / "small_volume_obs.csv"
PTS = EX / "small_volume_points.csv"
DATA = Path(__file__).resolve().parent / "data" / "interop"
GAMA_OUT = DATA / "small_volume_gama_out.xml"                  # gama-local 1.18b, the former export
GAMA_OUT_224 = DATA / "small_volume_gama224_out.xml"          # gama-local 2.24, the current export
GAMA_OUT_POST = DATA / "small_volume_gama224_aposteriori_out.xml"  # the same, sigma-apr 10, aposteriori

D_TOL = 1e-8     # the formats' printed precision of distances and coordinates (8 decimals of m)
S_TOL = 1e-10    # printed precision of σ (10 decimals of m; Gama: 7 decimals of mm)


@pytest.fixture(scope="module")
def net():
    obs = read_observations(OBS)
    pts = read_points(PTS)
    res = adjust(obs, points=pts)
    return obs, pts, res


def _by_pair(obs):
    return {(obs.station_ids[obs.station_index[k]], obs.target_ids[obs.target_index[k]]):
            (obs.distance_m[k], obs.sigma_m[k]) for k in range(obs.n_obs)}


def _same_network(a, b, pts, got_pts, d_tol=D_TOL):
    pa, pb = _by_pair(a), _by_pair(b)
    assert set(pa) == set(pb)
    assert a.station_ids == b.station_ids
    dd = max(abs(pa[k][0] - pb[k][0]) for k in pa)
    ds = max(abs(pa[k][1] - pb[k][1]) for k in pa)
    assert dd <= d_tol and ds <= S_TOL, (dd, ds)
    for i, x in zip(pts.ids, pts.xyz_m):
        np.testing.assert_allclose(got_pts.get(i), x, atol=D_TOL, rtol=0)


def _offsets(res):
    return {s: float(o) for s, o in zip(res.station_ids, res.offset_m)}


# ------------------------------------------------------------------------------ round trips
def test_gama_round_trip_restores_the_fixed_offsets(net, tmp_path):
    obs, pts, res = net
    p = tmp_path / "net.xml"
    write_gama_local(p, obs, pts, offsets=_offsets(res))
    got = read_gama_local(p)
    # d - o written with 8 decimals, o with 10: the sum is back to within one printed unit
    _same_network(obs, got.obs, pts, got.points, d_tol=D_TOL / 2 + 1e-10)
    assert got.fixed == () and "restored" in got.notes[0]


def test_gama_without_our_offsets_line_reads_the_corrected_distances(net, tmp_path):
    obs, pts, res = net
    o = _offsets(res)
    text = gama_local_text(obs, pts, offsets=o).replace("multilat-offsets-m:", "offsets were:")
    p = tmp_path / "other.xml"
    p.write_text(text)
    got = _by_pair(read_gama_local(p).obs)
    for (s, t), (d, _) in _by_pair(obs).items():
        assert abs(got[(s, t)][0] - (d - o[s])) <= D_TOL / 2


def test_gama_refuses_offsets_to_be_estimated(net):
    obs, pts, _ = net
    with pytest.raises(MultilatError, match="no additive constant per instrument"):
        gama_local_text(obs, pts, offsets=None)


def test_jag3d_round_trip_keeps_offsets_as_group_parameters(net, tmp_path):
    obs, pts, _ = net
    write_jag3d(tmp_path / "p.txt", tmp_path / "sd.txt", obs, pts)   # offsets estimated in JAG3D
    text = (tmp_path / "sd.txt").read_text()
    assert "zero point offset" in text
    got = read_jag3d(tmp_path / "p.txt", tmp_path / "sd.txt")
    _same_network(obs, got.obs, pts, got.points)
    # JAG3D's own rule: a 4th number < 1 is σ; one line per distance, grouped by station
    rows = [ln.split() for ln in text.splitlines() if ln and not ln.startswith("#")]
    assert len(rows) == obs.n_obs and all(len(r) == 4 and float(r[3]) < 1 for r in rows)
    assert [r[0] for r in rows] == sorted((r[0] for r in rows), key=obs.station_ids.index)


def test_starnet_round_trip_with_fixed_points(net, tmp_path):
    obs, pts, res = net
    p = tmp_path / "net.dat"
    write_starnet(p, obs, pts, offsets=_offsets(res), fixed=("A", "B", "C"))
    got = read_starnet(p)
    _same_network(obs, got.obs, pts, got.points, d_tol=D_TOL / 2 + 1e-10)
    assert got.fixed == ("A", "B", "C")


def test_starnet_reader_order_units_and_sigma_default(tmp_path):
    p = tmp_path / "n.dat"
    p.write_text(".3D\n.UNITS FeetUS\nC A 10 20 30 ! ! !  'north first (default NE)\n"
                 "C T1 1 2 3\n.ORDER EN\nC T2 5 6 7 * * *\n"
                 "D A-T1 100.0 0.01   # feet\nD A-T2 50.0 &\n")
    got = read_starnet(p, sigma_m=2e-3)
    ft = 1200 / 3937
    np.testing.assert_allclose(got.points.get("A"), np.array([20, 10, 30]) * ft, rtol=1e-15)
    np.testing.assert_allclose(got.points.get("T2"), np.array([5, 6, 7]) * ft, rtol=1e-15)
    pr = _by_pair(got.obs)
    assert pr[("A", "T1")] == pytest.approx((100 * ft, 0.01 * ft), rel=1e-15)
    assert pr[("A", "T2")] == pytest.approx((50 * ft, 2e-3), rel=1e-15)
    assert got.fixed == ("A",)


def test_jag3d_reader_follows_jag3d_field_rules(tmp_path):
    (tmp_path / "p.txt").write_text("A 0 0 0\nT1;1;0;0\nT2 0 1 0 0.001\n")
    (tmp_path / "o.txt").write_text("# comment\nA T1 1.0001 0.00001\nA T2 0 0 1.0002\n"
                                    "A T3 1.5 2.0\n")
    with pytest.raises(MultilatError, match=r"o\.txt:4: unknown point 'T3'"):
        read_jag3d(tmp_path / "p.txt", tmp_path / "o.txt", sigma_m=1e-5)
    (tmp_path / "o.txt").write_text("A T1 1.0001 0.00001\nA T2 0 0 1.0002 5.0\n")
    with pytest.raises(MultilatError, match=r"o\.txt:2: distance A->T2 has no σ"):
        read_jag3d(tmp_path / "p.txt", tmp_path / "o.txt")     # 5.0 >= 1: a distance, not a σ
    got = read_jag3d(tmp_path / "p.txt", tmp_path / "o.txt", sigma_m=3e-5)
    assert _by_pair(got.obs) == {("A", "T1"): (1.0001, 1e-5), ("A", "T2"): (1.0002, 3e-5)}
    assert "point σ ignored" in got.notes[0]
    (tmp_path / "o.txt").write_text("A T1 1.5 0.1 1.0001 0.00001\n")
    with pytest.raises(MultilatError, match=r"o\.txt:1: instrument/target heights"):
        read_jag3d(tmp_path / "p.txt", tmp_path / "o.txt")


# ------------------------------------------------------------------------------ Gama's adjustment
def _compare_with_gama(g, obs, pts, res):
    """gama-local's result (offsets fixed at ours) against our adjustment: datum-free quantities."""
    fixed = adjust(obs, points=pts, offsets=_offsets(res))
    # Same minimum: vᵀPv equal; Gama's dof = ours + 4 (the offsets are not unknowns there)
    assert g.dof == fixed.dof == res.dof + obs.n_stations
    assert g.defect == 6
    assert g.sigma_aposteriori == pytest.approx(fixed.sigma0, rel=1e-6)
    assert g.sigma_aposteriori ** 2 * g.dof == pytest.approx(res.sigma0 ** 2 * res.dof, rel=1e-6)
    P = g.points().as_dict()
    dmax = max(abs(np.linalg.norm(P[a] - P[b]) - np.linalg.norm(res.xyz(a) - res.xyz(b)))
               for a, b in itertools.combinations(res.target_ids, 2))
    assert dmax < 1e-8, dmax          # interpoint distances of targets, to 0.01 µm
    # their standard uncertainties from Gama's full covariance (a-priori σ, offsets fixed in both)
    urel = max(abs(g.interpoint_distance_std_m(a, b) / fixed.interpoint_distance(a, b).u_m - 1)
               for a, b in itertools.combinations(res.target_ids, 2))
    assert urel < 1e-6, urel
    key = {fixed.obs.label(k): k for k in range(fixed.obs.n_obs)}
    idx = [key[f"{s}->{t}"] for s, t in zip(g.station, g.target)]
    assert np.abs(g.residual_m - fixed.residuals_m[idx]).max() < 1e-9           # residuals
    np.testing.assert_allclose(g.redundancy_from_sigma(fixed.obs.sigma_m[idx]),
                               fixed.redundancy[idx], atol=1e-6)                # from σ_adj
    np.testing.assert_allclose(g.redundancy, fixed.redundancy[idx], atol=3e-5)  # from f (3 dec.)
    assert np.nanmax(np.abs(g.std_residual - np.abs(fixed.w[idx]))) < 1e-3      # 3 decimals
    return dmax


@pytest.mark.parametrize("stored", [GAMA_OUT, GAMA_OUT_224], ids=["1.18b", "2.24"])
def test_gama_adjusted_output_equals_our_adjustment(net, stored):
    """gama-local's own adjustment of our export (tests/data/interop, made by
    `multilat export gama OBS --result DIR` then `gama-local X --xml OUT`): 1.18b with the former
    export (update-constrained-coordinates="yes"), 2.24 with the current one."""
    obs, pts, res = net
    g = read_gama_adjustment(stored)
    _compare_with_gama(g, obs, pts, res)


def test_redundancy_from_sigma_honours_sigma_act_and_sigma_apr(net):
    """The same export adjusted by gama-local 2.24 with its defaults sigma-apr="10" and
    sigma-act="aposteriori" (σ_adj scaled by σ0/σ_apr = 0.848): the redundancy numbers from σ_adj and
    the inputs' σ equal those from Gama's printed f (3 decimals of a percent: |Δr| <= 2(1-f/100)·5e-6,
    tolerance 1.1e-5) and ours; read as a-priori σ they were up to 0.28 off (1 - 0.848² of 1 - r)."""
    obs, pts, res = net
    g = read_gama_adjustment(GAMA_OUT_POST)
    assert g.sigma_used == "aposteriori" and g.sigma_apriori == 10.0
    assert g.sigma_ratio == pytest.approx(10.0 / 8.4778742, rel=1e-12)
    fixed = adjust(obs, points=pts, offsets=_offsets(res))
    key = {fixed.obs.label(k): k for k in range(fixed.obs.n_obs)}
    idx = [key[f"{s}->{t}"] for s, t in zip(g.station, g.target)]
    r = g.redundancy_from_sigma(fixed.obs.sigma_m[idx])
    assert np.abs(r - g.redundancy).max() < 1.1e-5
    assert np.abs(r - fixed.redundancy[idx]).max() < 1e-6      # σ_adj printed with 8 digits
    apriori_reading = 1 - (g.adjusted_std_m / fixed.obs.sigma_m[idx]) ** 2
    assert np.abs(apriori_reading - g.redundancy).max() > 0.1


def test_gama_local_2_24_on_the_mixed_example_exported_with_levelled_trackers():
    """examples/network/mixed exported with `--levelled AT1,AT2 --result DIR` (DIR: `adjust --levelled
    AT1,AT2`) and adjusted by gama-local 2.24 (tests/data/interop/mixed_levelled_*). Its trackers are
    tilted by ~0.01 rad, so the levelled model misfits (σ0 366 in both programs): a check that both
    find the same least-squares minimum of the same model, offsets fixed at the file's values and no
    data snooping. dof exactly; σ0 to 1e-6 (8 digits printed; seen 1.2e-7); target distances to
    1 µm (Gama stops when its linearisation test passes, residuals ~366 σ: seen 0.28 µm); the
    difference of the two orientations to 2e-7 rad (seen 5.5e-8)."""
    from multilat.cli.network_cmd import with_levelled

    text = (DATA / "mixed_levelled_export.xml").read_text()
    off = {k: float(v) for k, v in re.findall(r"(\w+)=([-0-9.]+)", text.split("multilat-offsets-m:")[1].splitlines()[0])}
    imp = read_gama_local(DATA / "mixed_levelled_export.xml")
    obs = with_levelled(read_observations(EX / "mixed" / "obs.csv"), "AT1,AT2")
    np.testing.assert_allclose(imp.obs.distance_m, obs.distance_m, atol=1e-8)
    with pytest.warns(UserWarning, match="sigma0 366"):          # the misfit is named, as it should be
        res = adjust(obs, points=imp.points, snooping=False, offsets=off)
    g = read_gama_adjustment(DATA / "mixed_levelled_gama224_out.xml")
    assert g.dof == res.dof == 82
    assert g.sigma_aposteriori == pytest.approx(res.sigma0, rel=1e-6)
    P = g.points().as_dict()
    dmax = max(abs(np.linalg.norm(P[a] - P[b]) - np.linalg.norm(res.xyz(a) - res.xyz(b)))
               for a, b in itertools.combinations(res.target_ids, 2))
    assert dmax < 1e-6, dmax
    k1, k2 = (res.orientations[s]["orientation_rad"][2] for s in ("AT1", "AT2"))
    dk = (g.orientation_rad["AT1"] - g.orientation_rad["AT2"]) - (k1 - k2)
    assert abs((dk + np.pi) % (2 * np.pi) - np.pi) < 2e-7


@pytest.mark.skipif(shutil.which("gama-local") is None, reason="gama-local not installed "
                    "(no Debian package; build GNU Gama from source to run this)")
def test_gama_local_live_on_our_export(net, tmp_path):
    obs, pts, res = net
    adj = Points(res.station_ids + res.target_ids, np.vstack([res.station_xyz_m, res.target_xyz_m]))
    write_gama_local(tmp_path / "in.xml", obs, adj, offsets=_offsets(res))
    r = subprocess.run(["gama-local", str(tmp_path / "in.xml"), "--xml", str(tmp_path / "out.xml")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-500:]
    _compare_with_gama(read_gama_adjustment(tmp_path / "out.xml"), obs, pts, res)


@pytest.mark.skipif(shutil.which("gama-local") is None, reason="gama-local not installed")
def test_gama_local_live_from_approximate_coordinates(net, tmp_path):
    """From the example's approximate coordinates (~5 mm off) gama-local iterates its
    linearisation itself; it stops when its own linearisation test passes, not at full
    convergence: measured 0.04 µm on interpoint distances and 0.1 % on σ0 (tolerances 0.2 µm,
    1 %), against 1e-9 m from our adjusted coordinates above."""
    obs, pts, res = net
    write_gama_local(tmp_path / "in.xml", obs, pts, offsets=_offsets(res))
    r = subprocess.run(["gama-local", str(tmp_path / "in.xml"), "--xml", str(tmp_path / "out.xml")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-500:]
    g = read_gama_adjustment(tmp_path / "out.xml")
    P = g.points().as_dict()
    dmax = max(abs(np.linalg.norm(P[a] - P[b]) - np.linalg.norm(res.xyz(a) - res.xyz(b)))
               for a, b in itertools.combinations(res.target_ids, 2))
    assert dmax < 2e-7, dmax
    assert g.sigma_aposteriori ** 2 * g.dof == pytest.approx(res.sigma0 ** 2 * res.dof, rel=1e-2)


# ------------------------------------------------------------------------------ bad input
def test_malformed_xml_names_file_and_line(tmp_path):
    p = tmp_path / "bad.xml"
    p.write_text('<?xml version="1.0"?>\n<gama-local>\n<network>\n<point id="A" x="1"\n</network>')
    with pytest.raises(MultilatError, match=r"bad\.xml:5: malformed XML"):
        read_gama_local(p)


def test_unknown_point_names_file_and_line(net, tmp_path):
    obs, pts, res = net
    text = gama_local_text(obs, pts, offsets=0.0)
    lines = text.splitlines()
    k = next(i for i, ln in enumerate(lines) if 's-distance to="7"' in ln)
    lines[k] = lines[k].replace('to="7"', 'to="77"')
    p = tmp_path / "u.xml"
    p.write_text("\n".join(lines))
    with pytest.raises(MultilatError, match=rf"u\.xml:{k + 1}: unknown point '77' in an observation"):
        read_gama_local(p)
    d = starnet_text(obs, pts, offsets=0.0).splitlines()
    k = next(i for i, ln in enumerate(d) if ln.startswith("D B-3 "))
    d[k] = d[k].replace("D B-3 ", "D B-X3 ")
    (tmp_path / "u.dat").write_text("\n".join(d))
    with pytest.raises(MultilatError, match=rf"u\.dat:{k + 1}: unknown point 'X3'"):
        read_starnet(tmp_path / "u.dat")


@pytest.mark.parametrize("element, named", [
    ('<angle bs="1" fs="2" val="12.3456" stdev="10"/>', "<angle> (horizontal angles)"),
    ('<distance to="1" val="0.5" stdev="1"/>', "<distance> (horizontal distances)"),
    ('<azimuth to="1" val="100" stdev="10"/>', "<azimuth> (azimuths)"),
])
def test_gama_unsupported_observation_refused_by_type(net, tmp_path, element, named):
    obs, pts, _ = net
    text = gama_local_text(obs, pts, offsets=0.0)
    lines = text.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith('<obs from="C">'))
    lines.insert(k + 1, element)
    p = tmp_path / "t.xml"
    p.write_text("\n".join(lines))
    with pytest.raises(MultilatError, match=rf"t\.xml:{k + 2}: {re.escape(named)} is not supported"):
        read_gama_local(p)


def test_gama_adjusted_output_with_horizontal_distances_refused(tmp_path):
    text = GAMA_OUT.read_text()
    text = text.replace("<slope-distance>", "<distance>", 1).replace("</slope-distance>", "</distance>", 1)
    p = tmp_path / "o.xml"
    p.write_text(text)
    line = text[:text.index("<distance>")].count("\n") + 1
    with pytest.raises(MultilatError, match=rf"o\.xml:{line}: <distance> observations are not supported: "
                       "multilat reads slope distances, directions and zenith angles"):
        read_gama_adjustment(p)


@pytest.mark.parametrize("line, named", [
    ("M A-1-2 90-00-00 0.5 90-00-00", "'M' lines (all measurements to another station)"),
    ("A A-1-2 90-00-00", "'A' lines (horizontal angles)"),
    (".2D", ".2D mode is not supported"),
    (".SCALE 1.0001", "inline option .SCALE is not supported"),
])
def test_starnet_unsupported_refused_by_type(tmp_path, line, named):
    p = tmp_path / "s.dat"
    p.write_text(f".3D\nC A 0 0 0 ! ! !\nC 1 1 0 0\n{line}\nD A-1 1.0 0.001\n")
    with pytest.raises(MultilatError, match=rf"s\.dat:4: .*{re.escape(named)}"):
        read_starnet(p)


def test_starnet_refuses_heights_horizontal_and_partial_fix(tmp_path):
    p = tmp_path / "s.dat"
    for body, msg in [("D A-1 1.0 0.001 1.5/1.6", "HI/HT"),
                      (".DELTA ON\nD A-1 1.0 0.001", "horizontal distance"),
                      ("C B 0 0 0 ! ! *", "partly fixed")]:
        p.write_text(f"C A 0 0 0 ! ! !\nC 1 1 0 0\n{body}\n")
        with pytest.raises(MultilatError, match=rf"s\.dat:\d+: .*{msg}"):
            read_starnet(p)


# ------------------------------------------------------------------------------ CLI
def _run(capsys, args):
    rc = main([str(a) for a in args])
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_cli_export_import_round_trip(capsys, tmp_path):
    for fmt in ("jag3d", "starnet", "gama"):
        out = tmp_path / f"net.{fmt}"
        extra = ["--offsets-um", "1234"] if fmt != "jag3d" else []
        rc, o, e = _run(capsys, ["export", fmt, OBS, "--points", PTS, "-o", out, "--json", *extra])
        assert rc == 0, e
        doc = json.loads(o)
        assert doc["n_obs"] == 56 and doc["offsets_subtracted"] == (fmt != "jag3d")
        args = ["import", fmt, out, "-o", tmp_path / f"imp-{fmt}"]
        if fmt == "jag3d":
            args += ["--points-file", tmp_path / f"net-points.{fmt}"]
        rc, o, e = _run(capsys, args)
        assert rc == 0, e
        back = read_observations(tmp_path / f"imp-{fmt}" / "distances.csv")
        _same_network(read_observations(OBS), back, read_points(PTS),
                      read_points(tmp_path / f"imp-{fmt}" / "points.csv"), d_tol=D_TOL)


def test_cli_import_gama_adjusted(capsys, tmp_path):
    rc, o, e = _run(capsys, ["import", "gama-adjusted", GAMA_OUT, "-o", tmp_path / "g", "--json"])
    assert rc == 0, e
    doc = json.loads(o)
    assert doc["dof"] == 8 and doc["n_obs"] == 56
    assert (tmp_path / "g" / "residuals.csv").exists() and (tmp_path / "g" / "points.csv").exists()


def test_cli_errors_are_one_line(capsys, tmp_path):
    rc, o, e = _run(capsys, ["export", "gama", OBS, "--points", PTS, "-o", tmp_path / "x.xml"])
    assert rc == 2 and e.count("\n") == 1 and "no additive constant per instrument" in e
    assert not (tmp_path / "x.xml").exists()
    bad = tmp_path / "bad.xml"
    bad.write_text("<gama-local><network>")
    rc, o, e = _run(capsys, ["import", "gama", bad, "-o", tmp_path / "i"])
    assert rc == 2 and e.count("\n") == 1 and "bad.xml:1: malformed XML" in e
    assert not (tmp_path / "i").exists()
    rc, o, e = _run(capsys, ["export", "gama-xml", OBS, "-o", tmp_path / "y"])
    assert rc == 2 and "export FORMAT must be one of gama, jag3d, starnet" in e


def test_xml_with_a_dtd_is_refused(tmp_path):
    p = tmp_path / "lol.xml"
    p.write_text('<?xml version="1.0"?>\n<!DOCTYPE lolz [<!ENTITY lol "lol"><!ENTITY lol2 '
                 '"&lol;&lol;&lol;&lol;">]>\n<gama-local>&lol2;</gama-local>\n')
    with pytest.raises(MultilatError, match=r"lol\.xml:2: XML with a DTD"):
        read_gama_local(p)


def test_gama_fixed_points_and_2d_points(net, tmp_path):
    obs, pts, res = net
    p = tmp_path / "f.xml"
    write_gama_local(p, obs, pts, offsets=_offsets(res), fixed=("B", "D", "C"))
    assert read_gama_local(p).fixed == ("B", "C", "D")           # file order (stations first)
    text = p.read_text().replace('<point id="7" x="0.52100000" y="0.69500000" z="0.38190000"',
                                 '<point id="7" x="0.52100000" y="0.69500000"')
    assert text != p.read_text()
    p.write_text(text)
    with pytest.raises(MultilatError, match=r"f\.xml:\d+: point '7' has some of x, y, z but not all"):
        read_gama_local(p)


def test_starnet_end_and_data_off(tmp_path):
    p = tmp_path / "e.dat"
    p.write_text("C A 0 0 0 ! ! !\nC 1 1 0 0\nC 2 0 1 0\n.DATA OFF\nD A-2 9.0 0.001\n.DATA ON\n"
                 "D A-1 1.0 0.001\n.END\nM this is not read\n")
    got = read_starnet(p)
    assert _by_pair(got.obs) == {("A", "1"): (1.0, 0.001)}


def test_cli_fix_and_control_note(capsys, tmp_path):
    rc, o, e = _run(capsys, ["export", "starnet", OBS, "--points", PTS, "--offsets-um", "0",
                             "--fix", "A,B,C", "-o", tmp_path / "n.dat"])
    assert rc == 0, e
    rc, o, e = _run(capsys, ["import", "starnet", tmp_path / "n.dat", "-o", tmp_path / "i"])
    assert rc == 0 and "--datum control:A,B,C" in o
    rc, o, e = _run(capsys, ["export", "jag3d", OBS, "--points", PTS, "--fix", "A",
                             "-o", tmp_path / "j.txt"])
    assert rc == 2 and "point type" in e


def test_cli_result_dir_gives_coordinates_and_offsets(capsys, tmp_path, net):
    obs, pts, res = net
    rc, o, e = _run(capsys, ["adjust", OBS, "--points", PTS, "--out", tmp_path / "adj"])
    assert rc == 0, e
    for fmt in ("gama", "jag3d"):
        rc, o, e = _run(capsys, ["export", fmt, OBS, "--result", tmp_path / "adj",
                                 "-o", tmp_path / f"r.{fmt}", "--json"])
        assert rc == 0, e
        assert json.loads(o)["offsets_subtracted"] == (fmt == "gama")   # JAG3D estimates them
    g = read_gama_local(tmp_path / "r.gama")        # offsets restored from the description
    _same_network(obs, g.obs, Points(res.station_ids + res.target_ids,
                                     np.vstack([res.station_xyz_m, res.target_xyz_m])),
                  g.points, d_tol=D_TOL / 2 + 1e-10)
    text = (tmp_path / "r.gama").read_text()
    o = _offsets(res)
    assert f"A={o['A']:.10f}" in text
