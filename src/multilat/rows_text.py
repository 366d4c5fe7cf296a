"""Text of long tables from their columns: JSON lists (or keyed objects) of objects and CSV lines,
written without one Python object per row.

A table's text repeats, row after row, the same sequence of *parts*: constant bytes (keys,
separators, indentation) and one *token* per column: a number's shortest round-trip text (orjson's,
one call per column), a label's quoted text (encoded once per distinct label) or a boolean. A
column of arrays (m, d1, ...) is a token per element (:func:`element_tokens`) inside the brackets,
commas and indentation of :func:`nested_template`. :func:`column_tokens` makes a column's tokens
(one byte buffer, each row's start and length) and :func:`assemble` lays the rows out: in one compiled
pass (numba, :mod:`multilat._text_kernels`) for tables of :data:`KERNEL_MIN_ROWS` rows or more, else
by joining Python byte strings. Both give the same bytes (``tests/test_rows_text.py``).

:class:`JsonRows` (a list of objects) and :class:`JsonKeyedRows` (an object of objects, keyed by a
label column) are the tables :func:`multilat.io.write_json` streams in chunks; as Python objects
they are a sequence and a mapping of row dicts.
"""

from __future__ import annotations

import csv
import io as _io
import os
from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np

__all__ = ["Tokens", "column_tokens", "element_tokens", "nested_template", "assemble", "JsonRows",
           "JsonKeyedRows", "KERNEL_MIN_ROWS"]

#: tables with at least this many rows are assembled by the compiled kernel (when numba is installed;
#: smaller ones do not pay for loading it)
KERNEL_MIN_ROWS = 10_000
#: rows per chunk of text (bounded memory: the chunk's tokens and text)
CHUNK_ROWS = 1 << 14

_COMMA = ord(",")


class Tokens(NamedTuple):
    """One token per row: ``buf[start[k]:start[k] + length[k]]`` (``buf`` uint8, the others int64)."""

    buf: np.ndarray
    start: np.ndarray
    length: np.ndarray


def _from_list(items: list[bytes]) -> Tokens:
    lens = np.fromiter(map(len, items), np.int64, len(items))
    start = np.zeros(len(items), np.int64)
    np.cumsum(lens[:-1], out=start[1:])
    return Tokens(np.frombuffer(b"".join(items), np.uint8), start, lens)


def _flat(text: bytes) -> Tokens:
    """The elements of a flat JSON list ``[a,b,...]`` of numbers or nulls (no comma inside one)."""
    buf = np.frombuffer(text, np.uint8)
    if buf.size <= 2:
        return Tokens(buf, np.zeros(0, np.int64), np.zeros(0, np.int64))
    commas = np.flatnonzero(buf == _COMMA)
    start = np.empty(commas.size + 1, np.int64)
    start[0] = 1
    start[1:] = commas + 1
    end = np.empty_like(start)
    end[:-1] = commas
    end[-1] = buf.size - 1
    return Tokens(buf, start, end - start)


def _label_texts(labels: Sequence[str], flavour: str, orjson) -> list[bytes]:
    """Each label as written: a JSON string, or a CSV field (quoted by the csv module when needed)."""
    if flavour == "csv":
        texts = [str(x) for x in labels]
        joined = "\x00".join(texts)
        if not any(ch in joined for ch in ',"\r\n\x00'):
            # no label needs quoting: each field is the label itself (one encode, one split)
            return joined.encode().split(b"\x00") if texts else []
        return [_csv_field(x).encode() for x in texts]
    if not labels:
        return []
    text = orjson.dumps(list(labels))
    if b"\\" not in text:
        # nothing escaped: the three bytes '","' only occur between two strings
        return [b'"' + e + b'"' for e in text[2:-2].split(b'","')]
    return [orjson.dumps(x) for x in labels]


def _csv_field(text: str) -> str:
    """``text`` as the csv module writes it in a row of several fields (quoted when needed)."""
    if not any(ch in text for ch in ',"\r\n'):
        return text
    buf = _io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow([text, ""])
    return buf.getvalue()[:-2]


def column_tokens(col, orjson, flavour: str = "json", *, labels: Tokens | None = None) -> Tokens:
    """The tokens of one column's rows.

    ``col``: a float/int/bool array (m,) or ``(labels, index)`` (strings ``labels[index[k]]``;
    ``labels`` pre-encoded by :func:`encode_labels` may be passed as ``labels=``). ``flavour``:
    ``"json"`` (non-finite floats are ``null``, booleans ``true``/``false``) or ``"csv"``
    (``nan``/``inf``/``-inf`` as ``repr`` writes them, ``True``/``False``). ``orjson`` None: the
    numbers' ``repr`` (CSV without orjson). Arrays (m, ...) are written by :func:`element_tokens`."""
    if isinstance(col, tuple):
        enc = labels if labels is not None else encode_labels(col[0], flavour, orjson)
        index = np.asarray(col[1], np.intp)
        return Tokens(enc.buf, enc.start[index], enc.length[index])
    col = np.asarray(col)
    if col.ndim != 1:
        raise ValueError("column_tokens takes a column (m,); an array (m, ...) goes to element_tokens")
    if col.dtype.kind == "b":
        words = [b"false", b"true"] if flavour == "json" else [b"False", b"True"]
        enc = _from_list(words)
        index = col.astype(np.intp)
        return Tokens(enc.buf, enc.start[index], enc.length[index])
    if col.dtype.kind in "iu":
        if orjson is None or col.dtype.kind == "u":
            return _from_list([str(v).encode() for v in col.tolist()])
        return _flat(orjson.dumps(np.ascontiguousarray(col, dtype=np.int64), option=orjson.OPT_SERIALIZE_NUMPY))
    vals = np.ascontiguousarray(col, dtype=np.float64)
    if orjson is None:
        return _from_list([repr(v).encode() for v in vals.tolist()])
    tok = _flat(orjson.dumps(vals, option=orjson.OPT_SERIALIZE_NUMPY))
    bad = np.flatnonzero(~np.isfinite(vals)) if flavour == "csv" else ()
    if len(bad):
        # orjson writes null; the CSV has repr's nan / inf / -inf, appended to the buffer
        extra = _from_list([repr(float(vals[i])).encode() for i in bad.tolist()])
        start, length = tok.start.copy(), tok.length.copy()
        start[bad] = extra.start + tok.buf.size
        length[bad] = extra.length
        tok = Tokens(np.concatenate([tok.buf, extra.buf]), start, length)
    return tok


def element_tokens(arr, orjson) -> list[Tokens]:
    """The tokens of every element of an array (m, d1, d2, ...) of numbers (JSON), one
    :class:`Tokens` (m rows) per element in C order: one orjson call for the whole array."""
    vals = np.ascontiguousarray(arr, dtype=np.float64)
    e = int(np.prod(vals.shape[1:], dtype=np.int64))
    if e == 0:
        return []
    tok = _flat(orjson.dumps(vals.reshape(-1), option=orjson.OPT_SERIALIZE_NUMPY))
    return [Tokens(tok.buf, tok.start[k::e], tok.length[k::e]) for k in range(e)]


def nested_template(shape: tuple, indent: int | None) -> list:
    """The parts of one row's nested JSON list of ``shape`` (the array's shape without its first
    axis): constant bytes (brackets, commas, orjson's two-space indentation when ``indent`` is the
    column of the line holding the value, None for compact text) and the element numbers 0, 1, ...
    in C order, as :func:`assemble` lays them out with :func:`element_tokens`."""
    count = iter(range(int(np.prod(shape, dtype=np.int64)) if shape else 1))

    def rec(dims, depth):
        if not dims:
            return [next(count)]
        if dims[0] == 0:
            return [b"[]"]
        out: list = [b"["]
        for i in range(dims[0]):
            if i:
                out.append(b",")
            if indent is not None:
                out.append(b"\n" + b" " * (indent + 2 * (depth + 1)))
            out += rec(dims[1:], depth + 1)
        if indent is not None:
            out.append(b"\n" + b" " * (indent + 2 * depth))
        out.append(b"]")
        return out

    return rec(tuple(shape), 0)


def encode_labels(labels: Sequence[str], flavour: str, orjson) -> Tokens:
    """Every label's text once (a table's label column is encoded once, not per chunk)."""
    return _from_list(_label_texts(labels, flavour, orjson))


def text_kernels():
    """The compiled text kernels (:mod:`multilat._text_kernels`), or None: numba not installed, or
    ``MULTILAT_NO_NUMBA`` set (checked before numba is imported)."""
    if os.environ.get("MULTILAT_NO_NUMBA"):
        return None
    from multilat import _text_kernels as K

    return K if K.HAVE_NUMBA else None


def assemble(parts: Sequence[bytes | int], tokens: Sequence[Tokens], n: int, *,
             compiled: bool | None = None) -> bytes:
    """The text of ``n`` rows, each the concatenation of ``parts``: a ``bytes`` part is written as is,
    an ``int`` part ``c`` is row ``k``'s token of ``tokens[c]``. ``compiled``: force (True) or
    forbid (False) the compiled kernel; None: the kernel for :data:`KERNEL_MIN_ROWS` rows or more."""
    merged: list = []
    for p in parts:                                   # adjacent constants joined
        if isinstance(p, bytes) and merged and isinstance(merged[-1], bytes):
            merged[-1] += p
        else:
            merged.append(p)
    K = text_kernels() if (compiled is None and n >= KERNEL_MIN_ROWS) or compiled else None
    kern = None if K is None else K.assemble_rows
    if compiled and kern is None:
        raise RuntimeError("the compiled row assembly needs numba")
    if n == 0:
        return b""
    if kern is None:
        lists = []
        for p in merged:
            if isinstance(p, bytes):
                lists.append([p] * n)
            else:
                t = tokens[p]
                b = t.buf.tobytes()
                lists.append([b[s:s + ln] for s, ln in zip(t.start.tolist(), t.length.tolist())])
        out: list = [None] * (n * len(lists))
        for i, lst in enumerate(lists):
            out[i::len(lists)] = lst
        return b"".join(out)
    consts = [p for p in merged if isinstance(p, bytes)]
    kind = np.array([0 if isinstance(p, bytes) else 1 for p in merged], np.int64)
    ref = np.zeros(len(merged), np.int64)
    ci = 0
    for i, p in enumerate(merged):
        if isinstance(p, bytes):
            ref[i], ci = ci, ci + 1
        else:
            ref[i] = p
    c = _from_list(consts)
    used = sorted({int(p) for p in merged if not isinstance(p, bytes)})
    tstart = np.zeros((len(tokens), n), np.int64)
    tlen = np.zeros((len(tokens), n), np.int64)
    bufs, at = [], 0
    for j in used:
        t = tokens[j]
        tstart[j] = t.start + at
        tlen[j] = t.length
        bufs.append(t.buf)
        at += t.buf.size
    tbuf = np.concatenate(bufs) if bufs else np.zeros(0, np.uint8)
    row_len = np.full(n, int(c.length.sum()), np.int64)
    for r in ref[kind == 1].tolist():                  # a column used twice counts twice
        row_len += tlen[r]
    row_at = np.zeros(n, np.int64)
    np.cumsum(row_len[:-1], out=row_at[1:])
    out_arr = np.empty(int(row_at[-1] + row_len[-1]), np.uint8)
    kern(kind, ref, c.buf, c.start, c.length, tbuf, tstart, tlen, row_at, out_arr)
    return out_arr.tobytes()


# ------------------------------------------------------------------------------------ JSON tables
class _ColumnTable:
    """Columns of equal length: each a float/int/bool array (m,), a float array (m, ...) (a nested
    list per row) or ``(labels, index)`` (strings ``labels[index[k]]``)."""

    def __init__(self, columns: dict):
        self.columns = {}
        n = None
        for name, col in columns.items():
            if isinstance(col, tuple):
                labels, index = col
                col = (tuple(labels), np.asarray(index, dtype=np.intp))
                size = col[1].shape[0]
            else:
                col = np.asarray(col)
                if col.ndim < 1 or col.dtype.kind not in "fiub" or (col.ndim > 1 and col.dtype.kind not in "fiu"):
                    raise ValueError(f"{type(self).__name__} column {name!r}: a numeric or bool array (m,), "
                                     "a numeric array (m, ...) or (labels, index)")
                size = col.shape[0]
            if n is not None and size != n:
                raise ValueError(f"{type(self).__name__} column {name!r}: {size} rows, expected {n}")
            n = size
            self.columns[str(name)] = col
        self.n = 0 if n is None else int(n)
        self._labels: dict = {}

    def _row(self, k: int) -> dict:
        out = {}
        for name, col in self.columns.items():
            if isinstance(col, tuple):
                out[name] = col[0][col[1][k]]
            elif col.ndim > 1:
                out[name] = col[k].tolist()
            else:
                out[name] = col[k].item()
        return out

    def _tokens(self, orjson, lo: int, hi: int) -> list[Tokens]:
        """Every column's tokens of rows [lo, hi): one per row, or one per element (arrays)."""
        toks = []
        for name, col in self.columns.items():
            if isinstance(col, tuple):
                if name not in self._labels:
                    self._labels[name] = encode_labels(col[0], "json", orjson)
                toks.append(column_tokens((col[0], col[1][lo:hi]), orjson, labels=self._labels[name]))
            elif col.ndim > 1:
                toks += element_tokens(col[lo:hi], orjson)
            else:
                toks.append(column_tokens(col[lo:hi], orjson))
        return toks

    def _write(self, orjson, write, indent: int | None, key: tuple | None, chunk: int) -> None:
        opening, closing = (b"{", b"}") if key is not None else (b"[", b"]")
        if self.n == 0:
            write(opening + closing)
            return
        names = [orjson.dumps(nm) for nm in self.columns]
        if indent is None:
            i1 = i2 = b""
            kv, end = b":", closing
        else:
            i1, i2 = b"\n" + b" " * (indent + 2), b"\n" + b" " * (indent + 4)
            kv, end = b": ", b"\n" + b" " * indent + closing
        # each column's parts with the tokens' numbers in the order _tokens makes them
        col_parts, at = [], 0
        for col in self.columns.values():
            if not isinstance(col, tuple) and col.ndim > 1:
                tpl = nested_template(col.shape[1:], None if indent is None else indent + 4)
                col_parts.append([p if isinstance(p, bytes) else p + at for p in tpl])
                at += int(np.prod(col.shape[1:], dtype=np.int64))
            else:
                col_parts.append([at])
                at += 1
        kcol = at                                          # the key's tokens follow the columns'
        parts: list = [i1, kcol, kv + b"{"] if key is not None else [i1 + b"{"]
        for c, nm in enumerate(names):
            parts += [(b"," if c else b"") + i2 + nm + kv, *col_parts[c]]
        parts.append((i1 if names else b"") + b"},")
        if key is not None and "\x00key" not in self._labels:
            self._labels["\x00key"] = encode_labels(key[0], "json", orjson)
        write(opening)
        for lo in range(0, self.n, chunk):
            hi = min(self.n, lo + chunk)
            toks = self._tokens(orjson, lo, hi)
            if key is not None:
                toks.append(column_tokens((key[0], key[1][lo:hi]), orjson, labels=self._labels["\x00key"]))
            text = assemble(parts, toks, hi - lo)
            write(text[:-1] if hi == self.n else text)    # no comma after the last row
        write(end)


class JsonRows(_ColumnTable, Sequence):
    """A table written to JSON as a list of objects, one per row, from its columns (see
    :class:`_ColumnTable`). As a Python sequence it gives the row dicts (``float``/``int``/``bool``/
    ``str`` values, nested lists); the JSON writer never builds them."""

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self._row(i) for i in range(*k.indices(self.n))]
        k = int(k)
        if k < 0:
            k += self.n
        if not 0 <= k < self.n:
            raise IndexError("JsonRows index out of range")
        return self._row(k)

    def __iter__(self):
        return (self._row(k) for k in range(self.n))

    def to_python(self) -> list:
        return list(self)

    def write(self, orjson, write, indent: int | None, chunk: int = CHUNK_ROWS) -> None:
        """Write the JSON list through ``write(bytes)``; ``indent``: the column of the line holding the
        list (orjson's two-space style) or None (compact)."""
        self._write(orjson, write, indent, None, chunk)


class JsonKeyedRows(_ColumnTable, Mapping):
    """A table written to JSON as an object of objects: row ``k`` under the key ``keys[k]`` (distinct
    strings), the columns as in :class:`JsonRows`. As a Python mapping: key -> row dict."""

    def __init__(self, keys: Sequence[str], columns: dict):
        super().__init__(columns)
        self.keys_ = tuple(str(x) for x in keys)
        if len(self.keys_) != self.n and self.columns:
            raise ValueError(f"JsonKeyedRows: {len(self.keys_)} keys for {self.n} rows")
        self.n = len(self.keys_)
        self._where = {k: i for i, k in enumerate(self.keys_)}
        if len(self._where) != self.n:
            raise ValueError("JsonKeyedRows: the keys are not distinct")

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, key: str) -> dict:
        return self._row(self._where[key])

    def __iter__(self):
        return iter(self.keys_)

    def to_python(self) -> dict:
        return {k: self._row(i) for i, k in enumerate(self.keys_)}

    def write(self, orjson, write, indent: int | None, chunk: int = CHUNK_ROWS) -> None:
        """Write the JSON object through ``write(bytes)`` (``indent`` as :meth:`JsonRows.write`)."""
        self._write(orjson, write, indent, (self.keys_, np.arange(self.n)), chunk)
