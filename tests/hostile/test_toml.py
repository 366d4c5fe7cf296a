"""Malformed TOML configurations: the instrument (budget, propagate, correct) and the LBB config
(lbb simulate, lbb compare): one line naming the file and the key or line, exit 2, nothing written."""

from __future__ import annotations

from pathlib import Path

import pytest

import multilat

PKG = Path(multilat.__file__).parent
INSTRUMENT = (PKG / "presets" / "seed2020.toml").read_text(encoding="utf-8")
LBB = (PKG / "lbb" / "canning2007.toml").read_text(encoding="utf-8")

#: kind -> (mutation of the text, needle besides the file name)
INSTRUMENT_CASES = {
    "empty": (lambda t: "", "missing"),
    "syntax": (lambda t: t.replace("[adm]", "[adm", 1), "malformed TOML"),
    "unterminated-string": (lambda t: t.replace('name = "seed2020"', 'name = "seed2020'), "malformed TOML"),
    "unknown-key": (lambda t: t.replace("phase_noise_rad =", "phase_nose_rad =", 1), "phase_nose_rad"),
    "wrong-type": (lambda t: t.replace("wavelength_nm = 1550.0", 'wavelength_nm = "red"', 1), "wavelength_nm"),
    "negative": (lambda t: t.replace("modulation_frequency_hz = 4.895e9", "modulation_frequency_hz = -1", 1),
                 "modulation_frequency_hz"),
    "nan": (lambda t: t.replace("pressure_hpa = 1013.25", "pressure_hpa = nan", 1), "pressure_hpa"),
    "huge": (lambda t: t.replace("temperature_c = 20.0", "temperature_c = 1e300", 1), "temperature_c"),
    "missing-section": (lambda t: t.split("[target]")[0], "target"),
    "duplicate-key": (lambda t: t.replace("[adm]", "[adm]\nwavelength_nm = 1.0", 1), "malformed TOML"),
    "array-for-number": (lambda t: t.replace("humidity_pct = 50.0", "humidity_pct = [50.0]", 1), "humidity_pct"),
}

LBB_CASES = {
    "empty": (lambda t: "", "missing"),
    "syntax": (lambda t: t.replace("[bar]", "[bar", 1), "malformed TOML"),
    "unknown-key": (lambda t: t.replace("la_m =", "la_mm =", 1), "la_mm"),
    "wrong-type": (lambda t: t.replace("la_m = 0.100", 'la_m = "long"', 1), "la_m"),
    "negative": (lambda t: t.replace("la_m = 0.100", "la_m = -0.1", 1), "la_m"),
    "zero-mass": (lambda t: t.replace("optics_mass_kg = 0.30", "optics_mass_kg = -3", 1), "optics_mass_kg"),
    "missing-section": (lambda t: t.replace("[bar.outer_tube]", "[bar.outer_tube_x]", 1), "outer_tube"),
    "bad-reach": (lambda t: t.replace("lb_max_m = 0.300", "lb_max_m = 0.01", 1), "lb"),
}


def _write(ws, name, text, kind):
    p = ws / name
    if kind == "non-utf8":
        p.write_bytes(text.encode() + b"\n# \xff\n")
    else:
        p.write_text(text, encoding="utf-8")
    return p


@pytest.mark.parametrize("kind", list(INSTRUMENT_CASES))
@pytest.mark.parametrize("command", [["budget", "--trials", "10", "--instrument"],
                                     ["propagate", "small-volume", "--trials", "100", "--instrument"]])
def test_bad_instrument(ws, kind, command):
    mutate, needle = INSTRUMENT_CASES[kind]
    p = _write(ws, "inst.toml", mutate(INSTRUMENT), kind)
    ws.fails(command + [str(p)], "inst.toml", needle)


@pytest.mark.parametrize("kind", list(LBB_CASES))
@pytest.mark.parametrize("command", [["lbb", "simulate", "--grid", "3", "--trials", "2", "--config"],
                                     ["lbb", "compare", "{d}/m60_edges.csv", "{d}/m60_ref.csv", "--config"]])
def test_bad_lbb_config(ws, kind, command):
    mutate, needle = LBB_CASES[kind]
    p = _write(ws, "lbb.toml", mutate(LBB), kind)
    ws.fails(command + [str(p)], "lbb.toml", needle)


@pytest.mark.parametrize("name", ["inst.toml", "lbb.toml"])
def test_non_utf8_toml(ws, name):
    p = ws / name
    p.write_bytes((INSTRUMENT if name == "inst.toml" else LBB).encode() + b"\n# \xff\n")
    args = ["budget", "--instrument", str(p)] if name == "inst.toml" else ["lbb", "simulate", "--config", str(p)]
    ws.fails(args, name, "not UTF-8")
