"""Coordinate-difference vector (a GNSS baseline, a tracker's point-to-point vector in the world
frame).

Model (metres), three rows per observation in the order dx, dy, dz::

    (dx, dy, dz) = P_to - P_from

in multilat's frame (x east, y north, z up). Each vector's 3 x 3 covariance, and any correlation
between vectors, is the block's ``cov`` (rows ordered vector by vector). Residual: observed minus
computed. Partials ``-1`` (from) and ``+1`` (to) on the matching coordinate.

Block: ``index["from"]``, ``index["to"]`` (m,); ``value`` (3 m,).
"""

from __future__ import annotations

import numpy as np

NAME = "coordinate_difference"
ANGULAR = False


def register(block, layout) -> dict:
    return {}


def evaluate(block, layout, cols, x):
    cf = layout.point_cols[np.asarray(block.index["from"], int)].reshape(-1)
    ct = layout.point_cols[np.asarray(block.index["to"], int)].reshape(-1)
    values = np.tile([-1.0, 1.0], (len(cf), 1))
    return x[ct] - x[cf], values, np.stack([cf, ct], 1)
