"""Issue 12's goals with their verdicts computed from the measured numbers in ``benchmarks/goals.json``.

``python benchmarks/goals.py`` prints the table; ``--write`` puts it into BENCHMARKS.md between the
``<!-- goals:begin -->`` and ``<!-- goals:end -->`` markers (whole file or nothing).
``tests/test_benchmark_goals.py`` checks that BENCHMARKS.md shows what this computes: a verdict is
never typed by hand.
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


def met(goal: dict) -> bool:
    """Whether ``measured op limit`` holds."""
    return bool(_OPS[goal["op"]](float(goal["measured"]), float(goal["limit"])))


def _num(x: float) -> str:
    return f"{x:,.0f}" if abs(x) >= 1000 else f"{x:g}"


def render(data: dict) -> str:
    """The markdown table: goal, quantity, limit, measured, ratio to the limit, met?, run."""
    rows = [f"Issue {data['issue']}'s goals, verdicts computed by `benchmarks/goals.py` from "
            "`benchmarks/goals.json` (each figure from the run named beside it):", "",
            "| goal | quantity | limit | measured | measured / limit | met? | run |",
            "| --- | --- | --- | --- | --- | --- | --- |"]
    for g in data["goals"]:
        ratio = float(g["measured"]) / float(g["limit"])
        unit = "" if g["unit"] in ("x",) else f" {g['unit']}"
        rows.append(f"| {g['goal']} | {g['quantity']} | {g['op']} {_num(g['limit'])}{unit} | "
                    f"{_num(g['measured'])}{unit} | {ratio:.2f} | {'yes' if met(g) else '**no**'} | {g['run']} |")
    n_met = sum(met(g) for g in data["goals"])
    rows += ["", f"{n_met} of {len(data['goals'])} goals met."]
    return "\n".join(rows)


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
