"""BENCHMARKS.md's verdicts on the issues' speed goals (issue 29's, issue 12's history) are computed, not
typed: the block between its markers is what ``benchmarks/goals.py`` renders from
``benchmarks/goals.json``; the judged value is the measured number or its ratio to the baseline measured
in the same run, and the verdict its comparison with the limit (checked here on both sides of each
limit). A goal without its numbers says "not measured" and why."""

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _goals():
    spec = importlib.util.spec_from_file_location("bench_goals", ROOT / "benchmarks" / "goals.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _data():
    return json.loads((ROOT / "benchmarks" / "goals.json").read_text(encoding="utf-8"))


def test_the_page_shows_the_computed_table():
    g = _goals()
    page = (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8")
    assert g.block(page) == g.render(_data()), "run: python benchmarks/goals.py --write"


def test_issue_29_has_every_goal_of_the_issue():
    sec = {s["issue"]: s for s in _data()["sections"]}[29]
    keys = [x["key"] for x in sec["goals"]]
    assert len(set(keys)) == len(keys)
    assert {"small_adjust", "adjust_20k", "adjust_200k", "adjust_200k_rss", "adjust_200k_out", "gama",
            "propagate_model", "propagate_gaussian", "dask_scaling", "first_command", "make_test",
            "growth_1k_4k", "growth_4k_16k"} == set(keys)
    for x in sec["goals"]:
        if x["measured"] is not None:          # a measured row names its run and the load it ran at
            assert x["run"] and x["load"] is not None


def test_verdicts_follow_the_numbers():
    g = _goals()
    for sec in _data()["sections"]:
        for goal in sec["goals"]:
            assert goal["op"] in ("<=", ">=") and goal["limit"] > 0
            v = g.value(goal)
            if v is None:                                  # never guessed: the reason is given
                assert g.met(goal) is None and goal["why_not_measured"]
                continue
            # a measured quantity is positive; an "extra" one is a difference of two runs (noise: < 0)
            assert v > 0 or (goal.get("quantity", "").startswith("extra") and abs(v) < goal["limit"])
            if goal.get("ratio") == "measured/baseline":
                assert v == pytest.approx(goal["measured"] / goal["baseline_measured"])
            elif goal.get("ratio") == "baseline/measured":
                assert v == pytest.approx(goal["baseline_measured"] / goal["measured"])
            else:
                assert v == goal["measured"]
            # the verdict moves with the judged value, on both sides of the limit
            at = dict(goal, ratio=None, measured=goal["limit"])
            assert g.met(at) is True                                       # the limit itself is met
            for factor, inside in ((0.5, goal["op"] == "<="), (2.0, goal["op"] == ">=")):
                assert g.met(dict(at, measured=goal["limit"] * factor)) is inside
        table = g.render_section(sec)
        verdicts = [g.met(x) for x in sec["goals"]]
        n_met, n_no, n_none = verdicts.count(True), verdicts.count(False), verdicts.count(None)
        assert table.count("| yes |") == n_met and table.count("| **no** |") == n_no
        assert table.count("| not measured |") == n_none
        assert f"{n_met} of {n_met + n_no} measured goals met; {n_none} not measured." in table


def test_a_ratio_goal_is_judged_on_the_ratio():
    """A baseline-relative goal: 2.0 s against a 1.0 s baseline is 2x slower (``measured/baseline``)
    or 0.5x 'faster' (``baseline/measured``); without the baseline it is not measured."""
    g = _goals()
    slow = {"goal": "x", "op": "<=", "limit": 2.5, "unit": "x", "ratio": "measured/baseline",
            "measured": 2.0, "baseline_measured": 1.0}
    assert g.value(slow) == 2.0 and g.met(slow) is True
    assert g.met(dict(slow, measured=3.0)) is False
    fast = dict(slow, op=">=", limit=3, ratio="baseline/measured")
    assert g.value(fast) == 0.5 and g.met(fast) is False
    assert g.met(dict(fast, measured=0.2)) is True                   # 5x faster
    assert g.met(dict(fast, baseline_measured=None)) is None
    with pytest.raises(ValueError, match="ratio must be one of"):
        g.value(dict(slow, ratio="measured-baseline"))
