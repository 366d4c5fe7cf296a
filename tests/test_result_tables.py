"""The per-point tables of ``adjust --out``: one definition (:func:`network.files.result_tables`) written
as CSV or Parquet.

Independent values: the row-by-row CSV writer as the tables were written before (stations.csv byte
for byte, reference lengths with an empty σ cell), and the CSV itself for the Parquet files: every
cell equal (floats bit for bit, labels, booleans, null where the CSV cell is empty), read back by
pyarrow. The CLI: ``--tables parquet`` writes .parquet files; a wrong or orphan ``--tables`` is one
line on stderr, exit 2, no directory.
"""

import csv
from pathlib import Path

import numpy as np
import pytest

from multilat.cli import main
from multilat.io import write_csv_atomic
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.io.files import read_observations, read_points, read_reference_lengths, write_result_tables

EX = Path(__file__).resolve().parents[1] / "examples" / "network"
OBS, REF, PTS = EX / "small_volume_obs.csv", EX / "small_volume_refs.csv", EX / "small_volume_points.csv"


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    # one reference length without its uncertainty: an empty cell, a null
    text = REF.read_text().splitlines()
    text[2] = ",".join(text[2].split(",")[:3]) + ","
    ref = tmp_path_factory.mktemp("refs") / "refs.csv"
    ref.write_text("\n".join(text) + "\n")
    refs = read_reference_lengths(ref)
    res = adjust(read_observations(OBS), points=read_points(PTS), datum="321:B,D,C")
    return res, refs


def _cells(path):
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.reader(f))


def test_stations_and_reference_tables_are_the_rows_written_before(tmp_path, result):
    res, refs = result
    write_result_tables(res, tmp_path, references=refs)
    (s_ax, _), _ = res.ellipsoids()
    write_csv_atomic(tmp_path / "old_s.csv", ["station", "x_m", "y_m", "z_m", "offset_m", "x_std_m", "y_std_m", "z_std_m",
                                              "offset_std_m", "offset_estimated", "semi_axis_1_95_m", "semi_axis_2_95_m",
                                              "semi_axis_3_95_m", "head"],
                     [[sid, *res.station_xyz_m[i], res.offset_m[i], *np.sqrt(np.clip(np.diag(res.station_cov_m2[i]), 0, None)),
                       res.offset_std_m[i], bool(res.offset_estimated[i]), *s_ax[i][::-1], res.obs.head_of_station[i]]
                      for i, sid in enumerate(res.station_ids)])
    assert (tmp_path / "stations.csv").read_bytes() == (tmp_path / "old_s.csv").read_bytes()
    write_csv_atomic(tmp_path / "old_r.csv", ["target_a", "target_b", "length_m", "length_std_m", "reference_m",
                                              "reference_std_m", "difference_m"],
                     [[c.target_a, c.target_b, c.length_m, c.u_m, c.reference_m,
                       "" if c.reference_u_m is None else c.reference_u_m, c.difference_m]
                      for c in res.compare_references(refs)])
    assert (tmp_path / "reference_lengths.csv").read_bytes() == (tmp_path / "old_r.csv").read_bytes()


def test_parquet_tables_hold_the_csv_cells(tmp_path, result):
    pq = pytest.importorskip("pyarrow.parquet")
    res, refs = result
    from dataclasses import replace

    used = res.used.copy()
    used[7] = False                                               # a rejected row: a True cell
    res = replace(res, used=used)
    c_dir, p_dir = tmp_path / "c", tmp_path / "p"
    c_dir.mkdir()
    p_dir.mkdir()
    written = write_result_tables(res, c_dir, references=refs)
    assert [p.name for p in write_result_tables(res, p_dir, references=refs, fmt="parquet")] == \
        [p.with_suffix(".parquet").name for p in written]
    for p in written:
        rows = _cells(p)
        table = pq.read_table(p_dir / p.with_suffix(".parquet").name)
        assert table.column_names == rows[0], p.name
        assert table.num_rows == len(rows) - 1
        for j, name in enumerate(rows[0]):
            got = table.column(name).to_pylist()
            for cell, v in zip((r[j] for r in rows[1:]), got):
                if v is None:
                    assert cell == "", (p.name, name)
                elif isinstance(v, bool):
                    assert cell == str(v), (p.name, name)
                elif isinstance(v, float):
                    assert float(cell) == v and repr(float(cell)) == repr(v), (p.name, name, cell, v)
                else:
                    assert cell == str(v), (p.name, name)
    assert pq.read_table(p_dir / "reference_lengths.parquet").column("reference_std_m").null_count == 1
    assert _cells(c_dir / "reference_lengths.csv")[1][5] == ""


def test_cli_tables_option(capsys, tmp_path):
    pytest.importorskip("pyarrow.parquet")
    out = tmp_path / "out"
    rc = main(["adjust", str(OBS), "--points", str(PTS), "--datum", "321:B,D,C", "--references", str(REF),
               "--out", str(out), "--tables", "parquet"])
    assert rc == 0, capsys.readouterr().err
    names = {p.name for p in out.iterdir()}
    assert {"stations.parquet", "targets.parquet", "observations.parquet", "reference_lengths.parquet",
            "result.json", "residuals.png"} <= names and not any(n.endswith(".csv") for n in names)
    # the same directory again (an earlier output) is accepted
    assert main(["adjust", str(OBS), "--out", str(out), "--tables", "parquet"]) == 0
    capsys.readouterr()
    for args, msg in ((["--tables", "xlsx", "--out", str(tmp_path / "x")], "--tables must be one of auto, csv, parquet"),
                      (["--tables", "parquet"], "--tables applies to the files of --out")):
        rc = main(["adjust", str(OBS), *args])
        err = capsys.readouterr().err
        assert rc == 2 and msg in err and len(err.strip().splitlines()) == 1
        assert not (tmp_path / "x").exists()
