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


def validation_error_line(err, source: str) -> str:
    """One line from a pydantic ``ValidationError``: ``"SOURCE: key.path: why (got value)"``.

    A mistyped (unknown) key is reported first, as the likeliest cause; further errors are counted,
    not listed, so the message stays one line.
    """
    errs = sorted(err.errors(), key=lambda x: x.get("type") != "extra_forbidden")  # a mistyped key first
    e = errs[0]
    loc = ".".join(str(x) for x in e.get("loc", ())) or "(top level)"
    msg = e.get("msg", "invalid").replace("Value error, ", "")
    if e.get("type") == "extra_forbidden":
        msg = "unknown key (mistyped?)"
    elif e.get("type") == "missing":
        msg = "missing required key"
    inp = e.get("input")
    extra = f" (got {inp!r})" if e.get("type") not in ("extra_forbidden", "missing") and \
        not isinstance(inp, dict) and "got" not in msg else ""
    more = f" (+{len(err.errors()) - 1} more)" if len(err.errors()) > 1 else ""
    return f"{source}: {loc}: {msg}{extra}{more}".replace("\n", " ")
