"""``multilat demo``: the papers' numbers beside multilat's, on the job-report machinery (what was
run: version, date, seed; the papers cited in full; every section's verdicts computed beside the
numbers they judge)."""

from __future__ import annotations

import importlib
from collections.abc import Callable

from multilat.report.html import Section, render
from multilat.report.job import JobContext, meta_section, warnings_section
from multilat.report.papers import PAPERS, cite

# Each module provides ``section(*, seed: int, quick: bool) -> multilat.report.html.Section``.
DEMO_SECTIONS = (
    "multilat.report.distance_demo",   # Guillory 2020 §2-3: air index, ADM, budget
    "multilat.report.network_demo",    # Guillory 2020 §4: self-calibrating multilateration
    "multilat.report.sequential_demo",  # heads moved over several stations (issue 16)
    "multilat.report.angles_demo",      # angles as observations: encoder angles, trackers (issue 15)
    "multilat.report.campaign_demo",   # Guillory 2020 §3.2, 4.2: raw readings -> corrected distances
    "multilat.report.propagate_demo",  # full Monte Carlo through the adjustment
    "multilat.report.lbb_demo",        # Canning 2007: laser ball bar
)
TITLE = "multilat: the papers reproduced"


def sources_section() -> Section:
    sec = Section("Sources")
    sec.items([f"[{i}] {p.citation()}" for i, p in enumerate(PAPERS, 1)])
    sec.paragraph("Each table puts the paper's value beside multilat's; a verdict column is computed from the "
                  "two numbers in its row (the rule is in the column's header or the caption).")
    return sec


def _cited(sec: Section) -> Section:
    return Section(cite(sec.title), [cite(b) for b in sec.blocks])


def build_demo(*, seed: int, quick: bool, context: JobContext | None = None,
               advance: Callable[[], None] | None = None,
               warnings: Callable[[], tuple] | None = None) -> str:
    """The whole demo page. ``advance`` is called after each section (progress); ``warnings()``
    gives the warnings raised while the sections were computed."""
    ctx = context or JobContext.from_options("demo", {"seed": seed, "quick": quick})
    sections = []
    for name in DEMO_SECTIONS:
        sections.append(_cited(importlib.import_module(name).section(seed=seed, quick=quick)))
        if advance is not None:
            advance()
    ctx = JobContext(ctx.command, ctx.command_line, ctx.options, ctx.inputs, ctx.version, ctx.date_utc,
                     tuple(ctx.warnings) + tuple(warnings() if warnings else ()))
    return render(TITLE, [meta_section(ctx, {}), sources_section(), *sections, warnings_section(ctx, {})],
                  subtitle="Every number below is computed when this page is built; the papers' values "
                           "are quoted from [1] and [2].")
