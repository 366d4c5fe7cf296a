"""Hostile inputs to the interchange readers (issue 25 items 3, 4 and 12): through the CLI, each is one
``error:`` line naming FILE:LINE and the culprit, exit 2, nothing written.

- NaN (or inf) in gama-local's adjusted output (coordinates, covariance, observations): was read.
- Star*Net ``.UNITS Furlongs`` (any unit the reader does not know): was read as metres; ``.ORDER``
  words it does not know were skipped.
- gama-local's set-wide instrument height ``<obs from_dh="1.500">`` over slope distances: was dropped
  (now refused by the distance path's reader, applied by ``import gama``'s general files).
"""

from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parents[1] / "data" / "interop"
GAMA_OUT = DATA / "small_volume_gama224_out.xml"


def _nth_line(text: str, needle: str, n: int = 0) -> int:
    hits = [i + 1 for i, ln in enumerate(text.splitlines()) if needle in ln]
    return hits[n]


@pytest.mark.parametrize("anchor, tag, value", [
    ("<adjusted>", "<X>", "nan"),                       # an adjusted coordinate
    ("<cov-mat>", "<flt>", "NaN"),
    ("<standard-deviation>", "<aposteriori>", "nan"),
    ("<observations>", "<obs>", "inf"),
])
def test_nan_in_gama_adjusted_output_is_refused(ws, anchor, tag, value):
    text = GAMA_OUT.read_text()
    i = text.index(tag, text.index(anchor)) + len(tag)
    bad = text[:i] + value + text[text.index("<", i):]            # the whole number replaced
    line = bad[:i].count("\n") + 1
    (ws / "out.xml").write_text(bad)
    ws.fails(["import", "gama-adjusted", "{d}/out.xml", "-o", "{d}/res"], f"out.xml:{line}:", tag, value)


def test_starnet_unknown_units_are_refused_by_name(ws):
    text = (DATA / "small_volume.dat").read_text()
    assert ".UNITS Meters" in text
    bad = text.replace(".UNITS Meters", ".UNITS Furlongs")
    (ws / "net.dat").write_text(bad)
    line = _nth_line(bad, ".UNITS")
    ws.fails(["import", "starnet", "{d}/net.dat", "-o", "{d}/imp"], f"net.dat:{line}:", ".UNITS Furlongs")


def test_starnet_miles_are_not_metres(ws):
    """``M...`` was taken for metres by its first letter."""
    bad = (DATA / "small_volume.dat").read_text().replace(".UNITS Meters", ".UNITS Miles DMS")
    (ws / "net.dat").write_text(bad)
    ws.fails(["import", "starnet", "{d}/net.dat", "-o", "{d}/imp"], ".UNITS Miles")


def test_gama_set_wide_instrument_height_is_applied_or_refused(ws, tmp_path):
    """The distance path's reader refuses the height (FILE:LINE); ``import gama`` now writes the
    general network's files, which apply it to every slope distance of the set, and no
    distances.csv (a note says why)."""
    from multilat.cli.app import main
    from multilat.errors import MultilatError
    from multilat.inputs import read_csv_table
    from multilat.network.io.files import read_observations, read_points
    from multilat.network.io.interop.gama import gama_local_text, read_gama_local

    text = gama_local_text(read_observations(ws / "obs.csv"), read_points(ws / "points.csv"), offsets=0.0)
    bad = text.replace('<obs from="A">', '<obs from="A" from_dh="1.500">')
    (ws / "net.xml").write_text(bad)
    line = _nth_line(bad, 'from_dh="1.500"')
    with pytest.raises(MultilatError, match=rf"net\.xml:{line}:.*from_dh=1\.5"):
        read_gama_local(ws / "net.xml")
    assert main(["import", "gama", str(ws / "net.xml"), "-o", str(ws / "imp")]) == 0
    assert not (ws / "imp" / "distances.csv").exists()
    tab = read_csv_table(ws / "imp" / "observations.csv", required=("kind", "from", "from_dh_m"), warn_unknown=False)
    dh = {(f, h) for f, h in zip(tab.column("from"), tab.column("from_dh_m"))}
    assert {h for f, h in dh if f == "A"} == {"1.5"} and {h for f, h in dh if f != "A"} == {"0.0"}


def test_starnet_unknown_order_is_refused_by_name(ws):
    """An ``.ORDER`` word the reader does not know was skipped (the coordinates then read in the order
    before it)."""
    bad = (DATA / "small_volume.dat").read_text().replace(".ORDER EN", ".ORDER ENZ")
    (ws / "net.dat").write_text(bad)
    ws.fails(["import", "starnet", "{d}/net.dat", "-o", "{d}/imp"], ".ORDER ENZ")


@pytest.mark.parametrize("name, cmd, needle", [
    ("small_volume_gama224_out.xml", ["import", "gama-adjusted"], "<id>"),
    ("small_volume.dat", ["import", "starnet"], "C "),
])
def test_invisible_formatting_characters_are_refused_by_line(ws, name, cmd, needle):
    """U+202E (right-to-left override) in an id reached the terminal and the outputs raw through the
    interchange readers (the CSV readers already refused it): now FILE:LINE and the code point."""
    text = (DATA / name).read_text()
    k = _nth_line(text, needle)
    lines = text.splitlines(keepends=True)
    i = lines[k - 1].index(needle) + len(needle)
    lines[k - 1] = lines[k - 1][:i] + "\u202e" + lines[k - 1][i:]      # before the id's first character
    bad = ws / name
    bad.write_text("".join(lines))
    ws.fails([*cmd, str(bad), "-o", "{d}/res"], f"{name}:{k}:", "U+202E")
