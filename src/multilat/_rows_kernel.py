"""The compiled pass of :func:`multilat.rows_text.assemble`: rows of text laid out from constant
parts and per-row tokens (numba; ``HAVE_NUMBA`` False without it, and the caller joins Python byte
strings instead)."""

from __future__ import annotations

from multilat._numba import HAVE_NUMBA, njit, prange  # noqa: F401


@njit(parallel=True, cache=True)
def assemble_rows(kind, ref, cbuf, cstart, clen, tbuf, tstart, tlen, row_at, out):
    """Write the rows into ``out`` (uint8, exactly their size), row ``r`` from ``row_at[r]``. Row ``r``
    is the parts ``p`` in order: ``kind[p] == 0``: constant ``ref[p]`` (``cbuf[cstart:cstart +
    clen]``); else token ``r`` of column ``ref[p]`` (``tbuf[tstart[c, r]:tstart[c, r] + tlen[c, r]]``).
    Rows are independent (parallel over rows; the bytes do not depend on the threads)."""
    n = tstart.shape[1]
    for r in prange(n):
        pos = row_at[r]
        for p in range(kind.shape[0]):
            j = ref[p]
            if kind[p] == 0:
                s = cstart[j]
                ln = clen[j]
                for b in range(ln):
                    out[pos + b] = cbuf[s + b]
            else:
                s = tstart[j, r]
                ln = tlen[j, r]
                for b in range(ln):
                    out[pos + b] = tbuf[s + b]
            pos += ln
