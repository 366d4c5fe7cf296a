"""Geometry the kinds share: the ends of a line of sight with instrument and target heights, and
the partial derivatives of a horizontal bearing.

Heights are applied exactly along the vertical (multilat's z is up): the instrument's point is
``P_from + from_dh e_z``, the target's ``P_to + to_dh e_z``. Bearings are multilat's azimuths,
counter-clockwise from +x (east) towards +y (north): ``atan2(dy, dx)`` (:mod:`multilat.network.model.angles`).
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError

__all__ = ["sight", "bearing_partials", "columns", "first_bad", "coordinates"]

# Every function here takes a parameter vector ``x`` of shape (n,) or (..., n) (a leading axis of
# Monte Carlo trials): the results carry the same leading axes; columns never do.


def _heights(block, key):
    h = block.data.get(key)
    m = len(block.index["from"]) if "from" in block.index else len(block.labels)
    return np.zeros(m) if h is None else np.asarray(h, float)


def first_bad(bad) -> int | None:
    """The observation (last-axis index) of the first True in ``bad`` (..., m), None when none."""
    if not np.any(bad):
        return None
    return int(np.nonzero(bad)[-1][0])


def coordinates(layout, x, idx, axes=(0, 1, 2)) -> np.ndarray:
    """Coordinates ``axes`` of points ``idx`` from ``x`` (n,) or (..., n): (..., m, len(axes))."""
    return np.asarray(x, float)[..., columns(layout, idx, axes)]


def sight(block, layout, x, a="from", b="to"):
    """Difference vectors ``(P_b + to_dh e_z) - (P_a + from_dh e_z)`` (..., m, 3), metres."""
    d = coordinates(layout, x, block.index[b]) - coordinates(layout, x, block.index[a])
    if a == "from" and b == "to" and ("to_dh" in block.data or "from_dh" in block.data):
        d[..., 2] += _heights(block, "to_dh") - _heights(block, "from_dh")
    return d


def bearing_partials(d, block):
    """``d atan2(dy, dx) / d(dx, dy)`` (..., m, 2) for difference vectors ``d`` (..., m, 3); a sight
    along the vertical (no horizontal extent) is named."""
    h2 = d[..., 0] ** 2 + d[..., 1] ** 2
    k = first_bad(h2 <= 0)
    if k is not None:
        raise MultilatError(f"{block.kind} {block.labels[k] if block.labels else k + 1}: the line of sight is "
                            "vertical (no horizontal bearing)")
    return np.stack([-d[..., 1] / h2, d[..., 0] / h2], -1)


def columns(layout, idx, axes=(0, 1, 2)) -> np.ndarray:
    """Full-layout columns (m, len(axes)) of the coordinates ``axes`` of points ``idx``."""
    return layout.point_cols[np.asarray(idx, int)][:, list(axes)]
