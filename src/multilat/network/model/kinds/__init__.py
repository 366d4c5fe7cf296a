"""Observation kinds of the general network, one module each, and the registry that names them.

Every kind module has the same small interface (the adjustment, the determinability analysis and
any later back end use only this):

``NAME``
    the kind's name, the key of :data:`KINDS`.
``ANGULAR``
    True when its residuals are angles to wrap to ``[-pi, pi)``.
``register(block, layout) -> dict``
    adds the parameters the block needs besides point coordinates (an instrument's constant and
    scale, a set's orientation, a set-up's frame) to the :class:`~..layout.Layout` and returns the
    block's column arrays.
``evaluate(block, layout, cols, x, jacobian=True) -> (computed, values, columns)``
    the model at the full parameter vector ``x``: computed observations (R,), and the Jacobian rows
    as values (R, k) with their full-layout columns (R, k) (``-1`` = no parameter), so a dense and a
    sparse back end assemble the same blocks. ``x`` may carry leading axes (``(T, n)``: one vector
    per Monte Carlo trial): ``computed`` is then (T, R) and ``values`` (T, R, k) (the columns do not
    change); ``jacobian=False`` returns ``(computed, None, None)`` (the Monte Carlo's chord steps
    need the model alone).

A new kind is one new module and one line in :data:`KINDS`.
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.angles import wrap_angle
from multilat.network.model.kinds import (coordinate_difference, direction, height_difference,
                                            horizontal_angle, horizontal_distance, observed_coordinates,
                                            slope_distance, tracker_angles, zenith_angle)

__all__ = ["KINDS", "kind", "residual"]

KINDS = {m.NAME: m for m in (slope_distance, direction, zenith_angle, horizontal_distance, horizontal_angle,
                             height_difference, coordinate_difference, observed_coordinates, tracker_angles)}


def kind(name: str):
    """The module of kind ``name`` (a one-line error naming the known kinds otherwise)."""
    try:
        return KINDS[name]
    except KeyError:
        raise MultilatError(f"unknown observation kind {name!r} (known: {', '.join(KINDS)})") from None


def residual(block, computed) -> np.ndarray:
    """Observed minus computed per row, angles wrapped to ``[-pi, pi)``."""
    r = np.asarray(block.value, float) - computed
    return wrap_angle(r) if kind(block.kind).ANGULAR else r
