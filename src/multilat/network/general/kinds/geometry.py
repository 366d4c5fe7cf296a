"""Geometry the kinds share: the ends of a line of sight with instrument and target heights, and
the partial derivatives of a horizontal bearing.

Heights are applied exactly along the vertical (multilat's z is up): the instrument's point is
``P_from + from_dh e_z``, the target's ``P_to + to_dh e_z``. Bearings are multilat's azimuths,
counter-clockwise from +x (east) towards +y (north): ``atan2(dy, dx)`` (:mod:`multilat.network.angles`).
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError

__all__ = ["sight", "bearing_partials", "columns"]


def _heights(block, key):
    h = block.data.get(key)
    m = len(block.index["from"]) if "from" in block.index else len(block.labels)
    return np.zeros(m) if h is None else np.asarray(h, float)


def sight(block, layout, x, a="from", b="to"):
    """Difference vectors ``(P_b + to_dh e_z) - (P_a + from_dh e_z)`` (m, 3), metres."""
    xyz = x[layout.point_cols]
    d = xyz[block.index[b]] - xyz[block.index[a]]
    if a == "from" and b == "to":
        d[:, 2] += _heights(block, "to_dh") - _heights(block, "from_dh")
    return d


def bearing_partials(d, block):
    """``d atan2(dy, dx) / d(dx, dy)`` (m, 2) for difference vectors ``d`` (m, 3); a sight along the
    vertical (no horizontal extent) is named."""
    h2 = d[:, 0] ** 2 + d[:, 1] ** 2
    if np.any(h2 <= 0):
        k = int(np.flatnonzero(h2 <= 0)[0])
        raise MultilatError(f"{block.kind} {block.labels[k] if block.labels else k + 1}: the line of sight is "
                            "vertical (no horizontal bearing)")
    return np.stack([-d[:, 1] / h2, d[:, 0] / h2], -1)


def columns(layout, idx, axes=(0, 1, 2)) -> np.ndarray:
    """Full-layout columns (m, len(axes)) of the coordinates ``axes`` of points ``idx``."""
    return layout.point_cols[np.asarray(idx, int)][:, list(axes)]
