"""``adjust`` schema ``multilat.adjust/2``: JSON for summaries, tables for rows.

The document lists only the observations that matter (rejected, failing w-tests, poorly controlled;
those of points left out before solving), with counts; every row is in the ``observations`` table of
``--out`` (Parquet or CSV, its row count and sha256 in ``result.json``) and in the document with
``--observations``. Checked on a network with a blunder against the independent lists of the same
document (``outliers``, ``w_failures``, ``reliability.poor_observations``) and against the files.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import json
from pathlib import Path

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.io.files import write_observations
from multilat.network.synthetic.generator import synthetic_network

DATA = Path(__file__).resolve().parent / "data" / "network"
FLAGS = ("rejected", "w_failed", "poorly_controlled")
BLUNDER = 37                  # the row given a 60 σ blunder


def _run(args):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(args)
    return rc, out.getvalue(), err.getvalue()


def _doc(args):
    rc, out, err = _run(args)
    assert rc == 0, err
    return json.loads(out)


@pytest.fixture(scope="module")
def blunder(tmp_path_factory):
    """8 stations x 30 targets, one distance 60 σ too long: (csv path, its pair, --json doc,
    --json --observations doc, --out csv dir)."""
    tmp = tmp_path_factory.mktemp("adjust2")
    truth = synthetic_network(7, population="shell", n_stations=8, n_targets=30)
    obs = truth.obs
    d = obs.distance_m.copy()
    d[BLUNDER] += 60 * obs.sigma_m[BLUNDER]
    from dataclasses import replace

    obs = replace(obs, distance_m=d)
    path = tmp / "obs.csv"
    write_observations(path, obs)
    pair = (obs.station_ids[obs.station_index[BLUNDER]], obs.target_ids[obs.target_index[BLUNDER]])
    flagged = _doc(["adjust", str(path), "--json"])
    every = _doc(["adjust", str(path), "--json", "--observations", "--out", str(tmp / "c"), "--tables", "csv"])
    return path, pair, flagged, every, tmp / "c"


def _pairs(rows):
    return {(r["station"], r["target"]) for r in rows}


def test_the_listed_rows_are_exactly_the_ones_that_matter(blunder):
    _, pair, flagged, every, _ = blunder
    rows = every["observations"]
    assert every["observation_counts"]["listing"] == "all" and len(rows) == every["n_obs"]
    # each flag against the document's own lists, made apart from the rows
    by = {f: _pairs(r for r in rows if r[f]) for f in FLAGS}
    assert by["rejected"] == _pairs(flagged["outliers"]) == {pair}           # the blunder, found
    assert by["w_failed"] == {(o["station"], o["target"]) for f in flagged["w_failures"]
                              for o in f["observations"]}
    assert by["poorly_controlled"] == _pairs(flagged["reliability"]["poor_observations"])
    # the flagged document lists exactly those rows, whole and in table order
    assert flagged["observation_counts"]["listing"] == "flagged"
    assert flagged["observations"] == [r for r in rows if any(r[f] for f in FLAGS)]
    assert [r["index"] for r in rows] == list(range(len(rows)))
    blunder_row = next(r for r in flagged["observations"] if (r["station"], r["target"]) == pair)
    assert blunder_row["rejected"] and blunder_row["index"] == BLUNDER
    assert blunder_row["residual_m"] > 50 * blunder_row["sigma_m"]          # 60 σ long, against the rest


def test_counts_equal_the_rows(blunder):
    _, _, flagged, every, _ = blunder
    rows = every["observations"]
    for doc in (flagged, every):
        c = doc["observation_counts"]
        assert c["n_obs"] == doc["n_obs"] == len(rows)
        assert c["n_used"] == doc["n_used"] == sum(not r["rejected"] for r in rows)
        for f in FLAGS:
            assert c[f"n_{f}"] == sum(r[f] for r in rows), f
        assert c["n_flagged"] == sum(any(r[f] for f in FLAGS) for r in rows) == len(flagged["observations"])
        assert c["n_listed"] == len(doc["observations"]) and c["n_excluded"] == 0
    assert flagged["observation_counts"]["n_rejected"] == 1


def test_summaries_follow_the_rows(blunder):
    _, _, flagged, every, _ = blunder
    rows = every["observations"]
    kept = [r for r in rows if not r["rejected"]]
    for key, ends in flagged["observation_extremes"].items():
        vals = [r[key] for r in kept if r[key] is not None]
        assert ends["smallest"]["value"] == min(vals) and ends["largest"]["value"] == max(vals), key
        lo = rows[ends["smallest"]["index"]]
        assert (lo["station"], lo["target"], lo[key]) == (ends["smallest"]["station"], ends["smallest"]["target"],
                                                          min(vals))
    top = sorted(rows, key=lambda r: -abs(r["w"]))[:10]
    assert flagged["largest_w"] == top


def _cell_is(cell: str, v) -> bool:
    if v is None:
        return cell in ("nan", "inf", "-inf", "")
    if isinstance(v, bool):
        return cell == str(v)
    if isinstance(v, (int, float)):
        return float(cell) == v
    return cell == v


def test_table_rows_count_and_sha256(blunder):
    _, _, _, every, out = blunder
    doc = json.loads((out / "result.json").read_text())
    assert doc["tables"] == every["tables"]
    recs = {t["name"]: t for t in doc["tables"]}
    assert set(recs) == {"stations", "targets", "observations"}
    for rec in recs.values():
        data = (out / rec["file"]).read_bytes()
        assert hashlib.sha256(data).hexdigest() == rec["sha256"], rec["name"]
        with open(out / rec["file"], newline="", encoding="utf-8") as f:
            assert sum(1 for _ in csv.reader(f)) - 1 == rec["n_rows"], rec["name"]
    assert recs["observations"]["format"] == "csv" and recs["observations"]["n_rows"] == every["n_obs"]
    with open(out / "observations.csv", newline="", encoding="utf-8") as f:
        table = list(csv.DictReader(f))
    rows = every["observations"]
    assert len(table) == len(rows) and list(table[0]) == list(rows[0])
    for cells, row in zip(table, rows):
        assert all(_cell_is(cells[k], v) for k, v in row.items()), row["index"]


def test_outliers_join_the_table_by_index(blunder):
    """adjust/3: an outlier carries ``index``, its row of the observations table (and of
    ``observations[]``): the row there is the same distance, rejected, with the same residual."""
    _, pair, flagged, every, out = blunder
    with open(out / "observations.csv", newline="", encoding="utf-8") as f:
        table = list(csv.DictReader(f))
    assert [o["index"] for o in flagged["outliers"]] == [BLUNDER]
    for o in flagged["outliers"]:
        cells, row = table[o["index"]], every["observations"][o["index"]]
        assert row["index"] == o["index"] and (row["station"], row["target"]) == (o["station"], o["target"]) == pair
        assert row["rejected"] and cells["rejected"] == "True"
        assert row["residual_m"] == o["residual_m"] and float(cells["residual_m"]) == o["residual_m"]
    # the snooping step that rejected it names the same row the same way
    steps = [s for s in flagged["tests"]["steps"] if s["action"] == "rejected"]
    assert [(s["index"], s["kind"]) for s in steps] == [(BLUNDER, "distance")]


def test_unlocated_join_the_table_by_index(tmp_path):
    """A 20 σ fault on one of four perfectly correlated distances (a target seen by four stations,
    each distance's w-test the same): ``unlocated`` lists the four, each with ``index``; the row
    there is the same distance, failing its w-test, with the same w and residual."""
    ex = Path(__file__).resolve().parents[1] / "examples" / "network"
    lines = (ex / "small_volume_obs.csv").read_text().splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith("C,9,"))
    st, tg, d, sig = lines[i].split(",")
    lines[i] = f"{st},{tg},{float(d) + 20 * 4.7e-6:.7f},{sig}"
    p = tmp_path / "obs.csv"
    p.write_text("\n".join(lines) + "\n")
    doc = _doc(["adjust", str(p), "--points", str(ex / "small_volume_points.csv"), "--json", "--observations"])
    assert doc["outliers"] == [] and len(doc["unlocated"]) == 4
    rows = doc["observations"]
    for u in doc["unlocated"]:
        row = rows[u["index"]]
        assert row["index"] == u["index"] and (row["station"], row["target"]) == (u["station"], u["target"])
        assert row["w_failed"] and not row["rejected"]
        assert (row["w"], row["residual_m"]) == (u["w"], u["residual_m"])
    assert sorted(rows[u["index"]]["station"] for u in doc["unlocated"]) == ["A", "B", "C", "D"]


def test_parquet_and_csv_tables_give_the_same_rows(blunder, tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    path, _, _, _, c_dir = blunder
    doc = _doc(["adjust", str(path), "--json", "--out", str(tmp_path / "p"), "--tables", "auto"])
    rec = {t["name"]: t for t in doc["tables"]}["observations"]
    assert rec["file"] == "observations.parquet"                   # auto: parquet where pyarrow is
    p = tmp_path / "p" / rec["file"]
    assert hashlib.sha256(p.read_bytes()).hexdigest() == rec["sha256"]
    table = pq.read_table(p)
    with open(c_dir / "observations.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    assert table.column_names == rows[0] and table.num_rows == len(rows) - 1 == rec["n_rows"]
    for j, name in enumerate(rows[0]):
        for cell, v in zip((r[j] for r in rows[1:]), table.column(name).to_pylist()):
            ok = (cell == str(v)) if isinstance(v, (bool, str)) else (float(cell) == v or (np.isnan(float(cell))
                                                                                        and np.isnan(v)))
            assert ok, (name, cell, v)


def test_observations_of_points_left_out_are_listed(tmp_path):
    doc = _doc(["adjust", str(DATA / "weak_target.csv"), "--json"])
    assert [e["id"] for e in doc["excluded"]] == ["W"]
    ex = doc["excluded_observations"]
    assert _pairs(ex) == {("A", "W"), ("B", "W")} and doc["observation_counts"]["n_excluded"] == 2
    assert [r["distance_m"] for r in ex] == [0.9, 0.8] and all("target W" in r["reason"] for r in ex)
    assert "W" not in {r["target"] for r in doc["observations"]}


def test_json_of_a_larger_network_is_small(tmp_path):
    """Rows grow with the observations, the document with the points: 8 stations x 400 targets
    (3 200 distances, few flagged) without every row is well under half the document with them."""
    obs = synthetic_network(3, population="shell", n_stations=8, n_targets=400).obs
    path = tmp_path / "obs.csv"
    write_observations(path, obs)
    rc, small, err = _run(["adjust", str(path), "--json"])
    assert rc == 0, err
    rc, big, err = _run(["adjust", str(path), "--json", "--observations"])
    assert rc == 0, err
    c = json.loads(small)["observation_counts"]
    assert c["n_listed"] == c["n_flagged"] < c["n_obs"] / 10
    assert len(small) < 0.5 * len(big)


def test_observations_option_needs_a_json_document(tmp_path):
    rc, _, err = _run(["adjust", str(DATA / "weak_target.csv"), "--observations"])
    assert rc == 2 and err.strip().splitlines() == [
        "error: --observations lists every observation in the JSON: give --json or --out DIR"]


def test_listing_is_checked():
    from multilat.network.adjust.distance.adjust import adjust
    from multilat.network.adjust.distance.result import result_to_json

    res = adjust(synthetic_network(1, population="shell", n_stations=5, n_targets=12).obs)
    with pytest.raises(MultilatError, match="observations listing must be 'flagged' or 'all'"):
        result_to_json(res, observations="some")
    assert len(result_to_json(res, observations="all")["observations"]) == res.obs.n_obs


def test_the_general_path_lists_by_the_same_rule():
    """--model general (adjust-general/2) lists the rows that matter, every row with --observations
    (the rule itself: tests/test_general_output.py)."""
    net = Path(__file__).resolve().parents[1] / "examples" / "network" / "mixed" / "obs.csv"
    a = _doc(["adjust", str(net), "--model", "general", "--json"])
    b = _doc(["adjust", str(net), "--model", "general", "--json", "--observations"])
    assert a["schema"] == b["schema"] == "multilat.adjust-general/3"
    assert a["observations"] == [o for o in b["observations"] if o["rejected"] or o["w_failed"]
                                 or o["poorly_controlled"]]
    assert len(b["observations"]) == b["observation_counts"]["n_obs"] == a["observation_counts"]["n_obs"]


def test_help_names_the_parquet_extra():
    """Rich markup would eat ``[parquet]`` (it reads it as a style tag): the help must show the extra to install."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "COLUMNS": "400", "NO_COLOR": "1"}
    r = subprocess.run([sys.executable, "-m", "multilat", "adjust", "--help"], capture_output=True, text=True, env=env)
    assert r.returncode == 0 and "pip install 'multilat[parquet]'" in " ".join(r.stdout.split())
