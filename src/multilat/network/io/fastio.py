"""Fast reader of large observation CSVs (millions of rows): ``pyarrow.csv`` when pyarrow is installed
and the file is large (:data:`ARROW_READ_ABOVE_BYTES`), else numpy (and numba's decimal reader).

:func:`multilat.network.io.files.read_observations` checks every cell in Python, which is right for
hand-made files but takes seconds per million rows. :func:`read_observations_fast` reads the same
format — header ``station,target,distance_m[,sigma_m]`` (in this order) — vectorised: the bytes are
split on newlines and commas with ``np.flatnonzero``, ids are gathered into fixed-width byte strings
and numbered with ``np.unique``, numbers are read by a compiled decimal reader (correctly rounded;
numpy's bytes-to-float cast for what it does not take, and without numba).

One grammar, two speeds: the vectorised path only takes the plain subset of the format (ASCII, no
quotes, no spaces, no blank or ``#`` lines after the header, ids of at most ``id_width`` characters,
every cell valid, no duplicate observation, no id both station and target). Any file outside it is
handed whole to the general reader, which accepts it or refuses it with its ``FILE:LINE`` message,
so both readers accept and refuse the same files with the same messages.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from multilat.errors import MultilatError

__all__ = ["read_observations_fast", "FastObservations", "plain_observations"]


class FastObservations:
    """Arrays of a large observation file (ids numbered in order of first appearance).

    Attributes: ``station_ids``, ``target_ids`` (tuples of str), ``station_index``, ``target_index``
    (int64, (m,)), ``distance_m``, ``sigma_m`` (float64, (m,); ``sigma_m`` NaN-free: the column, or the
    ``sigma_m`` argument).
    """

    def __init__(self, station_ids, target_ids, station_index, target_index, distance_m, sigma_m):
        self.station_ids = station_ids
        self.target_ids = target_ids
        self.station_index = station_index
        self.target_index = target_index
        self.distance_m = distance_m
        self.sigma_m = sigma_m

    def to_observations(self):
        """The general :class:`multilat.network.model.data.Observations` (with its full checks)."""
        from multilat.network.model.data import Observations

        return Observations(self.station_ids, self.target_ids, self.station_index, self.target_index,
                            self.distance_m, self.sigma_m)


class _NotPlain(Exception):
    """The file is outside the vectorised path's plain subset: the general reader decides."""


def _fields(buf, starts, ends, width):
    """Gather byte fields [starts, ends) into an (n, w) uint8 array (zero padded), w = longest field."""
    ln = ends - starts
    if ln.size and (ln.max() > width or ln.min() <= 0):
        raise _NotPlain
    w = int(ln.max())
    out = np.zeros((len(starts), w), np.uint8)
    last = len(buf) - 1
    for c in range(w):                     # w is small: one vectorised gather per character column
        out[:, c] = buf[np.minimum(starts + c, last)]
        out[:, c] *= ln > c
    return out


def _ids(fields):
    """Number ids (an (n, w) uint8 array) in order of first appearance."""
    n, w = fields.shape
    if w <= 8:                             # pack into one integer per id: fast unique
        packed = np.zeros((n, 8), np.uint8)
        packed[:, :w] = fields
        keys = packed.view(np.uint64).ravel()
    else:
        keys = np.ascontiguousarray(fields).view(f"S{w}").ravel()
    uniq, first, inv = np.unique(keys, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    sel = np.ascontiguousarray(fields[first[order]]).view(f"S{w}").ravel()   # trailing NULs dropped
    names = tuple(np.char.decode(sel, "ascii").tolist())
    return names, rank[inv.ravel()].astype(np.int64)


def _cast(fields):
    """numpy's bytes-to-float conversion of (n, w) uint8 fields."""
    fields = np.ascontiguousarray(fields).view(f"S{fields.shape[1]}").ravel()
    try:
        return fields.astype(np.float64)
    except ValueError:
        raise _NotPlain from None


def _floats(buf, starts, ends, width, compiled: bool = True):
    """The positive finite numbers in ``buf[starts:ends]``: the compiled decimal reader
    (:func:`multilat._text_kernels.parse_decimals`, correctly rounded, ~20x numpy's cast) where it
    applies, numpy's cast for the rest (and for all without numba or with ``compiled=False``: the
    probe's few rows, which should not pay for loading the kernels, 1-2 s on a loaded machine)."""
    ln = ends - starts
    if ln.size and (ln.max() > width or ln.min() <= 0):
        raise _NotPlain
    from multilat.rows_text import text_kernels

    K = text_kernels() if compiled else None
    if K is None:
        v = _cast(_fields(buf, starts, ends, width))
    else:
        v = np.empty(len(starts))
        fast = np.empty(len(starts), bool)
        # contiguous int64 bounds: the signature the warm-up compiles (a column of the comma table is strided)
        K.parse_decimals(buf, np.ascontiguousarray(starts, np.int64), np.ascontiguousarray(ends, np.int64),
                         K._POW10, v, fast)
        slow = np.flatnonzero(~fast)
        if slow.size:
            v[slow] = _cast(_fields(buf, starts[slow], ends[slow], width))
    if not np.all(np.isfinite(v) & (v > 0)):
        raise _NotPlain
    return v


_HEADER = ["station", "target", "distance_m"]


def read_observations_fast(path: str | os.PathLike, *, sigma_m: float | None = None,
                           id_width: int = 32, number_width: int = 32) -> FastObservations:
    """Read ``station,target,distance_m[,sigma_m]`` quickly.

    Parameters
    ----------
    path : path of the CSV
    sigma_m : float, optional
        Standard uncertainty for every row when the file has no ``sigma_m`` column.
    id_width, number_width : int
        Longest id / number field taken by the vectorised path (characters); longer fields go
        through the general reader (accepted there).

    Returns
    -------
    FastObservations

    Raises
    ------
    MultilatError
        ``FILE:LINE: ...`` exactly as :func:`multilat.network.io.files.read_observations`; a header
        other than the four columns above ("the fast reader needs the header ..."); no ``sigma_m``
        column and no ``sigma_m`` argument ("no sigma_m column: give sigma_m").
    """
    from multilat.inputs import read_input_bytes, read_input_head

    p = Path(path)
    if sigma_m is not None and not (np.isfinite(sigma_m) and sigma_m > 0):
        raise MultilatError(f"sigma_m must be finite and > 0, got {float(sigma_m)!r}")
    head = _header(p, _normalised(read_input_head(p, PROBE_BYTES)))        # the header before the file is read whole
    if head is None:
        return _general(p, sigma_m)          # the general reader's message
    line, header, _ = head
    if header[:3] != _HEADER or len(header) > 4 or (len(header) == 4 and header[3] != "sigma_m"):
        raise MultilatError(f"{p}:{line}: the fast reader needs the header station,target,distance_m[,sigma_m]"
                            f" (got {','.join(header)})")
    ncol = len(header)
    if ncol == 3 and sigma_m is None:
        raise MultilatError(f"{p}: no sigma_m column: give sigma_m")
    if not _probe(p, ncol, sigma_m, id_width, number_width):
        return _general(p, sigma_m)          # a bad early line: named without reading the file whole
    data = _normalised(read_input_bytes(p, "observations"))
    _, _, end = _header(p, data)
    try:
        return _plain(data, end, ncol, sigma_m, id_width, number_width)
    except _NotPlain:
        return _general(p, sigma_m)


def _normalised(data: bytes) -> bytes:
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    return data.replace(b"\r\n", b"\n") if b"\r" in data else data


def _header(p: Path, data: bytes):
    """(line number, header cells, offset of its newline) of the first line that is not blank or a
    comment, or None when there is none in ``data`` (:func:`_normalised` bytes)."""
    pos, line = 0, 1
    while pos < len(data) and (data[pos:pos + 1] in (b"#", b"\n") or data[pos:pos + 1].isspace()):
        nxt = data.find(b"\n", pos)
        pos = len(data) if nxt < 0 else nxt + 1
        line += 1
    end = data.find(b"\n", pos)
    if end < 0:
        end = len(data)
    if pos >= len(data):
        return None
    return line, [h.strip() for h in data[pos:end].decode("utf-8", errors="replace").split(",")], end


#: Bytes of the start of a file the vectorised path checks before reading the file whole: a bad
#: early line sends the file to the general reader at once, which names it after reading that far.
PROBE_BYTES = 1 << 16


def _probe(path, ncol: int, sigma_m, id_width: int, number_width: int) -> bool:
    """Whether the whole lines in the first :data:`PROBE_BYTES` of ``path`` are plain (syntax only:
    the screening of the distances needs the whole file)."""
    from multilat.inputs import read_input_head

    data = _normalised(read_input_head(path, PROBE_BYTES))
    head = _header(Path(path), data)
    if head is None:
        return False
    end = head[2]
    last = data.rfind(b"\n")
    if last <= end:
        return True                        # no whole row in the block: nothing to check here
    try:
        _plain(data[:last + 1], end, ncol, sigma_m, id_width, number_width, screen=False)
    except (_NotPlain, MultilatError):
        return False
    return True


def plain_observations(path: str | os.PathLike, sigma_m: float | None = None):
    """:class:`~multilat.network.model.data.Observations` of a file in the plain subset, read vectorised;
    None for any other file (the general reader then reads it and names its errors).

    Used by :func:`multilat.network.io.files.read_observations` for large files: header exactly
    ``station,target,distance_m,sigma_m`` (or the three columns and a ``sigma_m`` option), every
    row plain. A file with both a ``sigma_m`` column and option is left to the general reader (it warns).
    """
    from multilat.inputs import read_input_bytes, read_input_head

    try:
        head = read_input_head(path, PROBE_BYTES)    # the header before the file is read whole
    except MultilatError:
        return None
    if head.startswith(b"\xef\xbb\xbf"):
        head = head[3:]
    end = head.find(b"\n")
    if end < 0:
        return None
    header = head[:end].rstrip(b"\r")
    if header == b"station,target,distance_m,sigma_m" and sigma_m is None:
        ncol = 4
    elif header == b"station,target,distance_m" and sigma_m is not None and np.isfinite(sigma_m) and sigma_m > 0:
        ncol = 3
    else:
        return None
    if not _probe(path, ncol, sigma_m, 32, 32):
        return None
    try:
        data = _normalised(read_input_bytes(path, "observations"))
    except MultilatError:
        return None
    end = data.find(b"\n")
    try:
        if len(data) >= ARROW_READ_ABOVE_BYTES and _arrow_available():
            return _plain_arrow(data, end, ncol, sigma_m).to_observations()
        return _plain(data, end, ncol, sigma_m, 32, 32).to_observations()
    except (_NotPlain, MultilatError):
        return None


#: Bytes outside the vectorised path's plain subset: non-ASCII, control characters but the newline,
#: quotes, '#', spaces (tabs and lone CRs are control characters)
_NOT_PLAIN = np.ones(256, bool)
_NOT_PLAIN[33:127] = False
_NOT_PLAIN[[10]] = False
_NOT_PLAIN[[34, 35]] = True


def _plain(data: bytes, end: int, ncol: int, sigma_m, id_width: int, number_width: int,
           screen: bool = True) -> FastObservations:
    """The vectorised path; raises :class:`_NotPlain` on anything outside the plain subset (with
    ``screen=False`` the distances are not screened: a probe of the first lines)."""
    body = np.frombuffer(data, np.uint8, offset=min(end + 1, len(data)))
    if body.size and body[-1] != 10:
        body = np.concatenate([body, np.array([10], np.uint8)])
    if body.size == 0 or _NOT_PLAIN[body].any():
        raise _NotPlain
    nl = np.flatnonzero(body == 10)
    n = len(nl)
    starts = np.concatenate([[0], nl[:-1] + 1])
    if np.any(nl == starts):
        raise _NotPlain                    # blank lines
    commas = np.flatnonzero(body == 44)
    per_line = np.diff(np.searchsorted(commas, np.concatenate([starts, [len(body)]])))
    if np.any(per_line != ncol - 1):
        raise _NotPlain
    c = commas.reshape(n, ncol - 1)
    sf = _fields(body, starts, c[:, 0], id_width)
    tf = _fields(body, c[:, 0] + 1, c[:, 1], id_width)
    dend = c[:, 2] if ncol == 4 else nl
    d = _floats(body, c[:, 1] + 1, dend, number_width, compiled=screen)
    if ncol == 4:
        sig = _floats(body, c[:, 2] + 1, nl, number_width, compiled=screen)
    else:
        sig = np.full(n, float(sigma_m))
    sids, si = _ids(sf)
    tids, ti = _ids(tf)
    return _checked(FastObservations(sids, tids, si, ti, d, sig), screen)


def _checked(obs: FastObservations, screen: bool = True) -> FastObservations:
    """``obs`` when it has no duplicate pair, no id both station and target and (``screen``) no row the
    screening refuses; else :class:`_NotPlain` (the general reader names the rows with their lines)."""
    if _has_duplicate_pair(obs.station_index, obs.target_index, len(obs.station_ids), len(obs.target_ids)) \
            or set(obs.station_ids) & set(obs.target_ids):
        raise _NotPlain                    # duplicates, an id both station and target
    from multilat.network.io.screening import suspect_rows

    if screen and suspect_rows(obs):
        raise _NotPlain
    return obs


#: Files at least this large are parsed by ``pyarrow.csv`` when pyarrow is installed (importing it
#: costs ~0.13 s and ~35 MB; below this the numpy path is as fast): 1.6 M rows parsed in 0.53 s
#: against 0.77 s, on one thread (Arrow's pool of threads slowed the rest of ``adjust`` by ~5 s)
ARROW_READ_ABOVE_BYTES = 8 << 20


def _arrow_available() -> bool:
    import importlib.util

    return importlib.util.find_spec("pyarrow") is not None


def _strings(arr) -> tuple:
    """The ASCII strings of an Arrow string array (no nulls), sliced from its one value buffer (a
    tenth of the time of ``to_pylist`` for 10^5 ids)."""
    _, offsets, values = arr.buffers()
    o = np.frombuffer(offsets, np.int32)[arr.offset:arr.offset + len(arr) + 1]
    text = values.to_pybytes().decode("ascii")
    return tuple(text[a:b] for a, b in zip(o[:-1].tolist(), o[1:].tolist()))


def _plain_arrow(data: bytes, end: int, ncol: int, sigma_m) -> FastObservations:
    """The plain subset parsed by ``pyarrow.csv`` (same grammar: the bytes screened as in :func:`_plain`,
    no quoting, no blank line, no empty or unparsable cell, positive finite numbers; ids numbered in
    order of first appearance); :class:`_NotPlain` for anything else."""
    import pyarrow as pa
    import pyarrow.compute as pcompute
    import pyarrow.csv as pc

    body = np.frombuffer(data, np.uint8, offset=min(end + 1, len(data)))
    if body.size == 0 or _NOT_PLAIN[body].any():
        raise _NotPlain                    # (a blank line is a row of one cell: refused by the parser)
    names = _HEADER + (["sigma_m"] if ncol == 4 else [])
    types = {"station": pa.string(), "target": pa.string(), "distance_m": pa.float64(), "sigma_m": pa.float64()}
    try:
        tab = pc.read_csv(pa.py_buffer(memoryview(data)[end + 1:]),
                          read_options=pc.ReadOptions(column_names=names, use_threads=False),
                          parse_options=pc.ParseOptions(quote_char=False, double_quote=False, escape_char=False,
                                                        newlines_in_values=False, ignore_empty_lines=False),
                          convert_options=pc.ConvertOptions(column_types={k: types[k] for k in names}, null_values=[],
                                                            strings_can_be_null=False,
                                                            quoted_strings_can_be_null=False))
    except (pa.ArrowInvalid, pa.ArrowTypeError):
        raise _NotPlain from None
    cols = []
    for name in ("station", "target"):
        col = tab.column(name).combine_chunks()
        if pcompute.any(pcompute.equal(pcompute.utf8_length(col), 0)).as_py():
            raise _NotPlain                # an empty id
        enc = col.dictionary_encode()      # indices in order of first appearance
        cols.append((_strings(enc.dictionary), enc.indices.to_numpy(zero_copy_only=False).astype(np.int64)))
    d = np.array(tab.column("distance_m").to_numpy(), float)      # copies: the table is freed below
    sig = np.array(tab.column("sigma_m").to_numpy(), float) if ncol == 4 else np.full(len(d), float(sigma_m))
    del tab, col, enc
    pa.default_memory_pool().release_unused()      # Arrow's allocator keeps freed pages otherwise
    for v in (d, sig):
        if not np.all(np.isfinite(v) & (v > 0)):
            raise _NotPlain
    return _checked(FastObservations(cols[0][0], cols[1][0], cols[0][1], cols[1][1], d, sig))


def _has_duplicate_pair(si, ti, s: int, t: int) -> bool:
    """Whether some (station, target) pair occurs twice (counting when the table is small, else sorting)."""
    pair = si * t + ti
    if s * t <= 8 * len(pair) + 1024:
        return bool(np.bincount(pair, minlength=s * t).max(initial=0) > 1)
    p = np.sort(pair)
    return bool(np.any(p[1:] == p[:-1]))


def _general(path: Path, sigma_m) -> FastObservations:
    """The general reader's verdict on a file outside the plain subset, as FastObservations."""
    from multilat.network.io.files import read_observations

    obs = read_observations(path, sigma_m=sigma_m)
    return FastObservations(tuple(obs.station_ids), tuple(obs.target_ids),
                            np.asarray(obs.station_index, np.int64), np.asarray(obs.target_index, np.int64),
                            np.asarray(obs.distance_m, float), np.asarray(obs.sigma_m, float))
