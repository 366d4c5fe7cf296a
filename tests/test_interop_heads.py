"""Round trips multilat -> GNU Gama / JAG3D / Star*Net -> multilat keep the model (issue 28).

Before: the ``head`` column was lost in all three formats, so the sequential example (2 heads over 8
stations) came back as 8 independent stations: dof 36 instead of 42, T1's offset spread over
640..1378 µm instead of 975.5 ± 163.4 µm. Now each round trip, export -> import -> adjust, is compared
with the direct adjustment of the same observations, on the sequential example and on the mixed one
(4 heads and 2 trackers whose angles are observations; Gama and Star*Net model levelled instruments,
so both sides take the trackers as levelled):

* the imported observations have the same heads and levelled stations, and distances within the
  format's printed unit (8 decimals of a metre; offsets written with 10);
* dof equal; the adjustment of the imported file equals the direct adjustment of the same numbers
  (the original observations with the file's distances) to solver precision (1e-9);
* against the direct adjustment of the original numbers, offsets and σ0 within a bound derived from
  the rounding: a change e (|e_k| <= 5.1e-9 m) of the distances moves an offset by G e with
  sum_k G_k^2 σ_k^2 <= u_o^2, so |δo| <= e sqrt(m) u_o / σ_min (Cauchy-Schwarz), and vᵀPv by
  2 vᵀPe + eᵀPe to first order, |δ| <= 2 e sum|v_k|/σ_k^2 + m e^2/σ_min^2; the offsets' u to 1e-6
  relative (the geometry moves by nanometres).

Refusals are one line naming the head or station and the format, exit 2, nothing written.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.model.data import Points
from multilat.network.io.files import read_observations, read_points
from multilat.network.io.interop.gama import gama_local_text, read_gama_local
from multilat.network.io.interop.jag3d import head_file, read_jag3d, write_jag3d
from multilat.network.io.interop.starnet import read_starnet, starnet_text

EX = Path(__file__).resolve().parents[1] / "examples" / "network"
SEQ = EX / "sequential" / "obs.csv"
MIX = EX / "mixed" / "obs.csv"
E_ROUND = 5.1e-9      # half a unit of 8 decimals of a metre, plus half a unit of the offsets' 10 decimals
E_ANGLE = 2.5e-12     # half a unit of the angles: 1e-6" of arc (Star*Net d-m-s); 12 decimals of gon: 8e-15 rad
SOLVER = 1e-9         # the same numbers adjusted twice (Gauss-Newton to convergence)
_ANGLES = ("azimuth_rad", "elevation_rad", "sigma_azimuth_rad", "sigma_elevation_rad")


def _levelled(obs, ids):
    return dataclasses.replace(obs, levelled=tuple(ids))


@pytest.fixture(scope="module")
def seq():
    obs = read_observations(SEQ)
    return obs, adjust(obs, solver="dense")


@pytest.fixture(scope="module")
def mixed():
    obs = _levelled(read_observations(MIX), ("AT1", "AT2"))
    return obs, adjust(obs, solver="dense")


def _points(res) -> Points:
    return Points(tuple(res.station_ids) + tuple(res.target_ids), np.vstack([res.station_xyz_m, res.target_xyz_m]))


def _head_offsets(res) -> dict:
    return {h: float(res.offset_m[i]) for i, h in reversed(list(enumerate(res.obs.head_of_station)))}


def _per_head(res, values):
    heads = res.obs.head_of_station
    return {h: float(values[heads.index(h)]) for h in res.obs.head_ids}


def _round_trip(fmt, obs, res, tmp_path):
    pts = _points(res)
    if fmt == "gama":
        (tmp_path / "n.xml").write_text(gama_local_text(obs, pts, offsets=_head_offsets(res)))
        return read_gama_local(tmp_path / "n.xml")
    if fmt == "starnet":
        (tmp_path / "n.dat").write_text(starnet_text(obs, pts, offsets=_head_offsets(res)))
        return read_starnet(tmp_path / "n.dat")
    files = write_jag3d(tmp_path / "p.txt", tmp_path / "d.txt", obs, pts)      # offsets estimated in JAG3D
    return read_jag3d(tmp_path / "p.txt", files)


def _check(obs, res, net):
    got = net.obs
    assert dict(zip(got.station_ids, got.head_of_station)) == dict(zip(obs.station_ids, obs.head_of_station))
    assert set(got.levelled) == set(obs.levelled)
    row = {got.label(k): k for k in range(got.n_obs)}
    order = np.array([row[obs.label(k)] for k in range(obs.n_obs)])
    d_file = got.distance_m[order]
    assert np.max(np.abs(d_file - obs.distance_m)) <= E_ROUND
    np.testing.assert_allclose(got.sigma_m[order], obs.sigma_m, rtol=0, atol=1e-10)   # σ: 10 decimals of m
    back = adjust(got, points=net.points, solver="dense")
    assert back.dof == res.dof
    # the same numbers (the file's distances and angles) in the original model: equal to solver precision
    same = adjust(dataclasses.replace(obs, distance_m=d_file, **{
        a: None if getattr(got, a) is None else getattr(got, a)[order] for a in _ANGLES}),
        points=net.points, solver="dense")
    assert same.dof == back.dof and abs(back.sigma0 / same.sigma0 - 1) < SOLVER
    a, b = _per_head(back, back.offset_m), _per_head(same, same.offset_m)
    assert all(abs(a[h] - b[h]) < SOLVER * 1e-3 for h in a), (a, b)
    # the original numbers: within the bound of the rounding
    u = _per_head(res, res.offset_std_m)
    o_dir, o_back = _per_head(res, res.offset_m), a
    s_min, m = float(obs.sigma_m.min()), obs.n_obs
    for h in o_dir:
        bound = E_ROUND * np.sqrt(m) * u[h] / s_min
        assert abs(o_back[h] - o_dir[h]) <= bound, (h, o_back[h] - o_dir[h], bound)
    np.testing.assert_allclose(list(_per_head(back, back.offset_std_m).values()), list(u.values()), rtol=1e-6)
    v, sg = res.residuals_m, obs.sigma_m
    d_vpv = 2 * E_ROUND * np.sum(np.abs(v) / sg**2) + m * E_ROUND**2 / s_min**2
    va, sa = (np.array([a[k] for a in res.angles]) for k in ("residual_rad", "sigma_rad"))
    d_vpv += 2 * E_ANGLE * np.sum(np.abs(va) / sa**2) + va.size * E_ANGLE**2 / min(sa, default=1.0)**2
    assert abs(back.sigma0**2 * back.dof - res.sigma0**2 * res.dof) <= d_vpv
    return back


@pytest.mark.parametrize("fmt", ["gama", "jag3d", "starnet"])
def test_sequential_round_trip_keeps_heads_dof_and_offsets(fmt, seq, tmp_path):
    obs, res = seq
    assert obs.shares_heads and len(obs.head_ids) == 2 and obs.n_stations == 8
    back = _check(obs, res, _round_trip(fmt, obs, res, tmp_path))
    assert back.dof == 42


@pytest.mark.parametrize("fmt", ["gama", "jag3d", "starnet"])
def test_mixed_round_trip_keeps_levelled_trackers_and_their_angles(fmt, mixed, tmp_path):
    obs, res = mixed
    net = _round_trip(fmt, obs, res, tmp_path)
    back = _check(obs, res, net)
    assert back.dof == res.dof == 47 and len(back.obs.head_ids) == 6
    got, row = net.obs, {net.obs.label(k): k for k in range(net.obs.n_obs)}
    order = np.array([row[obs.label(k)] for k in range(obs.n_obs)])
    for name in ("sigma_azimuth_rad", "sigma_elevation_rad"):     # σ written to 1e-15 gon / 1e-9"
        np.testing.assert_allclose(getattr(got, name)[order], getattr(obs, name), rtol=1e-9, atol=0)
    has = np.isfinite(obs.sigma_azimuth_rad)
    da = (got.azimuth_rad[order] - obs.azimuth_rad + np.pi) % (2 * np.pi) - np.pi
    assert np.max(np.abs(da[has])) < 3e-11                         # 12 decimals of gon, 1e-6" of arc
    np.testing.assert_allclose(got.elevation_rad[order][has], obs.elevation_rad[has], rtol=0, atol=3e-11)


def test_jag3d_writes_one_group_file_per_head(seq, tmp_path):
    obs, res = seq
    files = write_jag3d(tmp_path / "p.txt", tmp_path / "d.txt", obs, _points(res))
    assert files == [head_file(tmp_path / "d.txt", "T1"), head_file(tmp_path / "d.txt", "T2")]
    assert not (tmp_path / "d.txt").exists()
    t1 = files[0].read_text().splitlines()
    assert "# multilat-head: T1" in t1
    assert {line.split()[0] for line in t1 if not line.startswith("#")} == {"S1", "S3", "S5", "S7"}
    one = read_jag3d(tmp_path / "p.txt", files[:1])          # one head's file alone: its stations, one head
    assert one.obs.head_ids == ("T1",) and one.obs.n_stations == 4


def test_fixed_scales_are_divided_out_and_restored(seq, tmp_path):
    obs, _ = seq
    res = adjust(obs, scales=["T2"], offsets=None, solver="dense")
    k = _per_head(res, res.scale)
    assert k["T2"] != 0 and k["T1"] == 0
    text = gama_local_text(obs, _points(res), offsets=_head_offsets(res), scales={"T2": k["T2"]})
    assert f"multilat-scales: T2={k['T2']!r}" in text
    (tmp_path / "n.xml").write_text(text)
    got = read_gama_local(tmp_path / "n.xml").obs
    assert np.max(np.abs(got.distance_m - obs.distance_m)) <= E_ROUND * (1 + abs(k["T2"]))


# ------------------------------------------------------------------------------ refusals
def _run(capsys, args):
    rc = main([str(a) for a in args])
    out = capsys.readouterr()
    return rc, out.out, out.err


def _one_line_error(rc, err, *needles):
    lines = [x for x in err.splitlines() if x.strip()]
    assert rc == 2 and len(lines) == 1 and lines[0].startswith("error:"), err
    for n in needles:
        assert n in lines[0], (n, lines[0])


@pytest.mark.parametrize("fmt,name", [("gama", "GNU Gama"), ("starnet", "Star*Net")])
def test_heads_to_estimate_refused_naming_heads_and_format(capsys, tmp_path, fmt, name):
    out = tmp_path / "n.out"
    rc, _, err = _run(capsys, ["export", fmt, SEQ, "--points", EX / "sequential" / "truth.csv", "-o", out])
    _one_line_error(rc, err, name, "heads T1, T2")
    assert not out.exists()


def test_two_offsets_for_one_head_refused(capsys, tmp_path, seq):
    obs, res = seq
    from multilat.network.io.files import write_result_tables

    write_result_tables(res, tmp_path / "adj")
    st = tmp_path / "adj" / "stations.csv"
    rows = st.read_text().splitlines()
    col = rows[0].split(",").index("offset_m")
    f = rows[3].split(",")                    # S3, a station of head T1
    f[col] = "0.002"
    st.write_text("\n".join(rows[:3] + [",".join(f)] + rows[4:]) + "\n")
    for fmt in ("gama", "starnet"):
        out = tmp_path / f"n.{fmt}"
        rc, _, err = _run(capsys, ["export", fmt, SEQ, "--result", tmp_path / "adj", "-o", out])
        _one_line_error(rc, err, "head 'T1' has two offsets", "S3")
        assert not out.exists()
    rc, _, err = _run(capsys, ["export", "gama", SEQ, "--points", EX / "sequential" / "truth.csv",
                               "--offsets-um", "S1=900,S2=50", "-o", tmp_path / "x.xml"])
    _one_line_error(rc, err, "unknown head id 'S1'")
    assert not (tmp_path / "x.xml").exists()


@pytest.mark.parametrize("fmt", ["gama", "jag3d", "starnet"])
def test_unlevelled_tracker_angles_refused_naming_station_and_format(capsys, tmp_path, fmt):
    out = tmp_path / "n.out"
    rc, _, err = _run(capsys, ["export", fmt, MIX, "--points", EX / "mixed" / "truth.csv", "-o", out,
                               "--offsets-um", "0"])
    _one_line_error(rc, err, f"{fmt}: station 'AT1' reads angles", "not levelled", "--levelled AT1")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("fmt", ["gama", "jag3d", "starnet"])
def test_weighted_control_refused_naming_the_point(capsys, tmp_path, fmt):
    pts = read_points(EX / "sequential" / "truth.csv")
    lines = (EX / "sequential" / "truth.csv").read_text().splitlines()
    body = [lines[0] + ",sx_m,sy_m,sz_m"] + [x + (",1e-5,1e-5,1e-5" if x.startswith("P3,") else ",,,")
                                              for x in lines[1:]]
    (tmp_path / "pts.csv").write_text("\n".join(body) + "\n")
    assert pts.get("P3") is not None
    out = tmp_path / "net.txt"
    rc, _, err = _run(capsys, ["export", fmt, SEQ, "--points", tmp_path / "pts.csv", "-o", out,
                               "--offsets-um", "T1=975,T2=56"] if fmt != "jag3d" else
                      ["export", fmt, SEQ, "--points", tmp_path / "pts.csv", "-o", out])
    _one_line_error(rc, err, f"{fmt}: point 'P3'", "weighted control")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pts.csv"]


def test_jag3d_head_id_that_cannot_name_a_file_refused(seq, tmp_path):
    obs, res = seq
    bad = dataclasses.replace(obs, station_heads=tuple("T/1" if h == "T1" else h for h in obs.head_of_station))
    with pytest.raises(MultilatError, match=r"jag3d: head id 'T/1' cannot name a file"):
        write_jag3d(tmp_path / "p.txt", tmp_path / "d.txt", bad, _points(res))
    assert not list(tmp_path.iterdir())


def test_import_refuses_an_inconsistent_file(seq, tmp_path):
    obs, res = seq
    text = gama_local_text(obs, _points(res), offsets=_head_offsets(res))
    line = next(x for x in text.splitlines() if x.startswith("multilat-offsets-m:"))
    (tmp_path / "a.xml").write_text(text.replace(line, line.replace("S3=", "S3=1")))
    with pytest.raises(MultilatError, match=r"a\.xml:\d+: head 'T1' has two offsets"):
        read_gama_local(tmp_path / "a.xml")
    heads = next(x for x in text.splitlines() if x.startswith("multilat-heads:"))
    (tmp_path / "b.xml").write_text(text.replace(heads, heads.replace(" S8=T2", "")))
    with pytest.raises(MultilatError, match=r"b\.xml:\d+: the heads line gives no head for station 'S8'"):
        read_gama_local(tmp_path / "b.xml")
    files = write_jag3d(tmp_path / "p.txt", tmp_path / "d.txt", obs, _points(res))
    (tmp_path / "other.txt").write_text(files[1].read_text().replace("\nS2 ", "\nS1 ", 1))
    with pytest.raises(MultilatError, match=r"other\.txt:\d+: station 'S1' is on head 'T2' here and on head 'T1'"):
        read_jag3d(tmp_path / "p.txt", [files[0], tmp_path / "other.txt"])


def test_cli_round_trip_jag3d_and_starnet_keep_heads(capsys, tmp_path, seq):
    obs, res = seq
    from multilat.network.io.files import write_result_tables

    write_result_tables(res, tmp_path / "adj")
    rc, o, e = _run(capsys, ["export", "jag3d", SEQ, "--result", tmp_path / "adj", "-o", tmp_path / "s.txt",
                             "--json"])
    assert rc == 0, e
    doc = json.loads(o)
    assert doc["heads"] == {"T1": ["S1", "S3", "S5", "S7"], "T2": ["S2", "S4", "S6", "S8"]}
    rc, o, e = _run(capsys, ["import", "jag3d", tmp_path / "s-T1.txt", tmp_path / "s-T2.txt", "--points-file",
                             tmp_path / "s-points.txt", "-o", tmp_path / "imp", "--json"])
    assert rc == 0, e
    assert json.loads(o)["n_heads"] == 2
    back = read_observations(tmp_path / "imp" / "distances.csv")
    assert dict(zip(back.station_ids, back.head_of_station)) == dict(zip(obs.station_ids, obs.head_of_station))
    rc, o, e = _run(capsys, ["export", "starnet", SEQ, "--result", tmp_path / "adj", "-o", tmp_path / "s.dat"])
    assert rc == 0, e
    rc, o, e = _run(capsys, ["import", "starnet", tmp_path / "s.dat", "-o", tmp_path / "imp2", "--json"])
    assert rc == 0, e
    assert read_observations(tmp_path / "imp2" / "distances.csv").head_of_station == obs.head_of_station
    rc, _, e = _run(capsys, ["import", "starnet", tmp_path / "s.dat", tmp_path / "s.dat", "-o", tmp_path / "x"])
    _one_line_error(rc, e, "import starnet reads one file")
    assert not (tmp_path / "x").exists()


def test_cli_result_with_estimated_scale_divides_it_out(capsys, tmp_path, seq):
    """``--result`` of ``adjust --scales``: the scale (from result.json) is divided out with the offset and
    recorded; the import restores the distances (within the printed unit, times 1 + k)."""
    obs, _ = seq
    rc, _, e = _run(capsys, ["adjust", SEQ, "--scales", "--fixed-scale", "T1", "--out", tmp_path / "adj"])
    assert rc == 0, e
    k = json.loads((tmp_path / "adj" / "result.json").read_text())["heads"]["T2"]["scale"]
    assert k != 0
    rc, _, e = _run(capsys, ["export", "gama", SEQ, "--result", tmp_path / "adj", "-o", tmp_path / "n.xml"])
    assert rc == 0, e
    assert f"multilat-scales: T2={k!r}" in (tmp_path / "n.xml").read_text()
    got = read_gama_local(tmp_path / "n.xml")
    assert any("fixed scales restored" in n for n in got.notes)
    row = {got.obs.label(j): j for j in range(got.obs.n_obs)}
    d = got.obs.distance_m[[row[obs.label(j)] for j in range(obs.n_obs)]]
    assert np.max(np.abs(d - obs.distance_m)) <= E_ROUND * (1 + abs(k))


@pytest.fixture(scope="module")
def mixed_results(tmp_path_factory):
    """``adjust --out`` of the mixed example as it is (trackers unlevelled: ω, φ, κ unknowns) and with
    ``--levelled AT1,AT2`` (κ only)."""
    d = tmp_path_factory.mktemp("mixed_results")
    for name, extra in (("free", []), ("levelled", ["--levelled", "AT1,AT2"])):
        assert main([str(a) for a in ["adjust", MIX, "--out", d / name, *extra]]) == 0
    return d


@pytest.mark.parametrize("fmt", ["gama", "jag3d", "starnet"])
def test_unlevelled_trackers_of_a_result_exported_levelled_refused(capsys, tmp_path, fmt, mixed_results):
    """An adjustment that estimated the trackers' tilt (ω, φ) exported with ``--levelled``: the format
    would hold them level, a model other than the one adjusted. Before: written silently (the tilt,
    -18382 µrad for AT2, dropped). Now one line naming the station, its estimated tilt and the format."""
    out = tmp_path / "n.out"
    rc, _, err = _run(capsys, ["export", fmt, MIX, "--result", mixed_results / "free", "--levelled", "AT1,AT2",
                               "-o", out])
    _one_line_error(rc, err, f"{fmt}: station 'AT1' is exported levelled", "estimated its tilt (omega = ",
                    "µrad, phi = ", "--levelled AT1")
    assert not list(tmp_path.iterdir())
    rc, _, err = _run(capsys, ["export", fmt, MIX, "--result", mixed_results / "free", "-o", out])
    _one_line_error(rc, err, f"{fmt}: station 'AT1' reads angles", "tilt (ω, φ) has no counterpart")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("fmt", ["gama", "jag3d", "starnet"])
def test_levelled_trackers_of_a_result_carried(capsys, tmp_path, fmt, mixed, mixed_results):
    """The levelled adjustment's result exports (its heads and angles carried) and comes back with the
    same heads, levelled stations, number of angles and dof as the direct adjustment."""
    obs, res = mixed
    out = tmp_path / ("n.xml" if fmt == "gama" else "n.txt" if fmt == "jag3d" else "n.dat")
    rc, o, err = _run(capsys, ["export", fmt, MIX, "--result", mixed_results / "levelled", "--levelled", "AT1,AT2",
                               "-o", out, "--json"])
    assert rc == 0, err
    doc = json.loads(o)
    assert doc["n_angles"] == int(np.isfinite(obs.sigma_azimuth_rad).sum() + np.isfinite(obs.sigma_elevation_rad).sum())
    if fmt == "gama":
        net = read_gama_local(out)
    elif fmt == "starnet":
        net = read_starnet(out)
    else:
        files = [Path(f) for f in doc["files"]]
        net = read_jag3d(files[-1], files[:-1])
    got = net.obs
    assert set(got.levelled) == {"AT1", "AT2"}
    assert dict(zip(got.station_ids, got.head_of_station)) == dict(zip(obs.station_ids, obs.head_of_station))
    assert np.isfinite(got.sigma_azimuth_rad).sum() == np.isfinite(obs.sigma_azimuth_rad).sum()
    assert adjust(got, points=net.points, solver="dense").dof == res.dof == 47


def test_import_gama_general_files_keep_the_heads(capsys, tmp_path):
    """``import gama`` of a multilat export writes two readings: distances.csv (heads restored) and the
    general network's observations.csv, which ``multilat adjust OUT`` takes. Before: observations.csv
    held Gama's model (distances minus the fixed offsets, no heads), so ``adjust OUT`` gave dof 44
    with the offsets silently held. Now it carries each head as an instrument with its offset
    estimated: dof 42 and the offsets of the distances.csv adjustment (same numbers, two solvers:
    1e-9 m), within the rounding bound of the direct adjustment."""
    rc, _, e = _run(capsys, ["adjust", SEQ, "--out", tmp_path / "adj"])
    assert rc == 0, e
    rc, _, e = _run(capsys, ["export", "gama", SEQ, "--result", tmp_path / "adj", "-o", tmp_path / "n.xml"])
    assert rc == 0, e
    rc, o, e = _run(capsys, ["import", "gama", tmp_path / "n.xml", "-o", tmp_path / "imp", "--json"])
    assert rc == 0, e
    notes = json.loads(o)["notes"]
    rc, o, e = _run(capsys, ["adjust", tmp_path / "imp", "--json"])
    assert rc == 0, e
    general = json.loads(o)
    rc, o, e = _run(capsys, ["adjust", tmp_path / "imp" / "distances.csv", "--points", tmp_path / "imp" / "points.csv",
                             "--json"])
    assert rc == 0, e
    dist = json.loads(o)
    assert general["dof"] == dist["dof"] == 42
    assert any("offsets are unknowns again" in n for n in notes)
    for h, v in dist["heads"].items():
        p = general["parameters"][f"offset:{h}"]
        assert abs(p["value"] - v["offset_m"]) < SOLVER and p["std"] == pytest.approx(v["offset_std_m"], rel=1e-6)
    direct = json.loads((tmp_path / "adj" / "result.json").read_text())
    obs = read_observations(SEQ)
    for h, v in direct["heads"].items():
        bound = E_ROUND * np.sqrt(obs.n_obs) * v["offset_std_m"] / float(obs.sigma_m.min())
        assert abs(general["parameters"][f"offset:{h}"]["value"] - v["offset_m"]) <= bound, h


TRACKERS = Path(__file__).resolve().parents[1] / "examples" / "tutorial" / "trackers.csv"


def test_result_of_the_general_model_exports(capsys, tmp_path):
    """``--result`` of ``adjust --model general`` (points.csv, result.json; before: ``stations.csv: no
    such file``): its coordinates and each head's estimated constant ``offset:H`` are used; the levelled
    trackers come back through Gama with the same dof 39 and constants within the file's rounding
    (the bound of the module docstring); the unlevelled adjustment (ω, φ estimated) exported with
    --levelled is refused naming the tilt."""
    for name, extra in (("lev", ["--levelled", "T1,T2"]), ("free", [])):
        rc, _, e = _run(capsys, ["adjust", TRACKERS, "--model", "general", "--out", tmp_path / name, *extra])
        assert rc == 0, e
    rc, _, e = _run(capsys, ["export", "gama", TRACKERS, "--result", tmp_path / "lev", "--levelled", "T1,T2",
                             "-o", tmp_path / "t.xml"])
    assert rc == 0, e
    rc, _, e = _run(capsys, ["import", "gama", tmp_path / "t.xml", "-o", tmp_path / "imp"])
    assert rc == 0, e
    rc, o, e = _run(capsys, ["adjust", tmp_path / "imp", "--json"])
    assert rc == 0, e
    back, direct = json.loads(o), json.loads((tmp_path / "lev" / "result.json").read_text())
    assert back["dof"] == direct["dof"] == 39
    obs = read_observations(TRACKERS)
    for h in ("T1", "T2"):
        a, b = back["parameters"][f"offset:{h}"], direct["parameters"][f"offset:{h}"]
        bound = E_ROUND * np.sqrt(obs.n_obs) * b["std"] / float(obs.sigma_m.min())
        assert abs(a["value"] - b["value"]) <= bound and a["std"] == pytest.approx(b["std"], rel=1e-6), h
    out = tmp_path / "x.xml"
    rc, _, err = _run(capsys, ["export", "gama", TRACKERS, "--result", tmp_path / "free", "--levelled", "T1,T2",
                               "-o", out])
    _one_line_error(rc, err, "gama: station 'T1' is exported levelled", "estimated its tilt (omega = ")
    assert not out.exists()
