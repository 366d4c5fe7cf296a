"""`multilat demo --quick` builds the whole report (every capability's section) in one HTML file, on
the job-report machinery: version, date, seed, the papers cited in full, verdicts computed from the
numbers beside them, one spelling of the micrometre."""

import re
from html.parser import HTMLParser

import pytest

from multilat.cli import main
from multilat.cli.demo_cmd import DEMO_SECTIONS


@pytest.fixture(scope="module")
def demo_html(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    assert main(["demo", "--quick", "--out", str(out), "--seed", "11"]) == 0
    assert [p.name for p in out.iterdir()] == ["report.html"]
    return out / "report.html"


def test_demo_quick_writes_report_with_every_section(demo_html):
    html = demo_html.read_text()
    assert html.startswith("<!doctype html>") and html.rstrip().endswith("</html>")
    assert len(DEMO_SECTIONS) == 7
    # what was run, the sources, one section per capability, the warnings
    assert html.count("<section>") == len(DEMO_SECTIONS) + 3
    for words in ("budget", "self-calibrat", "sequential", "campaign", "Monte Carlo", "ball bar", "encoder angles"):
        assert words.lower() in html.lower(), words


def test_demo_cites_the_papers_and_states_version_date_seed(demo_html):
    from importlib import metadata

    html = demo_html.read_text()
    for part in ("J. Guillory, D. Truong, J.-P. Wallerand",
                 "Uncertainty assessment of a prototype of multilateration coordinate measurement system",
                 "Precision Engineering 66 (2020) 496–506", "J. Suzanne Canning et al.",
                 "Coordinate metrology uncertainty using parallel kinematic techniques",
                 "International Journal of Machine Tools &amp; Manufacture 47 (2007) 658–665"):
        assert part in html, part
    assert "seed 000" not in html and "seed 003" not in html
    assert "Guillory et al. 2020 [1]" in html and "Canning et al. 2007 [2]" in html
    assert f"<td>{metadata.version('multilat')}</td>" in html and "<th>seed</th><td>11</td>" in html
    assert re.search(r"<th>date \(UTC\)</th><td>\d{4}-\d\d-\d\dT", html)


def test_demo_spells_micrometre_one_way(demo_html):
    text = re.sub(r"<[^>]+>", " ", re.sub(r"<(script|style)\b.*?</\1>", "", demo_html.read_text(), flags=re.S))
    assert not re.search(r"(?<![\w.])um\b", text), re.search(r".{30}(?<![\w.])um\b.{10}", text).group(0)


class _Tables(HTMLParser):
    def __init__(self):
        super().__init__()
        self.tables, self._row, self._cell = [], None, None

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th"):
            self._cell = ""

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self._row.append(self._cell)
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self.tables[-1].append(self._row)
            self._row = None


_NUM = re.compile(r"[+-]?\d+(?:\.(\d+))?(?:e([+-]?\d+))?")


def _value_and_digits(text):
    """(mantissa as Decimal, exponent, decimals) of the first number printed in ``text``."""
    from decimal import Decimal

    m = _NUM.search(text.replace("−", "-"))
    return Decimal(m.group(0).split("e")[0]), int(m.group(2) or 0), len(m.group(1) or "")


def test_demo_verdicts_are_the_rounding_rule_applied_to_their_row(demo_html):
    """Every 'same to paper's rounding' cell equals: multilat's number rounded to the paper's printed
    decimals is the paper's number (recomputed here from the two printed cells)."""
    p = _Tables()
    p.feed(demo_html.read_text())
    checked = 0
    for t in p.tables:
        head = t[0]
        if not head or head[-1] != "same to paper's rounding":
            continue
        ip = head.index("paper") if "paper" in head else 1
        io = head.index("multilat") if "multilat" in head else head.index("multilat u (µm)")
        for row in t[1:]:
            if row[-1] not in ("yes", "no"):
                assert row[-1] == "-"
                continue
            from decimal import ROUND_HALF_UP, Decimal

            pm, pe, pd = _value_and_digits(row[ip])
            om, oe, _ = _value_and_digits(row[io])
            ours = om.scaleb(oe - pe)                  # the printed number, in the paper's exponent
            q = Decimal(1).scaleb(-pd)
            assert (ours.quantize(q, ROUND_HALF_UP) == pm.quantize(q)) == (row[-1] == "yes"), row
            checked += 1
    assert checked >= 4 + 8 + 4


def test_demo_renders_in_headless_chromium(demo_html):
    from test_job_report import render_in_chromium

    r = render_in_chromium([demo_html])[str(demo_html)]
    assert not r["errors"], r["errors"]
    assert r["images"] and all(w > 0 for w in r["images"]), r["images"]


def test_demo_budget_per_input_rows_add_up_to_the_groups(demo_html):
    """The distance section carries the per-input budget (issue 28): every input quantity of the model
    has a row, and each group's "sum of the rows" is √(Σ ± share²) of the shares printed above it,
    within the rounding of the printed cells (each share ± 0.005 µm moves the root by at most
    Σ|share| 0.005 / u, the printed sum ± 0.005); the groups' table beside the paper shows those sums."""
    import math

    from multilat.budget_inputs import QUANTITIES

    p = _Tables()
    p.feed(demo_html.read_text())
    tab = next(t for t in p.tables if t and t[0][:2] == ["group", "input quantity"])
    head = tab[0]
    ig, ish = head.index("group"), head.index("share (µm)")
    groups, sums = {}, {}
    for row in tab[1:]:
        g = row[ig].split(" (")[0]
        if row[1].startswith("sum of the rows"):
            sums[g] = float(row[ish])
        elif g != "combined":
            groups.setdefault(g, []).append(float(row[ish]))
    assert set(groups) == {"telemetric", "head", "target", "air"}
    for g, shares in groups.items():       # every input and the bias row
        assert len(shares) == 1 + sum(q[1] == g for q in QUANTITIES), g
        u = math.sqrt(sum(math.copysign(s * s, s) for s in shares))
        bound = sum(abs(s) for s in shares) * 0.005 / u + 0.005
        assert abs(u - sums[g]) <= bound, (g, u, sums[g], bound)
    beside = next(t for t in p.tables if t and t[0][:3] == ["group", "paper", "multilat"]
                  and "Monte Carlo standard error (µm)" in t[0])
    shown = {r[0].split(" ")[0]: float(r[2]) for r in beside[1:]}
    assert {g: shown[g] for g in ("telemetric", "head", "target")} == {g: sums[g] for g in ("telemetric", "head", "target")}
    assert shown["combined"] == float(next(r for r in tab if r[ig] == "combined")[ish])
