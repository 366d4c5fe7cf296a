"""`multilat demo --quick` builds the whole report (every capability's section) in one HTML file."""

import importlib

from multilat.cli import main
from multilat.cli.demo_cmd import DEMO_SECTIONS


def test_demo_quick_writes_report_with_every_available_section(tmp_path, capsys):
    assert main(["demo", "--quick", "--out", str(tmp_path)]) == 0
    html = (tmp_path / "report.html").read_text()
    assert html.startswith("<!doctype html>") and html.rstrip().endswith("</html>")
    present = []
    for name in DEMO_SECTIONS:
        try:
            importlib.import_module(name)
        except ModuleNotFoundError:
            continue
        present.append(name)
    assert html.count("<section>") == len(present)
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]
