"""multilat's files for the general network (``network/io/general_files.py``; each kind's ``COLUMNS``,
``from_rows``, ``to_rows``): docs/general-network.md, "multilat's files for the general network".

- ``multilat import gama NET.xml -o DIR`` then ``multilat adjust DIR`` gives the adjustment of
  ``multilat adjust NET.xml`` on the 11 gama-local reference networks of tests/data/gama3d and the
  examples: dof and defect equal, σ0 to 1e-12 relative, every coordinate to 1e-12 m, every other
  parameter (orientations, instrument constants) and its σ, every residual and redundancy number.
  The files hold every float in its shortest round-trip text (``repr``), so the two networks are the
  same arrays and the results agree to the last bit; the tolerances are there so that a rounding
  (writing 10 or 12 digits, say) fails them: 1e-12 m is far below any rounding a writer would pick.
- write -> read is the identity on generated networks of every kind (hypothesis): points with every
  status per coordinate, no approximate coordinates, datum points; blocks with covariances, several
  blocks of one kind, direction sets, instruments, set-ups, heights, options, ids with commas and
  quotes.
- Hostile files are refused in one line naming FILE:LINE (unknown kind, missing column, σ <= 0,
  unknown point, a covariance not positive definite, a duplicate ...), through Python and the CLI.
- The documentation's tables of the columns are generated from the kinds' ``COLUMNS``: the test fails
  when docs and code differ.
"""

from __future__ import annotations

import json
import re
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from multilat.cli.app import main
from multilat.cli.general_adjust import compute
from multilat.errors import MultilatError
from multilat.network.adjust.general import FIXED, FREE, WEIGHTED, Block, Network, PointSet, read_gama_input
from multilat.network.io.general_files import (columns_markdown, read_network_dir, write_network_dir,
                                            write_network_files)
from multilat.network.model.kinds import KINDS

ROOT = Path(__file__).resolve().parents[1]
GAMA3D = ROOT / "tests" / "data" / "gama3d"
NETWORKS = sorted(GAMA3D.glob("*.xml"))
NETWORKS = [p for p in NETWORKS if not p.name.endswith("_out.xml")]
EXAMPLES = sorted((ROOT / "examples" / "general").glob("*.xml"))
TESTS = dict(alpha=0.001, variance_factor="known", strict=False)


def test_the_reference_networks_are_all_there():
    assert len(NETWORKS) == 11 and len(EXAMPLES) == 2


# ------------------------------------------------------------------------------ networks compared
def same_network(a: Network, b: Network) -> None:
    """Everything of two networks but labels and notes is equal (NaN = NaN)."""
    pa, pb = a.points, b.points
    assert pa.ids == pb.ids
    np.testing.assert_array_equal(pa.xyz_m, pb.xyz_m)
    np.testing.assert_array_equal(pa.status, pb.status)
    np.testing.assert_array_equal(pa.sigma_m, pb.sigma_m)
    np.testing.assert_array_equal(pa.constrained, pb.constrained)
    assert len(a.blocks) == len(b.blocks)
    for x, y in zip(a.blocks, b.blocks):
        assert x.kind == y.kind
        np.testing.assert_array_equal(x.value, y.value)
        np.testing.assert_array_equal(x.sigma, y.sigma)
        assert (x.cov is None) == (y.cov is None)
        if x.cov is not None:
            np.testing.assert_array_equal(x.cov, y.cov)
        assert x.index.keys() == y.index.keys() and x.data.keys() == y.data.keys()
        for k in x.index:
            np.testing.assert_array_equal(x.index[k], y.index[k])
        for k in x.data:
            np.testing.assert_array_equal(x.data[k], y.data[k])
        assert x.names == y.names and x.options == y.options
        assert len(y.labels) == y.n_rows


def _round_trip(net: Network) -> Network:
    with tempfile.TemporaryDirectory() as d:
        write_network_files(net, d)
        return read_network_dir(d)


@pytest.mark.parametrize("path", NETWORKS + EXAMPLES, ids=lambda p: p.parent.name + "/" + p.stem)
def test_import_then_adjust_dir_equals_adjust_xml(path, tmp_path, capsys):
    out = tmp_path / "net"
    assert main(["import", "gama", str(path), "-o", str(out), "--json"]) == 0
    doc_import = json.loads(capsys.readouterr().out)
    net = read_gama_input(path)
    assert doc_import["n_obs"] == net.n_rows and doc_import["n_points"] == net.points.n
    same_network(net, read_network_dir(out))
    a, _, _ = compute(out, **TESTS)
    b, _, _ = compute(path, **TESTS)
    assert a["format"] == "multilat-files" and b["format"] == "gama-local"
    assert a["dof"] == b["dof"] and a["defect"] == b["defect"] and a["n_obs"] == b["n_obs"]
    assert a["sigma0"] == pytest.approx(b["sigma0"], rel=1e-12, abs=0)
    assert a["vtpv"] == pytest.approx(b["vtpv"], rel=1e-12, abs=0)
    assert a["points"].keys() == b["points"].keys() and a["excluded"] == b["excluded"]
    for p, v in b["points"].items():
        w = a["points"][p]
        np.testing.assert_allclose(w["xyz_m"], v["xyz_m"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(w["xyz_std_m"], v["xyz_std_m"], rtol=1e-12, atol=1e-15)
        assert (w["status"], w["roles"], w["status_xyz"]) == (v["status"], v["roles"], v["status_xyz"])
    assert a["parameters"].keys() == b["parameters"].keys()
    for k, v in b["parameters"].items():
        assert a["parameters"][k]["value"] == pytest.approx(v["value"], rel=0, abs=1e-12)
        assert a["parameters"][k]["std"] == pytest.approx(v["std"], rel=1e-12, abs=1e-15)
    for x, y in zip(a["observations"], b["observations"]):
        assert x["kind"] == y["kind"] and x["label"] != y["label"]          # labels: the file each came from
        for key in ("value", "sigma", "residual", "redundancy", "w"):
            assert x[key] == pytest.approx(y[key], rel=1e-12, abs=1e-15), key


def test_import_keeps_distances_csv_where_the_distance_path_reads_the_file(tmp_path, capsys):
    """two_trackers (slope distances and levelled stations' angles): distances.csv as before, and
    the general files beside it; heights.xml (instrument heights) and station_control.xml (a point
    without coordinates, which the old points.csv left out): the general files only, a note."""
    from multilat.network.io.files import read_observations
    from multilat.network.io.interop.gama import read_gama_local

    assert main(["import", "gama", str(GAMA3D / "two_trackers.xml"), "-o", str(tmp_path / "a"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    old = read_gama_local(GAMA3D / "two_trackers.xml").obs
    back = read_observations(tmp_path / "a" / "distances.csv")
    np.testing.assert_array_equal(back.distance_m, old.distance_m)
    assert doc["levelled"] == ["T1", "T2"] and doc["n_stations"] == 2
    assert main(["import", "gama", str(GAMA3D / "heights.xml"), "-o", str(tmp_path / "b"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert not (tmp_path / "b" / "distances.csv").exists()
    assert any("no distances.csv" in n and "heights.xml:" in n for n in doc["notes"])
    assert sorted(p.name for p in (tmp_path / "b").iterdir()) == ["observations.csv", "points.csv"]
    assert main(["import", "gama", str(GAMA3D / "station_control.xml"), "-o", str(tmp_path / "c"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)            # station_control: the station has no coordinates
    assert not (tmp_path / "c" / "distances.csv").exists()
    assert any("no distances.csv" in n and "point(s) without coordinates (S, ...)" in n for n in doc["notes"])


def test_the_example_directory_is_what_import_writes(tmp_path, capsys):
    """examples/general/station_control_files is `import gama station_control.xml`, byte for byte."""
    ex = ROOT / "examples" / "general"
    assert main(["import", "gama", str(ex / "station_control.xml"), "-o", str(tmp_path / "s")]) == 0
    stored = sorted(p.name for p in (ex / "station_control_files").iterdir())
    assert stored == sorted(p.name for p in (tmp_path / "s").iterdir()) == ["observations.csv", "points.csv"]
    for name in stored:
        assert (ex / "station_control_files" / name).read_text() == (tmp_path / "s" / name).read_text(), name


# ------------------------------------------------------------------------------ write -> read: identity
_ID = st.text(alphabet="ABPQ0179_-.,\"' ", min_size=1, max_size=5).map(str.strip).filter(
    lambda s: s != "" and not s.startswith("#"))


@st.composite
def networks(draw):
    ids = draw(st.lists(_ID, min_size=3, max_size=7, unique=True))
    n = len(ids)
    coord = st.floats(-1e5, 1e5, allow_nan=False)
    xyz = np.array(draw(st.lists(st.lists(coord, min_size=3, max_size=3), min_size=n, max_size=n)), float)
    status = np.array(draw(st.lists(st.lists(st.sampled_from([FREE, FIXED, WEIGHTED]), min_size=3, max_size=3),
                                    min_size=n, max_size=n)), int)
    unknown = np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)))
    xyz[unknown[:, None] & (status == FREE)] = np.nan                 # no approximate value yet
    sigma = np.where(status == WEIGHTED, draw(st.floats(1e-9, 1e2)), np.nan)
    pts = PointSet(tuple(ids), xyz, status, sigma, np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n))))
    names = sorted(KINDS)
    chosen = draw(st.lists(st.sampled_from(names), min_size=1, max_size=12))
    return Network(pts, tuple(draw(_block(kind, n)) for kind in chosen))


@st.composite
def _block(draw, kind, n):
    mod = KINDS[kind]
    m = draw(st.integers(1, 5))
    lo = 1e-6 if kind in ("slope_distance", "horizontal_distance", "zenith_angle", "tracker_angles") else -1e4
    hi = 1.5 if kind in ("zenith_angle", "tracker_angles") else 1e4
    value = np.array(draw(st.lists(st.floats(lo, hi), min_size=m, max_size=m)))
    index, data, names, options = {}, {}, {}, {}
    for c in mod.COLUMNS:
        key = c.block_key
        if c.role == "point":
            index[key] = np.array(draw(st.lists(st.integers(0, n - 1), min_size=m, max_size=m)))
        elif c.role == "enum":
            index[key] = np.array(draw(st.lists(st.integers(0, len(c.choices) - 1), min_size=m, max_size=m)))
        elif c.role == "name" and (c.required or draw(st.booleans())):
            raw = draw(st.lists(_ID, min_size=m, max_size=m))
            if not c.required and draw(st.booleans()):
                raw[0] = ""                                            # a row without one: -1
                raw.append("spare")
            names[key] = tuple(dict.fromkeys(r for r in raw if r))
            index[key] = np.array([names[key].index(r) if r else -1 for r in raw[:m]])
            if not any(raw[:m]):
                del names[key], index[key]
        elif c.role == "number" and draw(st.booleans()):
            data[key] = np.array(draw(st.lists(st.floats(-10, 10), min_size=m, max_size=m)))
        elif c.role == "option" and draw(st.booleans()):
            options[key] = draw(st.booleans())
    if draw(st.booleans()):                                           # a correlated block
        off = draw(st.lists(st.floats(-0.5, 0.5), min_size=m * m, max_size=m * m))
        lower = np.tril(np.array(off).reshape(m, m), -1)
        lower += np.eye(m)
        d = np.array(draw(st.lists(st.floats(1e-8, 1e2), min_size=m, max_size=m)))
        cov = lower @ np.diag(d) @ lower.T
        cov = (cov + cov.T) / 2                                       # symmetric to the bit (else refused)
        sigma, cov = np.sqrt(np.diag(cov)), cov
    else:
        sigma, cov = np.array(draw(st.lists(st.floats(1e-12, 1e3), min_size=m, max_size=m))), None
    return Block(kind, value, sigma, cov, index, data, tuple("x" for _ in range(m)), names, options)


def _names_in_first_appearance(net: Network) -> Network:
    """``net`` with unused names dropped (the files keep the ids that rows use, in their order)."""
    blocks = []
    for b in net.blocks:
        index, names = dict(b.index), {}
        for k, nm in b.names.items():
            used = list(dict.fromkeys(int(i) for i in b.index[k] if i >= 0))
            names[k] = tuple(nm[i] for i in used)
            index[k] = np.array([used.index(int(i)) if i >= 0 else -1 for i in b.index[k]])
        blocks.append(Block(b.kind, b.value, b.sigma, b.cov, index, b.data, b.labels, names, b.options))
    return Network(net.points, tuple(blocks))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(networks())
def test_write_then_read_is_the_identity(net):
    same_network(_names_in_first_appearance(net), _round_trip(net))


def test_every_kind_and_role_is_generated():
    """The property test's generator covers every kind the registry has (a new kind is in it)."""
    assert {c.role for k in KINDS.values() for c in k.COLUMNS} == {"value", "sigma", "point", "name", "enum",
                                                                  "number", "option"}
    for k in KINDS.values():
        assert k.UNIT in ("m", "rad") and [c.name for c in k.COLUMNS][:2] == ["value", "sigma"]


def test_an_asymmetric_covariance_is_not_written(tmp_path):
    net = read_gama_input(GAMA3D / "vectors.xml")
    k = next(i for i, b in enumerate(net.blocks) if b.cov is not None)
    b = net.blocks[k]
    cov = b.cov.copy()
    cov[1, 0] = np.nextafter(cov[1, 0], 1.0)
    bad = Block(b.kind, b.value, b.sigma, cov, b.index, b.data, b.labels, b.names, b.options)
    net = Network(net.points, net.blocks[:k] + (bad,) + net.blocks[k + 1:])
    with pytest.raises(MultilatError, match=rf"coordinate_difference block {k + 1}: its covariance is not symmetric "
                                            r"\(entry \(1, 2\) differs from \(2, 1\)\)"):
        write_network_dir(net, tmp_path / "o")
    assert not (tmp_path / "o").exists()                              # all or nothing


@pytest.mark.parametrize("csv, levelled, scales", [("general/two_trackers_csv/obs.csv", "T1,T2", False),
                                                  ("network/mixed/obs.csv", None, False),
                                                  ("network/sequential/obs.csv", None, True)])
def test_csv_networks_round_trip_through_the_files(csv, levelled, scales):
    """multilat's observation CSVs as general networks (from_tables: heads as instruments with their
    estimated constants and scales, tracker set-ups levelled or not): written and read back, the
    same network and the same adjustment (dof, σ0, coordinates equal)."""
    from multilat.cli.network_cmd import with_levelled
    from multilat.network.io.files import read_observations
    from multilat.network.adjust.general import adjust_network
    from multilat.network.adjust.general.from_tables import network_from_tables

    obs = with_levelled(read_observations(ROOT / "examples" / csv), levelled)
    net, opt = network_from_tables(obs, scales=list(obs.head_ids[1:]) if scales else False)
    back = _round_trip(net)
    same_network(net, back)
    a, b = adjust_network(net, options=opt).result, adjust_network(back, options=opt).result
    assert a.dof == b.dof and a.sigma0 == pytest.approx(b.sigma0, rel=1e-12, abs=0)
    np.testing.assert_allclose(b.xyz_m, a.xyz_m, rtol=0, atol=1e-12)


def test_gama_networks_round_trip_exactly():
    for p in NETWORKS:
        net = read_gama_input(p)
        same_network(net, _round_trip(net))


# ------------------------------------------------------------------------------ hostile files
POINTS = """point,x_m,y_m,z_m,fixed,sx_m,sy_m,sz_m,datum
A,0,0,0,xyz,,,,
B,100,0,0,,,,0.001,
C,0,100,0,,,,,false
D,,,,,,,,
"""
OBS = """kind,block,from,to,set,axis,component,setup,estimate_offset,value,sigma,unit
slope_distance,,A,B,,,,,,100.0,0.001,m
direction,,A,B,S1,,,,,0.0,1e-5,rad
coordinate_difference,v,A,C,,x,,,,0.0,,m
coordinate_difference,v,A,C,,y,,,,100.0,,m
coordinate_difference,v,A,C,,z,,,,0.0,,m
tracker_angles,,A,D,,,elevation,U1,,0.1,1e-5,rad
"""
COV = """block,row,col,cov
v,1,1,1e-6
v,2,2,1e-6
v,3,3,1e-6
v,1,2,1e-7
"""


def _files(d: Path, points=POINTS, obs=OBS, cov=COV) -> Path:
    d.mkdir(exist_ok=True)
    (d / "points.csv").write_text(points)
    (d / "observations.csv").write_text(obs)
    (d / "covariances.csv").write_text(cov)
    return d


def _line(text: str, k: int, old: str, new: str) -> str:
    lines = text.splitlines(keepends=True)
    assert old in lines[k - 1], (old, lines[k - 1])
    lines[k - 1] = lines[k - 1].replace(old, new, 1)
    return "".join(lines)


def test_the_good_files_are_read():
    with tempfile.TemporaryDirectory() as d:
        net = read_network_dir(_files(Path(d) / "n"))
    assert [b.kind for b in net.blocks] == ["slope_distance", "direction", "coordinate_difference", "tracker_angles"]
    v = net.blocks[2]
    np.testing.assert_array_equal(v.cov, [[1e-6, 1e-7, 0], [1e-7, 1e-6, 0], [0, 0, 1e-6]])
    np.testing.assert_array_equal(v.sigma, np.sqrt([1e-6] * 3))
    assert list(net.points.status[1]) == [FREE, FREE, WEIGHTED] and list(net.points.status[0]) == [FIXED] * 3
    assert np.isnan(net.points.xyz_m[3]).all() and net.blocks[3].names == {"setup": ("U1",)}


HOSTILE = [  # (file, line, old, new, needle[, the line named])
    ("observations", 2, "slope_distance", "slope_distanse", "unknown observation kind 'slope_distanse'"),
    ("observations", 1, ",unit\n", "\n", "header lacks column(s) unit"),
    ("observations", 3, ",S1,", ",,", "needs column 'set'"),
    ("observations", 2, ",0.001,m", ",0,m", "column 'sigma': must be > 0"),
    ("observations", 2, ",0.001,m", ",-0.001,m", "column 'sigma': must be > 0"),
    ("observations", 2, ",A,B,", ",A,Q,", "point 'Q' is not in points.csv"),
    ("observations", 2, "100.0", "abc", "column 'value': not a number"),
    ("observations", 2, "100.0", "-100.0", "must be within (0, inf)"),
    ("observations", 2, ",m\n", ",rad\n", "column 'unit': a slope_distance is in m"),
    ("observations", 2, ",A,B,,,", ",A,B,,x,", "column 'axis' does not apply to a slope_distance"),
    ("observations", 2, "slope_distance,,", "slope_distance,v,", "block 'v' holds a slope_distance (line 2)", 4),
    ("observations", 5, ",y,", ",w,", "column 'axis' must be one of x, y, z"),
    ("observations", 5, ",100.0,,", ",100.0,0.5,", "column 'sigma': 0.5, but its variance"),
    ("observations", 7, ",0.1,", ",2.0,", "an elevation must be within [-pi/2, pi/2]"),
    ("observations", 7, ",elevation,", ",height,", "column 'component' must be one of azimuth, elevation"),
    ("observations", 2, ",0.001,m", ",,m", "column 'sigma': empty, and its block has no covariances"),
    ("observations", 2, ",,,,,100.0", ",,,,maybe,100.0", "column 'estimate_offset' must be true or false"),
    ("covariances", 5, "1e-7", "2e-6", "covariance of block 'v' is not positive definite (its first 2", 3),
    ("covariances", 5, "v,1,2,1e-7", "v,1,2,1e-7\nv,2,1,1e-8", "entry (1, 2) given twice (first at line 5)", 6),
    ("covariances", 5, "v,1,2", "w,1,2", "block 'w' is not a block id of observations.csv"),
    ("covariances", 5, "v,1,2", "v,1,4", "block 'v' has rows 1..3"),
    ("covariances", 5, "v,1,2", "v,1,1.5", "block 'v' has rows 1..3"),
    ("covariances", 2, "1e-6", "-1e-6", "a variance must be > 0"),
    ("points", 5, "D,", "A,", "point 'A' given twice (first at line 2)"),
    ("points", 3, "B,100,0,0,,", "B,100,0,0,z,", "z is fixed and has sz_m"),
    ("points", 2, "xyz", "xq", "column 'fixed'"),
    ("points", 5, "D,,,,,", "D,,,,z,", "its z is fixed but column 'z_m' is empty"),
    ("points", 3, "0.001", "0", "column 'sz_m': must be > 0"),
    ("points", 4, "false", "maybe", "column 'datum' must be true or false"),
    ("points", 1, "datum", "colour", "unknown column 'colour'"),
    ("observations", 1, ",unit", ",unit,to_dh", "unknown column 'to_dh'"),
    ("covariances", 1, ",cov", ",cov,note", "unknown column 'note'"),
]


@pytest.mark.parametrize("case", HOSTILE, ids=[h[4][:40] for h in HOSTILE])
def test_hostile_rows_are_refused_by_file_and_line(tmp_path, case):
    name, line, old, new, needle = case[:5]
    at = case[5] if len(case) > 5 else line                          # the line named, if not the one changed
    texts = {"points": POINTS, "observations": OBS, "covariances": COV}
    texts[name] = _line(texts[name], line, old, new)
    d = _files(tmp_path / "n", texts["points"], texts["observations"], texts["covariances"])
    with pytest.raises(MultilatError) as e:
        read_network_dir(d)
    msg = str(e.value)
    assert "\n" not in msg and needle in msg, msg
    assert msg.startswith(f"{d / (name + '.csv')}:{at}:"), msg


def test_missing_variance_is_named_at_its_observation_row(tmp_path):
    d = _files(tmp_path / "n", cov=COV.replace("v,3,3,1e-6\n", ""))
    with pytest.raises(MultilatError, match=re.escape(f"{d / 'observations.csv'}:6: block 'v': this row (its row 3) "
                                                      "has no variance")):
        read_network_dir(d)


def test_one_option_value_per_block(tmp_path):
    obs = OBS + "slope_distance,d,A,C,,,,,true,100.0,0.001,m\nslope_distance,d,B,C,,,,,false,140.0,0.001,m\n"
    d = _files(tmp_path / "n", obs=obs)
    with pytest.raises(MultilatError, match=re.escape(f"{d / 'observations.csv'}:9: column 'estimate_offset' is "
                                                      f"'false' here but true at {d / 'observations.csv'}:8")):
        read_network_dir(d)


def test_rows_without_block_ids_are_grouped_by_kind_and_options(tmp_path):
    obs = (OBS + "slope_distance,,A,C,,,,,true,100.0,0.001,m\nslope_distance,,B,C,,,,,TRUE,140.0,0.001,m\n"
           "slope_distance,,B,D,,,,,,140.0,0.001,m\n")
    net = read_network_dir(_files(tmp_path / "n", obs=obs))
    sd = [b for b in net.blocks if b.kind == "slope_distance"]
    assert [b.n_rows for b in sd] == [2, 2] and sd[1].options == {"estimate_offset": True} and sd[0].options == {}


def test_the_cli_refuses_in_one_line(tmp_path, capsys):
    d = _files(tmp_path / "n", obs=_line(OBS, 2, ",A,B,", ",A,Q,"))
    assert main(["adjust", str(d)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith(f"error: {d / 'observations.csv'}:2:") and "'Q'" in err
    assert main(["adjust", str(_files(tmp_path / "m")), "--datum", "free"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"error: --datum does not apply to a network directory ({tmp_path / 'm'}): the datum is "
                   "points.csv's fixed, sx_m.. and datum columns")
    (tmp_path / "e").mkdir()
    assert main(["adjust", str(tmp_path / "e")]) == 2
    assert "is a directory without points.csv" in capsys.readouterr().err


def test_adjust_dir_from_the_cli(tmp_path, capsys):
    """The summary and --out of ``multilat adjust DIR`` (the same document as --json)."""
    out = tmp_path / "net"
    assert main(["import", "gama", str(EXAMPLES[0]), "-o", str(out)]) == 0
    assert f"multilat adjust {out}" in capsys.readouterr().out.replace("\n", "")
    assert main(["adjust", str(out), "--out", str(tmp_path / "res")]) == 0
    text = capsys.readouterr().out
    assert "(multilat-files; general model)" in text
    doc = json.loads((tmp_path / "res" / "result.json").read_text())
    ref, _, _ = compute(EXAMPLES[0], **TESTS)
    assert doc["dof"] == ref["dof"] and doc["sigma0"] == pytest.approx(ref["sigma0"], rel=1e-12)


def test_the_documents_follow_the_shipped_schemas(tmp_path, capsys):
    """adjust DIR's document (adjust-general) and import gama's (import), both with the general files."""
    jsonschema = pytest.importorskip("jsonschema")
    from multilat.vocabulary import document_problems

    schemas = ROOT / "src" / "multilat" / "schemas"
    for name in ("heights", "two_trackers"):                 # with and without distances.csv
        assert main(["import", "gama", str(GAMA3D / f"{name}.xml"), "-o", str(tmp_path / name), "--json"]) == 0
        doc = json.loads(capsys.readouterr().out)
        schema = json.loads((schemas / "import.json").read_text("utf-8"))
        assert not list(jsonschema.Draft202012Validator(schema).iter_errors(doc))
        assert main(["adjust", str(tmp_path / name), "--json"]) == 0
        doc = json.loads(capsys.readouterr().out)
        schema = json.loads((schemas / "adjust-general.json").read_text("utf-8"))
        errors = list(jsonschema.Draft202012Validator(schema).iter_errors(doc))
        assert not errors, errors[0].message[:200]
        assert document_problems(doc) == [] and doc["format"] == "multilat-files"


# ------------------------------------------------------------------------------ docs
def test_the_docs_list_the_kinds_columns():
    """docs/general-network.md holds columns_markdown() between its markers, verbatim."""
    text = (ROOT / "docs" / "general-network.md").read_text()
    m = re.search(r"<!-- BEGIN generated by multilat\.network\.io\.general_files\.columns_markdown\(\) -->\n(.*?)"
                  r"<!-- END generated -->", text, re.S)
    assert m is not None, "the generated section is missing"
    assert m.group(1) == columns_markdown(), "docs/general-network.md differs from the kinds' COLUMNS: paste " \
                                             "columns_markdown() between the markers"
