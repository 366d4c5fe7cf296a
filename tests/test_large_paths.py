"""The shortcuts that keep ``adjust`` on 1.6 M distances fast (issue 29), each against an independent
value: Python's own sorting and ``statistics.median`` on random data with ties (so the order of equal
values matters wherever it could), the values written read back from the Parquet file bit for bit,
and the probe of the fast CSV reader run with the compiled text kernels made unavailable."""

import statistics

import numpy as np
import pytest

from multilat.network.adjust.distance import ambiguity
from multilat.network.io import fastio, result_rows, screening


def test_pair_codes_are_the_sorted_distinct_pairs():
    rng = np.random.default_rng(29)
    for m in (0, 1, 7, 500):
        si, ti = rng.integers(0, 4, m), rng.integers(0, 9, m)
        want = sorted({int(s) * 9 + int(t) for s, t in zip(si, ti)})
        assert ambiguity._pair_codes(si, ti, 9).tolist() == want


def test_group_medians_match_statistics_median():
    rng = np.random.default_rng(7)
    for m in (1, 2, 9, 400):
        values = rng.integers(0, 5, m).astype(float) * 0.25 + 1.0          # many ties
        groups = rng.integers(0, 6, m)
        med = screening._group_medians(values, groups, 8)
        for g in range(8):
            members = values[groups == g].tolist()
            if members:
                assert med[g] == statistics.median(members)      # exact: a mean of two quarter-multiples
            else:
                assert np.isnan(med[g])


def test_largest_w_is_the_stable_order_of_abs_w():
    rng = np.random.default_rng(11)
    for _ in range(200):
        m = int(rng.integers(0, 30))
        w = rng.integers(-3, 4, m).astype(float)
        w[rng.random(m) < 0.2] = np.nan       # a NaN ranks as |w| = 1 (|nan_to_num(w, nan=-1)|, as before)
        n = int(rng.integers(0, 12))
        key = [(-(1.0 if np.isnan(x) else abs(x)), k) for k, x in enumerate(w)]
        want = [k for _, k in sorted(key)[:n]]
        got = [r["index"] for r in result_rows.largest_w({"index": np.arange(m), "w": w}, n)]
        assert got == want


def test_probe_does_not_need_the_compiled_kernels(tmp_path, monkeypatch):
    # the probe of the first 64 KB parses with numpy's cast: loading the kernels cost 1-2 s before
    # the Arrow path, which never uses them
    import multilat.rows_text as rows_text

    def refuse():
        raise AssertionError("the probe loaded the compiled text kernels")

    monkeypatch.setattr(rows_text, "text_kernels", refuse)
    p = tmp_path / "obs.csv"
    p.write_text("station,target,distance_m,sigma_m\n" + "".join(f"S{k % 3},T{k},{1.5 + k * 1e-3:.9f},5e-06\n"
                                                                 for k in range(2000)))
    assert fastio._probe(p, 4, None, 32, 32) is True
    bad = tmp_path / "bad.csv"
    bad.write_text("station,target,distance_m,sigma_m\nS1,T1,abc,5e-06\n")
    assert fastio._probe(bad, 4, None, 32, 32) is False


def test_parquet_floats_plain_labels_dictionary(tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    from multilat.io import write_table_atomic

    rng = np.random.default_rng(3)
    n = 5000
    x = rng.normal(size=n)
    x[::97] = np.nan
    cols = {"index": np.arange(n), "station": (("S1", "S2"), rng.integers(0, 2, n)), "x_m": x,
            "flag": rng.random(n) < 0.5}
    path = write_table_atomic(tmp_path / "t", cols, "parquet")
    tab = pq.read_table(path)
    assert np.array_equal(tab.column("x_m").to_numpy().view(np.int64), x.view(np.int64))    # bit for bit
    assert tab.column("station").to_pylist() == [("S1", "S2")[k] for k in cols["station"][1]]
    assert tab.column("flag").to_pylist() == cols["flag"].tolist()
    meta = pq.ParquetFile(path).metadata.row_group(0)
    enc = {meta.column(i).path_in_schema: meta.column(i).encodings for i in range(meta.num_columns)}
    assert any("DICTIONARY" in e for e in enc["station"])
    assert not any("DICTIONARY" in e for e in enc["x_m"] + enc["index"])     # no wasted dictionary page


def test_reading_an_input_reserves_its_size_not_the_limit(tmp_path):
    """read(n) reserves n bytes up front: reading a 50 kB file must not reserve the 2 GB input limit
    (fatal on a machine without memory overcommit); a file read whole is returned whole."""
    import tracemalloc

    from multilat.inputs import read_input_bytes

    f = tmp_path / "obs.csv"
    body = b"station,target,distance_m\n" + b"".join(b"S%d,T%d,1.5\n" % (i % 4, i) for i in range(4000))
    f.write_bytes(body)
    tracemalloc.start()
    try:
        data = read_input_bytes(f)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert data == body
    assert peak < 20 * len(body), f"reading {len(body)} bytes reserved {peak} bytes"
