"""``multilat adjust`` through main(): summary, --json keys, --out files, and bad input giving one
line on stderr, exit 2 and no file written."""

import json
from pathlib import Path

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.io.files import read_observations, read_points, read_reference_lengths, table_format

EX = Path(__file__).resolve().parents[1] / "examples" / "network"
OBS = EX / "small_volume_obs.csv"
REF = EX / "small_volume_refs.csv"
PTS = EX / "small_volume_points.csv"
TRUTH = EX / "small_volume_truth.csv"


def _run(capsys, args):
    rc = main(args)
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_json_has_the_contract_keys(capsys):
    rc, out, err = _run(capsys, ["adjust", str(OBS), "--points", str(PTS), "--references", str(REF),
                                 "--datum", "321:B,D,C", "--json"])
    assert rc == 0, err
    doc = json.loads(out)
    for k in ("stations", "targets", "sigma0", "dof", "global_test", "outliers", "reference_lengths"):
        assert k in doc
    assert set(doc["stations"]) == {"A", "B", "C", "D"} and len(doc["targets"]) == 14
    for v in doc["stations"].values():
        assert set(v) >= {"xyz_m", "offset_m", "cov_m2"} and np.shape(v["cov_m2"]) == (3, 3)
    assert set(doc["global_test"]) >= {"statistic", "critical", "passed"}
    assert doc["dof"] == 56 - (3 * 4 + 3 * 14 + 4 - 6)
    assert len(doc["reference_lengths"]) == 9
    for c in doc["reference_lengths"]:
        assert set(c) >= {"target_a", "target_b", "length_m", "length_std_m", "reference_m", "difference_m"}
        # synthetic network: the triplet lengths are true to the noise (k = 4 on the reported u)
        assert abs(c["difference_m"]) < 4 * c["length_std_m"]
    # 3-2-1 frame of the paper: B at origin, D on x, C in the xy-plane
    assert np.allclose(doc["stations"]["B"]["xyz_m"], 0, atol=1e-12)
    # the offsets of the synthetic truth (A 1.234, B -0.871, C 2.105, D 0.412 mm) within 4 u
    truth = {"A": 1.234e-3, "B": -0.871e-3, "C": 2.105e-3, "D": 0.412e-3}
    for sid, o in truth.items():
        st = doc["stations"][sid]
        assert abs(st["offset_m"] - o) < 4 * st["offset_std_m"]


def test_summary_and_out_files(capsys, tmp_path):
    out_dir = tmp_path / "res"
    rc, out, err = _run(capsys, ["adjust", str(OBS), "--points", str(PTS), "--references", str(REF),
                                 "--out", str(out_dir)])
    assert rc == 0, err
    assert "σ0 =" in out and "global χ² test" in out and "offset" in out
    names = sorted(p.name for p in out_dir.iterdir())
    fmt = table_format("observations", "auto")          # parquet where pyarrow is installed
    assert names == sorted(["reference_lengths.csv", f"observations.{fmt}", "residuals.png", "result.json",
                            "stations.csv", "targets.csv", "top_view.png", "view_3d.png"])
    assert not any(p.name.endswith(".part") for p in tmp_path.iterdir())
    rec = {t["name"]: t for t in json.loads((out_dir / "result.json").read_text())["tables"]}["observations"]
    assert rec["file"] == f"observations.{fmt}" and rec["n_rows"] == 56     # 56 distances in the file


def test_blunder_with_four_heads_is_detected_but_not_located(capsys, tmp_path):
    """With 4 heads every target has 4 distances and 3 unknowns: the 4 w-tests of a target are
    perfectly correlated, so a 20σ fault is detected but cannot be located. Snooping must say so
    and reject nothing (rather than drop a good observation 3 times out of 4)."""
    lines = OBS.read_text().splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith("C,9,"))
    st, tg, d, s = lines[i].split(",")
    lines[i] = f"{st},{tg},{float(d) + 20 * 4.7e-6:.7f},{s}"
    p = tmp_path / "obs.csv"
    p.write_text("\n".join(lines) + "\n")
    rc, out, err = _run(capsys, ["adjust", str(p), "--points", str(PTS), "--json"])
    assert rc == 0, err
    doc = json.loads(out)
    assert doc["outliers"] == []
    assert sorted((o["station"], o["target"]) for o in doc["unlocated"]) == [
        ("A", "9"), ("B", "9"), ("C", "9"), ("D", "9")]
    assert abs(doc["unlocated"][0]["w"]) > 3.29
    rc, out, err = _run(capsys, ["adjust", str(p), "--points", str(PTS)])
    assert "cannot be located" in out


@pytest.mark.parametrize("content, msg", [
    ("station,target,distance_m,sigma_m\nA,1,nan,4e-6\n", "column 'distance_m': must be finite"),
    ("station,target,distance_m,sigma_m\nA,1,-1.0,4e-6\n", "must be > 0"),
    ("station,target,distance_m,sigma_m\nA,1,0,4e-6\n", "must be > 0"),
    # repeated readings of a pair are accepted (issue 16): the network is then judged on its structure
    ("station,target,distance_m,sigma_m\nA,1,1.0,4e-6\nA,1,1.1,4e-6\n", "at least 3 stations"),
    ("", "empty file"),
    ("station,target,dist\nA,1,1.0\n", "header lacks column"),
    ("station,target,distance_m,sigma_m\nA,1,1.0,4e-6\nA,2,1.1,4e-6\nA,3,1.2,4e-6\nA,4,1.0,4e-6\nA,5,1.3,4e-6\n",
     "at least 3 stations"),
    ("station,target,distance_m,sigma_m\nA,1,1.0\n", "expected 4 cells"),
    ("station,target,distance_m,sigma_m\nA,A,1.0,4e-6\n", "both as a station and as a target"),
    ("station,target,distance_m,sigma_m\nA,1,1.0,0\n", "column 'sigma_m': must be > 0"),
])
def test_bad_observation_files(capsys, tmp_path, content, msg):
    p = tmp_path / "bad.csv"
    p.write_text(content)
    out_dir = tmp_path / "out"
    rc, out, err = _run(capsys, ["adjust", str(p), "--out", str(out_dir)])
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and msg in lines[0], err
    assert not out_dir.exists()
    assert [x.name for x in tmp_path.iterdir()] == ["bad.csv"]


def test_bad_reference_and_points_files(capsys, tmp_path):
    ref = tmp_path / "ref.csv"
    ref.write_text("target_a,target_b,length_m\n1,99,0.15\n")
    rc, _, err = _run(capsys, ["adjust", str(OBS), "--references", str(ref), "--out", str(tmp_path / "o")])
    assert rc == 2 and "unknown point id '99'" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()
    ref.write_text("target_a,target_b,length_m\n1,2,0.15\n2,1,0.15\n")
    with pytest.raises(MultilatError, match="duplicate reference length"):
        read_reference_lengths(ref)
    pts = tmp_path / "p.csv"
    pts.write_text("point,x_m,y_m,z_m\nA,0,0,0\nA,1,0,0\n")
    with pytest.raises(MultilatError, match="p.csv:3: duplicate point 'A'"):
        read_points(pts)
    rc, _, err = _run(capsys, ["adjust", str(OBS), "--datum", "321:A,B"])
    assert rc == 2 and "exactly three" in err


def test_unknown_column_warns_and_sigma_sources(tmp_path, capsys):
    p = tmp_path / "o.csv"
    p.write_text("station,target,distance_m,comment\nA,1,1.0,x\nB,1,1.2,y\n")
    with pytest.warns(UserWarning, match="unknown column"):
        obs = read_observations(p, sigma_m=5e-6)
    assert np.all(obs.sigma_m == 5e-6)
    # no sigma at all: the distance model of the seed instrument (about 4-5 um for these lengths)
    p.write_text("station,target,distance_m\nA,1,1.0\nB,1,1.2\n")
    obs = read_observations(p)
    assert np.all((obs.sigma_m > 2e-6) & (obs.sigma_m < 1e-5))


def test_interrupted_out_leaves_no_half_files(tmp_path, monkeypatch, capsys):
    import multilat.report.network_figures as nf

    def boom(res, out_dir):
        raise KeyboardInterrupt

    monkeypatch.setattr(nf, "save_figures", boom)
    out_dir = tmp_path / "res"
    rc = main(["adjust", str(OBS), "--points", str(PTS), "--out", str(out_dir)])
    assert rc == 130
    assert not out_dir.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("signal_exc, rc, said", [(KeyboardInterrupt, 130, "interrupted"),
                                                   ("terminated", 143, "terminated")])
def test_signal_wrapped_by_numba_is_still_the_signal(tmp_path, monkeypatch, capsys, signal_exc, rc, said):
    """A signal that lands while numba unpickles or runs a compiled function surfaces as a SystemError
    ("... returned a result with an exception set") caused by the signal's exception (seen with Ctrl-C
    2 s into `propagate`): still an interruption (130) or a termination (143), not an internal error;
    --out left uncreated."""
    import multilat.report.network_figures as nf
    from multilat.cli.app import Terminated

    sig = Terminated if signal_exc == "terminated" else signal_exc

    def boom(res, out_dir):
        try:
            raise sig()
        except BaseException as e:
            raise SystemError("CPUDispatcher(<function solve_frozen>) returned a result with an exception "
                              "set") from e

    monkeypatch.setattr(nf, "save_figures", boom)
    out_dir = tmp_path / "res"
    assert main(["adjust", str(OBS), "--points", str(PTS), "--out", str(out_dir)]) == rc
    err = capsys.readouterr().err
    assert said in err and "internal error" not in err
    assert not out_dir.exists() and list(tmp_path.iterdir()) == []


def test_angles_read_and_figures_take_axes(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from multilat.network.adjust.distance.adjust import adjust
    from multilat.report.network_figures import plot_3d, plot_residuals, plot_top_view

    p = tmp_path / "o.csv"
    p.write_text("station,target,distance_m,sigma_m,azimuth_rad,elevation_rad\nA,1,1.0,5e-6,0.1,\n"
                 "B,1,1.2,5e-6,0.2,0.3\n")
    obs = read_observations(p)
    assert obs.azimuth_rad[0] == 0.1 and np.isnan(obs.elevation_rad[0])
    p.write_text("station,target,distance_m,azimuth_rad\nA,1,1.0,0.1\n")
    with pytest.raises(MultilatError, match="both azimuth_rad and elevation_rad"):
        read_observations(p, sigma_m=5e-6)
    res = adjust(read_observations(OBS), points=read_points(PTS))
    fig = plt.figure()
    ax1 = fig.add_subplot(1, 3, 1)
    ax2 = fig.add_subplot(1, 3, 2)
    ax3 = fig.add_subplot(1, 3, 3, projection="3d")
    assert plot_residuals(res, ax=ax1) is ax1
    assert plot_top_view(res, ax=ax2, magnify=100) is ax2
    assert plot_3d(res, ax=ax3, magnify=100) is ax3
    # one residual marker per used observation, per head
    assert sum(len(line.get_xdata()) for line in ax1.get_lines()[:4]) == 56
    plt.close(fig)


def test_control_datum_from_the_command_line(capsys):
    # hold heads B, C, D at their true coordinates: they appear unchanged in the output and the
    # triplet lengths agree with the free datum's to the noise level of an over-constraint
    rc, out, err = _run(capsys, ["adjust", str(OBS), "--points", str(TRUTH), "--datum", "control:B,C,D",
                                 "--references", str(REF), "--json"])
    assert rc == 0, err
    doc = json.loads(out)
    truth = read_points(TRUTH)
    for sid in "BCD":
        np.testing.assert_allclose(doc["stations"][sid]["xyz_m"], truth.get(sid), atol=1e-12)
        assert np.all(np.asarray(doc["stations"][sid]["cov_m2"]) == 0)
    assert doc["dof"] == 4 + 3          # 9 fixed coordinates instead of a 6-parameter datum
    for c in doc["reference_lengths"]:
        assert abs(c["difference_m"]) < 4 * c["length_std_m"]


def test_from_distances_alone_same_invariants_as_from_points():
    from multilat.network.adjust.distance.adjust import adjust

    obs = read_observations(OBS)
    a = adjust(obs, rng=1)                              # initial values from the distances alone
    b = adjust(obs, points=read_points(PTS))            # initial values from approximate points
    np.testing.assert_allclose(a.offset_m, b.offset_m, atol=1e-9)
    for x, y in [("1", "14"), ("A", "7"), ("B", "D")]:
        assert a.interpoint_distance(x, y).length_m == pytest.approx(b.interpoint_distance(x, y).length_m,
                                                                     abs=1e-9)


CAMPAIGN = Path(__file__).resolve().parents[1] / "examples" / "campaign"


def test_adjust_reads_raw_readings_like_correct_then_adjust(capsys, tmp_path):
    """``adjust RAW --environment ENV`` is ``correct RAW --out OBS`` followed by ``adjust OBS``: same
    σ0, offsets and coordinates (to float round trip of the written CSV: 1e-9 m on 17 digits)."""
    env = ["--environment", str(CAMPAIGN / "environment.csv"), "--heights", str(CAMPAIGN / "heights.csv")]
    rc, out, err = _run(capsys, ["adjust", str(CAMPAIGN / "raw.csv"), *env, "--json"])
    assert rc == 0, err
    direct = json.loads(out)
    obs = tmp_path / "obs.csv"
    rc, _, err = _run(capsys, ["correct", str(CAMPAIGN / "raw.csv"), *env, "--out", str(obs)])
    assert rc == 0, err
    rc, out, err = _run(capsys, ["adjust", str(obs), "--json"])
    assert rc == 0, err
    twostep = json.loads(out)
    assert direct["dof"] == twostep["dof"] == 4
    wc = direct["with_correlations"]          # G C Gᵀ with the sensors' correlations (campaign.correlated)
    assert set(wc["stations"]) == set(direct["stations"]) and "with_correlations" not in twostep
    diag_max = max(np.sqrt(np.diag(t["cov_m2"])).max() for t in direct["targets"].values())
    assert wc["target_std_diagonal_max_m"] == pytest.approx(diag_max, rel=1e-12)
    assert all(v["offset_std_m"] > 0 for v in wc["stations"].values())
    assert direct["sigma0"] == pytest.approx(twostep["sigma0"], rel=1e-6)
    for sid, st in direct["stations"].items():
        assert st["offset_m"] == pytest.approx(twostep["stations"][sid]["offset_m"], abs=1e-9)
        np.testing.assert_allclose(st["xyz_m"], twostep["stations"][sid]["xyz_m"], atol=1e-9)


def test_adjust_raw_options_are_checked(capsys, tmp_path):
    rc, _, err = _run(capsys, ["adjust", str(CAMPAIGN / "raw.csv")])
    assert rc == 2 and "no environment" in err and "Traceback" not in err
    rc, _, err = _run(capsys, ["adjust", str(CAMPAIGN / "raw.csv"), "--environment",
                               str(CAMPAIGN / "environment.csv"), "--sigma-um", "5"])
    assert rc == 2 and "--sigma-um" in err
    rc, _, err = _run(capsys, ["adjust", str(OBS), "--environment", str(CAMPAIGN / "environment.csv")])
    assert rc == 2 and "raw readings" in err


def _write_obs(path, H, T, off, sigma=5e-6, seed=0):
    rng = np.random.default_rng(seed)
    rows = ["station,target,distance_m,sigma_m"]
    for i, h in enumerate(H):
        for j, t in enumerate(T):
            d = np.linalg.norm(h - t) + off[i] + rng.normal(0, sigma)
            rows.append(f"S{i},T{j},{d:.9f},{sigma}")
    path.write_text("\n".join(rows) + "\n")


@pytest.mark.parametrize("case", ["coplanar", "collinear"])
def test_degenerate_network_from_distances_alone_is_named(capsys, tmp_path, case):
    """No --points: the initial values come from the distances; the cause is still named."""
    rng = np.random.default_rng(7)
    off = rng.normal(0, 1.5e-3, 5)
    if case == "coplanar":
        ang = np.linspace(0, 2 * np.pi, 5, endpoint=False)
        H = np.c_[1.3 * np.cos(ang), 1.1 * np.sin(ang), np.zeros(5)]
        T = rng.uniform(-0.6, 0.6, (15, 3)) + [0, 0, 0.8]
    else:
        H = np.array([[0, 0, 0], [2.5, 0, 0.2], [1.2, 2.1, -0.3], [1.1, 0.9, 1.9], [1.8, 1.2, -1.1]])
        u = np.array([1.0, 0.6, 0.3]) / np.linalg.norm([1.0, 0.6, 0.3])
        T = np.outer(np.linspace(-0.8, 0.8, 15), u) + [1.3, 0.9, 0.3]
    p = tmp_path / f"{case}.csv"
    _write_obs(p, H, T, off)
    rc, out, err = _run(capsys, ["adjust", str(p), "--out", str(tmp_path / "o")])
    assert rc == 2
    lines = err.strip().splitlines()
    want = "5 stations are (nearly) coplanar" if case == "coplanar" else "15 targets are (nearly) collinear"
    assert len(lines) == 1 and want in lines[0] and "near-degenerate geometry" in lines[0], err
    assert not (tmp_path / "o").exists()


def test_control_datum_with_approximate_points_is_refused_as_inconsistent(capsys):
    """The example points are approximate (truth + ~5 mm): held fixed as control they contradict
    the distances. The error says so (it used to blame the distances through data snooping)."""
    rc, out, err = _run(capsys, ["adjust", str(OBS), "--points", str(PTS), "--datum", "control"])
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "control coordinates inconsistent with the distances" in lines[0], err
    assert "σ0 =" in lines[0] and "global test" in lines[0] and "snooping" not in lines[0]
    # the true coordinates are consistent: accepted, global test passed
    rc, out, err = _run(capsys, ["adjust", str(OBS), "--points", str(TRUTH), "--datum", "control",
                                 "--json"])
    assert rc == 0, err
    assert json.loads(out)["global_test"]["passed"]


def test_squared_cost_reports_unit_and_no_snooping(capsys):
    rc, out, err = _run(capsys, ["adjust", str(OBS), "--points", str(PTS), "--cost", "squared", "--json"])
    assert rc == 0, err
    doc = json.loads(out)
    assert doc["sigma0_unit"] == "m^2" and doc["snooping"] is False and doc["outliers"] == []
    rc, out, err = _run(capsys, ["adjust", str(OBS), "--points", str(PTS), "--cost", "squared"])
    assert "m²" in out and "data snooping not done for this cost" in out
    assert "no observation rejected" not in out
    rc, out, err = _run(capsys, ["adjust", str(OBS), "--points", str(PTS), "--json"])
    doc = json.loads(out)
    assert doc["sigma0_unit"] == "1" and doc["snooping"] is True


def test_fix_offsets_per_station(capsys):
    rc, out, err = _run(capsys, ["adjust", str(OBS), "--points", str(PTS), "--json",
                                 "--fix-offsets-um", "A=1234, B=-871"])
    assert rc == 0, err
    doc = json.loads(out)
    st = doc["stations"]
    assert st["A"]["offset_m"] == pytest.approx(1.234e-3, abs=1e-15) and not st["A"]["offset_estimated"]
    assert st["B"]["offset_m"] == pytest.approx(-0.871e-3, abs=1e-15) and not st["B"]["offset_estimated"]
    assert st["C"]["offset_estimated"] and st["D"]["offset_estimated"]
    # two offsets fixed at their true values: C and D still estimated, within 4 u of the truth
    for sid, o in (("C", 2.105e-3), ("D", 0.412e-3)):
        assert abs(st[sid]["offset_m"] - o) < 4 * st[sid]["offset_std_m"]
    assert doc["dof"] == 4 + 2
    rc, out, err = _run(capsys, ["adjust", str(OBS), "--points", str(PTS), "--json", "--fix-offsets-um", "0"])
    assert rc == 0 and not any(v["offset_estimated"] for v in json.loads(out)["stations"].values())
    for bad, msg in (("A=1234,Q=5", "unknown station id 'Q'"), ("A=x", "not a number"),
                     ("12x", "expected a number"), ("A=1,A=2", "given twice")):
        rc, _, err = _run(capsys, ["adjust", str(OBS), "--fix-offsets-um", bad])
        lines = err.strip().splitlines()
        assert rc == 2 and len(lines) == 1 and msg in lines[0], (bad, err)


def test_unknown_point_ids_warn_and_reference_errors_name_the_line(capsys, tmp_path):
    pts = tmp_path / "pts.csv"
    pts.write_text(PTS.read_text() + "ZZ,0,0,0\nYY,1,1,1\n")
    rc, out, err = _run(capsys, ["adjust", str(OBS), "--points", str(pts), "--json"])
    assert rc == 0
    assert "warning: points: 2 id(s) not in the observations, ignored: ZZ, YY" in err
    ref = tmp_path / "ref.csv"
    ref.write_text("# comment\ntarget_a,target_b,length_m\n1,2,0.15\n\n1,99,0.15\n")
    rc, _, err = _run(capsys, ["adjust", str(OBS), "--references", str(ref)])
    assert rc == 2 and err.strip() == f"error: {ref}:5: unknown point id '99'"


def test_sparse_solver_reads_any_column_order(capsys, tmp_path):
    """The fast reader wants station,target,distance_m[,sigma_m]; another order or extra columns go
    through the general reader to the same sparse solver (same σ0 to 1e-9 relative)."""
    rows = [line.split(",") for line in OBS.read_text().strip().splitlines() if not line.startswith("#")]
    p = tmp_path / "reordered.csv"
    p.write_text("\n".join(",".join([r[2], *r[:2], *r[3:]]) for r in rows) + "\n")
    rc, out, err = _run(capsys, ["adjust", str(OBS), "--solver", "sparse", "--json"])
    assert rc == 0, err
    ref = json.loads(out)
    rc, out, err = _run(capsys, ["adjust", str(p), "--solver", "sparse", "--json"])
    assert rc == 0, err
    doc = json.loads(out)
    assert doc["solver"] == "sparse" and doc["sigma0"] == pytest.approx(ref["sigma0"], rel=1e-9)


def test_large_documents_are_written_compact(capsys, tmp_path, monkeypatch):
    """Above ``io.INDENT_MAX_ROWS`` rows listed (or targets) the adjust document (stdout and --out's
    result.json) is one line: the same JSON value as the indented document of a small network,
    whitespace and the --out directory's table records aside."""
    import multilat.io as mio

    rc, indented, err = _run(capsys, ["adjust", str(OBS), "--json"])
    assert rc == 0, err
    assert indented.count("\n") > 100
    monkeypatch.setattr(mio, "INDENT_MAX_ROWS", 10)           # the example has 56 distances
    rc, compact, err = _run(capsys, ["adjust", str(OBS), "--json", "--out", str(tmp_path / "o")])
    assert rc == 0, err
    assert compact.count("\n") == 1 and compact.endswith("}\n")
    filed = (tmp_path / "o" / "result.json").read_text(encoding="utf-8")
    assert filed.count("\n") == 1
    a, b, c = json.loads(indented), json.loads(compact), json.loads(filed)
    for d in (a, b, c):
        d.pop("elapsed_s", None)
    assert "tables" not in a and b.pop("tables") == c.pop("tables")
    assert a == b == c
    monkeypatch.setattr(mio, "INDENT_MAX_ROWS", 56)           # the limit itself is still indented
    rc, out, err = _run(capsys, ["adjust", str(OBS), "--json"])
    assert rc == 0 and out.count("\n") > 100
