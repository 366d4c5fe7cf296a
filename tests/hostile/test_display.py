"""Ids and file names printed literally: no rich markup, no emoji codes, control characters escaped."""

from __future__ import annotations

import pytest

@pytest.fixture(autouse=True)
def wide_console(monkeypatch):
    """A wide terminal, so that a long id is not cut by the column width (a narrow terminal cuts
    cells with an ellipsis: a display limit, documented)."""
    from multilat.cli.app import console

    monkeypatch.setattr(console, "width", 250)


HOSTILE_IDS = ["[/bold]", "[bold]x", "[/x]", "[link=http://e]A", ":smile:", "\x1b[31mA", "A\x07", "a\u009bb"]


def _rename_station(ws, new):
    p = ws / "obs.csv"
    text = p.read_text().replace("\nA,", f"\n{new},")
    p.write_text(text)


@pytest.mark.parametrize("sid", HOSTILE_IDS)
def test_station_ids_in_adjust_tables(ws, sid):
    _rename_station(ws, sid.replace(",", ""))
    rc, out, err = ws.run(["adjust", "{d}/obs.csv"])
    assert rc == 0, err
    assert "\x1b" not in out and "\x07" not in out and "\u009b" not in out
    shown = sid.replace("\x1b", "\\x1b").replace("\x07", "\\x07").replace("\u009b", "\\x9b")
    assert shown.replace(" ", "") in _flat(out)


def _flat(out):
    """The output without table rules and wrapping (a long id may fold inside its cell)."""
    return "".join(ch for ch in out if ch not in " \n│┃")


@pytest.mark.parametrize("sid", ["[/bold]", "\x1b[2J"])
def test_station_ids_in_correct_table(ws, sid):
    p = ws / "raw.csv"
    p.write_text(p.read_text().replace(",1,2020", f",{sid},2020"))
    h = ws / "heights.csv"
    h.write_text(h.read_text().replace("\n1,", f"\n{sid},"))
    rc, out, err = ws.run(["correct", "{d}/raw.csv", "-e", "{d}/env.csv", "--heights", "{d}/heights.csv"])
    assert rc == 0, err
    assert "\x1b" not in out
    assert sid.replace("\x1b", "\\x1b") in _flat(out)


def test_file_name_with_markup_keeps_its_name_in_the_title(ws):
    src = ws / "edges.csv"
    dst = ws / "[bold]e.csv"
    dst.write_bytes(src.read_bytes())
    rc, out, err = ws.run(["lbb", "trilaterate", str(dst)])
    assert rc == 0, err
    assert "[bold]e.csv" in out.replace("\n", "")


def test_ids_in_error_messages_are_escaped(ws):
    p = ws / "obs.csv"
    # (a repeated pair is accepted since issue 16: an id used as station and target is the error here)
    p.write_text(p.read_text() + "\x1b[31mZ,1,0.7,4.7e-6\n1,\x1b[31mZ,0.7,4.7e-6\n")
    line = ws.fails(["adjust", "{d}/obs.csv"], "obs.csv:")
    assert "\x1b" not in line


def test_point_label_with_markup_in_lbb(ws):
    p = ws / "edges.csv"
    p.write_text(p.read_text().replace("\nP1,", "\n[/P1],"))
    rc, out, err = ws.run(["lbb", "trilaterate", "{d}/edges.csv"])
    assert rc in (0, 3), err
    assert "[/P1]" in out
