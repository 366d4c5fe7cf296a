"""Argument checks shared by the Monte Carlo engine's entry points (one line, naming the argument)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from multilat.errors import MultilatError


def _validate_inputs(inputs) -> tuple:
    if not isinstance(inputs, Mapping) or not inputs:
        raise MultilatError("inputs must be a non-empty mapping name -> distribution")
    out = []
    for name, d in inputs.items():
        if not isinstance(name, str) or not name.isidentifier():
            raise MultilatError(f"input name must be a Python identifier, got {name!r}")
        if not callable(getattr(d, "sample", None)):
            raise MultilatError(f"input {name!r} must have a sample(rng, size) method, got {type(d).__name__}")
        out.append((name, d))
    return tuple(out)


def _check_int(name, v, lo):
    if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < lo:
        raise MultilatError(f"{name} must be an integer >= {lo}, got {v!r}")
    return int(v)


def _check_coverage(coverage):
    if not (isinstance(coverage, (int, float, np.floating)) and 0.0 < float(coverage) < 1.0):
        raise MultilatError(f"coverage must lie in (0, 1), got {coverage!r}")
