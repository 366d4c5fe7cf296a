"""Slope distance from an instrument to a target, with the instrument's additive constant and scale.

Model (metres)::

    rho = | (P_to + to_dh e_z) - (P_from + from_dh e_z) |
    s   = (1 + k_I) rho + c_I

``from_dh`` is the instrument height over the point it stands on, ``to_dh`` the target (reflector)
height over its point, both along the vertical z (up); ``c_I`` the additive constant of instrument
``I`` (positive makes distances longer, as multilat's head offset ``o_i``), ``k_I`` its scale
(dimensionless). One instrument may stand on many points (a head moved between stations): its
``c`` and ``k`` are shared by all its distances (JAG3D's ``SlopeDistanceGroup``). Residual: observed
minus computed. Partials: ``ds/dP_to = (1 + k) u``, ``ds/dP_from = -(1 + k) u`` with ``u`` the unit
vector of the sight, ``ds/dc = 1``, ``ds/dk = rho``.

Block: ``index["from"]``, ``index["to"]`` (points), optional ``index["instrument"]`` (into
``names["instrument"]``, -1 for none); ``data["from_dh"]``, ``data["to_dh"]`` optional; options
``estimate_offset`` and ``estimate_scale`` (default False: held at 0).
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.kinds.geometry import columns, first_bad, sight

NAME = "slope_distance"
ANGULAR = False


def register(block, layout) -> dict:
    inst = block.index.get("instrument")
    m = len(block.index["from"])
    if inst is None:
        return {"offset": np.full(m, -1), "scale": np.full(m, -1)}
    names = block.names["instrument"]
    off = layout.columns("offset", names, free=bool(block.options.get("estimate_offset", False)))
    sca = layout.columns("scale", names, free=bool(block.options.get("estimate_scale", False)))
    inst = np.asarray(inst, int)
    has = inst >= 0
    return {"offset": np.where(has, off[np.maximum(inst, 0)], -1), "scale": np.where(has, sca[np.maximum(inst, 0)], -1)}


def evaluate(block, layout, cols, x, jacobian=True):
    x = np.asarray(x, float)
    d = sight(block, layout, x)
    rho = np.sqrt(np.einsum("...i,...i->...", d, d))
    bad = first_bad(rho <= 0)
    if bad is not None:
        raise MultilatError(f"slope distance {block.labels[bad] if block.labels else bad + 1}: its two ends "
                            "coincide")
    c = np.where(cols["offset"] >= 0, x[..., cols["offset"]], 0.0)
    k = np.where(cols["scale"] >= 0, x[..., cols["scale"]], 0.0)
    computed = (1.0 + k) * rho + c
    if not jacobian:
        return computed, None, None
    g = ((1.0 + k) / rho)[..., None] * d
    values = np.concatenate([-g, g, np.ones(rho.shape + (1,)), rho[..., None]], -1)
    cols_ = np.concatenate([columns(layout, block.index["from"]), columns(layout, block.index["to"]),
                            cols["offset"][:, None], cols["scale"][:, None]], 1)
    return computed, values, cols_


# ---------------------------------------------------------------------------------------------------
# multilat's files: this kind's columns in observations.csv (kinds/columns.py, general/files.py)
from multilat.network.model.kinds.columns import Column, block_from_rows, rows_from_block, value_sigma  # noqa: E402

UNIT = "m"
#: this kind's columns of observations.csv (besides kind, block, unit)
COLUMNS = (
    *value_sigma(UNIT, "slope distance", within=(5e-324, float("inf"), "(0, inf)")),
    Column("from", "point", "the point the instrument stands on", required=True),
    Column("to", "point", "the target's point", required=True),
    Column("instrument", "name", "the instrument (head) whose additive constant and scale the distance shares "
           "(empty: none)"),
    Column("from_dh_m", "number", "instrument height above `from` along z, m (empty: 0)", key="from_dh"),
    Column("to_dh_m", "number", "target (reflector) height above `to` along z, m (empty: 0)", key="to_dh"),
    Column("estimate_offset", "option", "estimate the block's instruments' additive constants (default false: "
           "held at 0)"),
    Column("estimate_scale", "option", "estimate the block's instruments' scales (default false: held at 0)"),
)


def from_rows(rows):
    """This kind's rows of ``observations.csv`` (:class:`~.columns.Rows`) -> its Block."""
    return block_from_rows(NAME, COLUMNS, rows)


def to_rows(block, point_ids) -> dict:
    """This kind's cells of ``observations.csv`` (column -> one str per row) for ``block``."""
    return rows_from_block(block, COLUMNS, point_ids)
