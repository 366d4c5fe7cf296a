"""The CLI shell: usage errors give one line and exit 2; io helpers write whole or nothing."""

import json

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.io import atomic_path, read_csv_table, to_jsonable, write_csv_atomic


def test_unknown_command_is_one_line_error(capsys):
    assert main(["no-such-command"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:")


def test_atomic_path_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.csv"
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise KeyboardInterrupt
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []


def test_csv_roundtrip_and_row_errors(tmp_path):
    p = tmp_path / "a.csv"
    write_csv_atomic(p, ["station", "target", "distance_m"], [["A", "1", 1.25], ["B", "1", 2.5]])
    t = read_csv_table(p, required=["station", "target", "distance_m"])
    np.testing.assert_array_equal(t.floats("distance_m"), [1.25, 2.5])
    p.write_text("station,target,distance_m\nA,1,1.0\nB,1,nan\n")
    with pytest.raises(MultilatError, match=r"a.csv:3: column 'distance_m'"):
        read_csv_table(p, required=["station", "target", "distance_m"]).floats("distance_m")
    p.write_text("station,target\nA,1\n")
    with pytest.raises(MultilatError, match="lacks column"):
        read_csv_table(p, required=["station", "target", "distance_m"])


def test_to_jsonable_handles_numpy():
    out = json.loads(json.dumps(to_jsonable({"a": np.arange(3.0), "b": np.float32(1.5), "c": np.nan})))
    assert out == {"a": [0.0, 1.0, 2.0], "b": 1.5, "c": None}


def test_atomic_file_gets_umask_permissions(tmp_path):
    import os

    p = tmp_path / "x.txt"
    from multilat.io import write_text_atomic

    write_text_atomic(p, "ok")
    umask = os.umask(0)
    os.umask(umask)
    assert (p.stat().st_mode & 0o777) == (0o666 & ~umask)


def test_unwritable_output_path_is_one_line_exit_2(tmp_path, capsys):
    """An --out under an ordinary file (NotADirectoryError/FileExistsError): one line, exit 2."""
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    rc = main(["lbb", "simulate", "--grid", "2", "--trials", "5", "--out", str(blocker / "sub")])
    err = capsys.readouterr().err
    assert rc == 2, err
    err = err.strip()  # a transient progress bar may leave a blank line
    assert err.startswith("error: ") and len(err.splitlines()) == 1 and "Traceback" not in err
