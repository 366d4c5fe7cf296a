"""One grammar for observation files whatever their size: the fast (vectorised) reader and the
general reader accept and refuse the same files, with the same FILE:LINE messages."""

from __future__ import annotations

import pytest

from multilat.errors import MultilatError
from multilat.network.io.fastio import read_observations_fast
from multilat.network.io.files import read_observations

HEADER = "station,target,distance_m,sigma_m\n"
ROWS = "".join(f"{s},T{t},{1.0 + 0.1 * t + 0.01 * k:.4f},5e-6\n" for k, s in enumerate("ABCD")
               for t in range(6))

VARIANTS = {
    "plain": HEADER + ROWS,
    "trailing-blank-line": HEADER + ROWS + "\n",
    "blank-line-inside": HEADER + ROWS[:40] + "\n" + ROWS[40:],
    "comment-above-header": "# made by hand\n" + HEADER + ROWS,
    "comment-below-header": HEADER + "# a note\n" + ROWS,
    "hash-station-id": HEADER + ROWS + "#E,T1,1.5,5e-6\n",
    "leading-space-id": HEADER + ROWS.replace("A,T1,", " A,T1,"),
    "long-ids": HEADER + ROWS.replace("T1,", "T" * 40 + ","),
    "non-utf8-id": (HEADER + ROWS).encode().replace(b"B,T2,", b"B\xff,T2,"),
    "utf8-id": HEADER + ROWS.replace("C,", "Ç,"),
    "quoted-id": HEADER + ROWS.replace("D,T3,", '"D",T3,'),
    "crlf": (HEADER + ROWS).replace("\n", "\r\n"),
    "bom": "\ufeff" + HEADER + ROWS,
    "tab-in-id": HEADER + ROWS.replace("A,T0,", "A\t,T0,"),
    "duplicate": HEADER + ROWS + "A,T1,1.1,5e-6\n",
    "station-is-target": HEADER + ROWS + "T1,T2,1.1,5e-6\n",
    "negative": HEADER + ROWS.replace("1.1000", "-1.1000"),
    "zero": HEADER + ROWS.replace("1.1000", "0"),
    "not-a-number": HEADER + ROWS.replace("1.1000", "1,1000"),
    "word": HEADER + ROWS.replace("1.1000", "abc"),
    "nan": HEADER + ROWS.replace("1.1000", "nan"),
    "empty-id": HEADER + ROWS.replace("B,T1,", ",T1,"),
    "empty-distance": HEADER + ROWS.replace("1.1000", ""),
    "too-few-cells": HEADER + ROWS.replace(",5e-6\n", "\n", 1),
    "mm-among-m": HEADER + ROWS.replace("1.1000", "1100.0"),
    "1e300": HEADER + ROWS.replace("1.1000", "1e300"),
    "sigma-1e-300": HEADER + ROWS.replace("1.1000,5e-6", "1.1000,1e-300"),
    "underscore-number": HEADER + ROWS.replace("1.1000", "1_1"),
    "header-only": HEADER,
    "empty": "",
}


def _outcome(fn, path):
    try:
        o = fn(path, sigma_m=5e-6)
    except MultilatError as exc:
        return "error", str(exc)
    return "ok", (tuple(o.station_ids), tuple(o.target_ids), tuple(o.distance_m.tolist()),
                  tuple(o.sigma_m.tolist()), tuple(o.station_index.tolist()), tuple(o.target_index.tolist()))


@pytest.mark.parametrize("name", list(VARIANTS))
def test_fast_and_general_readers_agree(tmp_path, name):
    text = VARIANTS[name]
    p = tmp_path / "obs.csv"
    p.write_bytes(text if isinstance(text, bytes) else text.encode())
    general = _outcome(read_observations, p)
    fast = _outcome(read_observations_fast, p)
    assert fast == general
    if general[0] == "error":
        assert str(p) in general[1] and "\n" not in general[1]


@pytest.mark.parametrize("name,line", [("hash-station-id", 26), ("non-utf8-id", 10), ("comment-below-header", 2),
                                       ("mm-among-m", 3), ("1e300", 3), ("sigma-1e-300", 3)])
def test_errors_name_the_line(tmp_path, name, line):
    text = VARIANTS[name]
    p = tmp_path / "obs.csv"
    p.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(MultilatError, match=f"obs.csv:{line}"):
        read_observations_fast(p, sigma_m=5e-6)


def _large(tmp_path, bad_row: str, at: int = 15000):
    rows = [f"S{k % 6},P{k // 6},{1.0 + (k % 997) * 1e-3:.6f},5e-6" for k in range(21000)]
    rows[at] = bad_row
    p = tmp_path / "big.csv"
    p.write_bytes(("station,target,distance_m,sigma_m\n" + "\n".join(rows) + "\n").encode("utf-8", "surrogateescape"))
    return p, at + 2


@pytest.mark.parametrize("bad,needle", [("S1\udcff,P9999,1.0,5e-6", "not UTF-8"),
                                        ("#S1,P9999,1.0,5e-6", "'#'"),
                                        ("S1,P9999,abc,5e-6", "not a number"),
                                        ("S1,P9999,1e300,5e-6", "suspect"),
                                        ("S1,P9999,1.0", "expected 4 cells")])
def test_large_file_through_the_cli(ws, tmp_path, bad, needle):
    p, line = _large(tmp_path, bad)
    ws.fails(["adjust", str(p)], f"big.csv:{line}", needle)
