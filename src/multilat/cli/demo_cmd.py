"""``multilat demo``: reproduce the seed papers' numbers beside ours in one HTML report."""

from __future__ import annotations

import importlib
from pathlib import Path

import typer

from multilat.cli.app import app, console, progress
from multilat.io import write_text_atomic

# Each module provides ``section(*, seed: int, quick: bool) -> multilat.report.html.Section``.
DEMO_SECTIONS = (
    "multilat.report.distance_demo",   # seed 000 §2-3: air index, ADM, budget
    "multilat.report.network_demo",    # seed 000 §4: self-calibrating multilateration
    "multilat.report.sequential_demo",  # heads moved over several stations (issue 16)
    "multilat.report.campaign_demo",   # seed 000 §3.2, 4.2: raw readings -> corrected distances
    "multilat.report.propagate_demo",  # full Monte Carlo through the adjustment
    "multilat.report.lbb_demo",        # seed 003: laser ball bar
)


@app.command()
def demo(
    out: Path = typer.Option(Path("demo-report"), "--out", help="Directory for report.html."),
    seed: int = typer.Option(20200808, "--seed", help="Seed of every Monte Carlo in the report."),
    quick: bool = typer.Option(False, "--quick", help="Smaller Monte Carlo sample sizes (for tests)."),
) -> None:
    """Reproduce the seed papers' numbers beside multilat's own, as DIR/report.html."""
    from multilat.cli import checks
    from multilat.report.html import render

    checks.seed(seed)
    if out.exists() and not out.is_dir():
        from multilat.errors import MultilatError

        raise MultilatError(f"--out {out}: exists and is not a directory")
    sections = []
    with progress() as p:
        task = p.add_task("demo", total=len(DEMO_SECTIONS))
        for name in DEMO_SECTIONS:
            mod = importlib.import_module(name)
            sections.append(mod.section(seed=seed, quick=quick))
            p.advance(task)
    target = out / "report.html"
    write_text_atomic(target, render("multilat: the seed papers reproduced", sections))
    console.print(f"wrote {target} ({len(sections)} sections)")
