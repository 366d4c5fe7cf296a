"""The project's exception for bad input.

Every check at a boundary (a file, a config, a CLI option, a public function's arguments) raises
:class:`MultilatError` with a one-line message that names the culprit (row, column, key or
parameter). The CLI turns it into ``error: <message>`` and a non-zero exit, never a traceback.
"""

from __future__ import annotations


class MultilatError(ValueError):
    """Bad input or an unsolvable problem, with a one-line message naming the culprit."""


def require_finite(name: str, value, *, positive: bool = False, nonnegative: bool = False) -> None:
    """Raise :class:`MultilatError` unless ``value`` (scalar or array) is finite (and signed as asked).

    Parameters
    ----------
    name : str
        Parameter name used in the message, e.g. ``"temperature_c"``.
    value : float or array_like
    positive, nonnegative : bool
        Additionally require ``value > 0`` or ``value >= 0``.
    """
    import numpy as np

    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise MultilatError(f"{name} must be finite, got {value!r}")
    if positive and not np.all(arr > 0):
        raise MultilatError(f"{name} must be > 0, got {value!r}")
    if nonnegative and not np.all(arr >= 0):
        raise MultilatError(f"{name} must be >= 0, got {value!r}")
