"""``multilat adjust NET.xml``: the general network layer from the command line and from Python.

- The two examples (examples/general/) through the CLI in a subprocess and through the Python API,
  against gama-local's stored outputs (tests/data/gama3d/NAME_out.xml) with the tolerances of
  tests/test_general_gama3d.py: dof equal, σ0 to 1e-6 relative, coordinates to 1e-6 m.
- The statistics against an independent computation written here (numpy/scipy.stats on the plain,
  unwhitened normal equations): redundancy numbers, w, MDB, the B-method's global α, Pope's τ
  critical value from the Beta distribution, 95 % ellipsoids.
- An undetermined point (two distances) and an unreachable one (no approximate coordinates) are
  left out and named, the rest adjusted to gama-local's solution of the network without them;
  ``--strict`` refuses in one line, nothing written.
- Options of the distance-only path are refused in one line naming them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.stats

import multilat
from multilat.cli import main

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_general_gama3d import gama_output  # noqa: E402  (Gama's output parser, one copy)

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples" / "general"
SRC = Path(multilat.__file__).resolve().parents[1]
EXAMPLES = ["two_trackers", "station_control"]


def _cli(*args, timeout=300):
    env = dict(os.environ, PYTHONPATH=str(SRC))
    return subprocess.run([sys.executable, "-c", "from multilat.cli import run; run()", "adjust", *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=timeout, cwd=ROOT)


def _main(capsys, *args):
    rc = main(["adjust", *map(str, args)])
    out = capsys.readouterr()
    return rc, out.out, out.err


def _against_gama(doc_points, sigma0, dof, name):
    g_dof, g_s0, coords, _, _ = gama_output(name)
    assert dof == g_dof
    assert sigma0 == pytest.approx(g_s0, rel=1e-6)
    worst = max(abs(doc_points[p][a] - v) for p, d in coords.items() for a, v in d.items())
    assert worst < 1e-6, f"{name}: worst coordinate difference {worst:.3g} m"
    return coords


@pytest.mark.parametrize("name", EXAMPLES)
def test_example_cli_json_against_gama(name):
    r = _cli(EX / f"{name}.xml", "--json", "--observations")        # every row (adjust-general/2)
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["schema"] == "multilat.adjust-general/3" and doc["format"] == "gama-local"
    coords = _against_gama({p: v["xyz_m"] for p, v in doc["points"].items()}, doc["sigma0"], doc["dof"], name)
    assert set(coords) <= set(doc["points"])
    for p, v in doc["points"].items():
        assert set(v) >= {"xyz_m", "xyz_std_m", "cov_m2", "semi_axes_95_m", "roles", "status"}
        assert np.shape(v["cov_m2"]) == (3, 3) and v["roles"]
    assert doc["excluded"] == [] and len(doc["observations"]) == doc["n_obs"]
    assert sum(o["redundancy"] for o in doc["observations"]) == pytest.approx(doc["dof"], abs=1e-9)
    assert set(doc["global_test"]) >= {"statistic", "critical", "passed", "alpha"}
    assert doc["sigma_source"]["kind"] == "file" and doc["datum"]


@pytest.mark.parametrize("name", EXAMPLES)
def test_example_python_api_against_gama(name):
    from multilat.network.adjust.general import adjust_network, read_gama_input, statistics, to_json

    adj = adjust_network(read_gama_input(EX / f"{name}.xml"))
    res = adj.result
    _against_gama({p: res.xyz_m[i] for i, p in enumerate(res.ids)}, res.sigma0, res.dof, name)
    doc = to_json(adj, statistics(adj.system, res), source=name)
    assert doc["points"][res.ids[0]]["xyz_m"] == res.xyz_m[0].tolist()


def test_roles_status_and_datum_words():
    from multilat.network.adjust.general import adjust_network, read_gama_input, statistics, to_json

    adj = adjust_network(read_gama_input(EX / "station_control.xml"))
    doc = to_json(adj, statistics(adj.system, adj.result), source="x")
    pts = doc["points"]
    assert pts["S"]["roles"] == ["station"] and pts["S"]["status"] == "free"
    assert pts["K1"]["roles"] == ["target", "control"] and pts["K1"]["status"] == "fixed"
    assert pts["K1"]["xyz_std_m"] == [0.0, 0.0, 0.0] and pts["Q01"]["roles"] == ["target"]
    assert doc["datum"] == "given by 5 fixed point(s) (K1, K2, K3, K4, K5)"
    adj = adjust_network(read_gama_input(ROOT / "tests" / "data" / "gama3d" / "partly_fixed.xml"))
    doc = to_json(adj, statistics(adj.system, adj.result), source="x")
    assert {v["status"] for v in doc["points"].values()} == {"fixed", "partly fixed", "free"}
    d = next(v for v in doc["points"].values() if v["status"] == "partly fixed")
    assert sorted(d["status_xyz"]) in (["fixed", "fixed", "free"], ["fixed", "free", "free"])
    adj = adjust_network(read_gama_input(EX / "two_trackers.xml"))
    doc = to_json(adj, statistics(adj.system, adj.result), source="x")
    assert doc["datum"].startswith("free network (datum defect 4): inner constraints")


# --------------------------------------------------------------------------- statistics
def _independent(adj, alpha, power=0.8):
    """Redundancy, w, MDB and the point covariances from the unwhitened normal equations, with a
    pseudo-inverse (the datum-invariant quantities for a free network) and scipy.stats."""
    sysm, res = adj.system, adj.result
    v, J = sysm.evaluate(res.parameters)
    C = np.zeros((sysm.n_rows, sysm.n_rows))
    for b, sl in zip(sysm.blocks, sysm.rows):
        C[sl, sl] = b.covariance
    P = np.linalg.inv(C)
    Qx = np.linalg.pinv(J.T @ P @ J)
    Qv = C - J @ Qx @ J.T
    r = np.diag(Qv @ P)
    lam = (scipy.stats.norm.ppf(1 - alpha / 2) + scipy.stats.norm.ppf(power)) ** 2
    sig = np.sqrt(np.diag(C))
    with np.errstate(divide="ignore", invalid="ignore"):     # r = 0 rows: compared apart
        return v, P, r, v / np.sqrt(np.diag(Qv)), sig * np.sqrt(lam / r), lam


@pytest.mark.parametrize("name", ["station_control", "two_trackers"])
def test_statistics_against_independent_formulas(name):
    """Both networks have independent observations only, so the whitened rows are the
    observations. Tolerances: 1e-8 on r and w (two factorisations of a condition ~1e6 system);
    1e-9 relative on the quantiles."""
    from multilat.network.adjust.general import adjust_network, read_gama_input, statistics

    adj = adjust_network(read_gama_input(EX / f"{name}.xml"))
    st = statistics(adj.system, adj.result, alpha=0.001, method="b-method")
    v, P, r, w, mdb, lam = _independent(adj, 0.001)
    assert np.allclose(st.redundancy, r, atol=1e-8)
    ok = r > 1e-6
    assert ok.sum() > 10
    assert np.allclose(st.w[ok], w[ok], atol=1e-8) and np.all(st.w[~ok] == 0)
    assert np.allclose(st.mdb[ok], mdb[ok], rtol=1e-6)
    assert st.lambda0 == pytest.approx(lam, rel=1e-9)
    dof = adj.result.dof
    assert st.vtpv == pytest.approx(v @ P @ v, rel=1e-10)
    crit = scipy.stats.ncx2.ppf(1 - 0.8, dof, lam)                 # B-method: equal power 80 %
    a_glob = scipy.stats.chi2.sf(crit, dof)
    assert st.global_test.alpha == pytest.approx(a_glob, rel=1e-6)
    assert st.global_test.critical == pytest.approx(scipy.stats.chi2.ppf(1 - a_glob, dof), rel=1e-6)
    assert st.critical == pytest.approx(scipy.stats.norm.ppf(1 - 0.0005), rel=1e-9)
    # 95 % ellipsoid of a free point: sqrt(χ²_3(0.95) λ) of its covariance
    i = adj.result.ids.index("Q01" if name == "station_control" else adj.result.ids[-1])
    lam_c = np.linalg.eigvalsh(st.cov_m2[i])
    assert np.allclose(st.semi_axes_95_m[i], np.sqrt(scipy.stats.chi2.ppf(0.95, 3) * lam_c), rtol=1e-9)


def test_variance_factor_unknown_tau_and_scaled_covariance():
    """τ = w / σ̂0; Pope's critical value from τ²/dof ~ Beta(1/2, (dof-1)/2); covariances × σ̂0²."""
    from multilat.network.adjust.general import adjust_network, read_gama_input, statistics

    adj = adjust_network(read_gama_input(EX / "two_trackers.xml"))
    known = statistics(adj.system, adj.result, alpha=0.01, method="b-method")
    unk = statistics(adj.system, adj.result, alpha=0.01, variance_factor="unknown", method="b-method")
    s0, dof = adj.result.sigma0, adj.result.dof
    assert np.allclose(unk.statistic, known.w / s0, rtol=1e-12)
    assert unk.critical == pytest.approx(np.sqrt(dof * scipy.stats.beta.ppf(0.99, 0.5, (dof - 1) / 2)), rel=1e-8)
    assert np.allclose(unk.cov_m2, known.cov_m2 * s0 ** 2, rtol=1e-12)
    ok = np.isfinite(known.mdb)
    assert np.allclose(unk.mdb[ok], known.mdb[ok] * s0, rtol=1e-12)


# --------------------------------------------------------------------------- undetermined points
def _with_weak_points(tmp_path):
    """station_control.xml plus FLAT (two distances from fixed points: it can turn about the K1-K2
    line) and LOST (one horizontal distance, no coordinates: no approximate position)."""
    text = (EX / "station_control.xml").read_text()
    extra = ('<point id="FLAT" x="1070.0" y="2060.0" z="300.0" adj="xyz" />\n'
             '<point id="LOST" adj="xyz" />\n'
             '<obs from="K1">\n  <s-distance to="FLAT" val="66.1" stdev="1.0" />\n</obs>\n'
             '<obs from="K2">\n  <s-distance to="FLAT" val="71.6" stdev="1.0" />\n</obs>\n'
             '<obs from="K3">\n  <distance to="LOST" val="50.0" stdev="1.0" />\n</obs>\n')
    text = text.replace("</points-observations>", extra + "</points-observations>")
    p = tmp_path / "weak.xml"
    p.write_text(text)
    return p


def test_undetermined_points_left_out_and_named(tmp_path, capsys):
    net = _with_weak_points(tmp_path)
    rc, out, err = _main(capsys, net, "--json")
    assert rc == 0, err
    doc = json.loads(out)
    ex = {e["id"]: e for e in doc["excluded"]}
    assert set(ex) == {"FLAT", "LOST"}
    assert ex["FLAT"]["n_obs"] == 2 and "not determined by the observations" in ex["FLAT"]["reason"]
    assert ex["LOST"]["n_obs"] == 1 and "no approximate coordinates" in ex["LOST"]["reason"]
    assert "warning: point 'FLAT' left out" in err and "warning: point 'LOST' left out" in err
    assert "FLAT" not in doc["points"] and "LOST" not in doc["points"]
    # what is left is station_control itself: gama-local's solution of it
    _against_gama({p: v["xyz_m"] for p, v in doc["points"].items()}, doc["sigma0"], doc["dof"], "station_control")


def test_strict_refuses_in_one_line_and_writes_nothing(tmp_path, capsys):
    net = _with_weak_points(tmp_path)
    out_dir = tmp_path / "res"
    rc, out, err = _main(capsys, net, "--strict", "--out", out_dir)
    assert rc == 2 and out == ""
    assert err.startswith("error: point 'LOST'") and err.count("\n") == 1
    assert not out_dir.exists()
    net.write_text(net.read_text().replace('<point id="LOST" adj="xyz" />\n', "").replace(
        '<obs from="K3">\n  <distance to="LOST" val="50.0" stdev="1.0" />\n</obs>\n', ""))
    rc, out, err = _main(capsys, net, "--strict")
    assert rc == 2 and err.startswith("error: point 'FLAT' not determined by the observations")


# --------------------------------------------------------------------------- options and files
@pytest.mark.parametrize("opt", [["--datum", "free"], ["--sigma-um", "3"], ["--mdb-limit-sigma", "5"], ["--scales"],
                                 ["--solver", "auto"], ["--seed", "0"], ["--points", "p.csv"]])
def test_options_of_the_distance_path_are_refused(capsys, tmp_path, opt):
    out_dir = tmp_path / "res"
    rc, out, err = _main(capsys, EX / "station_control.xml", *opt, "--out", out_dir)
    assert rc == 2 and err.count("\n") == 1
    name = opt[0] if opt[0] != "--no-snooping" else "--snooping/--no-snooping"
    assert err.startswith(f"error: {name} does not apply to a gama-local input")
    assert not out_dir.exists()


def test_out_written_whole_and_equal_to_json(capsys, tmp_path):
    out_dir = tmp_path / "res"
    rc, out, err = _main(capsys, EX / "station_control.xml", "--out", out_dir, "--json",
                         "--alpha", "0.01", "--variance-factor", "unknown", "--test-method", "b-method")
    assert rc == 0, err
    from multilat.network.io.files import table_format

    table = f"observations.{table_format('observations', 'auto')}"       # adjust-general/2: every row
    assert sorted(p.name for p in out_dir.iterdir()) == sorted([table, "points.csv", "result.json"])
    doc = json.loads(out)
    assert json.loads((out_dir / "result.json").read_text()) == doc
    assert doc["tests"]["test"] == "tau" and doc["tests"]["alpha0"] == 0.01
    lines = (out_dir / "points.csv").read_text().splitlines()
    assert lines[0].startswith("point,x_m,y_m,z_m") and len(lines) == 1 + len(doc["points"])


def test_summary_and_detection_by_root_element(capsys, tmp_path):
    """A gama-local file without the .xml suffix is recognised by its root element."""
    net = tmp_path / "net.dat"
    net.write_bytes((EX / "station_control.xml").read_bytes())
    rc, out, err = _main(capsys, net)
    assert rc == 0, err
    assert "gama-local" in out and "σ0 = 0.7566" in out and "datum: given by 5 fixed point(s)" in out
    assert "w-test: α0 = 0.00067" in out and "Šidák: 15 w-tests" in out and "note: approximate coordinates computed for 11 point(s)" in out


def test_fixed_global_alpha(capsys):
    """--test-method fixed (default α_global 0.05, as the distance path): two_trackers' vᵀPv 49.72 on
    41 dof passes at 5 % (χ²_0.95(41) = 56.94, gama-local's own test passes too) and fails the
    B-method's α 0.22 (critical 47.58): the option is applied, not ignored."""
    rc, out, err = _main(capsys, EX / "two_trackers.xml", "--json", "--test-method", "fixed")
    assert rc == 0, err
    gt = json.loads(out)["global_test"]
    assert gt["alpha"] == 0.05 and gt["method"] == "fixed" and gt["passed"] is True
    assert gt["critical"] == pytest.approx(scipy.stats.chi2.ppf(0.95, 41), rel=1e-9)
    rc, out, err = _main(capsys, EX / "two_trackers.xml", "--json", "--test-method", "b-method")
    gt = json.loads(out)["global_test"]
    assert gt["method"] == "b-method" and gt["passed"] is False and gt["alpha"] > 0.2
    rc, out, err = _main(capsys, EX / "two_trackers.xml", "--alpha-global", "0.01", "--test-method", "b-method")
    assert rc == 2 and err.startswith("error: --alpha-global goes with --test-method fixed")


def test_default_test_procedure_is_the_distance_paths(capsys):
    """One rule for both paths (statistics.test_levels, --test-method auto): 90 rows tested, so the
    B-method's family-wise α (1 - 0.999^90 = 0.086) exceeds α_family 0.01 and Šidák's α0 =
    1 - 0.99^(1/90) runs; the global test is the variance factor's at 0.01, both tails."""
    rc, out, err = _main(capsys, EX / "two_trackers.xml", "--json", "--observations")
    doc = json.loads(out)
    gt, t = doc["global_test"], doc["tests"]
    n = int(sum(1 for o in doc["observations"] if o["redundancy"] > 1e-9))
    a0 = 1 - 0.99 ** (1 / n)
    assert gt["method"] == "sidak" and gt["alpha"] == 0.01 and gt["passed"] is True
    assert t["alpha0"] == pytest.approx(a0, rel=1e-12)
    assert t["critical"] == pytest.approx(scipy.stats.norm.ppf(1 - a0 / 2), rel=1e-9)
    assert "Šidák" in t["rule"]


def test_a_network_without_datum_is_refused_not_emptied(capsys, tmp_path):
    """Every point free, none a datum point (lower-case adj): every point is undetermined. Leaving
    them all out would adjust nothing: refused in one line instead."""
    net = tmp_path / "nodatum.xml"
    net.write_text((EX / "two_trackers.xml").read_text().replace('adj="XYZ"', 'adj="xyz"'))
    rc, out, err = _main(capsys, net, "--json")
    assert rc == 2 and out == "" and err.count("\n") == 1
    assert err.startswith("error: point 'T1' (and 16 more") and "datum defect 4, no datum points" in err


def test_json_keys_follow_the_vocabulary():
    """Every key follows multilat's output vocabulary; the keys of the two id maps (`points`,
    `parameters`, in vocabulary.ID_MAPS) are ids and only their values are checked."""
    from multilat.cli.general_adjust import compute
    from multilat.vocabulary import ID_MAPS, document_problems

    doc, _, _ = compute(EX / "two_trackers.xml", alpha=0.001, variance_factor="known", strict=False)
    assert {"points", "parameters"} <= ID_MAPS
    assert document_problems(doc) == []
    doc["points"]["T1"]["xyz_u_m"] = doc["points"]["T1"].pop("xyz_std_m")     # a value's key is still checked
    assert any(p.startswith("$.points[T1].xyz_u_m") for p in document_problems(doc))


# --------------------------------------------------------------------------- without_points
GAMA3D = ROOT / "tests" / "data" / "gama3d"


def _rows(net):
    """Every row as (kind, {key: point id or set name}, value, label)."""
    ids = net.points.ids
    out = []
    for b in net.blocks:
        for k in range(b.n_rows):
            ref = {key: (b.names[key][int(v[k])] if key in b.names else
                         ids[int(v[k])] if key not in ("axis", "component") else int(v[k]))
                   for key, v in b.index.items()}
            out.append((b.kind, ref, float(b.value[k]), b.labels[k] if len(b.labels) == b.n_rows else ""))
    return out


def test_without_points_keeps_every_other_row_and_its_set():
    """Removing S2 (a station with one direction set) from direction_sets: every row not touching S2
    is kept with the same set name and value, S2's set is gone from the layout."""
    from multilat.network.adjust.general import System, read_gama_input, without_points

    net = read_gama_input(GAMA3D / "direction_sets.xml")
    out, n = without_points(net, ["S2"])
    before = [r for r in _rows(net) if "S2" not in r[1].values()]
    assert _rows(out) == before and n == len(_rows(net)) - len(before) > 0
    names = System(out).layout.names
    assert not any(x.startswith("orientation:S2#") or x.endswith(":S2") for x in names)
    assert sum(x.startswith("orientation:S1#") for x in names) == 3


def test_without_points_keeps_the_covariance_of_the_remaining_rows():
    from multilat.network.adjust.general import read_gama_input, without_points

    net = read_gama_input(GAMA3D / "vectors.xml")
    (vec,) = [b for b in net.blocks if b.kind == "coordinate_difference"]
    ids = net.points.ids
    keep = np.array([ids[f] != "G5" and ids[t] != "G5" for f, t in zip(vec.index["from"], vec.index["to"])])
    assert 0 < keep.sum() < len(keep)
    out, _ = without_points(net, ["G5"])
    (vec2,) = [b for b in out.blocks if b.kind == "coordinate_difference"]
    assert np.array_equal(vec2.cov, vec.cov[np.ix_(keep, keep)]) and np.array_equal(vec2.value, vec.value[keep])
    assert "G5" not in out.points.ids and out.points.n == net.points.n - 1
