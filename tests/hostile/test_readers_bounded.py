"""Inputs read with bounded memory (issue 25, item 12 "unbounded reads"): a huge file with a wrong
header or a bad line 4, a file over its kind's size limit, /dev/zero, endless pipes, a CSV cell
longer than the csv module's limit. Each is one line ``error: FILE[:LINE]: ...``, exit 2.

The cases that used to read a whole file run the CLI in a subprocess with its address space limited
to 1 GiB (a full adjustment of the small example runs within it): before the fix they ran out of
memory (or hung on the endless pipe: a time bound of 120 s); the files are sparse, so they cost no
disk."""

from __future__ import annotations

import os
import resource
import subprocess
import threading

import pytest

from conftest import CLI, assert_one_line_error, cli_env

#: address space of the subprocess: the CLI with numba needs < 1 GiB for the small example
ADDRESS_SPACE = 1 << 30
HEADER = "station,target,distance_m,sigma_m\n"


def _limited():
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def _cli(args, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(CLI + [str(a) for a in args], capture_output=True, text=True, env=cli_env(),
                          preexec_fn=_limited, timeout=120, **kw)


def _sparse(path, text: str, size: int):
    """``text`` followed by a hole up to ``size`` bytes (NUL bytes when read; no disk used)."""
    with open(path, "wb") as f:
        f.write(text.encode())
        f.truncate(size)
    return path


def test_huge_file_with_a_wrong_header_is_named_from_its_first_line(tmp_path):
    p = _sparse(tmp_path / "obs.csv", "station,target,distance\nA,T1,1.0\n", 3 * 2**29)   # 1.5 GiB
    r = _cli(["adjust", p])
    assert r.returncode == 2, r.stderr[-500:]
    assert_one_line_error(r.stderr, "obs.csv:1:", "header lacks column(s) distance_m")


def test_huge_file_with_nan_on_line_4_is_named_without_reading_it_whole(tmp_path):
    rows = "A,T1,1.0,1e-5\nA,T2,1.1,1e-5\nA,T3,nan,1e-5\nA,T4,1.2,1e-5\n"
    p = _sparse(tmp_path / "obs.csv", HEADER + rows, 3 * 2**29)
    r = _cli(["adjust", p])
    assert r.returncode == 2, r.stderr[-500:]
    assert_one_line_error(r.stderr, "obs.csv:4:", "column 'distance_m'", "nan")


def test_file_over_the_observations_limit_is_refused_before_it_is_read(tmp_path):
    p = _sparse(tmp_path / "obs.csv", HEADER, 2 * 2**30 + 1)      # multilat.inputs.MAX_OBSERVATIONS_BYTES + 1
    r = _cli(["adjust", p])
    assert r.returncode == 2, r.stderr[-500:]
    assert_one_line_error(r.stderr, "obs.csv:", "2 GiB", "observations")


def test_dev_zero_is_binary_data(tmp_path):
    r = _cli(["adjust", "/dev/zero"])
    assert r.returncode == 2, r.stderr[-500:]
    assert_one_line_error(r.stderr, "/dev/zero:1:", "binary data")


def _feed(fifo, block: bytes, head: bytes = b""):
    """Write ``head`` then ``block`` into the named pipe ``fifo`` until the reader goes away."""
    def run():
        try:
            with open(fifo, "wb") as f:
                f.write(head)
                while True:
                    f.write(block)
        except (BrokenPipeError, OSError):
            pass
    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def test_endless_pipe_without_newlines_is_a_line_too_long(tmp_path):
    fifo = tmp_path / "obs.fifo"
    os.mkfifo(fifo)
    _feed(fifo, b"x" * 65536)
    r = _cli(["adjust", fifo])
    assert r.returncode == 2, r.stderr[-500:]
    assert_one_line_error(r.stderr, "obs.fifo:1:", "a line longer than 1 MiB")


def test_endless_pipe_with_a_bad_line_4_is_named_at_once(tmp_path):
    fifo = tmp_path / "obs.fifo"
    os.mkfifo(fifo)
    head = (HEADER + "A,T1,1.0,1e-5\nA,T2,1.1,1e-5\nA,T3,-1,1e-5\n").encode()
    _feed(fifo, b"A,T1,1.0,1e-5\n" * 4096, head)
    r = _cli(["adjust", fifo])
    assert r.returncode == 2, r.stderr[-500:]
    assert_one_line_error(r.stderr, "obs.fifo:4:", "column 'distance_m'", "must be > 0")


def test_endless_valid_pipe_stops_at_the_size_limit(ws, monkeypatch):
    """The limit (here lowered to 1 MiB, the same code path as the 2 GiB default) names the file and
    the limit; in-process: the pipe's writer is a thread of this test."""
    from multilat import inputs

    monkeypatch.setitem(inputs.INPUT_LIMITS, "observations", 2**20)
    monkeypatch.setattr(inputs, "_PIPES", {})
    fifo = ws / "obs.fifo"
    os.mkfifo(fifo)
    _feed(fifo, b"A,T1,1.0,1e-5\n" * 4096, HEADER.encode())
    err = ws.fails(["adjust", str(fifo)], "obs.fifo", "1 MiB", "observations")
    assert "a pipe" in err


def test_table_over_its_limit(ws, monkeypatch):
    from multilat import inputs

    monkeypatch.setitem(inputs.INPUT_LIMITS, "table", 100)
    ws.fails(["adjust", "{d}/obs.csv", "--references", "{d}/refs.csv"], "refs.csv", "100 B", "'table'")


def test_csv_cell_longer_than_the_csv_limit(ws):
    p = ws / "obs.csv"
    lines = p.read_text().splitlines()
    lines[2] = "A" + "x" * 200_000 + "," + lines[2].split(",", 1)[1]
    p.write_text("\n".join(lines) + "\n")
    ws.fails(["adjust", "{d}/obs.csv"], "obs.csv:3:", "a cell longer than 131072")    # the csv module's limit


@pytest.mark.parametrize("command", [["adjust", "{d}/obs.csv", "--points", "{d}/points.csv"],
                                     ["lbb", "trilaterate", "{d}/edges.csv"]])
def test_nul_byte_in_a_table(ws, command):
    name = "points.csv" if command[0] == "adjust" else "edges.csv"
    p = ws / name
    text = p.read_bytes().split(b"\n")
    text[2] = text[2] + b"\x00"
    p.write_bytes(b"\n".join(text))
    ws.fails(command, f"{name}:3:", "binary data")


def test_utf16_file_is_named_as_utf16(ws):
    p = ws / "obs.csv"
    p.write_bytes(p.read_text().encode("utf-16"))
    ws.fails(["adjust", "{d}/obs.csv"], "obs.csv:1:", "UTF-16")


def test_fast_reader_keeps_large_plain_files_and_refuses_a_bad_early_line(tmp_path):
    """A 1.3 MB plain file goes through the vectorised reader (> FAST_READ_ABOVE_BYTES): the same
    observations as the general reader; a bad line 3 of the same file is the general reader's message."""
    import numpy as np

    from multilat.errors import MultilatError
    from multilat.network.io import fastio
    from multilat.network.io.files import FAST_READ_ABOVE_BYTES, read_observations

    rng = np.random.default_rng(7)
    n = 60_000
    d = rng.uniform(1, 10, n).tolist()
    rows = [f"S{k % 7},T{k // 7},{d[k]!r},1e-05" for k in range(n)]
    p = tmp_path / "obs.csv"
    p.write_text(HEADER + "\n".join(rows) + "\n")
    assert p.stat().st_size > FAST_READ_ABOVE_BYTES
    fast = fastio.read_observations_fast(p)
    assert fast.distance_m.tolist() == d          # exact: shortest repr round-trips
    assert len(fast.station_ids) == 7 and len(fast.target_ids) == -(-n // 7)
    rows[1] = rows[1].replace(",1e-05", ",inf")
    p.write_text(HEADER + "\n".join(rows) + "\n")
    with pytest.raises(MultilatError, match=r"obs\.csv:3: column 'sigma_m': must be finite"):
        read_observations(p)
    with pytest.raises(MultilatError, match=r"obs\.csv:3: column 'sigma_m': must be finite"):
        fastio.read_observations_fast(p)
