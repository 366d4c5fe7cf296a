"""The project's exception for bad input.

Every check at a boundary (a file, a config, a CLI option, a public function's arguments) raises
:class:`MultilatError` with a one-line message that names the culprit (row, column, key or
parameter). The CLI turns it into ``error: <message>`` and a non-zero exit, never a traceback.
"""

from __future__ import annotations

import re


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


#: The invisible formatting characters that change how text is shown: bidirectional marks,
#: embeddings, overrides (U+202E RIGHT-TO-LEFT OVERRIDE) and isolates, zero-width characters, the BOM,
#: line and paragraph separators, interlinear annotations, tag characters. Refused in ids and cells
#: (:mod:`multilat.inputs`); escaped by :func:`printable`.
FORMAT_CHARACTERS = ("\u061c\u200b-\u200f\u2028-\u202e\u2060-\u206f\ufeff\ufff9-\ufffb"
                     "\U000e0000-\U000e007f")
#: What :func:`printable` escapes: control characters (C0 but tab, DEL, C1) and :data:`FORMAT_CHARACTERS`.
HIDDEN_CHARACTERS = re.compile(f"[\x00-\x08\x0a-\x1f\x7f-\x9f{FORMAT_CHARACTERS}]")


def _escape(m) -> str:
    o = ord(m.group())
    return f"\\x{o:02x}" if o < 0x100 else f"\\u{o:04x}" if o < 0x10000 else f"\\U{o:08x}"


def printable(text: str, *, keep_newlines: bool = True) -> str:
    """``text`` with control characters (ANSI escapes, BEL, C1 codes) written as ``\\xNN`` escapes and
    invisible formatting characters (U+202E RIGHT-TO-LEFT OVERRIDE, zero-width ones:
    :data:`HIDDEN_CHARACTERS`) as ``\\uNNNN``, so that an id or a file name is shown literally and
    never acts on the terminal."""
    text = str(text)
    if keep_newlines:
        return "\n".join(HIDDEN_CHARACTERS.sub(_escape, part) for part in text.split("\n"))
    return HIDDEN_CHARACTERS.sub(_escape, text.replace("\t", "\\x09"))


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
