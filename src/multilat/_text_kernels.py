"""Compiled text kernels (numba; ``HAVE_NUMBA`` False without it and the callers take their numpy or
Python paths): :func:`assemble_rows` lays out rows of text for :func:`multilat.rows_text.assemble`,
:func:`parse_decimals` reads decimal numbers for the large-file reader :mod:`multilat.network.io.fastio`.

IEEE division (``multilat._numba.njit``: ``error_model="numpy"``): a zero divisor gives inf or nan, never an
exception out of a parallel region.
"""

from __future__ import annotations

import numpy as np

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


#: 10**k, k = 0..22: exactly representable in float64
_POW10 = np.array([10.0 ** k for k in range(23)])


@njit(parallel=True, cache=True)
def parse_decimals(buf, starts, ends, pow10, out, fast):
    """Decimal numbers ``buf[starts[k]:ends[k]]`` (ASCII ``[+-]digits[.digits][(e|E)[+-]digits]``)
    into ``out``, correctly rounded where ``fast[k]`` is set: at most 19 significant digits forming an
    integer ``M < 2**53`` and a decimal exponent ``|E| <= 22``, so that ``M * 10**E`` or
    ``M / 10**-E`` is one correctly rounded operation on exact operands (Clinger 1990, *How to read
    floating point numbers accurately*, the fast path). Anything else leaves ``fast[k]`` False for the
    caller's general conversion."""
    for k in prange(starts.shape[0]):
        p = starts[k]
        e = ends[k]
        fast[k] = False
        out[k] = 0.0
        neg = False
        if p < e and (buf[p] == 43 or buf[p] == 45):          # + -
            neg = buf[p] == 45
            p += 1
        mant = np.uint64(0)
        nd = 0              # significant digits taken
        frac = 0            # digits after the point
        seen = 0            # digits seen at all
        bad = False
        in_frac = False
        while p < e:                                          # digits, one '.', digits
            ch = buf[p]
            if 48 <= ch <= 57:
                seen += 1
                if in_frac:
                    frac += 1
                if mant != 0 or ch != 48:
                    nd += 1
                    if nd > 19:
                        bad = True
                    mant = mant * np.uint64(10) + np.uint64(ch - 48)
            elif ch == 46 and not in_frac:
                in_frac = True
            else:
                break
            p += 1
        if seen == 0 or bad:
            continue
        ex = 0
        if p < e and (buf[p] == 101 or buf[p] == 69):         # e E
            p += 1
            eneg = False
            if p < e and (buf[p] == 43 or buf[p] == 45):
                eneg = buf[p] == 45
                p += 1
            ne = 0
            while p < e and 48 <= buf[p] <= 57 and ne < 6:
                ex = ex * 10 + (buf[p] - 48)
                ne += 1
                p += 1
            if ne == 0:
                continue
            if eneg:
                ex = -ex
        if p != e or mant >= np.uint64(9007199254740992):    # trailing text, or M >= 2**53
            continue
        ex -= frac
        v = float(mant)
        if ex >= 0:
            if ex > 22:
                continue
            v = v * pow10[ex]
        else:
            if ex < -22:
                continue
            v = v / pow10[-ex]
        out[k] = -v if neg else v
        fast[k] = True
