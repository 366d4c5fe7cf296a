"""The typer application object, shared helpers for output, and :func:`main`."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import warnings
from collections.abc import Sequence

import typer
from rich.console import Console

from multilat.errors import MultilatError, format_error, printable
from multilat.io import dumps_json, write_json

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

class LiteralConsole(Console):
    """A console that prints every string literally: no rich markup (an id ``[/bold]`` is text, not
    a closing tag), no emoji codes, control characters (an ANSI escape in an id or a file name)
    written as ``\\xNN``. Tables, titles and messages all go through :meth:`render_str`; styling is
    asked for explicitly with ``markup=True`` on a string that holds no user text."""

    def render_str(self, text, *, markup=None, **kw):
        if markup:
            return super().render_str(text, markup=True, **kw)
        return super().render_str(printable(text), markup=False, **kw)


    def print(self, *objects, **kw):
        from rich.table import Table

        for o in objects:
            if isinstance(o, Table):
                fit_table(o, self)
        return super().print(*objects, **kw)


def fit_table(table, console) -> None:
    """Make a summary table fit the console's width without cutting a number: when its natural
    width is too wide, drop the vertical rules and outer padding, let the headers wrap, and give
    every column at least the width of its longest cell (ids fold onto a second line rather than
    numbers being cut to ``-0.0000…``)."""
    from rich import box
    from rich.measure import Measurement

    width = console.width
    if Measurement.get(console, console.options.update_width(10**4), table).maximum <= width:
        return
    table.box = box.SIMPLE_HEAD
    table.show_edge = False
    table.pad_edge = False
    table.padding = (0, 1)
    table.title_justify = "left"
    for i, col in enumerate(table.columns):
        cells = [c if isinstance(c, str) else str(c) for c in col._cells]
        col.overflow = "fold"
        col.no_wrap = False
        if i > 0:   # values: a fixed width of the longest value (or header word); never shrunk
            words = str(col.header).split() or [""]
            col.width = max([len(c) for c in cells] + [len(w) for w in words] + [1])
        else:       # ids: the column that gives way, folded onto more lines
            col.min_width = min(max((len(c) for c in cells), default=1), 8)


console = LiteralConsole(stderr=False, highlight=False, markup=False, emoji=False)
err_console = LiteralConsole(stderr=True, highlight=False, markup=False, emoji=False)


def emit_json(obj, command: str, *, indent: bool = True) -> None:
    """Print ``obj`` (dataclasses, numpy values allowed) as JSON on stdout, stamped with the schema of
    ``command`` (:func:`multilat.vocabulary.stamp`: ``"schema": "multilat.<command>/<version>"``);
    two-space indented unless ``indent=False``."""
    import dataclasses

    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        obj = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict):
        from multilat.vocabulary import stamp

        obj = stamp(obj, command)
    sys.stdout.flush()
    buf = getattr(sys.stdout, "buffer", None)
    if buf is None:         # a text-only stream (some test harnesses)
        sys.stdout.write(dumps_json(obj, indent=indent).decode("utf-8"))
    else:
        write_json(obj, buf, indent=indent)
        buf.flush()
    sys.stdout.flush()


def progress(*, transient: bool = True, disable: bool = False):
    """A rich progress bar on stderr (so ``--json`` stdout stays clean): shown whenever stderr is a
    terminal, with ``--json`` too; nothing at all (not even a newline) when stderr is a file or pipe.

    Usage::

        with progress() as p:
            task = p.add_task("Monte Carlo", total=n)
            p.advance(task, k)
    """
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                               TimeElapsedColumn, TimeRemainingColumn)

    return Progress(TextColumn("[progress.description]{task.description}"), BarColumn(),
                    MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn(),
                    console=err_console, transient=transient,
                    disable=disable or not err_console.is_terminal)


_WARNINGS: list[str] = []


def collected_warnings() -> tuple[str, ...]:
    """The warnings printed by the running command so far (for its ``--report``)."""
    return tuple(_WARNINGS)


def _showwarning(message, category, filename, lineno, file=None, line=None):
    _WARNINGS.append(format_error(message))
    err_console.print(f"warning: {format_error(message)}", soft_wrap=True)


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that every ``finally`` (staged outputs, temporary
    files) runs before the process exits with 143."""


def _on_sigterm(signum, frame):
    raise Terminated()


def _signal_behind(exc: BaseException):
    """The KeyboardInterrupt or :class:`Terminated` behind ``exc``, if any: a signal that arrives while
    numba loads or runs a compiled function can surface as a ``SystemError`` ("returned a result with an
    exception set") whose cause is the signal's exception."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, (KeyboardInterrupt, Terminated)):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def _error(message: str) -> None:
    err_console.print(f"error: {message}", soft_wrap=True)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI with ``argv`` (default ``sys.argv[1:]``); return the exit code.

    Bad input (:class:`MultilatError`, usage errors, an output path that cannot be written) prints
    one line on stderr and returns 2; Ctrl-C returns 130; a closed stdout pipe returns 141 quietly. Tests call ``main([...])`` directly.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    old = warnings.showwarning
    warnings.showwarning = _showwarning
    _WARNINGS.clear()
    old_term = None
    if threading.current_thread() is threading.main_thread():
        old_term = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        from multilat.cli import load_commands

        load_commands(args)     # only the command asked for is imported (issue 29)
        rv = app(args=args, standalone_mode=False, prog_name="multilat")
        if rv == 130:             # typer turns Ctrl-C into a return value of 130 in this mode
            _error("interrupted")
        return int(rv) if isinstance(rv, int) else 0
    except MultilatError as exc:
        _error(format_error(exc))
        return 2
    except typer.Exit as exc:
        return int(getattr(exc, "exit_code", 0) or 0)
    except (typer.Abort, KeyboardInterrupt):
        _error("interrupted")
        return 130
    except Terminated:
        _error("terminated (SIGTERM); no output written")
        return 143
    except BrokenPipeError:  # `multilat ... | head`: the reader left; nothing to report
        _quiet_stdout()
        return 141
    except SystemExit as exc:  # click turns EPIPE into sys.exit(1) (and silences stderr): 141 instead
        if isinstance(exc.__context__, BrokenPipeError):
            sys.stderr = sys.__stderr__
            _quiet_stdout()
            return 141
        raise
    except OSError as exc:  # an output path that cannot be written: a directory missing, disk full
        where = exc.filename or "output"
        _error(f"{format_error(where)}: {format_error(exc.strerror or exc)}")
        return 2
    except typer.TyperException as exc:  # click's usage errors (typer vendors click)
        if type(exc).__name__ == "NoArgsIsHelpError":
            err_console.print(exc.format_message())
            return 0
        _error(format_error(exc.format_message()))
        return int(getattr(exc, "exit_code", 2) or 2)
    except MemoryError:
        _error("out of memory: the request is too large for this machine (reduce --trials, --grid "
               "or the problem size)")
        return 2
    except Exception as exc:  # noqa: BLE001  the last guard: one line, never a traceback
        import numpy as np

        sig = _signal_behind(exc)
        if isinstance(sig, KeyboardInterrupt):
            _error("interrupted")
            return 130
        if isinstance(sig, Terminated):
            _error("terminated (SIGTERM); no output written")
            return 143

        if isinstance(exc, (np.linalg.LinAlgError, FloatingPointError, OverflowError)):
            _error(f"numerical failure ({format_error(exc)}): the problem is singular or overflows for "
                   "these inputs; check the observations for gross errors (a distance in the wrong "
                   "unit, an absurd sigma) and the options for values far beyond the network's size")
            return 2
        if os.environ.get("MULTILAT_TRACEBACK"):
            raise
        _error(f"internal error ({type(exc).__name__}: {format_error(exc)}); please report it "
               "(MULTILAT_TRACEBACK=1 shows the traceback)")
        return 70
    finally:
        warnings.showwarning = old
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)


def run_and_exit(argv: Sequence[str] | None = None) -> None:
    """:func:`main`, then flush stdout (a reader that left early gives 141, quietly) and exit."""
    code = main(argv)
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        _quiet_stdout()
        code = 141
    except (OSError, ValueError):
        pass
    sys.exit(code)


def _quiet_stdout() -> None:
    """After EPIPE: point stdout at /dev/null so the interpreter's final flush stays quiet."""
    with contextlib.suppress(OSError, ValueError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
