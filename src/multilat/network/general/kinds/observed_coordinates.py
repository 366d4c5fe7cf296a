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
