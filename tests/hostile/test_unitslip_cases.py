"""Issue 25, cases 1, 2 and 8 from the command line: a unit slip in the distances, in σ, in the
control points or in an instrument TOML stops with one line naming the file, the column or key and
the likely unit; the searches that used to run for many minutes on such input are bounded."""

from __future__ import annotations

import subprocess
import time

import pytest

from conftest import CLI, assert_one_line_error, cli_env

ROWS_FROM = 3          # small_volume_obs.csv: two comment lines and the header before the rows


def _scaled(src, dst, column: int, factor: float, fmt: str = "{:.10g}"):
    """``src`` with ``column`` of every data row multiplied by ``factor``."""
    out = []
    for k, line in enumerate(src.read_text().splitlines()):
        if k >= ROWS_FROM:
            c = line.split(",")
            c[column] = fmt.format(float(c[column]) * factor)
            line = ",".join(c)
        out.append(line)
    dst.write_text("\n".join(out) + "\n")
    return dst


def _big_network_csv(path, factor: float):
    """8 stations, 40 targets (15 % of the pairs unobserved), σ 5 µm, distances times ``factor``."""
    from multilat.network.synthetic.generator import synthetic_network

    o = synthetic_network(1, population="shell", n_stations=8, n_targets=40, gap_fraction=0.15).obs
    rows = [f"{o.station_ids[i]},{o.target_ids[j]},{d * factor:.10g},{s:g}"
            for i, j, d, s in zip(o.station_index, o.target_index, o.distance_m, o.sigma_m)]
    path.write_text("station,target,distance_m,sigma_m\n" + "\n".join(rows) + "\n")
    return path


def _run_bounded(args, timeout_s: float):
    """The CLI in a subprocess that must end within ``timeout_s`` (a bound, not a timing: these
    inputs used to run for more than 25 minutes)."""
    t0 = time.monotonic()
    p = subprocess.run(CLI + [str(a) for a in args], capture_output=True, text=True, env=cli_env(),
                       timeout=timeout_s)
    return p.returncode, p.stderr, time.monotonic() - t0


def test_distances_in_mm_stop_with_one_line(ws):
    """Case 1 on the example network: distance_m in mm, sigma_m in metres. Before: exit 0 after the
    minimum search, sigma0 1199 and a 'possible false minimum' warning; now exit 2 within the bound,
    one line naming the file, the columns, the unit and the factor (~1000: σ0 of the valid file is
    1.199, and the scaled network's σ0 is exactly 1000 times it)."""
    obs = _scaled(ws / "obs.csv", ws / "obs_mm.csv", 2, 1000.0)
    rc, err, _ = _run_bounded(["adjust", obs, "--json"], 60)
    assert rc == 2, err
    assert_one_line_error(err, "obs_mm.csv:", "distance_m in mm", "sigma_m", "~1199x",
                          "--variance-factor unknown")


def test_distances_in_mm_larger_network_is_bounded(tmp_path):
    """Case 1 where it hung: 8 stations x 40 targets in mm. Before: every random restart of the
    initial values took seconds to minutes (the first initial values alone ran > 90 s); now the
    restarts stop when one finds the same minimum again, and adjust stops with the unit slip."""
    obs = _big_network_csv(tmp_path / "big_mm.csv", 1000.0)
    rc, err, _ = _run_bounded(["adjust", obs, "--json"], 180)
    assert rc == 2, err
    assert_one_line_error(err, "big_mm.csv:", "distance_m in mm", "sigma_m")


def test_sigma_in_um_stops_with_one_line(ws):
    """Case 2: σ written in µm into sigma_m (4.7 for 4.7e-6). Before: exit 0, σ0 = 0.000, 'global
    test passed', semi-axes of 100 m; now one line naming the column and µm."""
    obs = _scaled(ws / "obs.csv", ws / "obs_sig_um.csv", 3, 1e6)
    ws.fails(["adjust", str(obs)], "obs_sig_um.csv:", "sigma_m written in µm", "4.7 where 4.7e-06 m",
             "--variance-factor unknown")


def test_unit_slip_accepted_with_an_unknown_variance_factor(ws):
    """The way out the message names: σ right up to a common factor, σ0 estimated (here 1.2e-6)."""
    obs = _scaled(ws / "obs.csv", ws / "obs_sig_um.csv", 3, 1e6)
    rc, out, err = ws.run(["adjust", str(obs), "--variance-factor", "unknown", "--json"])
    assert rc == 0, err
    import json

    doc = json.loads(out)
    assert doc["sigma0"] == pytest.approx(1.199e-6, rel=2e-3)   # 1.199 (the valid file) / 1e6


def test_control_points_in_mm_name_the_control_file(ws):
    """Case 8a: control coordinates in mm, distances in metres. Before: 'the adjustment did not
    converge ... check the distances'; now the control file and the scale mismatch (~1000x)."""
    truth = (ws / "obs.csv").parent / "truth.csv"
    rows = ["point,x_m,y_m,z_m", "A,504,938,491", "B,0,0,0", "C,524,-7,909", "D,1050,0,0",
            "1,300,250,200"]
    truth.write_text("\n".join(rows) + "\n")
    ws.fails(["adjust", "{d}/obs.csv", "--points", str(truth), "--datum", "control"],
             "truth.csv:", "control coordinates are ~999x larger", "x_m, y_m, z_m in mm")


@pytest.mark.parametrize("old,new,key", [
    ("beam_offset_m = [-320e-6, 320e-6]", "beam_offset_m = [-320, 320]", "head_common.beam_offset_m"),
    ("tot_m = 11e-6", "tot_m = 11", "target.tot_m"),
    ("toh_std_m = 2e-6", "toh_std_m = 2", "heads.A.toh_std_m"),
])
def test_instrument_unit_slip_names_file_and_key(ws, old, new, key):
    """Case 8b: a value in µm under a metres key of an instrument TOML. Before: a numpy warning
    ('invalid value encountered in sqrt') and 'measured_m must be finite and > 0', or 'measured_m is
    shorter than the transit offset', or (toh_std_m) an adjustment with σ 10^5 too large; now the
    file and the key, and no numpy warning."""
    from importlib import resources

    text = resources.files("multilat").joinpath("presets", "seed2020.toml").read_text(encoding="utf-8")
    assert old in text
    toml = ws / "inst.toml"
    toml.write_text(text.replace(old, new, 1))
    obs = ws / "nosig.csv"
    rows = (ws / "obs.csv").read_text().splitlines()[ROWS_FROM:]
    obs.write_text("station,target,distance_m\n" + "\n".join(",".join(r.split(",")[:3]) for r in rows) + "\n")
    rc, out, err = ws.run(["adjust", str(obs), "--instrument", str(toml)])
    assert rc == 2, err
    assert "warning:" not in err, err
    assert_one_line_error(err, "inst.toml:", key, "µm written in a metres key")


def test_scales_suggestion_is_a_command_the_cli_accepts(ws):
    """Case 8c: the 7th-datum-defect error suggested '--scales A,B', which --scales (a flag)
    refuses; each suggestion is now a command line that runs."""
    line = ws.fails(["adjust", "{d}/obs.csv", "--scales"], "--scales --fixed-scale HEAD")
    assert "--scales A,B" not in line
    rc, out, err = ws.run(["adjust", "{d}/obs.csv", "--scales", "--fixed-scale", "A", "--json"])
    assert rc == 0, err


def test_no_target_seen_by_four_stations_gives_the_intended_message(ws):
    """Case 8d: every target seen by 3 stations, control on the stations and 4 targets. Before:
    'error: no observations' (Observations.subset refused the empty subset first)."""
    rows = (ws / "obs.csv").read_text().splitlines()
    drop = {"A": 0, "B": 1, "C": 2, "D": 3}
    kept = rows[:ROWS_FROM] + [r for r in rows[ROWS_FROM:]
                               if drop[r.split(",")[0]] != int(r.split(",")[1]) % 4]
    (ws / "three.csv").write_text("\n".join(kept) + "\n")
    pts = (ws / "points.csv").read_text().splitlines()
    (ws / "ctrl.csv").write_text("\n".join(pts[:10]) + "\n")      # comment, header, A-D, 1-4
    ws.fails(["adjust", "{d}/three.csv", "--points", "{d}/ctrl.csv", "--datum", "control"],
             "4 or more stations", "0 of 14 targets", "--points")


def test_valid_file_unchanged(ws):
    """The valid example network adjusts as before (σ0 1.199, no warning from the new checks)."""
    rc, out, err = ws.run(["adjust", "{d}/obs.csv", "--json"])
    assert rc == 0, err
    import json

    assert json.loads(out)["sigma0"] == pytest.approx(1.199, abs=5e-4)


def test_an_unused_instrument_is_refused_not_ignored(ws):
    """`--instrument` with a file that gives sigma_m for every distance and no angles used none of the
    instrument: even a malformed TOML passed silently. Now the TOML is loaded (its error named) and
    the unused option refused by name."""
    bad = ws / "bad.toml"
    bad.write_text("[a\nb = 1\n")
    ws.fails(["adjust", "{d}/obs.csv", "--instrument", str(bad)], "bad.toml", "malformed TOML")
    ws.fails(["adjust", "{d}/obs.csv", "--instrument", "seed2020"], "--instrument seed2020: not used",
             "sigma_m")
