"""The scale datum: with every head's scale estimated the network's scale is a 7th datum defect,
fixed by a held scale, by control points, or by scale bars — reference lengths used as weighted
observations (:mod:`multilat.network.model.couplings`; one bar is the scale datum with zero redundancy:
the adjusted length is the reference and the bar's uncertainty enters every coordinate's covariance
along the scale direction)."""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.data import Observations

__all__ = ["check_scale_datum"]


def check_scale_datum(obs: Observations, sc_free, datum, *, bars: bool = False) -> None:
    """Distances fix the size of a network through the scales held fixed: with every head's scale
    estimated (and no control points, no scale bars) the scale is a 7th datum defect."""
    if bars or datum.kind == "control" or not np.all(sc_free):
        return
    # each suggestion is a command line the CLI accepts (issue 25, 8c: it suggested "--scales A,B")
    raise MultilatError("every head's scale is estimated, so the network's scale is undetermined (a 7th "
                        "datum defect): hold one head's scale (--scales --fixed-scale HEAD; in Python "
                        "scales=[the other heads]), use reference lengths as scale bars (--scales "
                        "--references FILE --scale-bars), or control points (--scales --points FILE "
                        "--datum control)")
