"""Coordinate-difference vector (a GNSS baseline, a tracker's point-to-point vector in the world
frame), one row per observed component.

Model (metres)::

    d_a = P_to[a] - P_from[a]        a = 0, 1, 2: x (east), y (north), z (up)

in multilat's frame. A vector is three rows with the same ``from`` and ``to``; its 3 x 3
covariance, and any correlation between vectors, is the block's ``cov``. The rows may come in any
order of components (a reader keeps its file's order, which fixes the Cholesky decorrelation and so
the redundancy numbers of correlated rows, :mod:`..adjust`). Residual: observed minus computed.
Partials ``-1`` (from) and ``+1`` (to) on the row's coordinate.

Block: ``index["from"]``, ``index["to"]``, ``index["axis"]`` (R,).
"""

from __future__ import annotations

import numpy as np

NAME = "coordinate_difference"
ANGULAR = False


def register(block, layout) -> dict:
    return {}


def evaluate(block, layout, cols, x, jacobian=True):
    x = np.asarray(x, float)
    axis = np.asarray(block.index["axis"], int)
    cf = layout.point_cols[np.asarray(block.index["from"], int), axis]
    ct = layout.point_cols[np.asarray(block.index["to"], int), axis]
    computed = x[..., ct] - x[..., cf]
    if not jacobian:
        return computed, None, None
    values = np.broadcast_to(np.array([-1.0, 1.0]), computed.shape + (2,)).copy()
    return computed, values, np.stack([cf, ct], 1)


# ---------------------------------------------------------------------------------------------------
# multilat's files: this kind's columns in observations.csv (kinds/columns.py, general/files.py)
from multilat.network.model.kinds.columns import Column, block_from_rows, rows_from_block, value_sigma  # noqa: E402

UNIT = "m"
#: this kind's columns of observations.csv (besides kind, block, unit)
COLUMNS = (
    *value_sigma(UNIT, "component of P_to - P_from"),
    Column("from", "point", "the vector's start", required=True),
    Column("to", "point", "the vector's end", required=True),
    Column("axis", "enum", "the component: x (east), y (north) or z (up); a vector is 3 rows of one block, "
           "its covariance in covariances.csv", required=True, choices=("x", "y", "z")),
)


def from_rows(rows):
    """This kind's rows of ``observations.csv`` (:class:`~.columns.Rows`) -> its Block."""
    return block_from_rows(NAME, COLUMNS, rows)


def to_rows(block, point_ids) -> dict:
    """This kind's cells of ``observations.csv`` (column -> one str per row) for ``block``."""
    return rows_from_block(block, COLUMNS, point_ids)
