"""Outputs written whole or not at all: staged --out directories replaced whole, inputs never
overwritten, all-or-nothing file sets, full disks, SIGTERM, closed pipes, named pipes."""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import threading
import time

import pytest

from conftest import CLI, cli_env, snapshot
from multilat.errors import MultilatError
from multilat.io import staging_dir


def _no_parts(d):
    assert not [p for p in d.rglob("*") if ".part" in p.name or p.name.endswith(".old")]


def test_adjust_twice_leaves_no_stale_file(ws):
    out = ws / "res"
    rc, _, err = ws.run(["adjust", "{d}/obs.csv", "--references", "{d}/refs.csv", "--out", out])
    assert rc == 0, err and (out / "reference_lengths.csv").exists()
    rc, _, err = ws.run(["adjust", "{d}/obs.csv", "--out", out])
    assert rc == 0, err
    assert not (out / "reference_lengths.csv").exists()       # the first run's file is gone
    assert (out / "stations.csv").exists()
    _no_parts(ws.path)


def test_out_foreign_directory_refused(ws):
    out = ws / "mine"
    out.mkdir()
    (out / "thesis.tex").write_text("precious")
    ws.fails(["adjust", "{d}/obs.csv", "--out", out], "thesis.tex")


def test_out_holding_the_input_refused(ws):
    ws.fails(["adjust", "{d}/obs.csv", "--out", "{d}"], "obs.csv")


def test_out_is_a_file(ws):
    ws.fails(["propagate", "small-volume", "--trials", "100", "--out", "{d}/obs.csv"], "obs.csv")


def test_propagate_out_with_a_directory_in_the_way(ws):
    out = ws / "res"
    (out / "summary.json").mkdir(parents=True)
    ws.fails(["propagate", "small-volume", "--trials", "100", "--noise", "gaussian", "--out", out],
             "summary.json")


def test_lbb_simulate_out_foreign(ws):
    (ws / "o").mkdir()
    (ws / "o" / "notes.txt").write_text("x")
    ws.fails(["lbb", "simulate", "--grid", "3", "--trials", "2", "--out", "{d}/o"], "notes.txt")


@pytest.mark.parametrize("opt", ["--out", "--cov", "--plot"])
def test_correct_never_overwrites_its_input(ws, opt):
    ws.fails(["correct", "{d}/raw.csv", "-e", "{d}/env.csv", "--heights", "{d}/heights.csv", opt, "{d}/raw.csv"], "raw.csv")


def test_correct_output_over_environment_refused(ws):
    ws.fails(["correct", "{d}/raw.csv", "-e", "{d}/env.csv", "--heights", "{d}/heights.csv", "--out", "{d}/env.csv"], "env.csv")


def test_correct_same_file_twice_refused(ws):
    ws.fails(["correct", "{d}/raw.csv", "-e", "{d}/env.csv", "--heights", "{d}/heights.csv", "--out", "{d}/a.csv", "--cov", "{d}/a.csv"],
             "a.csv")


def test_correct_cov_and_out_all_or_nothing(ws):
    (ws / "b.csv").mkdir()                      # --out cannot be written: --cov must not appear either
    ws.fails(["correct", "{d}/raw.csv", "-e", "{d}/env.csv", "--heights", "{d}/heights.csv", "--cov", "{d}/a.csv", "--out", "{d}/b.csv"],
             "b.csv")
    assert not (ws / "a.csv").exists()


def test_correct_writes_both(ws):
    rc, _, err = ws.run(["correct", "{d}/raw.csv", "-e", "{d}/env.csv", "--heights", "{d}/heights.csv", "--cov", "{d}/a.csv",
                         "--out", "{d}/b.csv", "--json"])
    assert rc == 0, err and (ws / "a.csv").exists() and (ws / "b.csv").exists()
    _no_parts(ws.path)


def test_full_disk_names_the_output_not_the_temporary(ws, monkeypatch):
    real = os.replace

    def full(src, dst, *a, **k):
        if str(dst).endswith("b.csv"):
            raise OSError(errno.ENOSPC, "No space left on device", str(src))
        return real(src, dst, *a, **k)

    monkeypatch.setattr(os, "replace", full)
    line = ws.fails(["correct", "{d}/raw.csv", "-e", "{d}/env.csv", "--heights", "{d}/heights.csv", "--out", "{d}/b.csv"],
                    "b.csv", "No space left")
    assert ".b.csv." not in line


def test_full_disk_during_staged_out(ws, monkeypatch):
    import matplotlib.figure

    def full(self, fname, *a, **k):
        raise OSError(errno.ENOSPC, "No space left on device", str(fname))

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", full)
    line = ws.fails(["adjust", "{d}/obs.csv", "--out", "{d}/res"], "res", "No space left")
    assert ".part" not in line


def test_unwritable_out_parent(ws):
    ws.fails(["adjust", "{d}/obs.csv", "--out", "{d}/obs.csv/sub"], "obs.csv")


def test_interleaved_staging_never_mixes(tmp_path):
    """Two writers of one --out: the later commit wins whole; no file of the other survives."""
    out = tmp_path / "o"
    with staging_dir(out) as a:
        (a / "stations.csv").write_text("a")
        (a / "reference_lengths.csv").write_text("a")
        with staging_dir(out) as b:
            (b / "stations.csv").write_text("b")
        assert sorted(p.name for p in out.iterdir()) == ["stations.csv"]
    assert sorted(p.name for p in out.iterdir()) == ["reference_lengths.csv", "stations.csv"]
    assert (out / "stations.csv").read_text() == "a"
    _no_parts(tmp_path)


def test_staging_error_keeps_previous_results(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "summary.json").write_text("old")
    with pytest.raises(MultilatError):
        with staging_dir(out) as t:
            (t / "summary.json").write_text("new")
            raise MultilatError("boom")
    assert (out / "summary.json").read_text() == "old"
    _no_parts(tmp_path)


# ------------------------------------------------------------------ subprocess: signals and pipes

SLOW_FIGURES = """
import time, multilat.report.network_figures as nf
real = nf.save_figures
def slow(res, out):
    (out / "residuals.png").write_bytes(b"half a PNG")
    print("READY", flush=True)
    time.sleep(60)
nf.save_figures = slow
from multilat.cli import run
run()
"""


def test_sigterm_during_adjust_out_leaves_nothing(ws):
    out = ws / "res"
    p = subprocess.Popen([CLI[0], "-c", SLOW_FIGURES, "adjust", str(ws / "obs.csv"), "--out", str(out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=cli_env(), text=True)
    try:
        line = p.stdout.readline()
        assert "READY" in line, p.stderr.read()
        p.send_signal(signal.SIGTERM)
        rc = p.wait(timeout=30)
    finally:
        p.kill()
    err = p.stderr.read()
    assert rc == 143, err
    assert "terminated" in err and "Traceback" not in err
    assert not out.exists()
    _no_parts(ws.path)


def test_closed_stdout_exits_141_quietly(ws):
    p = subprocess.Popen(CLI + ["adjust", str(ws / "obs.csv"), "--json"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, env=cli_env())
    p.stdout.close()                            # the reader leaves before the first byte
    rc = p.wait(timeout=60)
    err = p.stderr.read().decode()
    assert rc == 141, err
    assert err.strip() == ""


def test_named_pipe_input_is_opened_once(ws):
    fifo = ws / "obs.fifo"
    os.mkfifo(fifo)
    data = (ws / "obs.csv").read_bytes()

    def writer():
        with open(fifo, "wb") as f:
            f.write(data)

    t = threading.Thread(target=writer, daemon=True)
    t.start()
    p = subprocess.run(CLI + ["adjust", str(fifo), "--json"], capture_output=True, env=cli_env(),
                       timeout=60, text=True)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["n_obs"] == 56


def test_inputs_untouched_after_success(ws):
    before = snapshot(ws.path)
    rc, _, err = ws.run(["adjust", "{d}/obs.csv", "--references", "{d}/refs.csv", "--out", "{d}/res"])
    assert rc == 0, err
    after = snapshot(ws.path)
    assert {k: v for k, v in after.items() if not k.startswith("res")} == before
    assert time.time()  # the run is bounded by the CLI itself


def test_concurrent_writers_of_one_out(ws):
    """Two `adjust --out res` at once: whatever the interleaving, res holds one whole set of files
    (the other run finishes or gives one error line), and no staging directory is left."""
    out = ws / "res"
    procs = [subprocess.Popen(CLI + ["adjust", str(ws / "obs.csv"), "--out", str(out)] + extra,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=cli_env(), text=True)
             for extra in ([], ["--references", str(ws / "refs.csv")])]
    results = [(p.wait(timeout=120), p.stderr.read()) for p in procs]
    assert any(rc == 0 for rc, _ in results), results
    for rc, err in results:
        assert rc in (0, 2), err
        if rc == 2:
            assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    names = sorted(p.name for p in out.iterdir())
    from multilat.network.io.files import table_format

    base = sorted([f"observations.{table_format('observations', 'auto')}", "residuals.png", "result.json",
                   "stations.csv", "targets.csv", "top_view.png", "view_3d.png"])
    assert names in (base, sorted(base + ["reference_lengths.csv"]))
    _no_parts(ws.path)


def test_out_is_the_working_directory(ws, monkeypatch):
    empty = ws / "empty"
    empty.mkdir()
    monkeypatch.chdir(empty)
    ws.fails(["adjust", "{d}/obs.csv", "--out", "."], "--out")
