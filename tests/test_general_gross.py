"""Never silent on the general path: data snooping refuses gross errors instead of rejecting them one
by one, and a refusal on a network with azimuths names the sense (``--azimuth-sense cw``) when the
azimuths negated fit (multilat.network.adjust.general.snooping, .run.sense_hint, cli/general_adjust.py).

The case found by a user walk: the tutorial's two levelled trackers (examples/tutorial/trackers.csv)
with every azimuth negated (clockwise, as many trackers report), adjusted on 4 control points as
counter-clockwise. Before, data snooping removed 12 rows, among them every row to P02 and P05, and
passed the global test with the hall mirrored (P03 at (3.87, 1.84) instead of (5.42, 3.82)). The
independent values: the file negated twice is the tutorial's file, so the negated azimuths' fit is
the tutorial's (same σ0); the simulation's truth (examples/tutorial/truth.csv).

The rules, each with a network where it fires and one where it does not:

- a residual above 1000 σ (a 2000 σ distance in two_trackers.xml) is refused; 20 σ is rejected;
- three or more rejections above 5 % of the rows (3 distance blunders in direction_sets.xml's 47
  rows) are refused; two are rejected (tests/test_general_snooping.py);
- two or more rejections taking more than half of one point's rows (control point P05 given 1 mm
  off: its rows fail one after the other) are refused; P05 given right passes.
"""

from __future__ import annotations

import csv
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from multilat.cli import main
from multilat.network.adjust.general import read_gama_input
from multilat.network.model.observations import Network
from multilat.network.adjust.general.snooping import GROSS_SIGMA, SnoopingRefused, snoop

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples" / "tutorial"
DATA = ROOT / "tests" / "data" / "gama3d"
CONTROL = "P01,P02,P05,P09"


def _negated(tmp_path) -> Path:
    """trackers.csv with every azimuth negated (the clockwise file)."""
    rows = list(csv.DictReader((EX / "trackers.csv").read_text().splitlines()))
    out = tmp_path / "cw.csv"
    with open(out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({**r, "azimuth_rad": repr(-float(r["azimuth_rad"]))})
    return out


def _adjust(capsys, obs, *extra, points=EX / "points.csv"):
    capsys.readouterr()
    rc = main(["adjust", str(obs), "--model", "general", "--levelled", "T1,T2", "--points", str(points),
               "--datum", f"control:{CONTROL}", *map(str, extra)])
    out, err = capsys.readouterr()
    return rc, out, err


def _doc(capsys, obs, *extra, **kw) -> dict:
    rc, out, err = _adjust(capsys, obs, "--json", *extra, **kw)
    assert rc == 0, err
    return json.loads(out)


def _truth() -> dict:
    return {r["point"]: np.array([float(r[k]) for k in ("x_m", "y_m", "z_m")])
            for r in csv.DictReader((EX / "truth.csv").read_text().splitlines())}


# ------------------------------------------------------------------------ the mirrored hall
def test_mirrored_tracker_file_is_refused_with_the_hint(capsys, tmp_path):
    cw = _negated(tmp_path)
    ref = _doc(capsys, EX / "trackers.csv")
    out_dir = tmp_path / "out"
    rc, _, err = _adjust(capsys, cw, "--out", out_dir)
    assert rc == 2 and not out_dir.exists()                       # nothing written
    line = err.strip().splitlines()[-1]                           # the points file's warning comes first
    assert line.startswith("error: data snooping refused: ") and "T2->P02" in line
    assert f"more than {GROSS_SIGMA:g} σ" in line
    assert "clockwise azimuths? give --azimuth-sense cw" in line
    # the hint's σ0 of the negated azimuths is the tutorial file's (the same numbers, negated twice)
    flipped = float(line.split("they fit (σ0 = ")[1].split(",")[0])
    assert flipped == pytest.approx(ref["sigma0"], rel=5e-3)           # printed to 3 digits


def test_the_option_gives_the_correct_hall(capsys, tmp_path):
    cw = _negated(tmp_path)
    ref = _doc(capsys, EX / "trackers.csv")
    got = _doc(capsys, cw, "--azimuth-sense", "cw")
    assert ref["outliers"] == [] and got["outliers"] == [] and ref["global_test"]["passed"]
    assert got["dof"] == ref["dof"] == 47 and got["sigma0"] == pytest.approx(ref["sigma0"], rel=1e-9)
    assert not any("--azimuth-sense" in w for w in ref["warnings"])    # the correct file: no hint
    truth = _truth()
    for p, v in ref["points"].items():
        np.testing.assert_allclose(got["points"][p]["xyz_m"], v["xyz_m"], atol=1e-9, err_msg=p)
        if p in truth and v["status"] == "free":                     # within 4 u of the simulation's truth
            dev = np.abs(np.array(v["xyz_m"]) - truth[p])
            assert np.all(dev <= 4 * np.array(v["xyz_std_m"]) + 1e-9), (p, dev, v["xyz_std_m"])
    assert np.hypot(*(np.array(ref["points"]["P03"]["xyz_m"][:2]) - truth["P03"][:2])) < 1e-4


def test_without_snooping_the_failed_test_names_the_sense(capsys, tmp_path):
    doc = _doc(capsys, _negated(tmp_path), "--no-snooping")
    assert doc["global_test"]["passed"] is False and doc["sigma0"] > 1e3
    (hint,) = [w for w in doc["warnings"] if "--azimuth-sense cw" in w]
    assert f"give σ0 = {doc['sigma0']:.3g}" in hint


def test_a_declared_sense_gets_no_hint(capsys, tmp_path):
    """--azimuth-sense ccw given: the user said so; refused without the hint."""
    rc, _, err = _adjust(capsys, _negated(tmp_path), "--azimuth-sense", "ccw")
    assert rc == 2 and "data snooping refused" in err and "--azimuth-sense cw" not in err


# ------------------------------------------------------------------------ the rules
def _planted(net: Network, rows, factor: float) -> Network:
    blocks = list(net.blocks)
    for q, k in rows:
        b = blocks[q]
        value = b.value.copy()
        value[k] += factor * b.sigma[k]
        blocks[q] = replace(b, value=value)
    return Network(net.points, tuple(blocks), net.notes)


def test_a_gross_residual_is_refused_a_blunder_rejected():
    net = read_gama_input(DATA / "two_trackers.xml")
    b = net.blocks[1]
    assert b.kind == "slope_distance"
    sn = snoop(_planted(net, [(1, 4)], 20.0))
    assert [r["label"] for r in sn.rejected] == [b.labels[4]]
    with pytest.raises(SnoopingRefused) as e:
        snoop(_planted(net, [(1, 4)], 2000.0))
    msg = str(e.value)
    assert b.labels[4] in msg and f"more than {GROSS_SIGMA:g} σ" in msg and len(msg.splitlines()) == 1
    assert [r["label"] for r in e.value.rows] == [b.labels[4]]
    # Baarda's procedure alone (gross=False) rejects it, as before
    assert [r["label"] for r in snoop(_planted(net, [(1, 4)], 2000.0), gross=False).rejected] == [b.labels[4]]


def test_more_than_five_percent_of_the_rows_is_refused():
    net = read_gama_input(DATA / "direction_sets.xml")
    b = net.blocks[1]
    assert b.kind == "slope_distance" and sum(x.n_rows for x in net.blocks) == 47
    bad = _planted(net, [(1, 2), (1, 7), (1, 10)], 20.0)
    assert len(snoop(bad, gross=False).rejected) == 3              # what the rule prevents
    with pytest.raises(SnoopingRefused) as e:
        snoop(bad)
    assert "3 of the network's 47 observation rows" in str(e.value)
    assert {r["label"] for r in e.value.rows} == {b.labels[k] for k in (2, 7, 10)}


def _points_with(tmp_path, pid: str, dy_m: float) -> Path:
    lines = (EX / "points.csv").read_text().splitlines()
    for i, line in enumerate(lines):
        if line.startswith(f"{pid},"):
            f = line.split(",")
            f[2] = f"{float(f[2]) + dy_m:.6f}"
            lines[i] = ",".join(f)
    out = tmp_path / "points.csv"
    out.write_text("\n".join(lines) + "\n")
    return out


def test_most_rows_of_one_point_is_refused(capsys, tmp_path):
    """Control point P05 given 1 mm off in y (100 σ of a distance, below the gross rule): its 6 rows
    fail one after the other; the 4th rejection would take more than half of them."""
    rc, _, err = _adjust(capsys, EX / "trackers.csv", points=_points_with(tmp_path, "P05", 0.001))
    assert rc == 2
    line = err.strip().splitlines()[-1]
    assert line.startswith("error: data snooping refused: it would reject 4 of the 6 observation rows of point "
                           "'P05'")
    assert "--azimuth-sense" not in line                           # the azimuths negated do not fit either
    doc = _doc(capsys, EX / "trackers.csv", points=_points_with(tmp_path, "P05", 0.0))
    assert doc["outliers"] == [] and doc["global_test"]["passed"]


# ------------------------------------------------------------------------ units of the summary
def test_summary_prints_additive_constants_in_micrometres(capsys):
    doc = _doc(capsys, EX / "trackers.csv")
    rc, out, _ = _adjust(capsys, EX / "trackers.csv")
    flat = " ".join(out.split())
    o = doc["parameters"]["offset:T1"]
    assert rc == 0 and f"T1 {o['value'] * 1e6:+.1f} µm (u {o['std'] * 1e6:.1f} µm)" in flat
    assert " mm (u " not in flat
