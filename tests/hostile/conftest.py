"""Shared helpers of the hostile-input catalogue: run the CLI in-process, and check that an error is
one line naming the culprit and that nothing was lost or half-written."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from multilat.cli import main

ROOT = Path(__file__).resolve().parents[2]
EX = ROOT / "examples"
SRC = ROOT / "src"

#: The valid files every case starts from (name in the case's directory -> example file).
BASE = {
    "obs.csv": EX / "network" / "small_volume_obs.csv",
    "refs.csv": EX / "network" / "small_volume_refs.csv",
    "points.csv": EX / "network" / "small_volume_points.csv",
    "config.csv": EX / "network" / "small_volume_config.csv",
    "raw.csv": EX / "campaign" / "raw.csv",
    "env.csv": EX / "campaign" / "environment.csv",
    "heights.csv": EX / "campaign" / "heights.csv",
    "two_face.csv": EX / "campaign" / "two_face.csv",
    "edges.csv": EX / "lbb" / "edges.csv",
    "m60_edges.csv": EX / "lbb" / "m60_edges.csv",
    "m60_ref.csv": EX / "lbb" / "m60_reference.csv",
}


def snapshot(d: Path) -> dict[str, bytes | None]:
    """Every path under ``d`` -> its bytes (None for directories and special files)."""
    out = {}
    for p in sorted(d.rglob("*")):
        rel = str(p.relative_to(d))
        out[rel] = p.read_bytes() if p.is_file() and not p.is_fifo() else None
    return out


class Workspace:
    """A directory holding copies of the example inputs, and the CLI run against them."""

    def __init__(self, path: Path, capsys):
        self.path = path
        self.capsys = capsys
        for name, src in BASE.items():
            (path / name).write_bytes(src.read_bytes())

    def __truediv__(self, name) -> Path:
        return self.path / name

    def run(self, args) -> tuple[int, str, str]:
        args = [str(a).replace("{d}", str(self.path)) for a in args]
        self.capsys.readouterr()
        rc = main(args)
        cap = self.capsys.readouterr()
        return rc, cap.out, cap.err

    def fails(self, args, *needles, rc: int = 2) -> str:
        """Run ``args``; assert exit ``rc``, one ``error:`` line holding every needle, no traceback,
        and the directory unchanged (no input lost, no output half-written). Returns the line."""
        before = snapshot(self.path)
        code, out, err = self.run(args)
        assert code == rc, (code, err)
        assert_one_line_error(err, *needles)
        after = snapshot(self.path)
        assert after == before, f"files changed: {sorted(set(after) ^ set(before))}"
        return err.strip()


def assert_one_line_error(err: str, *needles: str) -> None:
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("warning:")]
    assert len(lines) == 1, err
    line = lines[0]
    assert line.startswith("error: "), line
    assert "Traceback" not in err and "np.float64" not in line and ".part" not in line, line
    for n in needles:
        assert n in line, (n, line)


@pytest.fixture
def ws(tmp_path, capsys) -> Workspace:
    return Workspace(tmp_path, capsys)


def cli_env() -> dict:
    """Environment for a subprocess running the CLI from this tree."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(SRC) + os.pathsep + env.get("PYTHONPATH", "")
    return env


CLI = [sys.executable, "-c", "from multilat.cli import run; run()"]
