"""Horizontal angle at a point between a backsight and a foresight.

Model (radians)::

    a = atan2(P_fs - P_from) - atan2(P_bs - P_from)      (horizontal bearings, counter-clockwise)

the foresight's bearing minus the backsight's, in multilat's counter-clockwise sense (a clockwise
reading, gama-local's ``angles="left-handed"``, is negated by its reader). No orientation unknown:
it cancels. Heights do not enter. Residual: observed minus computed, wrapped to ``[-pi, pi)``.
Partials: each bearing's ``(-dy, dx) / h^2`` with the sign of its term; the point ``from`` takes
minus the sum of the two.

Block: ``index["from"]``, ``index["bs"]``, ``index["fs"]``.
"""

from __future__ import annotations

import numpy as np

from multilat.network.model.kinds.geometry import bearing_partials, columns, sight

NAME = "horizontal_angle"
ANGULAR = True


def register(block, layout) -> dict:
    return {}


def evaluate(block, layout, cols, x, jacobian=True):
    df = sight(block, layout, x, "from", "fs")
    db = sight(block, layout, x, "from", "bs")
    gf, gb = bearing_partials(df, block), bearing_partials(db, block)
    a = np.arctan2(df[..., 1], df[..., 0]) - np.arctan2(db[..., 1], db[..., 0])
    if not jacobian:
        return a, None, None
    values = np.concatenate([gb - gf, -gb, gf], -1)
    cols_ = np.concatenate([columns(layout, block.index[k], (0, 1)) for k in ("from", "bs", "fs")], 1)
    return a, values, cols_


# ---------------------------------------------------------------------------------------------------
# multilat's files: this kind's columns in observations.csv (kinds/columns.py, general/files.py)
from multilat.network.model.kinds.columns import Column, block_from_rows, rows_from_block, value_sigma  # noqa: E402

UNIT = "rad"
#: this kind's columns of observations.csv (besides kind, block, unit)
COLUMNS = (
    *value_sigma(UNIT, "angle from the backsight to the foresight, counter-clockwise"),
    Column("from", "point", "the point the instrument stands on (the vertex)", required=True),
    Column("bs", "point", "the backsight", required=True),
    Column("fs", "point", "the foresight", required=True),
)


def from_rows(rows):
    """This kind's rows of ``observations.csv`` (:class:`~.columns.Rows`) -> its Block."""
    return block_from_rows(NAME, COLUMNS, rows)


def to_rows(block, point_ids) -> dict:
    """This kind's cells of ``observations.csv`` (column -> one str per row) for ``block``."""
    return rows_from_block(block, COLUMNS, point_ids)
