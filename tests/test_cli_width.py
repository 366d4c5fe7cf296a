"""Summaries fit an 80-column terminal and never cut a number (issue 13: ``-0.0000…``), and progress
shows on a terminal's stderr even with ``--json``."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from multilat.cli.app import console, main

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"
OBS = str(EX / "network" / "small_volume_obs.csv")


def _run(capsys, args):
    rc = main(args)
    out = capsys.readouterr()
    assert rc == 0, out.err
    return out.out


@pytest.fixture
def width80(monkeypatch):
    monkeypatch.setattr(console, "width", 80)


def _fits(text: str) -> None:
    lines = text.splitlines()
    assert max(len(s) for s in lines) <= 80, max(lines, key=len)
    assert "…" not in text


def test_adjust_summary_fits_80_columns_with_every_coordinate(capsys, width80):
    doc = json.loads(_run(capsys, ["adjust", OBS, "--json"]))
    text = _run(capsys, ["adjust", OBS])
    _fits(text)
    for sid, s in doc["stations"].items():
        for v in s["xyz_m"]:
            assert f"{v:.6f}" in text, (sid, v)
        assert f"{s['offset_m'] * 1e6:+.1f}" in text


def test_propagate_summary_fits_80_columns_with_every_u(capsys, width80):
    args = ["propagate", OBS, "--trials", "60", "--seed", "2"]
    doc = json.loads(_run(capsys, [*args, "--json"]))
    text = _run(capsys, args)
    _fits(text)
    for pid, p in doc["points"].items():
        for i in range(3):
            assert f"{math.sqrt(p['cov_mc_m2'][i][i]) * 1e6:.2f}" in text, pid


@pytest.mark.parametrize("args", [
    ["correct", str(EX / "campaign" / "raw.csv"), "-e", str(EX / "campaign" / "environment.csv"),
     "--heights", str(EX / "campaign" / "heights.csv")],
    ["lbb", "simulate", "--grid", "2", "--trials", "20"],
    ["budget", "--trials", "300", "--seed", "1"],
    ["simulate", "small-volume", "--trials", "3"],
])
def test_other_summaries_fit_80_columns(capsys, width80, args):
    _fits(_run(capsys, args))


def test_columns_env_80_in_a_real_process():
    env = dict(os.environ, COLUMNS="80", PYTHONPATH=str(ROOT / "src"))
    r = subprocess.run([sys.executable, "-c", "from multilat.cli import run; run()", "adjust", OBS],
                       capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 0, r.stderr
    _fits(r.stdout)
    assert "stations" in r.stdout


def test_long_ids_fold_instead_of_cutting_numbers(tmp_path, capsys, width80):
    """Station ids of 30 characters: the id column folds, the coordinates stay whole."""
    rows = [r for r in Path(OBS).read_text().splitlines() if not r.startswith("#")]
    head, body = rows[0], rows[1:]
    cols = head.split(",")
    si = cols.index("station")
    ren = []
    for r in body:
        c = r.split(",")
        c[si] = "station-with-a-very-long-name-" + c[si]
        ren.append(",".join(c))
    f = tmp_path / "obs.csv"
    f.write_text("\n".join([head, *ren]) + "\n")
    doc = json.loads(_run(capsys, ["adjust", str(f), "--json"]))
    text = _run(capsys, ["adjust", str(f)])
    assert "…" not in text
    table = text[text.index("stations"):]
    assert max(len(s) for s in table.splitlines()) <= 80
    assert "station-with-a" in table
    for s in doc["stations"].values():
        for v in s["xyz_m"]:
            assert f"{v:.6f}" in table
        u = s.get("offset_std_m", s.get("offset_std_m"))
        assert f"{s['offset_m'] * 1e6:+.1f}" in table and f"{u * 1e6:.1f}" in table
        # the last column (largest 95 % semi-axis) whole: a number with its decimal
        w = math.sqrt(7.814727903251178 * max(__import__("numpy").linalg.eigvalsh(s["cov_m2"])))
        assert f"{w * 1e6:.1f}" in table


def test_progress_on_a_terminal_stderr_with_json():
    """stderr a pseudo-terminal, stdout a pipe: the progress bar is drawn on the terminal and stdout
    is still pure JSON; with stderr a pipe nothing at all goes to stderr."""
    import pty

    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"), COLUMNS="100", TERM="xterm")
    env.pop("NO_COLOR", None)
    args = [sys.executable, "-c", "from multilat.cli import run; run()", "simulate", "small-volume",
            "--trials", "30", "--json"]
    master, slave = pty.openpty()
    try:
        p = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=slave, env=env)
        os.close(slave)
        chunks = []
        while True:
            try:
                b = os.read(master, 4096)
            except OSError:
                break
            if not b:
                break
            chunks.append(b)
        out, _ = p.communicate(timeout=300)
    finally:
        os.close(master)
    assert p.returncode == 0
    json.loads(out)
    assert "simulate" in b"".join(chunks).decode("utf-8", "replace")
    r = subprocess.run(args, capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0 and r.stderr == "" and json.loads(r.stdout)["trials"] == 30
