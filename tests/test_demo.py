"""`multilat demo --quick` builds the whole report (every capability's section) in one HTML file."""

from multilat.cli import main
from multilat.cli.demo_cmd import DEMO_SECTIONS


def test_demo_quick_writes_report_with_every_section(tmp_path, capsys):
    assert main(["demo", "--quick", "--out", str(tmp_path)]) == 0
    html = (tmp_path / "report.html").read_text()
    assert html.startswith("<!doctype html>") and html.rstrip().endswith("</html>")
    assert len(DEMO_SECTIONS) == 6
    assert html.count("<section>") == len(DEMO_SECTIONS)
    for words in ("budget", "self-calibrat", "sequential", "campaign", "Monte Carlo", "ball bar"):
        assert words.lower() in html.lower(), words
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]
