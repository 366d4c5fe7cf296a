"""Observed coordinates: a coordinate of a point measured directly (a weighted control point, a
point taken over from another adjustment with its covariance).

Model (metres), one row per observed coordinate::

    c = P[axis]        axis 0, 1, 2 = x (east), y (north), z (up)

Correlations between the coordinates of one or several points are the block's ``cov``. Residual:
observed minus computed. Partial ``+1`` on the coordinate.

Block: ``index["point"]``, ``index["axis"]`` (R,).
"""

from __future__ import annotations

import numpy as np

NAME = "observed_coordinates"
ANGULAR = False


def register(block, layout) -> dict:
    return {}


def evaluate(block, layout, cols, x, jacobian=True):
    x = np.asarray(x, float)
    c = layout.point_cols[np.asarray(block.index["point"], int), np.asarray(block.index["axis"], int)]
    computed = x[..., c]
    if not jacobian:
        return computed, None, None
    return computed, np.ones(computed.shape + (1,)), c[:, None]


# ---------------------------------------------------------------------------------------------------
# multilat's files: this kind's columns in observations.csv (kinds/columns.py, general/files.py)
from multilat.network.model.kinds.columns import Column, block_from_rows, rows_from_block, value_sigma  # noqa: E402

UNIT = "m"
#: this kind's columns of observations.csv (besides kind, block, unit)
COLUMNS = (
    *value_sigma(UNIT, "observed coordinate"),
    Column("point", "point", "the observed point", required=True),
    Column("axis", "enum", "the coordinate: x (east), y (north) or z (up)", required=True, choices=("x", "y", "z")),
)


def from_rows(rows):
    """This kind's rows of ``observations.csv`` (:class:`~.columns.Rows`) -> its Block."""
    return block_from_rows(NAME, COLUMNS, rows)


def to_rows(block, point_ids) -> dict:
    """This kind's cells of ``observations.csv`` (column -> one str per row) for ``block``."""
    return rows_from_block(block, COLUMNS, point_ids)
