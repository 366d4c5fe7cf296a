"""Bounds on the searches of an adjustment from distances alone, and their progress line.

Every search that tries starts until one is good enough (the random restarts of the initial values,
:mod:`multilat.network.adjust.approximate.initial`; the flat-solution restarts, :mod:`multilat.network.adjust.approximate.starts`; the
minimum search, :mod:`multilat.network.adjust.approximate.search`) is bounded twice:

* by **work**: a number of starts (the restarts' ``restarts``, ``PARTIAL_RESTARTS``, the minimum
  search's rounds and :data:`SEARCH_SOLVES` candidate solves) and, inside each start, the
  Levenberg-Marquardt iteration limit; this bound is deterministic;
* by **wall time**: :data:`RESTART_SECONDS` for the restarts of one set of initial values,
  :data:`SEARCH_SECONDS` for the whole minimum search (its own initial values included); checked
  between starts and between Levenberg-Marquardt iterations, so a bound is overrun by at most one
  iteration. The wall-time bound is a safety net for inputs that the work bound alone would let run
  for hours (issue 25: a unit slip made each restart take minutes); when it stops a search the
  result depends on the machine's speed, so a warning says so.

A search that stops at a bound keeps the best solution found so far; the record (the JSON
``initial`` block) says which bound stopped it.

Progress: the searches call :func:`report` with one short line (which search, which start); the CLI
shows it in its progress line on stderr when stderr is a terminal (:func:`reporting`), nothing
otherwise.
"""

from __future__ import annotations

import time
import warnings
from contextlib import contextmanager
from contextvars import ContextVar

__all__ = ["Bound", "RESTART_SECONDS", "SEARCH_SECONDS", "SEARCH_SOLVES", "report", "reporting"]

#: wall-time bound of the random restarts of one set of initial values, seconds
RESTART_SECONDS = 120.0
#: wall-time bound of one minimum search (candidate solves and their initial values), seconds
SEARCH_SECONDS = 300.0
#: work bound of one minimum search: candidate starts solved (3 rounds of ~25 on small networks)
SEARCH_SOLVES = 80

_reporter: ContextVar = ContextVar("multilat_search_reporter", default=None)


class Bound:
    """A work and wall-time bound for one search.

    ``what`` names the search in notes; ``max_work`` counts its starts (:meth:`spend`);
    ``max_seconds`` is wall time from creation, or from ``deadline`` (a :func:`time.monotonic`
    value) when that is earlier (a search inside a bounded search)."""

    def __init__(self, what: str, *, max_work: int, max_seconds: float, deadline: float | None = None,
                 clock=time.monotonic):
        self.what = what
        self.max_work = int(max_work)
        self.max_seconds = float(max_seconds)
        self.clock = clock
        self.started = clock()
        self.deadline = self.started + self.max_seconds
        if deadline is not None:
            self.deadline = min(self.deadline, float(deadline))
        self.work = 0
        self.stopped_by: str | None = None

    def spend(self, n: int = 1) -> None:
        self.work += n

    def exhausted(self) -> bool:
        """Whether the search must stop (and records which bound stopped it)."""
        if self.work >= self.max_work:
            self.stopped_by = self.stopped_by or "work"
        elif self.clock() >= self.deadline:
            self.stopped_by = self.stopped_by or "time"
        return self.stopped_by is not None

    def note(self) -> str | None:
        """One line when a bound stopped the search (None otherwise)."""
        if self.stopped_by is None:
            return None
        used = self.clock() - self.started
        if self.stopped_by == "work":
            return f"{self.what}: stopped at its work bound ({self.work} starts)"
        return (f"{self.what}: stopped at its wall-time bound ({used:.0f} s, {self.work} of at most "
                f"{self.max_work} starts): the best solution so far is kept; on a faster machine more "
                "starts would have been tried")

    def warn_if_timed_out(self) -> None:
        """A warning when the wall-time bound stopped the search (the result depends on the machine)."""
        if self.stopped_by == "time":
            warnings.warn(self.note(), UserWarning, stacklevel=3)


def report(text: str) -> None:
    """Show ``text`` as the current step of a search (in the CLI's progress line, if any)."""
    cb = _reporter.get()
    if cb is not None:
        cb(text)


@contextmanager
def reporting(callback):
    """Within the block, :func:`report` calls ``callback(text)``."""
    token = _reporter.set(callback)
    try:
        yield
    finally:
        _reporter.reset(token)
