"""Shared file primitives: atomic writes (reading: :mod:`multilat.inputs`, re-exported here).

Domain formats live beside their science (``network/io/files.py``, ``lbb/files.py``,
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
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from multilat.errors import MultilatError
from multilat.inputs import (CsvTable, count_lines, decode_text, read_csv_table, read_input_bytes,  # noqa: F401
                             read_input_head)
from multilat.rows_text import CHUNK_ROWS, JsonKeyedRows, JsonRows, assemble, column_tokens, encode_labels

#: The range of an elevation angle, for :meth:`CsvTable.floats` ``within=``.
ELEVATION_RANGE = (-np.pi / 2, np.pi / 2, "±π/2 rad")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it over ``path`` only if the block succeeds.

    An exception, Ctrl-C or SIGTERM (the CLI turns it into an exception) inside the block removes the
    temporary file, so the target is written whole or not at all (the rename is atomic on POSIX file
    systems). An :class:`OSError` names ``path``, never the temporary file.
    """
    with atomic_paths(path) as (tmp,):
        yield tmp


def _named(exc: OSError, target: Path) -> OSError:
    """``exc`` re-addressed to ``target`` when it names one of our temporary ``.part`` paths."""
    name = str(exc.filename or "")
    if not name or ".part" in name or name.startswith(tempfile.gettempdir()):
        return OSError(exc.errno, exc.strerror or str(exc), str(target))
    return exc


@contextlib.contextmanager
def atomic_paths(*paths: str | os.PathLike) -> Iterator[list[Path]]:
    """Several output files all or nothing: yields one temporary path per target (beside it),
    renamed over the targets only when the whole block succeeds (``correct --out a --cov b``)."""
    targets = [Path(p) for p in paths]
    tmps: list[Path] = []
    try:
        for target in targets:
            if target.is_dir():
                raise MultilatError(f"{target}: is a directory (expected a file to write)")
            try:
                target.parent.mkdir(parents=True, exist_ok=True)
                remove_stale_staging(target)
                fd, tmp = tempfile.mkstemp(prefix=_staging_prefix(target), suffix=".part", dir=target.parent)
            except OSError as exc:
                raise _named(exc, target) from None
            os.close(fd)
            tmps.append(Path(tmp))
        yield tmps
        for tmp, target in zip(tmps, targets):
            try:
                os.chmod(tmp, 0o666 & ~_umask())
                os.replace(tmp, target)
            except OSError as exc:
                raise _named(exc, target) from None
    finally:
        for tmp in tmps:
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()


def _umask() -> int:
    u = os.umask(0)
    os.umask(u)
    return u


#: Every file name a multilat ``--out`` directory can hold. An existing ``--out`` directory holding
#: only such files is a previous run's output and is replaced whole; anything else in it is refused.
OUTPUT_NAMES = frozenset({
    "stations.csv", "targets.csv", "residuals.csv", "reference_lengths.csv", "result.json",
    "residuals.png", "top_view.png", "view_3d.png",                                  # adjust
    "stations.parquet", "targets.parquet", "residuals.parquet", "reference_lengths.parquet",
    "observations.csv", "observations.parquet",                                      # adjust/2
    "summary.json", "parameters.csv", "distances.csv", "points.csv", "clouds.png",   # propagate
    "sides.csv", "fig8_mean_error.png", "fig8_std.png", "fig9_cdf.png",              # lbb simulate
    "comparison.csv", "fig7_comparison.png", "report.html",                          # lbb compare, demo
})


@contextlib.contextmanager
def staging_dir(out: str | os.PathLike, *, inputs: Sequence[str | os.PathLike] = ()) -> Iterator[Path]:
    """Write a set of output files into the directory ``out`` all or nothing.

    Yields a temporary directory beside ``out`` (same file system). When the block ends normally the
    staged directory *replaces* ``out`` whole (a previous run's files do not survive beside the new
    ones); when it raises (an error, Ctrl-C, SIGTERM) the staged directory is removed and ``out`` is
    left as it was. An existing ``out`` is replaced only if it is empty or a previous multilat
    output (nothing but :data:`OUTPUT_NAMES` files), and never if it holds one of ``inputs``.
    """
    import shutil

    out = Path(out)
    check_output_dir(out, inputs=inputs)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_staging(out)
        tmp = Path(tempfile.mkdtemp(prefix=_staging_prefix(out), suffix=".part", dir=out.parent))
    except OSError as exc:
        raise _named(exc, out) from None
    old = None
    try:
        try:
            yield tmp
        except OSError as exc:
            raise _named(exc, out) from None
        with _signals_held():                    # no Ctrl-C / SIGTERM between the two renames
            try:
                if out.exists():
                    old = Path(tempfile.mkdtemp(prefix=_staging_prefix(out), suffix=".old", dir=out.parent))
                    os.replace(out, old / "d")
                os.replace(tmp, out)
            except OSError as exc:
                if old is not None and (old / "d").exists() and not out.exists():
                    os.replace(old / "d", out)       # put the previous results back
                raise _named(exc, out) from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)


def _staging_prefix(out: Path) -> str:
    """``.NAME.PID.``: the staging directories of ``out`` carry the writing process's id, so that a
    later run can tell the leftovers of a killed run (:func:`remove_stale_staging`)."""
    return f".{out.name}.{os.getpid()}."


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):        # another user's process: alive
        return True
    return True


def remove_stale_staging(out: str | os.PathLike) -> list[Path]:
    """Remove the staging directories (and files) beside ``out`` left by a killed run (SIGKILL,
    power loss).

    Only directories named as :func:`staging_dir` names them (``.NAME.PID.XXXX.part`` or ``.old``),
    and files named as :func:`atomic_paths` names them (``.NAME.PID.XXXX.part``), whose process is no
    longer alive are touched. A stale ``.old`` directory holds the previous
    results moved aside just before the new ones were renamed in: when ``out`` is missing they are
    put back, never deleted. Returns the directories removed."""
    import re
    import shutil

    out = Path(out)
    pat = re.compile(rf"\.{re.escape(out.name)}\.(\d+)\.[A-Za-z0-9_]+\.(part|old)")
    removed = []
    try:
        entries = list(os.scandir(out.parent))
    except OSError:
        return removed
    for e in entries:
        m = pat.fullmatch(e.name)
        if m is None or _alive(int(m.group(1))):
            continue
        d = Path(e.path)
        if m.group(2) == "part" and e.is_file(follow_symlinks=False):
            with contextlib.suppress(OSError):
                d.unlink()
                removed.append(d)
            continue
        if not e.is_dir(follow_symlinks=False):
            continue
        if m.group(2) == "old" and (d / "d").is_dir() and not out.exists():
            with contextlib.suppress(OSError):
                os.replace(d / "d", out)          # the previous results, moved aside when the run died
        shutil.rmtree(d, ignore_errors=True)
        removed.append(d)
    return removed


@contextlib.contextmanager
def _signals_held():
    """Hold SIGINT and SIGTERM (delivered on exit from the block) in the main thread."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    held = {signal.SIGINT, signal.SIGTERM}
    old = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def check_output_dir(out: str | os.PathLike, *, inputs: Sequence[str | os.PathLike] = ()) -> None:
    """Refuse an ``--out`` directory that cannot be replaced whole: a file, a non-empty directory
    not written by multilat, or one holding an input file. Called before any work starts."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise MultilatError(f"--out {out}: exists and is not a directory")
    for i in inputs:
        if i is not None and _inside(Path(i), out):
            raise MultilatError(f"--out {out}: holds the input {i}; write the results elsewhere")
    if _inside(Path.cwd(), out):
        raise MultilatError(f"--out {out}: is the working directory or holds it; give a sub-directory")
    if out.is_dir():
        try:
            foreign = sorted(e.name for e in os.scandir(out)
                             if e.name not in OUTPUT_NAMES or not e.is_file(follow_symlinks=False))
        except OSError as exc:
            raise MultilatError(f"--out {out}: {exc.strerror or exc}") from None
        if foreign:
            raise MultilatError(f"--out {out}: holds {foreign[0]!r}, not a multilat output; the directory "
                                "is replaced whole, so give a new or empty one")


def _inside(path: Path, directory: Path) -> bool:
    try:
        return path.resolve().is_relative_to(directory.resolve())
    except (OSError, RuntimeError):
        return False


def check_not_input(out: str | os.PathLike | None, inputs: Sequence[str | os.PathLike | None],
                    option: str = "--out") -> None:
    """Refuse an output file that is one of the inputs (``correct raw.csv --out raw.csv``)."""
    if out is None:
        return
    o = Path(out)
    for i in inputs:
        if i is None:
            continue
        same = False
        with contextlib.suppress(OSError):
            same = o.exists() and Path(i).exists() and os.path.samefile(o, i)
        if same or o.resolve() == Path(i).resolve():
            raise MultilatError(f"{option} {out}: is the input file {i}; it would be overwritten")
    if o.is_dir():
        raise MultilatError(f"{option} {out}: is a directory (expected a file to write)")


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` whole or not at all."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_json_atomic(path: str | os.PathLike, obj, *, indent: bool = True) -> None:
    """Serialise ``obj`` (:func:`write_json`) and write it whole or not at all."""
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        write_json(obj, fh, indent=indent)


def write_csv_atomic(path: str | os.PathLike, header: Sequence[str], rows) -> None:
    """Write a CSV with ``header`` and ``rows`` (iterables of values) whole or not at all."""
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in rows:
        w.writerow([_fmt(v) for v in r])
    write_text_atomic(path, buf.getvalue())


def write_csv_columns_atomic(path: str | os.PathLike, columns: dict, *, chunk: int = CHUNK_ROWS) -> None:
    """The CSV :func:`write_csv_atomic` writes for the rows of ``columns`` (header = its keys), built
    from the columns (no Python list per row; :mod:`multilat.rows_text`): a column is a
    float/int/bool array (m,) or ``(labels, index)`` (strings ``labels[index[k]]``). The same values:
    booleans ``True``/``False``, strings quoted by the csv module when needed, integers in decimal,
    floats in their shortest round-trip text (orjson's, e.g. ``0.00001`` where ``repr`` writes
    ``1e-05``; ``repr`` itself for ``nan``/``inf`` and when orjson is missing)."""
    orjson = _orjson()
    names = list(columns)
    n = None
    labels = {}
    for name in names:
        col = columns[name]
        size = len(col[1]) if isinstance(col, tuple) else np.asarray(col).shape[0]
        if isinstance(col, tuple):
            labels[name] = encode_labels(col[0], "csv", orjson)
        if n is not None and size != n:
            raise ValueError(f"column {name!r}: {size} rows, expected {n}")
        n = size
    n = n or 0
    head = _io.StringIO()
    csv.writer(head, lineterminator="\n").writerow(names)
    parts: list = []
    for c in range(len(names)):
        parts += [c, b"," if c < len(names) - 1 else b"\n"]
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(head.getvalue().encode("utf-8"))
        for lo in range(0, n, chunk):
            hi = min(n, lo + chunk)
            toks = []
            for name in names:
                col = columns[name]
                if isinstance(col, tuple):
                    toks.append(column_tokens((col[0], np.asarray(col[1])[lo:hi]), orjson, "csv",
                                              labels=labels[name]))
                else:
                    toks.append(column_tokens(np.asarray(col)[lo:hi], orjson, "csv"))
            fh.write(assemble(parts, toks, hi - lo))


def write_parquet_columns_atomic(path: str | os.PathLike, columns: dict) -> None:
    """The table of ``columns`` (as :func:`write_csv_columns_atomic`; also lists with None for
    empty cells) as a Parquet file, whole or not at all: floats float64, integers int64, booleans,
    labels as dictionary-encoded strings, None as null. Needs pyarrow (``pip install
    'multilat[parquet]'``): without it a :class:`MultilatError` saying so."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise MultilatError("Parquet tables need pyarrow: pip install 'multilat[parquet]' "
                            "(or write CSV tables)") from None
    labels = {name: pa.array([str(x) for x in col[0]], pa.string())
              for name, col in columns.items() if isinstance(col, tuple)}

    def arrays(lo, hi):
        out = {}
        for name, col in columns.items():
            if isinstance(col, tuple):
                idx = pa.array(np.asarray(col[1][lo:hi], np.int32))
                out[name] = pa.DictionaryArray.from_arrays(idx, labels[name])
            elif isinstance(col, list):
                out[name] = pa.array(col[lo:hi])
            else:
                out[name] = pa.array(np.asarray(col)[lo:hi])
        return pa.table(out)

    n = 0
    for col in columns.values():
        n = len(col[1]) if isinstance(col, tuple) else len(col)
        break
    first = arrays(0, min(n, PARQUET_ROW_GROUP))
    # dictionary pages for the label columns only: for unique floats pyarrow fills a dictionary page
    # and then falls back to plain, half the write time at 1.6 M rows (same values read back)
    with atomic_path(path) as tmp, pq.ParquetWriter(str(tmp), first.schema, use_dictionary=list(labels)) as w:
        w.write_table(first)
        for lo in range(PARQUET_ROW_GROUP, n, PARQUET_ROW_GROUP):    # row groups: bounded memory
            w.write_table(arrays(lo, min(n, lo + PARQUET_ROW_GROUP)))
    del first
    pa.default_memory_pool().release_unused()          # Arrow's allocator keeps freed pages otherwise


#: rows per Parquet row group (and per conversion to Arrow: the memory the writer needs)
PARQUET_ROW_GROUP = 1 << 18


#: formats of the per-point tables of ``adjust --out``
TABLE_FORMATS = ("csv", "parquet")


def write_table_atomic(path: str | os.PathLike, columns: dict, fmt: str = "csv") -> Path:
    """Write the table of ``columns`` as ``path`` with the suffix of ``fmt`` (:data:`TABLE_FORMATS`),
    whole or not at all; returns the path written. CSV: :func:`write_csv_columns_atomic` for arrays
    and labels; columns given as lists (small tables: None an empty cell) through the row writer."""
    path = Path(path).with_suffix("." + fmt)
    if fmt == "parquet":
        write_parquet_columns_atomic(path, columns)
    elif fmt != "csv":
        raise MultilatError(f"table format must be one of {', '.join(TABLE_FORMATS)}, got {fmt!r}")
    elif any(isinstance(c, list) for c in columns.values()):
        cols = [c if isinstance(c, list) else (list(np.asarray(c[0], object)[np.asarray(c[1])])
                                                if isinstance(c, tuple) else np.asarray(c).tolist())
                for c in columns.values()]
        write_csv_atomic(path, list(columns), (["" if v is None else v for v in row] for row in zip(*cols)))
    else:
        write_csv_columns_atomic(path, columns)
    return path


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
    if isinstance(obj, (JsonRows, JsonKeyedRows)):
        return to_jsonable(obj.to_python())
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


# ---------------------------------------------------------------------------------------- JSON output
# One writer for every JSON document: orjson (C, numpy-aware) when installed, else the standard library
# through :func:`to_jsonable`. Both give the same values: non-finite floats are null, numpy scalars and
# arrays are converted exactly as ``float()`` / ``int()`` / ``tolist()`` convert them, dataclasses are
# objects of all their fields, paths are strings. Long per-row tables (:class:`JsonRows`) are written
# from their columns in chunks, without one Python object per row.

def _orjson():
    try:
        import orjson
    except ImportError:     # pragma: no cover - depends on the environment
        return None
    return orjson


def _json_default(obj):
    """orjson's fallback for the types it does not take natively, converted as :func:`to_jsonable`."""
    import dataclasses

    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, tuple):
        return list(obj)
    raise TypeError(f"Object of type {type(obj).__name__} is not JSON serializable")


#: a document with more rows than this in its per-point tables is written compact (one line): indented,
#: the 1.6 M-distance adjustment is 808 MB that no one reads by eye (577 MB compact, ~1 s less to write)
INDENT_MAX_ROWS = 20_000


def write_json(obj, fh, *, indent: bool = True) -> None:
    """Write ``obj`` as JSON (two-space indented unless ``indent=False``) and a newline to the binary
    file ``fh``. The same values as ``json.dumps(to_jsonable(obj))``; :class:`JsonRows` tables are
    streamed in chunks."""
    orjson = _orjson()
    if orjson is None:
        text = json.dumps(to_jsonable(obj), indent=2 if indent else None) + "\n"
        fh.write(text.encode("utf-8"))
        return
    tables: list = []
    mark = f"\x00jsonrows:{os.getpid()}:{id(tables)}:"

    def default(o):
        if isinstance(o, (JsonRows, JsonKeyedRows)):
            tables.append(o)
            return f"{mark}{len(tables) - 1}"
        return _json_default(o)

    opt = orjson.OPT_NON_STR_KEYS | orjson.OPT_PASSTHROUGH_DATACLASS | (orjson.OPT_INDENT_2 if indent else 0)
    text = orjson.dumps(obj, default=default, option=opt)
    if not tables:
        fh.write(text)
        fh.write(b"\n")
        return
    key = orjson.dumps(mark)[:-1]          # the opening quote and the escaped mark
    pos = 0
    for k, tab in enumerate(tables):
        tok = key + str(k).encode() + b'"'
        at = text.index(tok, pos)
        fh.write(text[pos:at])
        line = text.rfind(b"\n", 0, at) + 1
        lead = len(text[line:at]) - len(text[line:at].lstrip(b" "))
        tab.write(orjson, fh.write, lead if indent else None)
        pos = at + len(tok)
    fh.write(text[pos:])
    fh.write(b"\n")


def dumps_json(obj, *, indent: bool = True) -> bytes:
    """:func:`write_json` into bytes (UTF-8, ending with a newline)."""
    buf = _io.BytesIO()
    write_json(obj, buf, indent=indent)
    return buf.getvalue()
