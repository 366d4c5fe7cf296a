"""Reading input files with bounded memory: a size limit per kind of file, text lines checked as
they come, strict CSV tables, TOML.

Every reader of the package takes its bytes here, so that a hostile input is refused the same way
everywhere with one line naming the file (``FILE:LINE`` where a line is at fault):

* a file larger than the limit of its kind (:data:`INPUT_LIMITS`) is refused before it is read (a
  pipe when it has given that many bytes);
* binary data (a NUL byte: ``/dev/zero``, an image, a UTF-16 file) and a line longer than
  :data:`MAX_LINE_BYTES` (an endless pipe without newlines) are refused at the first such block;
* a CSV table is parsed line by line: the header is checked before the second line is read, and
  each row (cell count, cell length, the numbers asked for, plain-text cells) before the next one,
  so a bad line 4 of a 2 GB file is named after reading four lines;
* invisible formatting characters (``U+202E`` RIGHT-TO-LEFT OVERRIDE and the other bidirectional
  controls, zero-width characters: :data:`multilat.errors.FORMAT_CHARACTERS`) are refused in table
  cells: they would reach the terminal and the HTML report disguised as ids (control characters such
  as ANSI escapes are accepted and shown escaped, :func:`multilat.errors.printable`);
* TOML nested deeper than :data:`MAX_TOML_DEPTH` is refused (Python's parser recurses).
"""

from __future__ import annotations

import csv
import math
import os
import re
import stat as _stat
import unicodedata
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from multilat.errors import FORMAT_CHARACTERS, MultilatError

#: Largest observations file (network observations, raw campaign readings, interchange formats):
#: 2 GiB. The 1.6 M-distance benchmark file is 48 MB; 1 GiB files (~25 M rows) are legitimate.
MAX_OBSERVATIONS_BYTES = 2 * 2**30
#: Largest other table (points, reference lengths, environment, heights, LBB edges): 256 MiB.
MAX_TABLE_BYTES = 256 * 2**20
#: Largest configuration file (TOML: instruments, design, LBB, network configs): 16 MiB.
MAX_CONFIG_BYTES = 16 * 2**20
#: The limit of each kind of input, by kind name (the name used in the messages).
INPUT_LIMITS = {"observations": MAX_OBSERVATIONS_BYTES, "table": MAX_TABLE_BYTES, "config": MAX_CONFIG_BYTES}
#: Longest line of a text input (bytes): no table row or config line comes near it.
MAX_LINE_BYTES = 2**20
#: Longest CSV cell (characters): the csv module's own limit.
MAX_CELL_CHARS = csv.field_size_limit()
#: Deepest nesting of tables and arrays in a TOML file (the package's configs use 4).
MAX_TOML_DEPTH = 32
#: Share of the machine's physical memory a single request may plan to use (a table held as Python
#: strings by :func:`read_csv_table`, the CLI's requests: :func:`multilat.cli.checks.memory`).
MEMORY_SHARE = 0.8


def physical_memory_bytes() -> int:
    """Physical memory of the machine (bytes); 8 GiB when it cannot be read."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        return 8 * 2**30

_CHUNK = 2**20
_UTF16_BOMS = (b"\xff\xfe", b"\xfe\xff")

_HIDDEN = re.compile(f"[{FORMAT_CHARACTERS}]")


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g} TiB"  # pragma: no cover


def _limit(kind: str) -> int:
    return INPUT_LIMITS[kind]


def _too_large(p: Path, kind: str, size: str) -> MultilatError:
    return MultilatError(f"{p}: {size}, more than the {_size(_limit(kind))} an input of kind '{kind}' "
                         f"may hold (multilat.inputs.INPUT_LIMITS; docs/reliability.md)")


def _binary(p: Path, line: int, first: bytes) -> MultilatError:
    if first.startswith(_UTF16_BOMS):
        return MultilatError(f"{p}:{line}: UTF-16 text (a NUL byte); save the file as UTF-8")
    return MultilatError(f"{p}:{line}: binary data (a NUL byte), not a text file")


def _long_line(p: Path, line: int) -> MultilatError:
    return MultilatError(f"{p}:{line}: a line longer than {_size(MAX_LINE_BYTES)}: not a text table "
                         "(binary data, or no line ends?)")


def hidden_character(text: str) -> str | None:
    """The first invisible formatting character of ``text`` as ``U+XXXX (NAME)``, or None. Such
    characters are refused in ids and table cells (:data:`multilat.errors.FORMAT_CHARACTERS`)."""
    m = _HIDDEN.search(text)
    if m is None:
        return None
    ch = m.group()
    return f"U+{ord(ch):04X} ({unicodedata.name(ch, unicodedata.category(ch))})"


def finite_number(text: str, where: str) -> float:
    """``text`` as a finite float, or ``WHERE: not a number: 'x'`` / ``WHERE: must be finite, got 'nan'``:
    the one check of a number read from any file (CSV cells, Star*Net tokens, Gama XML)."""
    try:
        v = float(text)
    except ValueError:
        raise MultilatError(f"{where}: not a number: {text!r}") from None
    if not math.isfinite(v):
        raise MultilatError(f"{where}: must be finite, got {text!r}")
    return v


def check_plain_text(text: str, where: str) -> str:
    """``text``, or a :class:`MultilatError` ``"WHERE: ... holds the formatting character U+202E (...)"``
    when it holds an invisible formatting character (the id is shown with that character escaped)."""
    what = hidden_character(text)
    if what is not None:
        shown = _HIDDEN.sub(lambda m: f"\\u{ord(m.group()):04x}", text)
        raise MultilatError(f"{where}: '{shown}' holds the invisible formatting character {what}: "
                            "ids and cells must be plain text")
    return text


class _Pipe:
    """A pipe or other non-regular input, opened once and read as far as asked: the bytes read are
    kept, so that a header sniffed first and the table parsed next both see the same stream (a
    second open of a pipe would wait for a writer that never comes). Each block is checked as it
    comes (size limit, NUL bytes, line length), so memory stays within the limit of the kind."""

    def __init__(self, p: Path, kind: str):
        self.p, self.kind, self.buf, self.eof = p, kind, bytearray(), False
        self.lines, self.run, self.text = 0, 0, True
        try:
            self.fh = open(p, "rb")
        except OSError as exc:
            raise MultilatError(f"{p}: cannot read: {exc.strerror or exc}") from None

    def more(self) -> bool:
        """Read one more block; False at the end of the stream."""
        if self.eof:
            return False
        try:
            block = self.fh.read(_CHUNK)
        except OSError as exc:
            raise MultilatError(f"{self.p}: cannot read: {exc.strerror or exc}") from None
        if not block:
            self.eof = True
            self.fh.close()
            return False
        if len(self.buf) + len(block) > _limit(self.kind):
            raise _too_large(self.p, self.kind, f"more than {_size(len(self.buf))} (a pipe)")
        if self.text:
            nul = block.find(b"\0")
            if nul >= 0:
                raise _binary(self.p, self.lines + block.count(b"\n", 0, nul) + 1, bytes(self.buf[:2] or block[:2]))
            last = block.rfind(b"\n")
            self.run = self.run + len(block) if last < 0 else len(block) - last - 1
            if self.run > MAX_LINE_BYTES:
                raise _long_line(self.p, self.lines + block.count(b"\n") + 1)
            self.lines += block.count(b"\n")
        self.buf += block
        return True

    def upto(self, n: int) -> bytes:
        while len(self.buf) < n and self.more():
            pass
        return bytes(self.buf[:n])

    def whole(self) -> bytes:
        while self.more():
            pass
        return bytes(self.buf)


_PIPES: dict[str, _Pipe] = {}


def _pipe(p: Path, kind: str) -> _Pipe:
    pipe = _PIPES.get(str(p))
    if pipe is None:
        pipe = _PIPES[str(p)] = _Pipe(p, kind)
    pipe.kind = max(pipe.kind, kind, key=_limit)         # the largest limit any reader asked for
    return pipe


def _stat_input(p: Path) -> os.stat_result:
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise MultilatError(f"{p}: no such file") from None
    except OSError as exc:
        raise MultilatError(f"{p}: {exc.strerror or exc}") from None
    if _stat.S_ISDIR(st.st_mode):
        raise MultilatError(f"{p}: is a directory, not a file")
    return st


def _is_pipe(p: Path) -> bool:
    """Whether ``p`` is read as a stream (:class:`_Pipe`): anything but a regular file."""
    return str(p) in _PIPES or not _stat.S_ISREG(_stat_input(p).st_mode)


def read_input_bytes(path: str | os.PathLike, kind: str = "observations", *, text: bool = True) -> bytes:
    """The bytes of an input file, at most the limit of ``kind`` (:data:`INPUT_LIMITS`).

    A missing path, a directory, an unreadable file or one larger than the limit is a one-line
    :class:`MultilatError`; with ``text`` (default) so is binary data (a NUL byte) and, from a pipe, a
    line longer than :data:`MAX_LINE_BYTES`, found in the first block that holds it. A named pipe or
    other non-regular file (``<(cmd)``, ``/dev/stdin``) is opened once for the process
    (:class:`_Pipe`), so a command that sniffs a header and then parses the file reads it once.
    """
    p = Path(path)
    if _is_pipe(p):
        pipe = _pipe(p, kind)
        pipe.text = pipe.text and text
        return pipe.whole()
    st = _stat_input(p)
    if st.st_size > _limit(kind):
        raise _too_large(p, kind, _size(st.st_size))
    try:
        with open(p, "rb") as fh:
            # the file's size (+1 to see growth), not the limit: read(n) reserves n bytes up front
            # (about 2 GB of address space for every file otherwise, fatal without overcommit)
            data = fh.read(st.st_size + 1)
            if len(data) > st.st_size:                  # grew since stat: the rest, up to the limit
                data += fh.read(max(_limit(kind) + 1 - len(data), 0))
    except OSError as exc:
        raise MultilatError(f"{p}: cannot read: {exc.strerror or exc}") from None
    if len(data) > _limit(kind):                 # grew while read
        raise _too_large(p, kind, f"more than {_size(_limit(kind))}")
    nul = data.find(b"\0") if text else -1
    if nul >= 0:
        raise _binary(p, data.count(b"\n", 0, nul) + 1, data[:2])
    return data


def read_input_head(path: str | os.PathLike, size: int = 1 << 16) -> bytes:
    """The first ``size`` bytes of an input (for sniffing a header) without reading it whole."""
    p = Path(path)
    if _is_pipe(p):
        return _pipe(p, "observations").upto(size)
    try:
        with open(p, "rb") as fh:
            return fh.read(size)
    except OSError as exc:
        raise MultilatError(f"{p}: cannot read: {exc.strerror or exc}") from None


def count_lines(path: str | os.PathLike) -> int:
    """Number of newline characters of an input, streamed for regular files (0 if unreadable)."""
    p = Path(path)
    try:
        if not _is_pipe(p):
            with open(p, "rb") as f:
                return sum(block.count(b"\n") for block in iter(lambda: f.read(1 << 20), b""))
        return read_input_bytes(p).count(b"\n")
    except (OSError, MultilatError):
        return 0


def decode_text(data: bytes, path) -> str:
    """UTF-8 text of an input file (a BOM dropped); a bad byte is ``FILE:LINE: not UTF-8 ...``."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise _not_utf8(path, data.count(b"\n", 0, exc.start) + 1, data[exc.start]) from None


def _not_utf8(path, line: int, byte: int) -> MultilatError:
    return MultilatError(f"{path}:{line}: not UTF-8 text (byte 0x{byte:02x}); save the file as UTF-8")


def read_text_input(path: str | os.PathLike, kind: str = "config") -> str:
    """The UTF-8 text of an input of ``kind`` (:func:`read_input_bytes`, :func:`decode_text`)."""
    return decode_text(read_input_bytes(path, kind), Path(path))


def input_lines(path: str | os.PathLike, kind: str = "table") -> Iterator[tuple[int, str]]:
    """``(line number, text)`` of each line of a text input, read and checked as it comes.

    Lines are split as :meth:`str.splitlines` splits them (a UTF-8 BOM dropped). Refused with
    ``FILE:LINE``: binary data (a NUL byte), a line longer than :data:`MAX_LINE_BYTES`, bytes that
    are not UTF-8; with ``FILE``: a file larger than the limit of ``kind``. A regular file is
    streamed in blocks of about 1 MiB; a pipe is kept as far as it was read (:class:`_Pipe`).
    """
    p = Path(path)
    if _is_pipe(p):
        fh = _PipeLines(_pipe(p, kind))
    else:
        size = _stat_input(p).st_size
        if size > _limit(kind):
            raise _too_large(p, kind, _size(size))
        try:
            fh = open(p, "rb")
        except OSError as exc:
            raise MultilatError(f"{p}: cannot read: {exc.strerror or exc}") from None
    n = 0
    with fh:
        for block in _line_blocks(fh, p):
            if n == 0 and block.startswith(b"\xef\xbb\xbf"):
                block = block[3:]
            nul = block.find(b"\0")
            if nul >= 0:
                raise _binary(p, n + block.count(b"\n", 0, nul) + 1, block[:2] if n == 0 else b"")
            try:
                text = block.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise _not_utf8(p, n + block.count(b"\n", 0, exc.start) + 1, block[exc.start]) from None
            for piece in text.splitlines():
                n += 1
                yield n, piece


def _line_blocks(fh, p: Path) -> Iterator[bytes]:
    """Blocks of about :data:`_CHUNK` bytes of ``fh``, each ending with a newline (but the last);
    a run of more than :data:`MAX_LINE_BYTES` without one is refused (its line: counted so far)."""
    rest, lines = b"", 0
    while True:
        try:
            block = fh.read(_CHUNK)
        except OSError as exc:
            raise MultilatError(f"{p}: cannot read: {exc.strerror or exc}") from None
        if not block:
            if rest:
                yield rest
            return
        data = rest + block if rest else block
        cut = data.rfind(b"\n") + 1
        rest = data[cut:]
        if len(rest) > MAX_LINE_BYTES:
            raise _long_line(p, lines + data.count(b"\n", 0, cut) + 1)
        if cut:
            lines += data.count(b"\n", 0, cut)
            yield data[:cut]


class _PipeLines:
    """A :class:`_Pipe` read from its start (``read``, a context manager)."""

    def __init__(self, pipe: _Pipe):
        self.pipe, self.pos = pipe, 0

    def read(self, size: int) -> bytes:
        while len(self.pipe.buf) < self.pos + size and self.pipe.more():
            pass
        chunk = bytes(self.pipe.buf[self.pos:self.pos + size])
        self.pos += len(chunk)
        return chunk

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


# ------------------------------------------------------------------------------------------- CSV tables
def number(path, line: int, name: str, s: str, *, positive: bool = False, nonnegative: bool = False,
           required: bool = True, within: tuple[float, float, str] | None = None) -> float:
    """The number in cell ``s`` of column ``name`` on ``FILE:LINE``, checked: finite (and > 0, >= 0,
    within ``(lo, hi, text)`` if asked); an empty cell is NaN unless ``required``."""
    if s == "" and not required:
        return np.nan
    v = finite_number(s, f"{path}:{line}: column '{name}'")
    if positive and not v > 0:
        raise MultilatError(f"{path}:{line}: column '{name}': must be > 0, got {s!r}")
    if nonnegative and not v >= 0:
        raise MultilatError(f"{path}:{line}: column '{name}': must be >= 0, got {s!r}")
    if within is not None and not within[0] <= v <= within[1]:
        raise MultilatError(f"{path}:{line}: column '{name}': must be within {within[2]}, got {s!r}")
    return v


@dataclass(frozen=True)
class CsvTable:
    """A CSV read as strings: ``columns`` (header names) and ``rows``; ``line_numbers[i]`` is the
    1-based file line of ``rows[i]`` (the header is line 1) for error messages."""

    path: str
    columns: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    line_numbers: tuple[int, ...]
    #: columns already read as numbers while the file was read: name -> (the checks, the values)
    parsed: dict = field(default_factory=dict, compare=False, repr=False)

    def column(self, name: str) -> list[str]:
        i = self.columns.index(name)
        return [r[i] for r in self.rows]

    def has(self, name: str) -> bool:
        return name in self.columns

    def ids(self, name: str) -> list[str]:
        """Column ``name`` as ids: an empty cell is ``FILE:LINE: column 'name': empty id``."""
        vals = self.column(name)
        for k, v in enumerate(vals):
            if v == "":
                raise self.error(k, f"column '{name}': empty id")
        return vals

    def floats(self, name: str, *, positive: bool = False, nonnegative: bool = False,
               required: bool = True, within: tuple[float, float, str] | None = None) -> np.ndarray:
        """Column ``name`` as float64, each cell checked by :func:`number` (finite, and > 0 / >= 0 /
        within ``(lo, hi, text)`` if asked; an empty cell NaN unless ``required``).

        Raises :class:`MultilatError` ``"FILE:LINE: column 'name': ..."`` on the first bad cell.
        """
        i = self.columns.index(name)
        kw = dict(positive=positive, nonnegative=nonnegative, required=required, within=within)
        done = self.parsed.get(name)
        if done is not None and done[0] == kw:
            return np.array(done[1], dtype=float)
        out = np.empty(len(self.rows))
        for k, (r, ln) in enumerate(zip(self.rows, self.line_numbers)):
            out[k] = number(self.path, ln, name, r[i], positive=positive, nonnegative=nonnegative,
                            required=required, within=within)
        return out

    def error(self, row_index: int, message: str) -> MultilatError:
        """An error naming the file line of ``rows[row_index]``."""
        return MultilatError(f"{self.path}:{self.line_numbers[row_index]}: {message}")


def read_csv_table(path: str | os.PathLike, *, required: Sequence[str], optional: Sequence[str] = (),
                   warn_unknown: bool = True, numbers: dict[str, dict] | None = None,
                   kind: str = "table") -> CsvTable:
    """Read a header CSV strictly, line by line (:func:`input_lines`, limit of ``kind``).

    Checks: the file exists and is not empty, every ``required`` column is in the header, every row
    has as many cells as the header, no cell is longer than :data:`MAX_CELL_CHARS` or holds an
    invisible formatting character (:func:`hidden_character`), and each cell of ``numbers`` (column ->
    :func:`number`'s keywords, for the columns present) is a valid number — each row checked before
    the next is read. Columns neither required nor optional give a warning (or are ignored with
    ``warn_unknown=False``). Blank lines are skipped; lines starting with ``#`` are comments above
    the header and an error below it (an id may not begin with ``#``: such a row must not vanish
    silently). Bytes that are not UTF-8 are an error naming the line.
    """
    p = Path(path)
    at = [0, False, 0, False]       # last line given to csv, header seen, characters given, hidden character

    def lines():
        for n, ln in input_lines(p, kind):
            if not ln.strip():
                continue
            if ln.lstrip().startswith("#"):
                if at[1]:
                    raise MultilatError(f"{p}:{n}: a line beginning with '#' after the header: an id may "
                                        "not begin with '#' (comment lines go above the header)")
                continue
            at[0], at[1], at[2], at[3] = n, True, at[2] + len(ln), _HIDDEN.search(ln) is not None
            yield ln

    reader = csv.reader(lines())

    def row():
        try:
            return next(reader, None)
        except csv.Error as exc:
            why = (f"a cell longer than {MAX_CELL_CHARS} characters" if "field limit" in str(exc)
                   else f"malformed CSV ({exc})")
            raise MultilatError(f"{p}:{at[0]}: {why}") from None

    cells = row()
    if cells is None:
        raise MultilatError(f"{p}: empty file (expected a header with {', '.join(required)})")
    header = tuple(h.strip() for h in cells)
    _check_cells(p, at[0], header, header)
    missing = [c for c in required if c not in header]
    if missing:
        raise MultilatError(f"{p}:{at[0]}: header lacks column(s) {', '.join(missing)} "
                            f"(got {', '.join(header)})")
    if len(set(header)) != len(header):
        raise MultilatError(f"{p}:{at[0]}: duplicate column names in header")
    unknown = [c for c in header if c not in required and c not in optional]
    if unknown and warn_unknown:
        warnings.warn(f"{p}: ignoring unknown column(s) {', '.join(unknown)}", UserWarning, stacklevel=2)
    checks = [(header.index(c), c, kw, []) for c, kw in (numbers or {}).items() if c in header]
    rows, nums = [], []
    while (cells := row()) is not None:
        ln = at[0]
        if len(cells) != len(header):
            raise MultilatError(f"{p}:{ln}: expected {len(header)} cells, got {len(cells)}")
        r = tuple(c.strip() for c in cells)
        if at[3]:
            _check_cells(p, ln, r, header)
        for i, name, kw, vals in checks:
            vals.append(number(p, ln, name, r[i], **kw))
        rows.append(r)
        nums.append(ln)
        if not len(rows) % 65536:
            _check_held(p, ln, len(rows), len(header), at[2])
    if not rows:
        raise MultilatError(f"{p}: no data rows after the header")
    full = dict(positive=False, nonnegative=False, required=True, within=None)
    return CsvTable(str(p), header, tuple(rows), tuple(nums),
                    {name: ({**full, **kw}, vals) for _, name, kw, vals in checks})


#: bytes Python holds per row of a table and per cell, beyond the characters (tuple, str headers)
_ROW_BYTES, _CELL_BYTES = 100, 58


def _check_held(p: Path, line: int, rows: int, ncol: int, chars: int) -> None:
    """Refuse a table whose rows held as Python strings would exceed :data:`MEMORY_SHARE` of the
    physical memory (an endless pipe, a huge file outside the fast reader's plain format)."""
    held = chars + rows * (_ROW_BYTES + _CELL_BYTES * ncol)
    limit = MEMORY_SHARE * physical_memory_bytes()
    if held > limit:
        raise MultilatError(f"{p}:{line}: {rows:,} rows held take about {_size(held)} of memory, more than "
                            f"this machine can give ({_size(limit)}); a larger observations file must be "
                            "in the fast reader's plain format (docs/reliability.md)")


def _check_cells(p: Path, line: int, cells: tuple[str, ...], header: tuple[str, ...]) -> None:
    """Refuse an invisible formatting character in any cell of a row (FILE:LINE, column, code point)."""
    for c, name in zip(cells, header):
        if _HIDDEN.search(c):
            check_plain_text(c, f"{p}:{line}: column '{name}'" if cells is not header else f"{p}:{line}: header")


# ------------------------------------------------------------------------------------------------- TOML
def parse_toml(text: str, source: str) -> dict:
    """The mapping of a TOML text; malformed TOML is ``SOURCE: malformed TOML: ...`` (with its line)
    and nesting deeper than :data:`MAX_TOML_DEPTH` is ``SOURCE: KEY: nested more than N levels``."""
    import tomllib

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MultilatError(f"{source}: malformed TOML: {exc}".replace("\n", " ")) from None
    except RecursionError:
        raise MultilatError(f"{source}: tables or arrays nested more than Python's parser can take "
                            f"(configs are at most {MAX_TOML_DEPTH} levels deep)") from None
    _check_depth(data, source, "", 1)
    return data


def _check_depth(value, source: str, key: str, depth: int) -> None:
    if depth > MAX_TOML_DEPTH:
        raise MultilatError(f"{source}: {key or '(top level)'}: tables or arrays nested more than "
                            f"{MAX_TOML_DEPTH} levels (multilat.inputs.MAX_TOML_DEPTH)")
    if isinstance(value, dict):
        for k, v in value.items():
            _check_depth(v, source, f"{key}.{k}" if key else str(k), depth + 1)
    elif isinstance(value, list):
        for v in value:
            _check_depth(v, source, key, depth + 1)


def load_toml(path: str | os.PathLike) -> dict:
    """The mapping of a TOML file (:data:`MAX_CONFIG_BYTES`, UTF-8, :func:`parse_toml`)."""
    return parse_toml(read_text_input(path, "config"), str(path))
