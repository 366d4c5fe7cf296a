"""Zenith angle: the angle of a line of sight from the upward vertical.

Model (radians)::

    z = atan2(h, dz),   (dx, dy, dz) = (P_to + to_dh e_z) - (P_from + from_dh e_z),  h = hypot(dx, dy)

0 looks straight up, pi/2 is horizontal (elevation = pi/2 - z). Heights along the vertical, as for
the slope distance. The instrument is levelled (its vertical is the world's z). Residual: observed
minus computed. Partials: ``dz/d(dx, dy) = dz (dx, dy) / (h rho^2)``, ``dz/d(dz) = -h / rho^2``.

Block: ``index["from"]``, ``index["to"]``; ``data["from_dh"]``, ``data["to_dh"]`` optional.
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.kinds.geometry import columns, first_bad, sight

NAME = "zenith_angle"
ANGULAR = False


def register(block, layout) -> dict:
    return {}


def evaluate(block, layout, cols, x, jacobian=True):
    d = sight(block, layout, x)
    h = np.hypot(d[..., 0], d[..., 1])
    bad = first_bad(h <= 0)
    if bad is not None:
        raise MultilatError(f"zenith angle {block.labels[bad] if block.labels else bad + 1}: the sight is vertical "
                            "(its derivative is undefined)")
    if not jacobian:
        return np.arctan2(h, d[..., 2]), None, None
    r2 = h * h + d[..., 2] ** 2
    g = np.stack([d[..., 2] * d[..., 0] / (h * r2), d[..., 2] * d[..., 1] / (h * r2), -h / r2], -1)
    values = np.concatenate([-g, g], -1)
    cols_ = np.concatenate([columns(layout, block.index["from"]), columns(layout, block.index["to"])], 1)
    return np.arctan2(h, d[..., 2]), values, cols_


# ---------------------------------------------------------------------------------------------------
# multilat's files: this kind's columns in observations.csv (kinds/columns.py, general/files.py)
from multilat.network.model.kinds.columns import Column, block_from_rows, rows_from_block, value_sigma  # noqa: E402

UNIT = "rad"
#: this kind's columns of observations.csv (besides kind, block, unit)
COLUMNS = (
    *value_sigma(UNIT, "zenith angle, 0 up, pi/2 horizontal", within=(0.0, np.pi, "[0, pi]")),
    Column("from", "point", "the point the instrument stands on", required=True),
    Column("to", "point", "the target's point", required=True),
    Column("from_dh_m", "number", "instrument height above `from` along z, m (empty: 0)", key="from_dh"),
    Column("to_dh_m", "number", "target (reflector) height above `to` along z, m (empty: 0)", key="to_dh"),
)


def from_rows(rows):
    """This kind's rows of ``observations.csv`` (:class:`~.columns.Rows`) -> its Block."""
    return block_from_rows(NAME, COLUMNS, rows)


def to_rows(block, point_ids) -> dict:
    """This kind's cells of ``observations.csv`` (column -> one str per row) for ``block``."""
    return rows_from_block(block, COLUMNS, point_ids)
