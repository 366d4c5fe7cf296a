"""The typer application object, shared helpers for output, and :func:`main`."""

from __future__ import annotations

import contextlib
import json
import os
import sys
import warnings
from collections.abc import Sequence

import typer
from rich.console import Console

from multilat.errors import MultilatError
from multilat.io import to_jsonable

app = typer.Typer(
    name="multilat",
    help="Large-volume coordinate metrology: distance model, self-calibrating multilateration, "
    "laser ball bar, Monte Carlo uncertainty.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


@app.callback()
def _root() -> None:
    """Large-volume coordinate metrology: distance model, self-calibrating multilateration,
    laser ball bar, Monte Carlo uncertainty. Every computing command takes --json."""

console = Console(stderr=False, highlight=False)
err_console = Console(stderr=True, highlight=False)


def emit_json(obj) -> None:
    """Print ``obj`` (dataclasses, numpy values allowed) as JSON on stdout."""
    sys.stdout.write(json.dumps(to_jsonable(obj), indent=2) + "\n")
    sys.stdout.flush()


def progress(*, transient: bool = True, disable: bool = False):
    """A rich progress bar on stderr (so ``--json`` stdout stays clean).

    Usage::

        with progress() as p:
            task = p.add_task("Monte Carlo", total=n)
            p.advance(task, k)
    """
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                               TimeElapsedColumn, TimeRemainingColumn)

    return Progress(TextColumn("[progress.description]{task.description}"), BarColumn(),
                    MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn(),
                    console=err_console, transient=transient, disable=disable)


def _showwarning(message, category, filename, lineno, file=None, line=None):
    err_console.print(f"warning: {message}", markup=False, soft_wrap=True)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI with ``argv`` (default ``sys.argv[1:]``); return the exit code.

    Bad input (:class:`MultilatError`, usage errors, an output path that cannot be written) prints
    one line on stderr and returns 2; Ctrl-C returns 130; a closed stdout pipe returns 141 quietly. Tests call ``main([...])`` directly.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    old = warnings.showwarning
    warnings.showwarning = _showwarning
    try:
        rv = app(args=args, standalone_mode=False, prog_name="multilat")
        return int(rv) if isinstance(rv, int) else 0
    except MultilatError as exc:
        err_console.print(f"error: {exc}", markup=False, soft_wrap=True)
        return 2
    except typer.Exit as exc:
        return int(getattr(exc, "exit_code", 0) or 0)
    except (typer.Abort, KeyboardInterrupt):
        err_console.print("error: interrupted", markup=False)
        return 130
    except BrokenPipeError:  # `multilat ... | head`: the reader left; nothing to report
        with contextlib.suppress(OSError):
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115  (keep interpreter shutdown quiet)
        return 141
    except OSError as exc:  # an output path that cannot be written: a directory missing, disk full
        where = exc.filename or "output"
        err_console.print(f"error: {where}: {exc.strerror or exc}", markup=False, soft_wrap=True)
        return 2
    except typer.TyperException as exc:  # click's usage errors (typer vendors click)
        if type(exc).__name__ == "NoArgsIsHelpError":
            err_console.print(exc.format_message(), markup=False)
            return 0
        err_console.print(f"error: {exc.format_message()}", markup=False, soft_wrap=True)
        return int(getattr(exc, "exit_code", 2) or 2)
    finally:
        warnings.showwarning = old
