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


_NP_SCALAR = None


def printable(text: str, *, keep_newlines: bool = True) -> str:
    """``text`` with control characters (ANSI escapes, BEL, C1 codes) written as ``\\xNN`` escapes,
    so that an id or a file name is shown literally and never acts on the terminal."""
    out = []
    for ch in str(text):
        o = ord(ch)
        if (o < 32 and not (keep_newlines and ch in "\n\t")) or 0x7F <= o < 0xA0:
            out.append(f"\\x{o:02x}")
        else:
            out.append(ch)
    return "".join(out)


def format_error(exc: BaseException) -> str:
    """The one line printed for an error: ``np.float64(1.5)`` shown as ``1.5``, control characters
    escaped, newlines folded; used by the CLI for every error it reports."""
    import re

    global _NP_SCALAR
    if _NP_SCALAR is None:
        _NP_SCALAR = re.compile(r"np\.(?:float|int|uint|bool_|complex)\d*\((.*?)\)")
    msg = str(exc) or type(exc).__name__
    msg = _NP_SCALAR.sub(r"\1", msg)
    msg = " ".join(part.strip() for part in msg.splitlines() if part.strip())
    return printable(msg, keep_newlines=False)
