"""The general path's output follows the distance path's ``multilat.adjust/2`` decision (schema
``multilat.adjust-general/2``, issue 29): the JSON lists only the observations that matter with
``observation_counts``, every row goes to the ``observations`` table under ``--out`` (``--tables``)
with its row count and sha256 in ``result.json``; ``--observations`` lists every row. The back end
(``--backend``) and what it left out (``not_computed``) are said; the size is checked with the chosen
back end before the approximate coordinates; ``--model auto`` measures a network against the limit of
the back end that would run.

Independent values: the rule is re-applied here to the full listing with the distance path's
thresholds (:data:`multilat.network.adjust.distance.reliability.R_MIN`, ``MDB_LIMIT_SIGMA``); the table is read back
with the csv module and compared with the ``--observations`` rows, its sha256 with hashlib's; the
sparse back end against the dense one (two factorisations: 1e-9 m).
"""

from __future__ import annotations

import csv
import hashlib
import importlib
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples" / "general"
COUNT_KEYS = ["n_obs", "n_used", "n_rejected", "n_w_failed", "n_poorly_controlled", "n_flagged", "n_excluded",
              "n_listed", "listing"]       # multilat.adjust/2's observation_counts, in its order


def _main(capsys, *args):
    rc = main(["adjust", *map(str, args)])
    out = capsys.readouterr()
    return rc, out.out, out.err


def _doc(capsys, *args):
    rc, out, err = _main(capsys, *args)
    assert rc == 0, err
    return json.loads(out)


def _blunder(tmp: Path) -> Path:
    """two_trackers_csv with a 2 mm blunder in its 5th distance (σ 10 µm): one rejection."""
    lines = (EX / "two_trackers_csv" / "obs.csv").read_text().splitlines()
    cols = lines[5].split(",")
    cols[2] = f"{float(cols[2]) + 2e-3:.9f}"
    lines[5] = ",".join(cols)
    (tmp / "blunder.csv").write_text("\n".join(lines) + "\n")
    return tmp / "blunder.csv"


def _matters(o) -> bool:
    from multilat.network.adjust.distance.reliability import MDB_LIMIT_SIGMA, R_MIN

    return (not o["passed"] or o["redundancy"] < R_MIN or o["mdb_sigma"] is None
            or o["mdb_sigma"] > MDB_LIMIT_SIGMA)


def test_json_lists_the_rows_that_matter(capsys):
    """adjust-general/2: the rows that matter, with the distance path's keys; every row with --observations."""
    xml = EX / "two_trackers.xml"
    few = _doc(capsys, xml, "--json")
    every = _doc(capsys, xml, "--json", "--observations")
    assert few["schema"] == every["schema"] == "multilat.adjust-general/3"
    full = every["observations"]
    assert len(full) == every["n_obs"] == 90 and [o["index"] for o in full] == list(range(90))
    expect = [o["index"] for o in full if _matters(o)]
    assert 0 < len(expect) < len(full)                                  # the rule selects, on this network
    assert [o["index"] for o in few["observations"]] == expect
    assert few["observations"] == [full[k] for k in expect]
    c, ca = few["observation_counts"], every["observation_counts"]
    assert list(c) == COUNT_KEYS
    assert c == {"n_obs": 90, "n_used": 90, "n_rejected": 0, "n_w_failed": sum(not o["passed"] for o in full),
                 "n_poorly_controlled": len(expect), "n_flagged": len(expect), "n_excluded": 0,
                 "n_listed": len(expect), "listing": "flagged"}
    assert ca == {**c, "n_listed": 90, "listing": "all"}
    # the distance path's document has the same counts' keys (one vocabulary)
    d = _doc(capsys, ROOT / "examples" / "network" / "mixed" / "obs.csv", "--model", "multilateration", "--json")
    assert list(d["observation_counts"]) == COUNT_KEYS


def test_a_rejected_row_is_listed_and_counted(capsys, tmp_path):
    """A row rejected by data snooping is in the listing (flag ``rejected``) and in ``outliers``; the
    rows adjusted are ``n_used``."""
    doc = _doc(capsys, _blunder(tmp_path), "--levelled", "T1,T2", "--model", "general", "--json")
    out = doc["outliers"]
    assert len(out) == 1 and out[0]["kind"] == "slope_distance"
    rej = [o for o in doc["observations"] if o["rejected"]]
    assert len(rej) == 1 and rej[0]["label"] == out[0]["label"] and rej[0]["residual"] == out[0]["residual"]
    c = doc["observation_counts"]
    assert c["n_rejected"] == 1 and c["n_used"] == doc["n_obs"] and c["n_obs"] == doc["n_obs"] + 1
    assert rej[0]["index"] == doc["n_obs"] == out[0]["index"]          # after the adjusted rows in the table


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_out_writes_every_row_to_the_table(capsys, tmp_path, fmt):
    if fmt == "parquet":
        pytest.importorskip("pyarrow")
    out = tmp_path / "res"
    xml = EX / "two_trackers.xml"
    doc = _doc(capsys, xml, "--json", "--out", out, "--tables", fmt)
    every = _doc(capsys, xml, "--json", "--observations")["observations"]
    assert sorted(p.name for p in out.iterdir()) == [f"observations.{fmt}", "points.csv", "result.json"]
    assert json.loads((out / "result.json").read_text()) == doc
    (rec,) = doc["tables"]
    path = out / rec["file"]
    assert rec == {"name": "observations", "file": f"observations.{fmt}", "format": fmt, "n_rows": 90,
                   "sha256": hashlib.sha256(path.read_bytes()).hexdigest()}
    if fmt == "csv":
        rows = list(csv.DictReader(path.open()))
    else:
        import pyarrow.parquet as pq

        rows = pq.read_table(path).to_pylist()
    assert len(rows) == len(every)
    for r, o in zip(rows, every):
        assert int(r["index"]) == o["index"] and r["kind"] == o["kind"] and r["label"] == o["label"]
        for key in ("value", "sigma", "residual", "redundancy", "w", "mdb"):
            assert float(r[key]) == o[key], key                           # repr round trip: exact
        assert str(r["poorly_controlled"]) == str(o["poorly_controlled"])


def test_tables_auto_and_refusals(capsys, tmp_path):
    from multilat.network.io.files import table_format

    out = tmp_path / "a"
    doc = _doc(capsys, EX / "station_control.xml", "--json", "--out", out)
    assert doc["tables"][0]["format"] == table_format("observations", "auto")
    rc, _, err = _main(capsys, EX / "station_control.xml", "--json", "--tables", "parquet")
    assert rc == 2 and err == "error: --tables applies to the files of --out: give --out DIR\n"
    rc, _, err = _main(capsys, EX / "station_control.xml", "--out", tmp_path / "b", "--tables", "xlsx")
    assert rc == 2 and err.startswith("error: --tables must be one of auto") and not (tmp_path / "b").exists()


def test_backend_option(capsys):
    """--backend sparse gives the dense solution (1e-9 m: two factorisations of the same system) and
    says which ran; a wrong name, or --backend on the distance path, is refused in one line."""
    xml = EX / "two_trackers.xml"
    dense = _doc(capsys, xml, "--json", "--backend", "dense")
    sparse = _doc(capsys, xml, "--json", "--backend", "sparse")
    assert (dense["backend"], sparse["backend"]) == ("dense", "sparse")
    assert dense["not_computed"] == sparse["not_computed"] == []
    for p, v in dense["points"].items():
        np.testing.assert_allclose(sparse["points"][p]["xyz_m"], v["xyz_m"], rtol=0, atol=1e-9)
    assert sparse["sigma0"] == pytest.approx(dense["sigma0"], rel=1e-9)
    rc, _, err = _main(capsys, xml, "--json", "--backend", "fast")
    assert rc == 2 and err == "error: --backend must be one of auto, dense, sparse, got 'fast'\n"
    net = ROOT / "examples" / "network" / "mixed" / "obs.csv"
    rc, _, err = _main(capsys, net, "--model", "multilateration", "--backend", "sparse")
    assert rc == 2 and err.startswith("error: --backend applies to the general model") and err.count("\n") == 1


def test_not_computed_is_said(capsys, monkeypatch):
    """The sparse back end above its work bound leaves external reliability out: the JSON says so
    (``not_computed``, ``external_reliability.computed`` false, its shifts null) and the summary in one
    line."""
    general_adjust = importlib.import_module("multilat.network.adjust.general.adjust")   # the package exports adjust()
    monkeypatch.setattr(general_adjust, "EXTERNAL_MAX_WORK", 0.0)
    xml = EX / "two_trackers.xml"
    doc = _doc(capsys, xml, "--json", "--backend", "sparse", "--observations")
    assert doc["backend"] == "sparse" and doc["not_computed"] == ["external reliability"]
    assert doc["external_reliability"]["computed"] is False
    assert all(o["shift_max_m"] is None for o in doc["observations"])
    rc, out, err = _main(capsys, xml, "--backend", "sparse")
    assert rc == 0, err
    lines = [ln for ln in out.splitlines() if "not computed" in ln]
    assert len(lines) == 1 and "external reliability" in lines[0] and "sparse back end" in lines[0]


def test_size_checked_with_the_chosen_backend_before_approximations(monkeypatch):
    """adjust_network refuses a network above the dense limit when dense is forced before computing
    any approximate coordinates (never an hour of approximations to be refused after)."""
    from multilat.network.adjust.general import read_gama_input

    general_adjust = importlib.import_module("multilat.network.adjust.general.adjust")
    general_run = importlib.import_module("multilat.network.adjust.general.run")
    from multilat.network.adjust.general.adjust import AdjustOptions

    net = read_gama_input(EX / "two_trackers.xml")
    n = general_adjust.System(net).n_free
    monkeypatch.setattr(general_adjust, "MAX_DENSE_UNKNOWNS", n - 1)
    monkeypatch.setattr(general_adjust, "SPARSE_ABOVE", n - 1)     # auto would take the sparse one

    def approximate(_):
        raise AssertionError("approximate coordinates computed before the size check")

    monkeypatch.setattr(general_run, "approximate", approximate)
    with pytest.raises(MultilatError, match=f"dense back end takes at most {n - 1} unknowns"):
        general_run.adjust_network(net, options=AdjustOptions(backend="dense"))


def _tracker_obs(n_stations: int, n_targets: int):
    """The counts :func:`multilat.cli.general_adjust._general_takes` reads, for a tracker network with
    angles (every station reads azimuths)."""
    m = n_stations * n_targets
    return SimpleNamespace(n_stations=n_stations, n_targets=n_targets, head_ids=tuple(f"H{i}" for i in range(n_stations)),
                           station_index=np.repeat(np.arange(n_stations), n_targets),
                           sigma_azimuth_rad=np.full(m, 1e-5))


def test_auto_measures_against_the_backend_that_runs():
    """4 trackers x 1000 targets: 3016 unknowns, above the dense limit (2000), a reduced system of 28
    (the targets eliminated): the general path takes it; with --backend dense it does not; 1100
    stations leave a reduced system above sparse.MAX_REDUCED."""
    from multilat.cli.general_adjust import _general_takes
    from multilat.network.adjust.general.adjust import MAX_DENSE_UNKNOWNS
    from multilat.network.adjust.general.sparse import MAX_REDUCED

    big = _tracker_obs(4, 1000)
    assert 3 * 1004 + 4 + 12 > MAX_DENSE_UNKNOWNS
    assert _general_takes(big, "auto") and _general_takes(big, "sparse")
    assert not _general_takes(big, "dense")
    assert _general_takes(_tracker_obs(4, 100), "dense")
    many = _tracker_obs(MAX_REDUCED // 6 + 1, 3)                        # 7 unknowns per station stay
    assert not _general_takes(many, "auto")


def test_python_listing_refuses_an_unknown_listing():
    from multilat.network.adjust.general.report import list_observations

    with pytest.raises(MultilatError, match="observations listing must be 'flagged' or 'all'"):
        list_observations({"observations": [], "outliers": [], "excluded": []}, "some")


def test_observations_does_not_keep_auto_off_the_general_path(capsys, tmp_path):
    """--model auto with --observations: polar points the distance path would leave out still take the
    general path (--observations applies there), every row listed."""
    from test_general_csv import heads_tracker_polar

    case = heads_tracker_polar(np.random.default_rng(11)).simulate(np.random.default_rng(12))
    args = case.write(tmp_path)
    rc, out, err = _main(capsys, *args, "--json", "--observations")
    assert rc == 0 and "adjusted by the general model" in err, err
    doc = json.loads(out)
    assert doc["model"] == "general" and doc["notes"][0].startswith("--model auto")
    c = doc["observation_counts"]
    assert c["listing"] == "all" and len(doc["observations"]) == c["n_listed"] == c["n_obs"] == doc["n_obs"]
