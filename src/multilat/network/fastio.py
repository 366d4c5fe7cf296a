"""Fast reader of large observation CSVs (millions of rows), numpy only.

:func:`multilat.network.files.read_observations` checks every cell in Python, which is right for
hand-made files but takes seconds per million rows. :func:`read_observations_fast` reads the same
format — header ``station,target,distance_m[,sigma_m]`` (in this order; no quoting; ``#`` comment
lines and blank lines only before the header) — vectorised: the bytes are split on newlines and
commas with ``np.flatnonzero``, ids are gathered into fixed-width byte strings and numbered with
``np.unique``, numbers are converted by numpy's bytes-to-float cast. Errors name ``FILE:LINE``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from multilat.errors import MultilatError

__all__ = ["read_observations_fast", "FastObservations"]


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
        """The general :class:`multilat.network.data.Observations` (with its full checks)."""
        from multilat.network.data import Observations

        return Observations(self.station_ids, self.target_ids, self.station_index, self.target_index,
                            self.distance_m, self.sigma_m)


def _fields(buf, starts, ends, width, path, line0):
    """Gather byte fields [starts, ends) into an (n, w) uint8 array (zero padded), w = longest field."""
    ln = ends - starts
    if ln.size and ln.max() > width:
        k = int(np.argmax(ln > width))
        raise MultilatError(f"{path}:{line0 + k}: field longer than {width} characters")
    if ln.size and ln.min() <= 0:
        k = int(np.argmax(ln <= 0))
        raise MultilatError(f"{path}:{line0 + k}: empty field")
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
    names = tuple(s.strip() for s in np.char.decode(sel, "utf-8").tolist())
    return names, rank[inv.ravel()].astype(np.int64)


def _floats(fields, name, path, line0):
    fields = np.ascontiguousarray(fields).view(f"S{fields.shape[1]}").ravel()
    try:
        v = fields.astype(np.float64)
    except ValueError:
        for k, f in enumerate(fields):
            try:
                float(f)
            except ValueError:
                raise MultilatError(f"{path}:{line0 + k}: column '{name}': not a number: "
                                    f"{f.decode(errors='replace')!r}") from None
        raise MultilatError(f"{path}: column '{name}': not a number")  # pragma: no cover
    bad = ~(np.isfinite(v) & (v > 0))
    if bad.any():
        k = int(np.argmax(bad))
        raise MultilatError(f"{path}:{line0 + k}: column '{name}': must be finite and > 0, got {v[k]!r}")
    return v


def read_observations_fast(path: str | os.PathLike, *, sigma_m: float | None = None,
                           id_width: int = 32, number_width: int = 32) -> FastObservations:
    """Read ``station,target,distance_m[,sigma_m]`` quickly.

    Parameters
    ----------
    path : path of the CSV
    sigma_m : float, optional
        Standard uncertainty for every row when the file has no ``sigma_m`` column.
    id_width, number_width : int
        Longest id / number field accepted (characters).

    Returns
    -------
    FastObservations
    """
    p = Path(path)
    if not p.is_file():
        raise MultilatError(f"{p}: no such file")
    data = p.read_bytes()
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    data = data.replace(b"\r\n", b"\n")
    # skip comment / blank lines before the header
    pos, line = 0, 1
    while pos < len(data) and (data[pos:pos + 1] in (b"#", b"\n") or data[pos:pos + 1].isspace()):
        nxt = data.find(b"\n", pos)
        pos = len(data) if nxt < 0 else nxt + 1
        line += 1
    end = data.find(b"\n", pos)
    if end < 0:
        raise MultilatError(f"{p}: empty file (expected a header station,target,distance_m)")
    header = [h.strip() for h in data[pos:end].decode("utf-8", errors="replace").split(",")]
    if header[:3] != ["station", "target", "distance_m"] or len(header) > 4 or \
            (len(header) == 4 and header[3] != "sigma_m"):
        raise MultilatError(f"{p}:{line}: the fast reader needs the header station,target,distance_m[,sigma_m]"
                            f" (got {','.join(header)})")
    ncol = len(header)
    if ncol == 3 and sigma_m is None:
        raise MultilatError(f"{p}: no sigma_m column: give sigma_m")
    body = np.frombuffer(data, np.uint8, offset=end + 1)
    if body.size and body[-1] != 10:
        body = np.concatenate([body, np.array([10], np.uint8)])
    line0 = line + 1
    nl = np.flatnonzero(body == 10)
    n = len(nl)
    if n == 0:
        raise MultilatError(f"{p}: no data rows after the header")
    starts = np.concatenate([[0], nl[:-1] + 1])
    if np.any(nl == starts):
        k = int(np.argmax(nl == starts))
        raise MultilatError(f"{p}:{line0 + k}: blank line inside the data")
    commas = np.flatnonzero(body == 44)
    per_line = np.diff(np.searchsorted(commas, np.concatenate([starts, [len(body)]])))
    if np.any(per_line != ncol - 1):
        k = int(np.argmax(per_line != ncol - 1))
        raise MultilatError(f"{p}:{line0 + k}: expected {ncol} cells, got {int(per_line[k]) + 1}")
    c = commas.reshape(n, ncol - 1)
    sf = _fields(body, starts, c[:, 0], id_width, p, line0)
    tf = _fields(body, c[:, 0] + 1, c[:, 1], id_width, p, line0)
    dend = c[:, 2] if ncol == 4 else nl
    d = _floats(_fields(body, c[:, 1] + 1, dend, number_width, p, line0), "distance_m", p, line0)
    if ncol == 4:
        sig = _floats(_fields(body, c[:, 2] + 1, nl, number_width, p, line0), "sigma_m", p, line0)
    else:
        if not (np.isfinite(sigma_m) and sigma_m > 0):
            raise MultilatError(f"sigma_m must be finite and > 0, got {sigma_m!r}")
        sig = np.full(n, float(sigma_m))
    sids, si = _ids(sf)
    tids, ti = _ids(tf)
    return FastObservations(sids, tids, si, ti, d, sig)
