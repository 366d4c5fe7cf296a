"""Helpers shared by the benchmark modules (importable by name: run.py puts this folder on sys.path)."""

from __future__ import annotations

import os
import statistics
import time


def load_avg():
    """The machine's 1-minute load average (None where the platform has none): each row records it,
    since this machine is shared and timings are only comparable at similar load."""
    try:
        return os.getloadavg()[0]
    except OSError:  # pragma: no cover
        return None


def median_time(fn, repeats: int):
    """``(median wall time in s, the times)`` of ``repeats`` calls of ``fn``."""
    ts = []
    for _ in range(int(repeats)):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), ts
