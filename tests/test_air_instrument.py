"""``multilat air --instrument``: the group index at the instrument's own ADM wavelength (as budget and
correct use it), equal to the same command given that wavelength by hand; a contradicting
``--wavelength-nm`` is refused in one line naming both."""

import json
from pathlib import Path

from multilat.cli.app import main

PRESET = Path(__file__).resolve().parents[1] / "src" / "multilat" / "presets" / "seed2020.toml"


def _run(capsys, args):
    rc = main(["air", *args])
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_air_takes_the_instruments_wavelength(capsys, tmp_path):
    toml = tmp_path / "red.toml"
    toml.write_text(PRESET.read_text("utf-8").replace("wavelength_nm = 1550.0", "wavelength_nm = 633.0", 1), "utf-8")
    rc, out, err = _run(capsys, ["--instrument", str(toml), "--json"])
    assert rc == 0, err
    by_inst = json.loads(out)
    rc, out, _ = _run(capsys, ["--wavelength-nm", "633", "--json"])
    by_hand = json.loads(out)
    assert by_inst["inputs"]["wavelength_nm"] == 633.0
    assert by_inst["group_index"] == by_hand["group_index"]          # the same formula, the same inputs
    rc, out, _ = _run(capsys, ["--json"])
    assert json.loads(out)["group_index"] != by_inst["group_index"]   # 1550 nm differs: the test can fail


def test_a_contradicting_wavelength_is_refused(capsys):
    rc, out, err = _run(capsys, ["--instrument", "seed2020", "--wavelength-nm", "633"])
    assert rc == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "--wavelength-nm 633" in lines[0] and "adm.wavelength_nm = 1550" in lines[0]
