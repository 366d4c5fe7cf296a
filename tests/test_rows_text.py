"""Tables written from their columns (:mod:`multilat.rows_text`): JSON lists and keyed objects of
row objects, CSV lines.

Independent values: orjson itself on the same document built from plain Python objects (one dict per
row, ``tolist()`` values) must give the same bytes, indented and compact; the csv module row by row
for the CSV; and the compiled assembly against the joined Python byte strings (two methods, same
bytes). Tables not designed for the writer: random sizes (0, 1, around the chunk size), labels with
quotes, backslashes, commas, control characters and non-ASCII text, NaN and infinities, nested
arrays, empty nested rows.
"""

import csv
import io

import numpy as np
import orjson
import pytest

from multilat import rows_text as RT
from multilat.io import dumps_json, write_csv_columns_atomic
from multilat.rows_text import JsonKeyedRows, JsonRows, assemble, column_tokens, element_tokens, nested_template

LABELS = ("A", 'q"uote', "back\\slash", 'a",', "comma,", "µ-Ω", "tab\there", "nl\nx", "", "ctl\x01")

numba = pytest.importorskip("numba")


def _table(n, rng):
    f = rng.normal(size=n) * 10.0 ** rng.integers(-300, 300, n)
    if n:
        f[rng.integers(0, n, max(1, n // 7))] = rng.choice([np.nan, np.inf, -np.inf, 0.0, -0.0, 5e-324])
    return {
        "label": (LABELS, rng.integers(0, len(LABELS), n)),
        "x_m": f,
        "count": rng.integers(-2**40, 2**40, n),
        "flag": rng.random(n) < 0.5,
        "xyz_m": rng.normal(size=(n, 3)),
        "cov_m2": rng.normal(size=(n, 3, 3)),
        "empty": np.zeros((n, 2, 0)),
        "one": rng.normal(size=(n, 1, 1, 2)),
    }


def _plain_rows(cols, n):
    out = []
    for k in range(n):
        row = {}
        for name, col in cols.items():
            if isinstance(col, tuple):
                row[name] = col[0][col[1][k]]
            else:
                v = col[k].tolist()
                row[name] = None if isinstance(v, float) and not np.isfinite(v) else v
        out.append(row)
    return out


def _plain_nested(rows):
    """orjson writes NaN as null inside nested lists too: the plain reference does the same."""
    def fix(v):
        if isinstance(v, list):
            return [fix(x) for x in v]
        return None if isinstance(v, float) and not np.isfinite(v) else v
    return [{k: fix(v) for k, v in r.items()} for r in rows]


@pytest.mark.parametrize("n", [0, 1, 7, RT.CHUNK_ROWS + 3, RT.KERNEL_MIN_ROWS + 1])
@pytest.mark.parametrize("indent", [True, False])
def test_json_tables_are_the_bytes_orjson_writes_for_plain_objects(n, indent):
    rng = np.random.default_rng(n + 7 * indent)
    cols = _table(n, rng)
    keys = tuple(f"K{j}" if j % 5 else f'K"{j}\\' for j in range(n))
    doc = {"before": 1.5, "rows": JsonRows(cols), "targets": JsonKeyedRows(keys, cols),
           "nested": {"deeper": [JsonRows({"a": np.arange(3.0)})]}, "after": [1, 2]}
    plain_rows = _plain_nested(_plain_rows(cols, n))
    plain = {"before": 1.5, "rows": plain_rows, "targets": dict(zip(keys, plain_rows)),
             "nested": {"deeper": [[{"a": 0.0}, {"a": 1.0}, {"a": 2.0}]]}, "after": [1, 2]}
    opt = orjson.OPT_INDENT_2 if indent else 0
    assert dumps_json(doc, indent=indent) == orjson.dumps(plain, option=opt) + b"\n"


def test_compiled_and_joined_assembly_give_the_same_bytes():
    rng = np.random.default_rng(3)
    n = 2500
    cols = _table(n, rng)
    toks = [column_tokens(c, orjson) for c in cols.values() if isinstance(c, tuple) or c.ndim == 1]
    toks += element_tokens(cols["cov_m2"], orjson)                        # 9 element columns: 4..12
    nested = [p if isinstance(p, bytes) else p + 4 for p in nested_template((3, 3), 6)]
    parts = [b"<", 0, b"|", 1, 2, b"", 3, b"|\n", *nested, b"#", 1]     # column 1 used twice
    assert assemble(parts, toks, n, compiled=True) == assemble(parts, toks, n, compiled=False)
    assert assemble(parts, toks, 0, compiled=True) == b""
    # constants only
    assert assemble([b"ab", b"c"], [], 3, compiled=True) == b"abcabcabc"


def test_csv_columns_equal_the_csv_module(tmp_path):
    rng = np.random.default_rng(11)
    n = RT.KERNEL_MIN_ROWS + 17                                   # the compiled assembly
    cols = {k: v for k, v in _table(n, rng).items() if isinstance(v, tuple) or v.ndim == 1}
    write_csv_columns_atomic(tmp_path / "t.csv", cols)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(list(cols))
    lab, idx = cols["label"]
    for k in range(n):
        w.writerow([lab[idx[k]], repr(float(cols["x_m"][k])), int(cols["count"][k]), bool(cols["flag"][k])])
    got = list(csv.reader(io.StringIO((tmp_path / "t.csv").read_text(encoding="utf-8"))))
    ref = list(csv.reader(io.StringIO(buf.getvalue())))
    assert len(got) == len(ref) == n + 1 and got[0] == ref[0]
    for a, b in zip(got[1:], ref[1:]):
        assert a[0] == b[0] and a[2:] == b[2:]
        assert repr(float(a[1])) == b[1]                          # shortest text, the same float


def test_keyed_rows_as_a_mapping_and_bad_tables():
    t = JsonKeyedRows(("a", "b"), {"x": np.array([1.0, 2.0]), "m": np.eye(2)})
    assert dict(t) == {"a": {"x": 1.0, "m": [1.0, 0.0]}, "b": {"x": 2.0, "m": [0.0, 1.0]}}
    assert len(t) == 2 and "a" in t and list(t) == ["a", "b"]
    with pytest.raises(ValueError, match="not distinct"):
        JsonKeyedRows(("a", "a"), {"x": np.zeros(2)})
    with pytest.raises(ValueError, match="2 keys for 3 rows"):
        JsonKeyedRows(("a", "b"), {"x": np.zeros(3)})
    with pytest.raises(ValueError, match="numeric"):
        JsonRows({"x": np.array(["s"])})
    assert dumps_json({"t": JsonKeyedRows((), {})}, indent=False) == b'{"t":{}}\n'


@pytest.mark.parametrize("labels", [["T1", "T2", "é-3", "", "a b"], ["T1", 'q"t', "c,d"], ["a\nb", "x"],
                                    ["nul\x00in", "y"], [], ["only"]])
def test_csv_label_fields_equal_the_csv_module(labels):
    # the fast path (no label needs quoting: one join and split) and the per-label path give the
    # field the csv module writes in a row of several fields
    def field(x):
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow([x, ""])
        return buf.getvalue()[:-2].encode()

    assert RT._label_texts(labels, "csv", None) == [field(x) for x in labels]
