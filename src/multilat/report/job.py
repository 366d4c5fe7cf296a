"""The report of a user's own job (``--report FILE.html`` on the computing commands).

One machinery for every command: a :class:`JobContext` (what was run: inputs with their sha256,
options, seed, instrument and σ sources, multilat version, date, warnings) and the command's JSON
document go in; a self-contained HTML page comes out (figures as data URIs, the optional
interactive 3-D view inline). Every number in the results tables is read from the JSON document
the command prints with ``--json`` (a :class:`~multilat.report.html.Num` cell names its path), so
the page and the JSON cannot disagree; ``tests/test_job_report.py`` checks each cell.

Expanded uncertainties are ``U = k u`` with :data:`K_EXPANDED` = 2 (coverage probability about 95 %
for a normal distribution); 95 % ellipsoids use ``k = sqrt(chi2_3(0.95)) = 2.80``; Monte Carlo
intervals are the 95 % coverage intervals of the simulated distribution (JCGM 101), no k.
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from multilat.report.html import Num, Section, render

__all__ = ["JobContext", "K_EXPANDED", "build_report", "file_sha256", "multilat_version"]

#: Coverage factor of the expanded uncertainties in the reports (about 95 % for a normal distribution).
K_EXPANDED = 2.0
#: Options naming files the command writes (never listed as inputs).
OUTPUT_OPTIONS = frozenset({"report", "out", "plot", "cov"})
#: Commands that have a report, and their titles.
TITLES = {
    "adjust": "Self-calibrating multilateration adjustment",
    "propagate": "Monte Carlo propagation through the adjustment",
    "simulate": "Simulation of the adjustment's own uncertainty",
    "design": "Network design (pre-analysis)",
    "budget": "Uncertainty budget of one distance",
    "correct": "Raw readings corrected into distances",
    "lbb simulate": "Laser ball bar: Monte Carlo over the work volume",
    "lbb compare": "Laser ball bar against reference coordinates",
}


def file_sha256(path: str | os.PathLike) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def multilat_version() -> str:
    """The installed multilat's version (``importlib.metadata``), or ``"unknown"``."""
    from importlib import metadata

    try:
        return metadata.version("multilat")
    except metadata.PackageNotFoundError:  # pragma: no cover - run from a source tree
        return "unknown"


@dataclass(frozen=True)
class InputFile:
    option: str
    path: str
    sha256: str
    size_bytes: int


@dataclass(frozen=True)
class JobContext:
    """What was run. :func:`JobContext.from_options` fills it from the command's options."""

    command: str
    command_line: str = ""
    options: dict = field(default_factory=dict)
    inputs: tuple[InputFile, ...] = ()
    version: str = ""
    date_utc: str = ""
    warnings: tuple[str, ...] = ()

    @classmethod
    def from_options(cls, command: str, options: dict, *, command_line: str = "",
                     warnings=()) -> "JobContext":
        """Inputs are the option values that name an existing regular file (sha256 of each), except
        the outputs (:data:`OUTPUT_OPTIONS`)."""
        inputs = []
        for name, v in options.items():
            if name in OUTPUT_OPTIONS:
                continue
            if isinstance(v, (str, Path)) and v and os.path.isfile(v):
                inputs.append(InputFile(name, str(v), file_sha256(v), os.path.getsize(v)))
        return cls(command=command, command_line=command_line, options=dict(options),
                   inputs=tuple(inputs), version=multilat_version(),
                   date_utc=datetime.now(timezone.utc).isoformat(timespec="seconds"),
                   warnings=tuple(str(w) for w in warnings))


def _opt_text(v) -> str:
    if v is None:
        return "-"
    if hasattr(v, "value"):        # enums
        v = v.value
    return str(v)


def _sigma_source(ctx: JobContext, doc: dict) -> list[str]:
    """Where the instrument model and each distance's σ come from, in words."""
    o = ctx.options
    out = []
    inst = o.get("instrument")
    if inst is not None:
        out.append(f"instrument: {_opt_text(inst)}" + (" (TOML file, sha256 above)"
                                                       if os.path.isfile(str(inst)) else " (preset)"))
    recorded = doc.get("sigma_source") if isinstance(doc, dict) else None
    if recorded:        # the command's own record (adjust, propagate, simulate)
        from multilat.network.model.sigma_source import describe

        out.append(describe(recorded) + " (k = 1)")
    elif o.get("sigma_um") is not None and ctx.command not in ("simulate",):
        out.append(f"σ of every distance: --sigma-um {o['sigma_um']:g} µm (k = 1)")
    elif ctx.command in ("adjust", "propagate"):
        src = o.get("observations") or o.get("source")
        if src and os.path.isfile(str(src)):
            header = ""
            with open(src, encoding="utf-8", errors="replace") as f:
                for line in f:               # the first line that is not a comment or blank
                    if line.strip() and not line.lstrip().startswith("#"):
                        header = line
                        break
            if "sigma_m" in [c.strip() for c in header.split(",")]:
                out.append(f"σ of each distance: the sigma_m column of {src} (k = 1)")
            else:
                out.append("σ of each distance: the distance model of the instrument (k = 1)")
    if ctx.command == "simulate":
        out.append("noise: " + ("gaussian, with the σ above" if o.get("noise") == "gaussian"
                                else "each error drawn from the distance model of the instrument"))
    if ctx.command == "propagate":
        out.append(f"noise: {doc.get('noise')}")
    if ctx.command == "design" and doc.get("sigma"):
        out.append(f"σ: {doc['sigma']}")
    if ctx.command == "correct":
        out.append(f"group index formula: {_opt_text(o.get('formula'))}; σ of each distance: distance "
                   "model of the instrument combined with the environment sensors' uncertainties")
    return out


def meta_section(ctx: JobContext, doc: dict) -> Section:
    """What was measured and how it was computed: inputs, options, seed, version, date (the last
    section: the reader wants the results and their verdicts first)."""
    sec = Section("What was run: inputs and options", key="run")
    rows = [("command", ctx.command_line or f"multilat {ctx.command}"),
            ("multilat version", ctx.version), ("date (UTC)", ctx.date_utc)]
    seed = ctx.options.get("seed")
    ent = doc.get("seed")
    if seed is not None:
        seed_text = f"{seed}"
    elif ent is not None:
        seed_text = f"fresh entropy {ent}"
    elif "seed" in ctx.options:
        seed_text = "fresh entropy (not recorded by this command: give --seed to repeat the run)"
    else:
        seed_text = "- (nothing random)"
    rows.append(("seed", seed_text))
    sec.blocks.append("<table class='meta'><tbody>" + "".join(
        f"<tr><th>{_esc(k)}</th><td>{_esc(v)}</td></tr>" for k, v in rows) + "</tbody></table>")
    if ctx.inputs:
        sec.table(("option", "file", "bytes", "sha256"),
                  [(i.option, i.path, i.size_bytes, i.sha256) for i in ctx.inputs],
                  caption="Inputs (sha256 of the file's bytes: the same file gives the same checksum)")
    else:
        sec.paragraph("Inputs: no input file (built-in configuration or preset).")
    src = _sigma_source(ctx, doc)
    if src:
        sec.items(src)
    skip = {"report", "as_json", "json_out"}
    sec.table(("option", "value"), [(k, _opt_text(v)) for k, v in ctx.options.items() if k not in skip],
              caption="Options")
    return sec


def _esc(s) -> str:
    import html

    return html.escape(str(s))


def job_warnings(ctx: JobContext, doc: dict) -> list[str]:
    """Every warning of the job: those the command printed, then those in its JSON not printed."""
    return list(ctx.warnings) + [str(w) for w in (doc.get("warnings") or []) if str(w) not in ctx.warnings]


def warnings_section(ctx: JobContext, doc: dict) -> Section:
    sec = Section("Warnings", key="warnings")
    ws = job_warnings(ctx, doc)
    if ws:
        sec.items(ws, cls="warn")
    else:
        sec.paragraph("No warning was raised.", cls="ok")
    return sec


def uncertainty_note() -> str:
    from multilat.network.adjust.statistics import CHI2_3_95   # here: scipy loads only for a report

    return (f"Standard uncertainties u are k = 1. Expanded uncertainties U = k u with k = {K_EXPANDED:g} "
            "(coverage probability about 95 % for a normal distribution). 95 % ellipsoids: semi-axes "
            f"sqrt(χ²₃(0.95)) = {math.sqrt(CHI2_3_95):.2f} × the principal standard deviations. "
            "Monte Carlo coverage intervals are quantiles of the simulated distribution (JCGM 101), "
            "no coverage factor.")


def build_report(ctx: JobContext, doc: dict, *, result=None, title: str | None = None) -> str:
    """The whole HTML page of one job: results (verdicts first), figures, warnings, and last what
    was run (inputs, options, seed, version).

    ``doc`` is the command's JSON document (as printed by ``--json``); ``result`` the library's
    result object where a figure needs more than the JSON (samples, the adjusted network).
    """
    from multilat.io import to_jsonable
    from multilat.report import job_sections

    doc = to_jsonable(doc)
    results = job_sections.sections(ctx.command, doc, result=result, options=ctx.options,
                                    warnings=job_warnings(ctx, doc))
    sections = [*results, warnings_section(ctx, doc), meta_section(ctx, doc)]
    head = title or TITLES.get(ctx.command, ctx.command)
    return render(f"multilat {ctx.command}: {head}", sections, subtitle=uncertainty_note())


__all__ += ["InputFile", "Num", "Section"]
