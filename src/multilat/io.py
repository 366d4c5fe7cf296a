"""Shared file primitives: atomic writes and strict CSV reading.

Domain formats live beside their science (``network/files.py``, ``lbb/files.py``,
``campaign/files.py``); they build on these helpers so that every reader reports errors the same
way (``FILE:ROW: message``) and every writer writes a file whole or not at all.
"""

from __future__ import annotations

import contextlib
import csv
import io as _io
import json
import os
import tempfile
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from multilat.errors import MultilatError


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it over ``path`` only if the block succeeds.

    An exception or KeyboardInterrupt inside the block removes the temporary file, so the target is
    written whole or not at all (the rename is atomic on POSIX file systems).
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp makes 0600; give the file the usual permissions
    try:
        yield tmp_path
        os.replace(tmp_path, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        raise


@contextlib.contextmanager
def staging_dir(out: str | os.PathLike) -> Iterator[Path]:
    """Write a set of output files into ``out`` all or nothing.

    Yields a temporary directory beside ``out`` (same file system); when the block ends normally its
    files are moved into ``out`` (created if missing), each by an atomic rename; when it raises (an
    error, or Ctrl-C) the temporary directory is removed and ``out`` is left as it was.
    """
    import shutil

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".part", dir=out.parent))
    try:
        yield tmp
        out.mkdir(parents=True, exist_ok=True)
        for f in sorted(tmp.iterdir()):
            os.replace(f, out / f.name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` whole or not at all."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_json_atomic(path: str | os.PathLike, obj) -> None:
    """Serialise ``obj`` with :func:`to_jsonable` and write it atomically."""
    write_text_atomic(path, json.dumps(to_jsonable(obj), indent=2) + "\n")


def write_csv_atomic(path: str | os.PathLike, header: Sequence[str], rows) -> None:
    """Write a CSV with ``header`` and ``rows`` (iterables of values) whole or not at all."""
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in rows:
        w.writerow([_fmt(v) for v in r])
    write_text_atomic(path, buf.getvalue())


def _fmt(v):
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    return v


def to_jsonable(obj):
    """Convert dataclasses, numpy arrays/scalars, paths and mappings to plain JSON types."""
    import dataclasses

    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        f = float(obj)
        return f if np.isfinite(f) else None
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, Path):
        return str(obj)
    return obj


@dataclass(frozen=True)
class CsvTable:
    """A CSV read as strings: ``columns`` (header names) and ``rows``; ``line_numbers[i]`` is the
    1-based file line of ``rows[i]`` (the header is line 1) for error messages."""

    path: str
    columns: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    line_numbers: tuple[int, ...]

    def column(self, name: str) -> list[str]:
        i = self.columns.index(name)
        return [r[i] for r in self.rows]

    def has(self, name: str) -> bool:
        return name in self.columns

    def floats(self, name: str, *, positive: bool = False, nonnegative: bool = False,
               required: bool = True) -> np.ndarray:
        """Column ``name`` as float64, each cell checked: finite (and > 0 / >= 0 if asked).

        Raises :class:`MultilatError` ``"FILE:LINE: column 'name': ..."`` on the first bad cell.
        An empty cell is an error when ``required``, otherwise NaN.
        """
        i = self.columns.index(name)
        out = np.empty(len(self.rows))
        for k, (r, ln) in enumerate(zip(self.rows, self.line_numbers)):
            s = r[i].strip()
            if s == "" and not required:
                out[k] = np.nan
                continue
            try:
                v = float(s)
            except ValueError:
                raise MultilatError(f"{self.path}:{ln}: column '{name}': not a number: {s!r}") from None
            if not np.isfinite(v):
                raise MultilatError(f"{self.path}:{ln}: column '{name}': must be finite, got {s!r}")
            if positive and not v > 0:
                raise MultilatError(f"{self.path}:{ln}: column '{name}': must be > 0, got {s!r}")
            if nonnegative and not v >= 0:
                raise MultilatError(f"{self.path}:{ln}: column '{name}': must be >= 0, got {s!r}")
            out[k] = v
        return out

    def error(self, row_index: int, message: str) -> MultilatError:
        """An error naming the file line of ``rows[row_index]``."""
        return MultilatError(f"{self.path}:{self.line_numbers[row_index]}: {message}")


def read_csv_table(path: str | os.PathLike, *, required: Sequence[str], optional: Sequence[str] = (),
                   warn_unknown: bool = True) -> CsvTable:
    """Read a header CSV strictly.

    Checks: the file exists and is not empty, every ``required`` column is in the header, every row
    has as many cells as the header. Columns neither required nor optional give a warning (or are
    ignored with ``warn_unknown=False``). Blank lines and lines starting with ``#`` are skipped.
    """
    p = Path(path)
    if not p.is_file():
        raise MultilatError(f"{p}: no such file")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise MultilatError(f"{p}: not a UTF-8 text file") from None
    lines = [(n + 1, ln) for n, ln in enumerate(text.splitlines())
             if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise MultilatError(f"{p}: empty file (expected a header with {', '.join(required)})")
    reader = csv.reader([ln for _, ln in lines])
    parsed = list(reader)
    header = tuple(h.strip() for h in parsed[0])
    missing = [c for c in required if c not in header]
    if missing:
        raise MultilatError(f"{p}:{lines[0][0]}: header lacks column(s) {', '.join(missing)} "
                            f"(got {', '.join(header)})")
    if len(set(header)) != len(header):
        raise MultilatError(f"{p}:{lines[0][0]}: duplicate column names in header")
    unknown = [c for c in header if c not in required and c not in optional]
    if unknown and warn_unknown:
        warnings.warn(f"{p}: ignoring unknown column(s) {', '.join(unknown)}", UserWarning, stacklevel=2)
    rows, nums = [], []
    for (ln, _), cells in zip(lines[1:], parsed[1:]):
        if len(cells) != len(header):
            raise MultilatError(f"{p}:{ln}: expected {len(header)} cells, got {len(cells)}")
        rows.append(tuple(c.strip() for c in cells))
        nums.append(ln)
    if not rows:
        raise MultilatError(f"{p}: no data rows after the header")
    return CsvTable(str(p), header, tuple(rows), tuple(nums))
