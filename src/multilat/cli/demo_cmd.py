"""``multilat demo``: reproduce the seed papers' numbers beside ours in one HTML report."""

from __future__ import annotations

from pathlib import Path

import typer

from multilat.cli.app import app, collected_warnings, console, progress
from multilat.io import write_text_atomic
from multilat.report.demo import DEMO_SECTIONS  # noqa: F401  (re-exported: tests count the sections)


@app.command()
def demo(
    out: Path = typer.Option(Path("demo-report"), "--out", "-o", help="Directory for report.html."),
    seed: int = typer.Option(20200808, "--seed", help="Seed of every Monte Carlo in the report."),
    quick: bool = typer.Option(False, "--quick", help="Smaller Monte Carlo sample sizes (for tests)."),
) -> None:
    """Reproduce the seed papers' numbers beside multilat's own, as DIR/report.html."""
    from multilat.cli import checks
    from multilat.cli.report_opt import current_context
    from multilat.report.demo import build_demo
    from multilat.report.job import JobContext

    checks.seed(seed)
    if out.exists() and not out.is_dir():
        from multilat.errors import MultilatError

        raise MultilatError(f"--out {out}: exists and is not a directory")
    ctx = current_context()
    jc = JobContext.from_options("demo", dict(ctx.params) if ctx else {"seed": seed, "quick": quick},
                                 command_line=ctx.command_path if ctx else "multilat demo")
    with progress() as p:
        task = p.add_task("demo", total=len(DEMO_SECTIONS))
        page = build_demo(seed=seed, quick=quick, context=jc, advance=lambda: p.advance(task),
                          warnings=collected_warnings)
    target = out / "report.html"
    write_text_atomic(target, page)
    console.print(f"wrote {target} ({len(DEMO_SECTIONS)} sections)")
