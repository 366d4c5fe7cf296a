"""Direction in a set: a horizontal bearing read on a circle whose zero is unknown.

Model (radians)::

    t = atan2(dy, dx) - o_S,      (dx, dy) = P_to - P_from  (horizontal)

the bearing counter-clockwise from +x (east) towards +y (north), multilat's azimuth convention
(``docs/conventions.md``, :mod:`multilat.network.model.angles`), minus ``o_S``, the orientation unknown of
direction set ``S`` (one per set; several sets on one point each have their own). A reader of a
clockwise instrument (gama-local's ``angles="left-handed"``) negates its readings first. Heights
do not enter (a vertical shift leaves the bearing unchanged). Residual: observed minus computed,
wrapped to ``[-pi, pi)``. Partials: ``dt/d(dx, dy) = (-dy, dx) / h^2``, ``dt/do_S = -1``.

Block: ``index["from"]``, ``index["to"]``, ``index["set"]`` (into ``names["set"]``).
"""

from __future__ import annotations

import numpy as np

from multilat.network.model.kinds.geometry import bearing_partials, columns, sight

NAME = "direction"
ANGULAR = True


def register(block, layout) -> dict:
    return {"orientation": layout.columns("orientation", block.names["set"])[np.asarray(block.index["set"], int)]}


def evaluate(block, layout, cols, x, jacobian=True):
    x = np.asarray(x, float)
    d = sight(block, layout, x)
    g = bearing_partials(d, block)
    computed = np.arctan2(d[..., 1], d[..., 0]) - x[..., cols["orientation"]]
    if not jacobian:
        return computed, None, None
    values = np.concatenate([-g, g, -np.ones(g.shape[:-1] + (1,))], -1)
    cols_ = np.concatenate([columns(layout, block.index["from"], (0, 1)), columns(layout, block.index["to"], (0, 1)),
                            cols["orientation"][:, None]], 1)
    return computed, values, cols_


# ---------------------------------------------------------------------------------------------------
# multilat's files: this kind's columns in observations.csv (kinds/columns.py, general/files.py)
from multilat.network.model.kinds.columns import Column, block_from_rows, rows_from_block, value_sigma  # noqa: E402

UNIT = "rad"
#: this kind's columns of observations.csv (besides kind, block, unit)
COLUMNS = (
    *value_sigma(UNIT, "direction, counter-clockwise from +x (east) towards +y (north)"),
    Column("from", "point", "the point the instrument stands on", required=True),
    Column("to", "point", "the sighted point", required=True),
    Column("set", "name", "the direction set: one orientation unknown per set (several sets on one point "
           "have different ids)", required=True),
)


def from_rows(rows):
    """This kind's rows of ``observations.csv`` (:class:`~.columns.Rows`) -> its Block."""
    return block_from_rows(NAME, COLUMNS, rows)


def to_rows(block, point_ids) -> dict:
    """This kind's cells of ``observations.csv`` (column -> one str per row) for ``block``."""
    return rows_from_block(block, COLUMNS, point_ids)
