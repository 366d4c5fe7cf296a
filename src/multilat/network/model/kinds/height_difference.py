"""Height difference (levelling): the rise of z from one point to another.

Model (metres)::

    dh = z_to - z_from

Residual: observed minus computed. Partials ``-1`` (from) and ``+1`` (to). A levelling line's
correlated block carries its full covariance (``Block.cov``).

Block: ``index["from"]``, ``index["to"]``.
"""

from __future__ import annotations

import numpy as np

from multilat.network.model.kinds.geometry import columns

NAME = "height_difference"
ANGULAR = False


def register(block, layout) -> dict:
    return {}


def evaluate(block, layout, cols, x, jacobian=True):
    x = np.asarray(x, float)
    cf, ct = columns(layout, block.index["from"], (2,)), columns(layout, block.index["to"], (2,))
    computed = x[..., ct[:, 0]] - x[..., cf[:, 0]]
    if not jacobian:
        return computed, None, None
    values = np.broadcast_to(np.concatenate([-np.ones_like(cf, float), np.ones_like(ct, float)], 1),
                             computed.shape + (2,)).copy()
    return computed, values, np.concatenate([cf, ct], 1)


# ---------------------------------------------------------------------------------------------------
# multilat's files: this kind's columns in observations.csv (kinds/columns.py, general/files.py)
from multilat.network.model.kinds.columns import Column, block_from_rows, rows_from_block, value_sigma  # noqa: E402

UNIT = "m"
#: this kind's columns of observations.csv (besides kind, block, unit)
COLUMNS = (
    *value_sigma(UNIT, "height difference z_to - z_from"),
    Column("from", "point", "the point levelled from (z_from)", required=True),
    Column("to", "point", "the point levelled to (z_to)", required=True),
)


def from_rows(rows):
    """This kind's rows of ``observations.csv`` (:class:`~.columns.Rows`) -> its Block."""
    return block_from_rows(NAME, COLUMNS, rows)


def to_rows(block, point_ids) -> dict:
    """This kind's cells of ``observations.csv`` (column -> one str per row) for ``block``."""
    return rows_from_block(block, COLUMNS, point_ids)
