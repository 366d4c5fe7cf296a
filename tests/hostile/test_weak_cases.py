"""The weak cases of issue 14, each a test: wrong culprits, silent skips, unreadable messages."""

from __future__ import annotations

import numpy as np
import pytest

from multilat.errors import MultilatError, format_error


def test_elevation_out_of_range_in_raw(ws):
    p = ws / "raw.csv"
    p.write_text(p.read_text().replace(",-0.10374206035729017,", ",100,", 1))
    ws.fails(["correct", "{d}/raw.csv", "-e", "{d}/env.csv", "--heights", "{d}/heights.csv"],
             "raw.csv:2", "elevation_rad", "±π/2")


def test_elevation_out_of_range_in_observations(ws):
    p = ws / "o.csv"
    p.write_text("station,target,distance_m,sigma_m,azimuth_rad,elevation_rad\nA,1,1.0,1e-6,0.1,100\n")
    ws.fails(["adjust", str(p)], "o.csv:2", "elevation_rad")


@pytest.mark.parametrize("trials", ["500"])
def test_huge_gaussian_sigma_is_one_line(ws, trials):
    """σ = 3 cm on a 1 m network: the trials fail (counted) or the nominal problem is singular;
    either way one line, never 'Singular matrix' as a traceback."""
    line = ws.fails(["propagate", "small-volume", "--noise", "gaussian", "--sigma-um", "30000",
                     "--trials", trials])
    assert "converged" in line or "numerical failure" in line


def test_lbb_compare_names_unmatched_points(ws):
    e = ws / "m60_edges.csv"
    r = ws / "m60_ref.csv"
    lines = r.read_text().splitlines()
    r.write_text("\n".join(lines[:4]) + "\n")          # three reference points for 75 measured ones
    rc, out, err = ws.run(["lbb", "compare", str(e), str(r), "--trials", "20", "--json"])
    assert rc == 0, err
    assert "warning:" in err and "without a reference" in err and "M04" in err


def test_config_replace_message_names_the_keys():
    from multilat.lbb.config import load_config

    cfg = load_config()
    with pytest.raises(MultilatError) as exc:
        cfg.replace(monte_carlo__point_draws=1)
    assert "<replace>" not in str(exc.value) and "monte_carlo" in str(exc.value)


@pytest.mark.parametrize("raw,shown", [
    (f"got {np.float64(1.5)!r}", "got 1.5"),
    (f"got {np.int64(3)!r} and {np.float32(2.0)!r}", "got 3 and 2.0"),
    ("two\nlines", "two lines"),
    ("bell\x07 and \x1b[2J", "bell\\x07 and \\x1b[2J"),
])
def test_error_formatter(raw, shown):
    assert format_error(MultilatError(raw)) == shown


@pytest.mark.parametrize("cmd", [["adjust"], ["propagate"], ["simulate"], ["two-face"], ["lbb", "trilaterate"],
                                 ["correct"]])
def test_directory_for_a_file_is_named_as_such(ws, cmd):
    (ws / "d.csv").mkdir()
    ws.fails(cmd + ["{d}/d.csv"], "d.csv", "is a directory")


def test_adjust_twice_same_results(ws):
    for _ in range(2):
        rc, _, err = ws.run(["adjust", "{d}/obs.csv", "--out", "{d}/res"])
        assert rc == 0, err
    from multilat.network.io.files import table_format

    assert sorted(p.name for p in (ws / "res").iterdir()) == sorted([
        f"observations.{table_format('observations', 'auto')}", "residuals.png", "result.json", "stations.csv",
        "targets.csv", "top_view.png", "view_3d.png"])


def test_hash_station_id_does_not_vanish(ws):
    p = ws / "obs.csv"
    p.write_text(p.read_text().replace("\nA,", "\n#A,"))
    ws.fails(["adjust", "{d}/obs.csv"], "obs.csv:4", "'#'")


def test_read_only_directory_out(ws, monkeypatch):
    import tempfile

    def denied(*a, **k):
        raise PermissionError(13, "Permission denied", f"{k.get('dir', 'x')}/.res.abc.part")

    monkeypatch.setattr(tempfile, "mkdtemp", denied)
    line = ws.fails(["adjust", "{d}/obs.csv", "--out", "{d}/res"], "res", "Permission denied")
    assert ".part" not in line


@pytest.mark.parametrize("exc,rc,needle", [(TypeError("bad operand"), 70, "internal error"),
                                           (MemoryError(), 2, "out of memory"),
                                           (np.linalg.LinAlgError("Singular matrix"), 2, "numerical failure"),
                                           (KeyboardInterrupt(), 130, "interrupted")])
def test_last_guard_is_one_line(ws, monkeypatch, exc, rc, needle):
    import multilat.lbb.files as lf

    def boom(*a, **k):
        raise exc

    monkeypatch.setattr(lf, "read_edges", boom)
    ws.fails(["lbb", "trilaterate", "{d}/edges.csv"], needle, rc=rc)
