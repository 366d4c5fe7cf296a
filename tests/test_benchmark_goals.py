"""BENCHMARKS.md's verdicts on issue 12's goals are computed, not typed: the block between its
markers is what ``benchmarks/goals.py`` renders from ``benchmarks/goals.json``; the verdict is the
comparison of the measured number with the limit (checked here on both sides of each limit)."""

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _goals():
    spec = importlib.util.spec_from_file_location("bench_goals", ROOT / "benchmarks" / "goals.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_page_shows_the_computed_table():
    g = _goals()
    data = json.loads((ROOT / "benchmarks" / "goals.json").read_text(encoding="utf-8"))
    page = (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8")
    assert g.block(page) == g.render(data), "run: python benchmarks/goals.py --write"


def test_verdicts_follow_the_numbers():
    g = _goals()
    data = json.loads((ROOT / "benchmarks" / "goals.json").read_text(encoding="utf-8"))
    for goal in data["goals"]:
        assert goal["op"] in ("<=", ">=") and goal["limit"] > 0
        # a measured quantity is positive; an "extra" one is a difference of two runs (noise can make it < 0)
        assert goal["measured"] > 0 or (goal["quantity"].startswith("extra") and abs(goal["measured"]) < goal["limit"])
        for factor, inside in ((0.5, goal["op"] == "<="), (2.0, goal["op"] == ">=")):
            assert g.met(dict(goal, measured=goal["limit"] * factor)) is inside
        assert g.met(dict(goal, measured=goal["limit"])) is True        # the limit itself is met
    table = g.render(data)
    n_met = sum(g.met(x) for x in data["goals"])
    assert table.count("| yes |") == n_met and table.count("| **no** |") == len(data["goals"]) - n_met
    assert f"{n_met} of {len(data['goals'])} goals met." in table
