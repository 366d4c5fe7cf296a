"""`multilat lbb` through main([...]): JSON outputs, files, one-line errors with exit 2."""

import json
from pathlib import Path

import numpy as np
import pytest

from multilat.cli import main
from multilat.lbb.config import DEFAULT_CONFIG, load_config
from multilat.lbb.simulate import base_xyz
from multilat.lbb.trilateration import edges_from_points

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "lbb" / "edges.csv"


def _one_error_line(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:"), err
    return err[0]


def _write_edges(path, pts):
    e = edges_from_points(base_xyz(load_config()), np.asarray(pts))
    rows = "".join(f"P{i},{','.join(repr(float(v)) for v in r)}\n" for i, r in enumerate(e))
    path.write_text("point,l12_m,l13_m,l23_m,l1_m,l2_m,l3_m\n" + rows)


def test_trilaterate_json(tmp_path, capsys):
    pts = np.array([[0.1, 0.2, 0.3], [0.4, 0.1, 0.05]])
    p = tmp_path / "e.csv"
    _write_edges(p, pts)
    assert main(["lbb", "trilaterate", str(p), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [q["point"] for q in out["points"]] == ["P0", "P1"]
    np.testing.assert_allclose([q["xyz_m"] for q in out["points"]], pts, atol=1e-12)
    assert main(["lbb", "trilaterate", str(EXAMPLE)]) == 0
    assert "P7" in capsys.readouterr().out


@pytest.mark.parametrize("edit, pattern", [
    (lambda r: r.replace("P1,0.564", "P1,-0.564", 1), r"e\.csv:3: column 'l12_m': must be > 0"),
    (lambda r: r.replace("P1,0.564,0.564,0.564,", "P1,0.564,0.564,1.5,", 1),
     r"e\.csv:3: point P1: base face 1-2-3 violates the triangle inequality"),
    (lambda r: r.replace("P0,", "P1,", 1), r"duplicate point id"),
])
def test_trilaterate_bad_rows(tmp_path, capsys, edit, pattern):
    p = tmp_path / "e.csv"
    _write_edges(p, [[0.1, 0.2, 0.3], [0.4, 0.1, 0.05]])
    p.write_text(edit(p.read_text()))
    assert main(["lbb", "trilaterate", str(p)]) == 2
    import re

    assert re.search(pattern, _one_error_line(capsys))


def test_trilaterate_singular_point_is_one_line_error(tmp_path, capsys):
    p = tmp_path / "e.csv"
    _write_edges(p, [[0.1, 0.2, 0.3], [0.3, 0.2, 0.0]])
    assert main(["lbb", "trilaterate", str(p), "--on-singular", "error"]) == 2
    assert "point P1: the tool socket is at the base plane" in _one_error_line(capsys)


def test_trilaterate_reports_singular_points_beside_the_valid_ones(tmp_path, capsys):
    """Default --on-singular report: the valid points are printed (exact to 1e-9 m), the singular one
    is flagged with its reason and z², never NaN, and the exit code is 3."""
    p = tmp_path / "e.csv"
    pts = [[0.1, 0.2, 0.3], [0.3, 0.2, 0.0], [0.25, 0.1, 0.4]]
    _write_edges(p, pts)
    assert main(["lbb", "trilaterate", str(p), "--json"]) == 3
    doc = json.loads(capsys.readouterr().out)
    assert [q["valid"] for q in doc["points"]] == [True, False, True] and doc["n_singular"] == 1
    bad = doc["points"][1]
    assert bad["xyz_m"] is None and "base plane" in bad["reason"] and abs(bad["z_squared_m2"]) < 1e-12
    np.testing.assert_allclose([doc["points"][i]["xyz_m"] for i in (0, 2)], [pts[0], pts[2]], atol=1e-9)
    assert main(["lbb", "trilaterate", str(p)]) == 3
    assert "1 of 3 point(s) not trilaterated" in capsys.readouterr().out
    _write_edges(p, [pts[0], pts[2]])
    assert main(["lbb", "trilaterate", str(p)]) == 0


def test_simulate_json_and_out(tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["lbb", "simulate", "--grid", "3", "--trials", "40", "--seed", "3", "--json", "--out", str(out)])
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert res["trials"] == 40 and res["method"] == "procedure"
    assert len(res["points"]) == res["n_points"] > 5
    p0 = res["points"][0]
    assert len(p0["nominal_m"]) == 3 and len(p0["error_mean_m"]) == 3 and len(p0["std_m"]) == 3
    assert res["std_max_m"] == pytest.approx(max(max(p["std_m"]) for p in res["points"]))
    assert 1e-7 < res["std_max_m"] < 1e-4
    names = {f.name for f in out.iterdir()}
    assert {"points.csv", "sides.csv", "summary.json", "fig8_mean_error.png", "fig8_std.png",
            "fig9_cdf.png"} <= names
    assert not [n for n in names if n.endswith(".part")]
    # same seed, same numbers; direct method runs too
    assert main(["lbb", "simulate", "--grid", "3", "--trials", "40", "--seed", "3", "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["points"][0]["error_mean_m"] == p0["error_mean_m"]
    assert main(["lbb", "simulate", "--grid", "2", "--method", "direct", "--trials", "20", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["method"] == "direct" and d["trials"] == 20


def test_simulate_bad_config_and_options(tmp_path, capsys):
    text = DEFAULT_CONFIG.read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("side_draws = 100", "side_drawz = 100"))
    assert main(["lbb", "simulate", "--config", str(bad), "--json"]) == 2
    line = _one_error_line(capsys)
    assert "bad.toml" in line and "monte_carlo" in line
    bad.write_text(text.replace("init_draws = 2000", 'init_draws = "many"'))
    assert main(["lbb", "simulate", "--config", str(bad)]) == 2
    assert "monte_carlo.init_draws" in _one_error_line(capsys)
    bad.write_text(text.replace("[monte_carlo]", "[monte_carlo"))
    assert main(["lbb", "simulate", "--config", str(bad)]) == 2
    assert "malformed TOML" in _one_error_line(capsys)
    assert main(["lbb", "simulate", "--method", "magic", "--grid", "2"]) == 2
    assert "method" in _one_error_line(capsys)
    assert main(["lbb", "simulate", "--trials", "1"]) == 2
    assert "--trials" in _one_error_line(capsys)
    assert main(["lbb", "simulate", "--where", "moon"]) == 2
    assert "--where" in _one_error_line(capsys)


def test_compare_reference(tmp_path, capsys):
    cfg = load_config()
    ref = cfg.comparison.points()[:4]
    e = tmp_path / "m.csv"
    _write_edges(e, ref + np.array([1e-6, -1e-6, 2e-6]))
    r = tmp_path / "r.csv"
    r.write_text("point,x_m,y_m,z_m\n" + "".join(f"P{i},{float(a)!r},{float(b)!r},{float(c)!r}\n" for i, (a, b, c) in enumerate(ref)))
    assert main(["lbb", "compare", str(e), str(r), "--trials", "50", "--json", "--out", str(tmp_path / "c")]) == 0
    res = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose([p["difference_m"] for p in res["points"]], [[1e-6, -1e-6, 2e-6]] * 4, atol=1e-12)
    assert (tmp_path / "c" / "fig7_comparison.png").is_file()
    # per-axis statistics, recomputed here from the per-point fields (an independent evaluation)
    d = np.array([p["difference_m"] for p in res["points"]])
    m = np.array([p["error_mean_mc_m"] for p in res["points"]])
    sd = np.array([p["std_mc_m"] for p in res["points"]])
    z = (d - m) / sd
    np.testing.assert_allclose([res["normalised_rms_per_axis"][a] for a in "xyz"], np.sqrt((z**2).mean(0)),
                               rtol=1e-12)
    np.testing.assert_allclose([res["fraction_inside_2sigma_per_axis"][a] for a in "xyz"],
                               (np.abs(z) <= 2).mean(0), rtol=1e-12)
    assert res["method"] == "procedure"
    r.write_text("point,x_m,y_m,z_m\nQ9,0.1,0.1,0.1\n")
    assert main(["lbb", "compare", str(e), str(r)]) == 2
    assert "without edges: Q9" in _one_error_line(capsys)
