"""The general document's observation rows are built from the statistics arrays (issue 29): ``to_json``
does not build one dict per row, ``list_observations`` builds dicts only for the rows the JSON lists.

Independent value: the per-row builder itself (``report._row``, one row at a time from the blocks and
statistics); the table read from the arrays must equal its dicts key by key, type by type.
"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NET = ROOT / "examples" / "general" / "two_trackers.xml"       # 90 rows: tracker angles, distances


def _adjusted():
    from multilat.network.adjust.general import adjust_network, read_gama_input, statistics

    adj = adjust_network(read_gama_input(NET))
    return adj, statistics(adj.system, adj.result)


def test_no_row_dict_for_the_rows_the_json_does_not_list(monkeypatch):
    from multilat.network.adjust.general import report

    adj, stats = _adjusted()
    calls = []
    real = report._row
    monkeypatch.setattr(report, "_row", lambda *a: calls.append(a[2]) or real(*a))
    doc = report.to_json(adj, stats, source="x")
    listed = report.list_observations(doc, "flagged")
    n_rows = adj.system.n_rows
    assert 0 < listed["observation_counts"]["n_listed"] < n_rows      # the listing leaves rows out
    # only external_reliability's largest shifts are built as rows (not every row of the system)
    assert len(calls) <= report.WORST_SHIFTS < n_rows


def test_table_from_the_arrays_equals_the_row_dicts():
    from multilat.network.adjust.general import report

    adj, stats = _adjusted()
    doc = report.to_json(adj, stats, source="x")
    rows = [report.row_record(adj.system, stats, i) for i in range(adj.system.n_rows)]   # one at a time
    assert list(doc["observations"]) == rows
    cols = report.observation_table(doc)
    for key in report.TABLE_KEYS:
        assert [type(v) for v in cols[key]] == [type(o.get(key)) for o in rows], key
        assert cols[key] == [o.get(key) for o in rows], key
    listed = report.list_observations(doc, "all")["observations"]
    assert [{k: v for k, v in o.items() if k in report.TABLE_KEYS} for o in listed] == rows
