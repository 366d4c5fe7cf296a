"""Horizontal distance between two points.

Model (metres)::

    h = hypot(dx, dy),   (dx, dy) = P_to - P_from  (horizontal components)

Heights do not enter (a vertical shift leaves it unchanged). Residual: observed minus computed.
Partials: ``dh/d(dx, dy) = (dx, dy) / h``.

Block: ``index["from"]``, ``index["to"]``.
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.kinds.geometry import columns, first_bad, sight

NAME = "horizontal_distance"
ANGULAR = False


def register(block, layout) -> dict:
    return {}


def evaluate(block, layout, cols, x, jacobian=True):
    d = sight(block, layout, x)
    h = np.hypot(d[..., 0], d[..., 1])
    bad = first_bad(h <= 0)
    if bad is not None:
        raise MultilatError(f"horizontal distance {block.labels[bad] if block.labels else bad + 1}: the two points "
                            "are on one vertical")
    if not jacobian:
        return h, None, None
    g = d[..., :2] / h[..., None]
    values = np.concatenate([-g, g], -1)
    cols_ = np.concatenate([columns(layout, block.index["from"], (0, 1)), columns(layout, block.index["to"], (0, 1))], 1)
    return h, values, cols_


# ---------------------------------------------------------------------------------------------------
# multilat's files: this kind's columns in observations.csv (kinds/columns.py, general/files.py)
from multilat.network.model.kinds.columns import Column, block_from_rows, rows_from_block, value_sigma  # noqa: E402

UNIT = "m"
#: this kind's columns of observations.csv (besides kind, block, unit)
COLUMNS = (
    *value_sigma(UNIT, "horizontal distance", within=(5e-324, float("inf"), "(0, inf)")),
    Column("from", "point", "the point the instrument stands on", required=True),
    Column("to", "point", "the other end", required=True),
)


def from_rows(rows):
    """This kind's rows of ``observations.csv`` (:class:`~.columns.Rows`) -> its Block."""
    return block_from_rows(NAME, COLUMNS, rows)


def to_rows(block, point_ids) -> dict:
    """This kind's cells of ``observations.csv`` (column -> one str per row) for ``block``."""
    return rows_from_block(block, COLUMNS, point_ids)
