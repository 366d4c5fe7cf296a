"""Azimuth and elevation read in an instrument's own frame (a laser tracker's encoders).

Model (radians), per set-up ``U`` standing on point ``P_from`` with frame ``R_U = Rz(kappa)
Ry(phi) Rx(omega)`` (:mod:`multilat.network.model.angles`)::

    v  = R_U^T ((P_to + to_dh e_z) - (P_from + from_dh e_z))
    az = atan2(v_y, v_x)              counter-clockwise from the instrument's x axis
    el = atan2(v_z, hypot(v_x, v_y))  above the instrument's horizontal plane

one row per reading, ``index["component"]`` 0 (azimuth) or 1 (elevation). A levelled set-up
(``options["levelled"]``, default True) holds ``omega = phi = 0`` and estimates ``kappa`` only.
Residual: observed minus computed, azimuths wrapped to ``[-pi, pi)`` (elevations lie in
``[-pi/2, pi/2]`` and are unaffected by the wrap). Partials from
:func:`multilat.network.model.angles.angle_jacobian`.

Block: ``index["from"]``, ``index["to"]``, ``index["setup"]`` (into ``names["setup"]``),
``index["component"]``; ``data["from_dh"]``, ``data["to_dh"]`` optional.
"""

from __future__ import annotations

import numpy as np

from multilat.network.model.angles import angle_jacobian, predicted_angles
from multilat.network.model.kinds.geometry import columns, sight

NAME = "tracker_angles"
ANGULAR = True


def register(block, layout) -> dict:
    names = block.names["setup"]
    tilt_free = not bool(block.options.get("levelled", True))
    frame = np.stack([layout.columns("omega", names, free=tilt_free), layout.columns("phi", names, free=tilt_free),
                      layout.columns("kappa", names)], 1)
    return {"frame": frame[np.asarray(block.index["setup"], int)]}


def evaluate(block, layout, cols, x, jacobian=True):
    x = np.asarray(x, float)
    d = sight(block, layout, x)
    lead = d.shape[:-1]                                   # (..., m): the angle functions take flat rows
    d = d.reshape(-1, 3)
    ori = np.broadcast_to(x[..., cols["frame"]], lead + (3,)).reshape(-1, 3)
    m = len(d)
    zero = np.zeros((m, 3))
    comp = np.broadcast_to(np.asarray(block.index["component"], int), lead).reshape(-1)
    az, el = predicted_angles(zero, ori, d, np.arange(m), np.arange(m))
    computed = np.where(comp == 0, az, el).reshape(lead)
    if not jacobian:
        return computed, None, None
    d_st, d_ori, d_tg = angle_jacobian(zero, ori, d, np.arange(m), np.arange(m))
    rows = np.arange(m)
    values = np.concatenate([d_st[rows, comp], d_tg[rows, comp], d_ori[rows, comp]], 1).reshape(lead + (9,))
    cols_ = np.concatenate([columns(layout, block.index["from"]), columns(layout, block.index["to"]), cols["frame"]], 1)
    return computed, values, cols_


# ---------------------------------------------------------------------------------------------------
# multilat's files: this kind's columns in observations.csv (kinds/columns.py, general/files.py)
from multilat.errors import MultilatError  # noqa: E402
from multilat.network.model.kinds.columns import Column, block_from_rows, rows_from_block, value_sigma  # noqa: E402

UNIT = "rad"
#: this kind's columns of observations.csv (besides kind, block, unit)
COLUMNS = (
    *value_sigma(UNIT, "azimuth (counter-clockwise from the instrument's x) or elevation "
                "(above its horizontal, within [-pi/2, pi/2]; refused outside)"),
    Column("from", "point", "the point the instrument stands on", required=True),
    Column("to", "point", "the target's point", required=True),
    Column("setup", "name", "the instrument set-up whose frame (omega, phi, kappa) the reading is in", required=True),
    Column("component", "enum", "azimuth or elevation", required=True, choices=("azimuth", "elevation")),
    Column("from_dh_m", "number", "instrument height above `from` along z, m (empty: 0)", key="from_dh"),
    Column("to_dh_m", "number", "target (reflector) height above `to` along z, m (empty: 0)", key="to_dh"),
    Column("levelled", "option", "the block's set-ups are levelled: omega, phi held at 0 (default true)"),
)


def from_rows(rows):
    """This kind's rows of ``observations.csv`` (:class:`~.columns.Rows`) -> its Block; an elevation
    outside ``[-pi/2, pi/2]`` is ``FILE:LINE``."""
    block = block_from_rows(NAME, COLUMNS, rows)
    bad = np.flatnonzero((np.asarray(block.index["component"]) == 1) & ~(np.abs(block.value) <= np.pi / 2))
    if bad.size:
        raise MultilatError(f"{rows.where[bad[0]]}: an elevation must be within [-pi/2, pi/2], got "
                            f"{float(block.value[bad[0]])!r}")
    return block


def to_rows(block, point_ids) -> dict:
    """This kind's cells of ``observations.csv`` (column -> one str per row) for ``block``."""
    return rows_from_block(block, COLUMNS, point_ids)
