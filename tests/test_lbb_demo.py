"""The LBB demo section (quick mode) renders with the paper's numbers beside ours."""

from multilat.report.html import render
from multilat.report.lbb_demo import PAPER_MAX_STD_UM, section


def test_lbb_demo_quick():
    sec = section(seed=3, quick=True)
    html = render("t", [sec])
    assert "Laser ball bar" in html and str(PAPER_MAX_STD_UM) in html
    assert html.count("<img") == 3 and "<table>" in html
