"""``--report FILE.html`` of the computing commands: the option's help and the one call each
command makes after its JSON document is built (:func:`write_report`)."""

from __future__ import annotations

from pathlib import Path

from multilat.errors import MultilatError

HELP = ("Write a self-contained HTML report of this job (inputs with sha256, options, seed, version, "
        "results with standard and expanded uncertainties, figures, warnings), atomically.")


def check_report_path(path, inputs=()) -> None:
    """Refuse a report path that is an input or does not end in .html/.htm (before any work)."""
    if path is None:
        return
    from multilat.io import check_not_input

    if Path(path).suffix.lower() not in (".html", ".htm"):
        raise MultilatError(f"--report {path}: expected a file name ending in .html")
    check_not_input(path, [p for p in inputs if p is not None], "--report")


def write_report(path, command: str, doc: dict, *, result=None, build=None) -> None:
    """Build the report of the running command from its JSON ``doc`` and write it to ``path``
    (nothing when ``path`` is None). Options and input files are read from the command line being
    run (click's context); warnings from those printed so far. ``build``: the page's builder
    (default :func:`multilat.report.job.build_report`; the general layer's is
    :func:`multilat.report.general_sections.build_report`)."""
    if path is None:
        return
    from multilat.cli.app import collected_warnings, console
    from multilat.io import write_text_atomic
    from multilat.report.job import JobContext, build_report

    ctx = current_context()
    options = dict(ctx.params) if ctx is not None else {}
    line = ctx.command_path if ctx is not None else f"multilat {command}"
    jc = JobContext.from_options(command, options, command_line=line, warnings=collected_warnings())
    write_text_atomic(path, (build or build_report)(jc, doc, result=result))
    if not any(o for k, o in options.items() if k in ("as_json", "json_out") and o):
        console.print(f"report written to {path}", markup=False)


def current_context():
    """The running command's click context (typer >= 0.2x carries its own copy of click)."""
    try:
        from typer._click.globals import get_current_context
    except ImportError:  # pragma: no cover - typer on the public click
        from click import get_current_context
    return get_current_context(silent=True)


_current_context = current_context      # the former private name
