"""The issues' speed goals with their verdicts computed from the measured numbers in ``benchmarks/goals.json``.

``python benchmarks/goals.py`` prints the tables (one per issue section, newest first); ``--write`` puts
them into BENCHMARKS.md between the ``<!-- goals:begin -->`` and ``<!-- goals:end -->`` markers (whole
file or nothing). ``tests/test_benchmark_goals.py`` checks that BENCHMARKS.md shows what this computes:
a ratio or a verdict is never typed by hand.

A goal's judged value is ``measured`` itself, or, with ``ratio`` = ``"measured/baseline"`` or
``"baseline/measured"``, that ratio of ``measured`` and ``baseline_measured`` (the baseline measured in
the same run, ``benchmarks/goals29.py``). A goal without its numbers is "not measured", with the reason
(``why_not_measured``), never guessed.
"""

from __future__ import annotations

import json
import operator
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
DATA = HERE / "goals.json"
PAGE = HERE.parent / "BENCHMARKS.md"
BEGIN, END = "<!-- goals:begin -->", "<!-- goals:end -->"
_OPS = {"<=": operator.le, ">=": operator.ge}
RATIOS = ("measured/baseline", "baseline/measured")


def value(goal: dict) -> float | None:
    """The judged value: ``measured``, or its ratio to the same run's baseline; None when a number
    it needs is missing."""
    m, ratio = goal.get("measured"), goal.get("ratio")
    if m is None:
        return None
    if ratio is None:
        return float(m)
    b = goal.get("baseline_measured")
    if b is None:
        return None
    if ratio not in RATIOS:
        raise ValueError(f"goal {goal.get('key', goal['goal'])!r}: ratio must be one of {RATIOS}, got {ratio!r}")
    return float(m) / float(b) if ratio == RATIOS[0] else float(b) / float(m)


def met(goal: dict) -> bool | None:
    """Whether ``value op limit`` holds; None for a goal not measured."""
    v = value(goal)
    return None if v is None else bool(_OPS[goal["op"]](v, float(goal["limit"])))


def _num(x: float) -> str:
    if abs(x) >= 1000:
        return f"{x:,.0f}"
    return f"{x:.3g}" if abs(x) < 100 else f"{x:.0f}"


def _with_unit(x, unit: str) -> str:
    if x is None:
        return "—"
    if unit == "x":
        return f"{_num(x)}x"
    return f"{_num(x)} {unit}"


def _row(g: dict) -> str:
    mu = g.get("measured_unit", g["unit"])
    v, ok = value(g), met(g)
    verdict = "not measured" if ok is None else ("yes" if ok else "**no**")
    base = g.get("baseline", "—")
    if g.get("ratio") is not None:
        base = f"{base}: {_with_unit(g.get('baseline_measured'), mu)}"
    run = g.get("run") or ""
    if ok is None:
        run = (run + "; " if run else "") + f"not judged: {g['why_not_measured']}"
    load = g.get("load")
    return (f"| {g['goal']} | {_with_unit(g.get('measured'), mu)} | {base} | {_with_unit(v, g['unit'])} | "
            f"{g['op']} {_with_unit(g['limit'], g['unit'])} | {verdict} | {'—' if load is None else f'{load:.1f}'} "
            f"| {run} |")


def render_section(sec: dict) -> str:
    """One issue's table: goal, measured, baseline (same run), judged value, limit, met?, load, run."""
    rows = [f"Issue {sec['issue']}'s goals, ratios and verdicts computed by `benchmarks/goals.py` from "
            "`benchmarks/goals.json` (each figure from the run named beside it):", "",
            "| goal | measured | baseline in the same run | judged | goal | met? | load | run |",
            "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    rows += [_row(g) for g in sec["goals"]]
    verdicts = [met(g) for g in sec["goals"]]
    n_met, n_no = verdicts.count(True), verdicts.count(False)
    rows += ["", f"{n_met} of {n_met + n_no} measured goals met; {verdicts.count(None)} not measured."]
    return "\n".join(rows)


def render(data: dict) -> str:
    """Every section's table, in the file's order."""
    return "\n\n".join(render_section(sec) for sec in data["sections"])


def block(page: str) -> str:
    """The text between the markers of ``page``."""
    a, b = page.index(BEGIN) + len(BEGIN), page.index(END)
    return page[a:b].strip("\n")


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    data = json.loads(DATA.read_text(encoding="utf-8"))
    table = render(data)
    if "--write" in argv:
        page = PAGE.read_text(encoding="utf-8")
        a, b = page.index(BEGIN) + len(BEGIN), page.index(END)
        tmp = PAGE.with_suffix(".md.tmp")
        tmp.write_text(page[:a] + "\n" + table + "\n" + page[b:], encoding="utf-8")
        tmp.replace(PAGE)
    else:
        print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
