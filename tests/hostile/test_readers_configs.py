"""Configs and options that used to end in an internal error (exit 70) or grow until memory ran out
(issue 25, item 12), ids with invisible formatting characters, and the staging directories a killed
run leaves behind. Each refusal is one line naming the file and the key or option, exit 2."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import CLI, EX, assert_one_line_error, cli_env

CUBE = (EX / "design" / "cube.toml").read_text(encoding="utf-8")
PKG = Path(__file__).resolve().parents[2] / "src" / "multilat"
INSTRUMENT = (PKG / "presets" / "seed2020.toml").read_text(encoding="utf-8")
LBB = (PKG / "lbb" / "canning2007.toml").read_text(encoding="utf-8")


def _write(ws, name, text):
    p = ws / name
    p.write_text(text, encoding="utf-8")
    return p


# ------------------------------------------------------------------------------ deeply nested TOML
DEEP = "x = " + "[" * 5000 + "]" * 5000 + "\n"          # Python's TOML parser recurses per level
NESTED_40 = "x = " + "[" * 40 + "1" + "]" * 40 + "\n"     # parsed, but deeper than any config


def _toml_commands(ws):
    """Every command that loads a TOML file, with the file's name: design, the instrument (budget,
    adjust), the LBB config, a network simulation config."""
    return {
        "design": ["design", "{d}/c.toml"],
        "instrument": ["budget", "--trials", "10", "--instrument", "{d}/c.toml"],
        "correct-instrument": ["correct", "{d}/raw.csv", "-e", "{d}/env.csv", "--instrument", "{d}/c.toml"],
        "lbb": ["lbb", "simulate", "--grid", "3", "--trials", "2", "--config", "{d}/c.toml"],
        "simulate": ["simulate", "{d}/c.toml", "--trials", "1"],
    }


@pytest.mark.parametrize("loader", ["design", "instrument", "correct-instrument", "lbb", "simulate"])
def test_deeply_nested_toml_in_every_loader(ws, loader):
    _write(ws, "c.toml", DEEP)
    ws.fails(_toml_commands(ws)[loader], "c.toml", "nested")


@pytest.mark.parametrize("loader", ["design", "instrument", "lbb", "simulate"])
def test_toml_deeper_than_the_limit_names_the_key(ws, loader):
    from multilat.inputs import MAX_TOML_DEPTH

    _write(ws, "c.toml", NESTED_40)
    ws.fails(_toml_commands(ws)[loader], "c.toml", "x:", f"more than {MAX_TOML_DEPTH} levels")


# ------------------------------------------------------------------------------------ design options
def test_design_negative_seed(ws):
    _write(ws, "cube.toml", CUBE)
    ws.fails(["design", "{d}/cube.toml", "--seed", "-1"], "--seed", ">= 0")


def test_design_datum_with_unknown_points(ws):
    _write(ws, "cube.toml", CUBE + '\n[network]\ndatum = "321:X,Y,Z"\n')
    ws.fails(["design", "{d}/cube.toml"], "cube.toml", "network.datum", "'X'")


@pytest.mark.parametrize("option", ["321:X,Y,Z", "free:A,Q"])
def test_adjust_datum_option_with_unknown_points(ws, option):
    ws.fails(["adjust", "{d}/obs.csv", "--datum", option], "datum", "unknown point")


def _limited_cli(args, cwd) -> subprocess.CompletedProcess:
    """The CLI in a subprocess limited to 1 GiB of address space (before the limits these cases grew
    until memory ran out: bounded here, they fail instead of taking the machine)."""
    import resource

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))

    return subprocess.run(CLI + [str(a) for a in args], capture_output=True, text=True, env=cli_env(),
                          preexec_fn=limit, timeout=300, cwd=cwd)


@pytest.mark.parametrize("grid,needle", [("[1e20, 1, 1]", "targets.grid"),
                                         ("[1000000000000000000, 1, 1]", "200,000"),
                                         ("[1000, 1000, 1000]", "1,000,000,000 targets")])
def test_design_grid_beyond_the_limit(tmp_path, grid, needle):
    p = tmp_path / "cube.toml"
    p.write_text(CUBE.replace("grid = [3, 3, 3]", f"grid = {grid}"), encoding="utf-8")
    r = _limited_cli(["design", p], tmp_path)
    assert r.returncode == 2, r.stderr[-500:]
    assert_one_line_error(r.stderr, "cube.toml", "grid", needle)


@pytest.mark.parametrize("count", ["1e6", "1000000"])
def test_design_head_count_beyond_the_limit(tmp_path, count):
    p = tmp_path / "cube.toml"
    p.write_text(CUBE.replace("count = 4", f"count = {count}"), encoding="utf-8")
    r = _limited_cli(["design", p], tmp_path)
    assert r.returncode == 2, r.stderr[-500:]
    assert_one_line_error(r.stderr, "cube.toml", "heads", "count", "at most 200")   # MAX_DESIGN_HEADS


def test_design_memory_estimate(ws, monkeypatch):
    """A grid and head count within the limits but beyond the machine's memory (here a 64 MiB
    machine): refused before any work, as ``lbb simulate --grid`` is."""
    from multilat import inputs

    monkeypatch.setattr(inputs, "physical_memory_bytes", lambda: 64 * 2**20)
    monkeypatch.setattr("multilat.cli.checks.physical_memory_bytes", lambda: 64 * 2**20)
    _write(ws, "cube.toml", CUBE.replace("grid = [3, 3, 3]", "grid = [50, 50, 50]").replace("count = 4", "count = 8"))
    ws.fails(["design", "{d}/cube.toml"], "cube.toml", "targets.grid x heads.count", "more than this machine")


def test_design_targets_file_beyond_the_limit(ws, monkeypatch):
    monkeypatch.setattr("multilat.network.design.config.MAX_DESIGN_TARGETS", 5)
    _write(ws, "cube.toml", CUBE.replace("box_min_m = [0, 0, 0]\nbox_max_m = [1, 1, 1]\ngrid = [3, 3, 3]",
                                         'file = "points.csv"'))
    ws.fails(["design", "{d}/cube.toml"], "cube.toml", "targets", "more than the 5")


# ------------------------------------------------------------------ invisible formatting characters in ids
RLO = "\u202e"

#: file, text replaced in it, command: every CSV reader that takes ids
ID_READERS = {
    "observations-station": ("obs.csv", "\nA,", "\nA{c}B,", ["adjust", "{d}/obs.csv"], "column 'station'"),
    "observations-target": ("obs.csv", ",1,", ",1{c}x,", ["adjust", "{d}/obs.csv"], "column 'target'"),
    "points": ("points.csv", "\n1,", "\n1{c},", ["adjust", "{d}/obs.csv", "--points", "{d}/points.csv"],
               "column 'point'"),
    "references": ("refs.csv", "\n1,", "\n1{c},", ["adjust", "{d}/obs.csv", "--references", "{d}/refs.csv"],
                   "column 'target_a'"),
    "raw": ("raw.csv", ",1,2020", ",1{c},2020", ["correct", "{d}/raw.csv", "-e", "{d}/env.csv"], "column 'target'"),
    "lbb-edges": ("edges.csv", "\n", "\nP{c}", ["lbb", "trilaterate", "{d}/edges.csv"], "column 'point'"),
    "heights": ("heights.csv", "\n", "\nH{c}", ["correct", "{d}/raw.csv", "-e", "{d}/env.csv", "--heights",
                                               "{d}/heights.csv"], "column 'id'"),
}


@pytest.mark.parametrize("char", [RLO, "\u2066", "\u200b", "\u200f", "\ufeff"])
@pytest.mark.parametrize("reader", list(ID_READERS))
def test_formatting_characters_in_ids_are_refused(ws, reader, char):
    name, old, new, command, column = ID_READERS[reader]
    p = ws / name
    text = p.read_text(encoding="utf-8")
    lines = text.split("\n")
    h = next(i for i, ln in enumerate(lines) if ln.strip() and not ln.startswith("#"))   # the header
    k = text.index(old, len("\n".join(lines[:h + 1])))     # from the end of the header: a data row
    p.write_text(text[:k] + new.format(c=char) + text[k + len(old):], encoding="utf-8")
    line = text[:k + 1].count("\n") + 1
    err = ws.fails(command, f"{name}:{line}:", column, f"U+{ord(char):04X}")
    assert char not in err


def test_error_messages_escape_formatting_characters():
    from multilat.errors import format_error, printable

    assert printable(f"A{RLO}B") == "A\\u202eB"
    assert format_error(ValueError(f"id A{RLO}\u2067B")) == "id A\\u202e\\u2067B"
    assert printable("a\tb\nc") == "a\tb\nc"                # tabs and newlines kept where asked


# ---------------------------------------------------------------------------- stale staging directories
def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_stale_staging_directories_of_dead_runs_are_removed(ws):
    """A SIGKILL between mkdtemp and the rename leaves ``.out.PID.XXXX.part``; the next run writing
    ``out`` removes those of dead processes, and only those (a live process's, another name's and a
    foreign directory stay)."""
    dead = _dead_pid()
    stale = ws / f".out.{dead}.abcd1234.part"
    stale.mkdir()
    (stale / "result.json").write_text("{}")
    alive = ws / f".out.{os.getppid()}.abcd1234.part"
    alive.mkdir()
    other = ws / f".other.{dead}.abcd1234.part"
    other.mkdir()
    foreign = ws / ".out.keep"
    foreign.mkdir()
    rc, out, err = ws.run(["adjust", "{d}/obs.csv", "--out", "{d}/out"])
    assert rc == 0, err
    assert not stale.exists()
    assert alive.exists() and other.exists() and foreign.exists()
    assert (ws / "out" / "result.json").is_file()
    assert sorted(p.name for p in ws.path.iterdir() if p.name.startswith(".out.")) == sorted(
        [alive.name, foreign.name])


def test_stale_old_directory_gives_back_the_previous_results(ws):
    """Killed between moving the previous results aside and renaming the new ones in: ``out`` is
    missing and ``.out.PID.XXXX.old/d`` holds the previous results; the next run puts them back before
    it replaces them (nothing lost if that run fails)."""
    dead = _dead_pid()
    old = ws / f".out.{dead}.abcd1234.old"
    (old / "d").mkdir(parents=True)
    (old / "d" / "result.json").write_text('{"previous": true}')
    from multilat.io import remove_stale_staging

    removed = remove_stale_staging(ws / "out")
    assert removed == [old] and not old.exists()
    assert (ws / "out" / "result.json").read_text() == '{"previous": true}'


def test_staging_directories_carry_the_pid(ws):
    from multilat.io import staging_dir

    with staging_dir(ws / "out") as tmp:
        assert tmp.name.startswith(f".out.{os.getpid()}.") and tmp.name.endswith(".part")


def test_stale_part_files_of_dead_runs_are_removed(ws):
    """A SIGKILL while a single output file is written leaves ``.NAME.PID.XXXX.part`` beside it; the
    next write of that file removes it (a live process's stays)."""
    dead = _dead_pid()
    stale = ws / f".obs_out.csv.{dead}.abcd1234.part"
    stale.write_text("half a file")
    alive = ws / f".obs_out.csv.{os.getppid()}.abcd1234.part"
    alive.write_text("being written")
    from multilat.io import write_text_atomic

    write_text_atomic(ws / "obs_out.csv", "x\n")
    assert not stale.exists() and alive.exists()
    assert (ws / "obs_out.csv").read_text() == "x\n"
