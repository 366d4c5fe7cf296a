"""``--report FILE.html`` on the general path (``multilat adjust NET.xml|obs.csv --model general``, and
``--model auto`` when it takes the general layer): the auditor's order (verdicts, frame and datum,
points, instrument parameters, reliability, residuals by kind, tests; warnings and what was run
last), every printed number the JSON's (the ``data-path`` cells, at the printed precision), and every
verdict recomputed here from the JSON with the rules written out in this file (the global test,
the largest |w| of each kind against the critical value, poorly controlled rows: redundancy < 0.1
or MDB > 10 σ, points whose every row has redundancy 0, points left out).

Networks: the polar-point network of tests/test_general_csv.py under ``--model auto`` (5 points
kept without control), the shipped station_control.xml (gama-local: fixed points, direction sets),
and the shipped two-tracker CSV with a 2 mm blunder in one distance (data snooping rejects it).

Without ``--observations`` (the JSON lists only the rows that matter) the page is built from every row
of the result: its numbers equal the printed JSON wherever it lists them (``data-path``), every row's
numbers equal the ``observations`` table under ``--out`` (``data-row``, ``data-key``), and the page
reads the same as with ``--observations`` (station_control and the blunder network, in Chromium).
The page is read as headless Chromium renders it (skipped without /usr/bin/chromium or playwright);
the numbers are also checked from the HTML alone (no browser).
"""

from __future__ import annotations

import csv
import json
import math
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from test_general_csv import heads_tracker_polar
from test_job_report import CHROMIUM, _browser, _run, check_numbers
from test_report_sections import _DOM, printed, section, table

ROOT = Path(__file__).resolve().parents[1]
ORDER = ["verdicts", "frame", "points", "parameters", "reliability", "residuals", "tests", "warnings", "run"]
R_MIN, MDB_LIMIT = 0.1, 10.0          # the distance path's defaults (network/adjust/distance/reliability.py), written out


def _blunder(tmp: Path) -> Path:
    lines = (ROOT / "examples" / "general" / "two_trackers_csv" / "obs.csv").read_text().splitlines()
    cols = lines[5].split(",")
    cols[2] = f"{float(cols[2]) + 2e-3:.9f}"          # a 2 mm blunder in the 5th distance (σ 10 µm)
    lines[5] = ",".join(cols)
    (tmp / "blunder.csv").write_text("\n".join(lines) + "\n")
    return tmp / "blunder.csv"


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """{name: (html text, doc, stderr)}: each network adjusted once with --json --report."""
    tmp = tmp_path_factory.mktemp("general_report")
    case = heads_tracker_polar(np.random.default_rng(11)).simulate(np.random.default_rng(12))
    polar = [str(a) for a in case.write(tmp)]
    args = {"polar": polar, "station_control": [str(ROOT / "examples" / "general" / "station_control.xml")],
            "blunder": [str(_blunder(tmp)), "--levelled", "T1,T2", "--model", "general"]}
    out = {}
    for name, a in args.items():
        rc, stdout, err = _run(["adjust", *a, "--json", "--observations", "--report", str(tmp / f"{name}.html")])
        assert rc == 0, (name, err)
        out[name] = ((tmp / f"{name}.html").read_text("utf-8"), json.loads(stdout), err, tmp / f"{name}.html")
    return out


@pytest.mark.parametrize("name", ["polar", "station_control", "blunder"])
def test_every_number_is_the_jsons(runs, name):
    text, doc, _, _ = runs[name]
    n, bad = check_numbers(text, doc)
    assert n > 100 and not bad, bad[:5]


FLAGGED = ("station_control", "blunder")


@pytest.fixture(scope="module")
def flagged(runs, tmp_path_factory):
    """{name: (html text, doc, observations table rows, html path)}: station_control and the blunder
    network again, with --json --report --out (CSV tables) and without --observations."""
    tmp = tmp_path_factory.mktemp("general_report_flagged")
    args = {"station_control": [str(ROOT / "examples" / "general" / "station_control.xml")],
            "blunder": [str(runs["blunder"][3].parent / "blunder.csv"), "--levelled", "T1,T2", "--model", "general"]}
    out = {}                                          # the same input files as ``runs``: the pages name them
    for name in FLAGGED:
        html_path, out_dir = tmp / f"{name}.html", tmp / f"{name}_out"
        rc, stdout, err = _run(["adjust", *args[name], "--json", "--report", str(html_path), "--out", str(out_dir),
                                "--tables", "csv"])
        assert rc == 0, (name, err)
        doc = json.loads(stdout)
        assert doc["observation_counts"]["listing"] == "flagged"
        with open(out_dir / "observations.csv", newline="") as f:
            table = list(csv.DictReader(f))
        out[name] = (html_path.read_text("utf-8"), doc, table, html_path)
    return out


class _RowCells(HTMLParser):
    """(attrs, text) of every <td> naming a row of the observations table (data-row)."""

    def __init__(self):
        super().__init__()
        self.cells, self._cur = [], None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "td" and "data-row" in a:
            self._cur = [a, ""]

    def handle_data(self, data):
        if self._cur is not None:
            self._cur[1] += data

    def handle_endtag(self, tag):
        if tag == "td" and self._cur is not None:
            self.cells.append(tuple(self._cur))
            self._cur = None


@pytest.mark.parametrize("name", FLAGGED)
def test_without_observations_every_number_is_the_jsons_and_the_tables(flagged, name):
    """Every cell with a JSON path equals the printed JSON (the rows that matter are listed there at
    their own positions); every observation row's cell equals the --out table at its row and column,
    read with the csv module, sqrt / k / scale applied here, to half a unit of the printed digit; and
    the page does show rows the JSON does not list."""
    text, doc, table, _ = flagged[name]
    n, bad = check_numbers(text, doc)
    assert n > 100 and not bad, bad[:5]
    p = _RowCells()
    p.feed(text)
    unlisted = 0
    for a, shown in p.cells:
        assert a["data-table"] == "observations"
        raw = table[int(a["data-row"])][a["data-key"]]
        unlisted += "data-path" not in a
        if raw == "":
            assert shown.strip() == "-", (a, shown)
            continue
        v = float(raw)
        v = math.sqrt(max(v, 0.0)) if a["data-op"] == "sqrt" else v
        v *= float(a["data-k"]) * float(a["data-scale"])
        m = re.fullmatch(r"\s*([+-]?\d+(?:\.(\d+))?)\s*", shown)
        assert m is not None, (a, shown)
        half = 0.5 * 10.0 ** -len(m.group(2) or "")
        assert abs(float(m.group(1)) - v) <= half * (1 + 1e-9) + 1e-12 * abs(v), (a, shown, v)
    assert len(p.cells) > 20 and unlisted > 0, (len(p.cells), unlisted)


def test_auto_report_is_the_general_one(runs):
    text, doc, err, _ = runs["polar"]
    assert doc["model"] == "general" and "multilat adjust: General network adjustment" in text
    assert "adjusted by the general model" in err


def test_report_refused_before_any_work_when_it_is_an_input(tmp_path):
    src = ROOT / "examples" / "general" / "station_control.xml"
    rc, _, err = _run(["adjust", str(src), "--report", str(tmp_path / "r.txt")])
    assert rc == 2 and "--report" in err and ".html" in err and not (tmp_path / "r.txt").exists()


# ------------------------------------------------------------------------------- in the browser
@pytest.fixture(scope="module")
def pages(runs):
    sync_playwright = _browser()
    got = {}
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, headless=True,
                               args=["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run"])
        try:
            for name, (_, doc, _, path) in runs.items():
                page = b.new_page()
                errors = []
                page.on("pageerror", lambda exc, e=errors: e.append(str(exc)))
                page.goto(path.resolve().as_uri(), wait_until="load")
                got[name] = (page.evaluate(_DOM), doc)
                assert not errors, (name, errors)
                page.close()
        finally:
            b.close()
    return got


@pytest.mark.parametrize("name", FLAGGED)
def test_page_is_the_same_with_or_without_observations(runs, flagged, name):
    """In Chromium: every results section (all but "what was run", whose options differ) reads the
    same, table by table and cell by cell, whether the JSON lists every row or only those that matter."""
    sync_playwright = _browser()
    doms = []
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, headless=True,
                               args=["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run"])
        try:
            for path in (runs[name][3], flagged[name][3]):
                page = b.new_page()
                page.goto(path.resolve().as_uri(), wait_until="load")
                doms.append([s for s in page.evaluate(_DOM) if s["key"] != "run"])
                page.close()
        finally:
            b.close()
    every, listed = doms
    assert [s["key"] for s in listed] == ORDER[:-1]
    assert listed == every
    assert len(flagged[name][1]["observations"]) < len(runs[name][1]["observations"])


def _controlled(o):
    return o["redundancy"] > 1e-9


@pytest.mark.parametrize("name", ["polar", "station_control", "blunder"])
def test_sections_in_the_auditors_order(pages, name):
    dom, _ = pages[name]
    assert [s["key"] for s in dom] == ORDER
    opts = next(t for t in section(dom, "run")["tables"] if t["caption"] == "Options")
    listed = {r[0]["text"] for r in opts["rows"]}
    assert {"alpha", "strict", "tables", "backend"} <= listed     # adjust-general/2: --tables, --backend apply
    assert not listed & {"cost", "mdb_limit_sigma", "solver"}
    assert ("points" in listed) == (name != "station_control")   # a gama-local file carries its points


@pytest.mark.parametrize("name", ["polar", "station_control", "blunder"])
def test_verdicts_follow_the_numbers(pages, name):
    dom, doc = pages[name]
    obs, crit = [o for o in doc["observations"] if not o["rejected"]], doc["tests"]["critical"]   # rows adjusted
    seen = set()
    for r in table(section(dom, "verdicts"), "verdicts")["rows"]:
        label, value, _, high, verdict = (c["text"] for c in r)
        flag = r[4]["verdict"]
        if label.startswith("global χ² test"):
            seen.add("global")
            gt = doc["global_test"]
            ok = printed(value)[0] <= printed(high)[0]
            assert ok == gt["passed"] and verdict.startswith("passed" if ok else "FAILED")
            assert flag == ("ok" if ok else "bad")
        elif label.startswith("largest |w| of the"):
            m = re.match(r"largest \|w\| of the (.+?) rows \(", label)
            kind = m.group(1)
            ws = [o["statistic"] for o in obs if _controlled(o) and
                  o["kind"].replace("_", " ") + (f" ({o['component']})" if o.get("component") else "")
                  + (f" {o['axis']}" if o.get("axis") else "") == kind]
            assert abs(printed(value)[0] - max(ws, key=abs)) <= 0.005 + 1e-9
            assert abs(printed(high)[0] - crit) <= 0.0005 + 1e-9
            ok = abs(printed(value)[0]) <= printed(high)[0]
            assert (verdict == "|w| <= critical") == ok and flag == ("ok" if ok else "bad")
            seen.add(kind)
        elif label.startswith("observation rows rejected"):
            assert int(value) == len(doc["outliers"]) and (flag == "ok") == (int(value) == 0)
        elif label.startswith("poorly controlled"):
            n = sum(o["redundancy"] < R_MIN or o["mdb_sigma"] is None or o["mdb_sigma"] > MDB_LIMIT for o in obs)
            assert int(value) == n and (flag == "ok") == (n == 0)
            seen.add("poor")
        elif label.startswith("points kept without control"):
            ends = {}
            for o in obs:
                for e in ("from", "to", "point", "bs", "fs"):
                    if e in o:
                        ends.setdefault(o[e], []).append(o["redundancy"])
            zero = [p for p, rs in ends.items() if max(rs) <= 1e-9 and doc["points"][p]["status"] != "fixed"]
            assert int(value) == len(zero) and (flag == "ok") == (not zero)
            seen.add("zero")
        elif label.startswith("points left out"):
            assert int(value) == len(doc["excluded"])
    kinds = {o["kind"].replace("_", " ") + (f" ({o['component']})" if o.get("component") else "")
             + (f" {o['axis']}" if o.get("axis") else "") for o in obs if _controlled(o)}
    assert seen == {"global", "poor", "zero"} | kinds
    if name == "polar":
        pts = table(section(dom, "points"), "points")
        flagged = {r[0]["text"] for r in pts["rows"] if r[-1]["verdict"] == "bad"}
        assert flagged == {f"Q{i}" for i in range(5)}


def test_snooping_rejects_the_blunder_and_says_so(pages):
    dom, doc = pages["blunder"]
    assert [o["to"] for o in doc["outliers"]] == ["P05"]
    rows = table(section(dom, "tests"), "outliers")["rows"]
    assert len(rows) == 1 and rows[0][3]["text"] == "T1->P05"
    assert rows[0][8]["text"] == str(doc["outliers"][0]["index"])    # its row of the observations table
    assert abs(printed(rows[0][4]["text"])[0]) > printed(rows[0][5]["text"])[0]


def test_parameters_with_their_uncertainties(pages):
    dom, doc = pages["polar"]
    rows = table(section(dom, "parameters"), "parameters")["rows"]
    assert len(rows) == len(doc["parameters"]) == 6         # 5 additive constants, AT's κ
    for r in rows:
        owner, what = r[0]["text"], r[1]["text"]
        key = ("offset:" if what == "additive constant" else "kappa:") + owner
        p = doc["parameters"][key]
        scale = 1e6 if p["unit"] == "m" else 1.0
        assert abs(printed(r[2]["text"])[0] - p["value"] * scale) <= 0.5 * 10 ** -printed(r[2]["text"])[1] + 1e-12
        assert abs(printed(r[4]["text"])[0] - p["std"] * 1e6) <= 0.005 + 1e-9
        assert abs(printed(r[5]["text"])[0] - 2 * p["std"] * 1e6) <= 0.005 + 1e-9
