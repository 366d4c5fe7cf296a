"""Helpers shared by the benchmark modules (importable by name: run.py puts this folder on sys.path)."""

from __future__ import annotations

import os


def load_avg():
    """The machine's 1-minute load average (None where the platform has none): each row records it,
    since this machine is shared and timings are only comparable at similar load."""
    try:
        return os.getloadavg()[0]
    except OSError:  # pragma: no cover
        return None
