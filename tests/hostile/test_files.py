"""Malformed input files, for every reader of every command: each gets exit 2, one ``error:`` line
naming the file (and the line where there is one), and leaves every file as it was."""

from __future__ import annotations

import pytest

#: reader -> (argv with FILE for the file under test, file name, a numeric column that must be > 0
#: or None, a numeric column of any sign)
READERS = {
    "adjust-obs": (["adjust", "FILE"], "obs.csv", "distance_m", None),
    "propagate-obs": (["propagate", "FILE", "--trials", "100"], "obs.csv", "sigma_m", None),
    "adjust-refs": (["adjust", "{d}/obs.csv", "--references", "FILE"], "refs.csv", "length_m", None),
    "adjust-points": (["adjust", "{d}/obs.csv", "--points", "FILE", "--datum", "control"], "points.csv",
                      None, "x_m"),
    "simulate-config": (["simulate", "FILE", "--trials", "1"], "config.csv", None, "x_m"),
    "correct-raw": (["correct", "FILE", "-e", "{d}/env.csv", "--heights", "{d}/heights.csv"], "raw.csv", "optical_path_m", None),
    "correct-env": (["correct", "{d}/raw.csv", "-e", "FILE", "--heights", "{d}/heights.csv"], "env.csv", "pressure_hpa", None),
    "correct-heights": (["correct", "{d}/raw.csv", "-e", "{d}/env.csv", "--heights", "FILE"], "heights.csv",
                        None, "height_m"),
    "two-face": (["two-face", "FILE"], "two_face.csv", "distance_m", None),
    "lbb-edges": (["lbb", "trilaterate", "FILE"], "edges.csv", "l12_m", None),
    "lbb-reference": (["lbb", "compare", "{d}/m60_edges.csv", "FILE", "--trials", "2"], "m60_ref.csv",
                      None, "x_m"),
}


def _lines(text: str):
    lines = text.splitlines()
    h = next(i for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#"))
    return lines, h


def _set_cell(text: str, row: int, col: str, value: str) -> tuple[str, int]:
    """Replace ``col`` of the ``row``-th data row; returns the text and the 1-based file line."""
    lines, h = _lines(text)
    header = [c.strip() for c in lines[h].split(",")]
    i = h + 1 + row
    cells = lines[i].split(",")
    cells[header.index(col)] = value
    lines[i] = ",".join(cells)
    return "\n".join(lines) + "\n", i + 1


def _first_id_col(text):
    lines, h = _lines(text)
    return lines[h].split(",")[0].strip()


def _mutate(kind: str, text: str, pos_col, any_col):
    """(new bytes or None for 'make it a directory' / 'remove it', needle with the line or '')"""
    lines, h = _lines(text)
    num = pos_col or any_col
    if kind == "empty":
        return b"", ""
    if kind == "comments-only":
        return b"# nothing here\n\n", ""
    if kind == "header-only":
        return (lines[h] + "\n").encode(), ""
    if kind == "missing-column":
        header = [c for c in lines[h].split(",") if c.strip() != num]
        lines[h] = ",".join(header)
        return ("\n".join(lines) + "\n").encode(), ""
    if kind == "binary":
        return b"\x00\x01\x02\xff\xfe" * 40, ""
    if kind == "not-a-number":
        t, ln = _set_cell(text, 0, num, "abc")
        return t.encode(), f":{ln}"
    if kind == "nan":
        t, ln = _set_cell(text, 1, num, "nan")
        return t.encode(), f":{ln}"
    if kind == "inf":
        t, ln = _set_cell(text, 2, num, "inf")
        return t.encode(), f":{ln}"
    if kind == "negative":
        t, ln = _set_cell(text, 1, pos_col, "-1")
        return t.encode(), f":{ln}"
    if kind == "too-few-cells":
        i = h + 2
        lines[i] = ",".join(lines[i].split(",")[:-1])
        return ("\n".join(lines) + "\n").encode(), f":{i + 1}"
    if kind == "too-many-cells":
        i = h + 1
        lines[i] = lines[i] + ",1"
        return ("\n".join(lines) + "\n").encode(), f":{i + 1}"
    if kind == "hash-id":
        i = h + 2
        lines[i] = "#" + lines[i]
        return ("\n".join(lines) + "\n").encode(), f":{i + 1}"
    if kind == "non-utf8":
        i = h + 1
        lines[i] = "\udcff" + lines[i]
        return ("\n".join(lines) + "\n").encode("utf-8", "surrogateescape"), f":{i + 1}"
    if kind == "empty-id":
        i = h + 1
        cells = lines[i].split(",")
        cells[0] = ""
        lines[i] = ",".join(cells)
        return ("\n".join(lines) + "\n").encode(), f":{i + 1}"
    if kind in ("directory", "missing"):
        return None, ""
    raise AssertionError(kind)


KINDS = ["empty", "comments-only", "header-only", "missing-column", "binary", "not-a-number", "nan", "inf",
         "negative", "too-few-cells", "too-many-cells", "hash-id", "non-utf8", "empty-id", "directory",
         "missing"]


def _cases():
    for reader, (argv, name, pos_col, any_col) in READERS.items():
        for kind in KINDS:
            if kind == "negative" and pos_col is None:
                continue
            yield pytest.param(reader, kind, id=f"{reader}-{kind}")


@pytest.mark.parametrize("reader,kind", list(_cases()))
def test_malformed_file(ws, reader, kind):
    argv, name, pos_col, any_col = READERS[reader]
    target = ws / name
    data, line = _mutate(kind, target.read_text(encoding="utf-8"), pos_col, any_col)
    target.unlink()
    if kind == "directory":
        target.mkdir()
    elif data is not None:
        target.write_bytes(data)
    args = [str(target) if a == "FILE" else a for a in argv]
    ws.fails(args, name + line)
