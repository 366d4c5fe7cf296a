"""``--report FILE.html``: every number in a job report equals the command's JSON, the metadata is
right (sha256 of the inputs, version, seed), and the pages render in a real headless browser.

The number check is independent of the report code: it parses the HTML with the standard library,
reads each cell's JSON path, applies sqrt / k / scale itself and compares with the printed text to
half a unit of its last printed digit (the rounding of the printed value, nothing more).
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import math
import os
import re
from html.parser import HTMLParser
from pathlib import Path

import pytest

from multilat.cli.app import main

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"
CHROMIUM = "/usr/bin/chromium"


class _Cells(HTMLParser):
    """Collects (attrs, text) of every <td> with a data-path, and the <img> sources."""

    def __init__(self):
        super().__init__()
        self.cells, self.imgs, self._cur = [], [], None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "td" and "data-path" in a:
            self._cur = [a, ""]
        if tag == "img":
            self.imgs.append(a.get("src", ""))

    def handle_data(self, data):
        if self._cur is not None:
            self._cur[1] += data

    def handle_endtag(self, tag):
        if tag == "td" and self._cur is not None:
            self.cells.append(tuple(self._cur))
            self._cur = None


def _lookup(doc, path):
    v = doc
    for raw in path.split("/"):
        key = raw.replace("~1", "/").replace("~0", "~")
        v = v[int(key)] if isinstance(v, list) else v[key]
    return v


def check_numbers(html_text: str, doc: dict) -> tuple[int, list[str]]:
    """(number of checked cells, mismatches) of a report against its JSON document."""
    p = _Cells()
    p.feed(html_text)
    bad = []
    for a, text in p.cells:
        v = _lookup(doc, a["data-path"])
        if v is None:                                   # a quantity the command could not give
            if text.strip() != "-":
                bad.append(f"{a['data-path']}: JSON null printed as {text!r}")
            continue
        v = float(v)
        if a.get("data-op") == "sqrt":
            if -1e-18 < v < 0:                          # a datum coordinate's zero variance, rounded
                v = 0.0
            v = math.sqrt(v) if v >= 0 else math.nan
        elif a.get("data-op") == "inv":                 # the lower bound 1/f of a band [1/f, f]
            v = 1.0 / v
        elif a.get("data-op"):
            bad.append(f"{a['data-path']}: unknown data-op {a['data-op']!r}")
            continue
        v *= float(a["data-k"]) * float(a["data-scale"])
        m = re.fullmatch(r"\s*([+-]?\d+(?:\.(\d+))?)\s*", text)
        if m is None:
            bad.append(f"{a['data-path']}: not a number {text!r}")
            continue
        half = 0.5 * 10.0 ** -len(m.group(2) or "")
        if not abs(float(m.group(1)) - v) <= half * (1 + 1e-9) + 1e-12 * abs(v):
            bad.append(f"{a['data-path']}: printed {text}, JSON gives {v!r}")
    return len(p.cells), bad


def _heads_csv(path: Path) -> Path:
    path.write_text("point,x_m,y_m,z_m\nA,-1,-1,0\nB,2,-1,0.5\nC,0.5,2,0\nD,0.5,0.5,2\n")
    return path


def _commands(tmp: Path) -> dict[str, list[str]]:
    n, c, lb = EX / "network", EX / "campaign", EX / "lbb"
    return {
        "adjust": ["adjust", str(n / "small_volume_obs.csv"), "--references", str(n / "small_volume_refs.csv")],
        "propagate": ["propagate", str(n / "small_volume_obs.csv"), "--trials", "200", "--seed", "3",
                      "--cloud-points", "A,3"],
        "simulate": ["simulate", "small-volume", "--trials", "4", "--seed", "5"],
        "design": ["design", str(EX / "design" / "cube.toml"), "--evaluate", str(_heads_csv(tmp / "heads.csv"))],
        "budget": ["budget", "--trials", "400", "--seed", "7"],
        "correct": ["correct", str(c / "raw.csv"), "-e", str(c / "environment.csv"), "--heights",
                    str(c / "heights.csv")],
        "lbb simulate": ["lbb", "simulate", "--grid", "2", "--trials", "20", "--seed", "9"],
        "lbb compare": ["lbb", "compare", str(lb / "m60_edges.csv"), str(lb / "m60_reference.csv"),
                        "--trials", "20"],
    }


def _run(args) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(args)
    return rc, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    """Each shipped example's command run once with --json --report: {name: (html path, doc, args)}."""
    tmp = tmp_path_factory.mktemp("reports")
    got = {}
    for name, args in _commands(tmp).items():
        path = tmp / (name.replace(" ", "_") + ".html")
        rc, out, err = _run([*args, "--json", "--report", str(path)])
        assert rc == 0, (name, err)
        got[name] = (path, json.loads(out), args)
    return got


NAMES = ["adjust", "propagate", "simulate", "design", "budget", "correct", "lbb simulate", "lbb compare"]
#: the fewest JSON-backed cells each report must show (its main tables), so that a report that
#: silently drops a table fails
MIN_CELLS = {"adjust": 4 * 10 + 14 * 12, "propagate": 18 * 10, "simulate": 9 + 4, "design": 4 * 9 + 27 * 7,
             "budget": 4 * 5 + 4, "correct": 56 * 6, "lbb simulate": 4 * 12, "lbb compare": 6}


@pytest.mark.parametrize("name", NAMES)
def test_report_numbers_equal_the_json(reports, name):
    path, doc, _ = reports[name]
    n, bad = check_numbers(path.read_text(encoding="utf-8"), doc)
    assert not bad, bad[:5]
    assert n >= MIN_CELLS[name], n


def test_the_checker_catches_a_changed_number(reports):
    path, doc, _ = reports["adjust"]
    doc = json.loads(json.dumps(doc))
    hid = next(iter(doc["heads"]))
    doc["heads"][hid]["offset_m"] += 0.2e-6             # 0.2 µm: the tables print 0.1 µm
    n, bad = check_numbers(path.read_text(encoding="utf-8"), doc)
    # the head's offset is printed twice: in the verdicts' first section and in Heads
    assert len(bad) == 2 and all(b.startswith(f"heads/{hid}/offset_m:") for b in bad), bad


@pytest.mark.parametrize("name", NAMES)
def test_report_states_inputs_version_seed_and_uncertainty_convention(reports, name):
    from importlib import metadata

    path, doc, args = reports[name]
    text = path.read_text(encoding="utf-8")
    for a in args:
        if os.path.isfile(a):
            assert hashlib.sha256(Path(a).read_bytes()).hexdigest() in text, a
    assert f"<td>{metadata.version('multilat')}</td>" in text
    if "--seed" in args:
        assert f"<th>seed</th><td>{args[args.index('--seed') + 1]}</td>" in text
    assert "k = 2" in text and "95 %" in text
    assert "date (UTC)" in text and "Warnings" in text
    # self-contained: no element loads an external resource (plotly.js, inline, holds URL strings)
    markup = re.sub(r"<script\b.*?</script>", "", text, flags=re.S)
    assert not re.search(r"""(src|href)\s*=\s*["'](https?:|//)""", markup)
    assert not re.search(r"""<script[^>]*\bsrc=""", text)


def test_report_names_the_sigma_source(reports, tmp_path):
    """The example's observations carry sigma_m (after comment lines): the report says so; without
    the column, the instrument's distance model; with --sigma-um, the option."""
    text = reports["adjust"][0].read_text(encoding="utf-8")
    assert "sigma_m column (" in text
    obs = EX / "network" / "small_volume_obs.csv"
    rows = [r.rsplit(",", 1)[0] for r in obs.read_text().splitlines() if not r.startswith("#")]
    f = tmp_path / "nosigma.csv"
    f.write_text("\n".join(rows) + "\n")
    for extra, words in (([], "distance model of instrument"), (["--sigma-um", "5"],
                                                                            "5 µm for every distance (--sigma-um)")):
        rc, out, err = _run(["adjust", str(f), *extra, "--report", str(tmp_path / "r.html")])
        assert rc == 0, err
        assert words in (tmp_path / "r.html").read_text(encoding="utf-8")


def test_report_lists_the_warnings_the_command_printed(tmp_path):
    obs = EX / "network" / "small_volume_obs.csv"
    rows = [r for r in obs.read_text().splitlines() if not r.startswith("#")]
    f = tmp_path / "extra.csv"
    f.write_text("\n".join([rows[0] + ",colour"] + [r + ",red" for r in rows[1:]]) + "\n")
    rc, out, err = _run(["adjust", str(f), "--report", str(tmp_path / "r.html")])
    assert rc == 0 and "warning:" in err and "colour" in err
    text = (tmp_path / "r.html").read_text(encoding="utf-8")
    warn = text[text.index('<h2 id="warnings">Warnings</h2>'):]
    warn = warn[:warn.index("<h2", 5)]                  # the Warnings section only (what was run follows)
    assert "colour" in warn and "No warning was raised" not in warn


def test_report_figures_are_embedded(reports):
    for name in NAMES:
        p = _Cells()
        p.feed(reports[name][0].read_text(encoding="utf-8"))
        assert p.imgs and all(s.startswith("data:image/png;base64,") for s in p.imgs), name


def test_report_verdicts_are_computed_from_the_row(reports):
    """The reference-length verdict: |difference| <= 2 u_c with u_c from the same row's u and u_ref."""
    path, doc, _ = reports["adjust"]
    text = path.read_text(encoding="utf-8")
    for c in doc["reference_lengths"]:
        uc = math.hypot(c["length_std_m"], c["reference_std_m"])
        row = re.search(rf"<td>{re.escape(c['target_a'])}-{re.escape(c['target_b'])}</td>(.*?)</tr>", text).group(1)
        assert row.endswith(">yes</td>" if abs(c["difference_m"]) <= 2 * uc else ">NO</td>")


def test_report_path_errors_are_one_line(tmp_path):
    obs = str(EX / "network" / "small_volume_obs.csv")
    rc, out, err = _run(["adjust", obs, "--report", str(tmp_path / "r.txt")])
    assert rc == 2 and err.startswith("error: --report") and err.count("\n") == 1
    (tmp_path / "d.html").mkdir()
    rc, out, err = _run(["adjust", obs, "--report", str(tmp_path / "d.html")])
    assert rc == 2 and err.startswith("error: --report") and "directory" in err and err.count("\n") == 1


# ------------------------------------------------------------------------------ a real browser
def _browser():
    if not os.path.exists(CHROMIUM):
        pytest.skip(f"{CHROMIUM} not installed (apt-get install chromium; .ci/run installs it)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("playwright (the 'test' extra) not installed")
    return sync_playwright


def render_in_chromium(paths, screenshot_dir=None) -> dict:
    """Open each page in headless Chromium: {path: {"errors": [...], "images": [naturalWidth...],
    "h1": text}}."""
    sync_playwright = _browser()
    got = {}
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, headless=True,
                               args=["--headless", "--no-sandbox", "--disable-gpu",
                                     "--disable-background-networking", "--disable-component-update",
                                     "--disable-sync", "--no-first-run"])
        try:
            for path in paths:
                page = b.new_page(viewport={"width": 1200, "height": 900})
                errors = []
                page.on("console", lambda m, e=errors: e.append(m.text) if m.type == "error" else None)
                page.on("pageerror", lambda exc, e=errors: e.append(str(exc)))
                page.on("requestfailed", lambda r, e=errors: e.append(f"request failed: {r.url[:80]}"))
                page.goto(Path(path).resolve().as_uri(), wait_until="load")
                page.wait_for_timeout(300)
                widths = page.eval_on_selector_all("img", "els => els.map(e => e.complete ? e.naturalWidth : -1)")
                h1 = page.inner_text("h1")
                if screenshot_dir is not None:
                    page.screenshot(path=str(Path(screenshot_dir) / (Path(path).stem + ".png")), full_page=True)
                got[str(path)] = {"errors": errors, "images": widths, "h1": h1,
                                  "plotly": page.eval_on_selector_all(".js-plotly-plot", "els => els.length")}
                page.close()
        finally:
            b.close()
    return got


def test_reports_render_in_headless_chromium(reports):
    """Every report in one browser: no console or page error, no failed request, every figure
    decoded (naturalWidth > 0); with plotly (the 'report' extra) the adjust and design reports carry
    a live 3-D plot, without it a PNG."""
    res = render_in_chromium([p for p, _, _ in reports.values()])
    for name, (path, _, _) in reports.items():
        r = res[str(path)]
        assert not r["errors"], (name, r["errors"])
        assert r["h1"].startswith("multilat "), name
        assert all(w > 0 for w in r["images"]), (name, r["images"])
        assert r["images"], name
    for name in ("adjust", "design"):
        path = reports[name][0]
        live = "plotly" in path.read_text(encoding="utf-8")
        assert res[str(path)]["plotly"] == (1 if live else 0), name
