"""Instrument config: the seed2020 preset holds Tables I, III, IV; bad configs fail with one line naming the key."""

import re
import tomllib
from importlib import resources

import pytest

from multilat.errors import MultilatError
from multilat.instrument import Instrument, load_instrument, parse_instrument, presets


def _preset_dict():
    return tomllib.loads(resources.files("multilat").joinpath("presets", "seed2020.toml").read_text())


def test_preset_listed_and_loads():
    assert "seed2020" in presets()
    inst = load_instrument("seed2020")
    assert isinstance(inst, Instrument)
    assert inst.name == "seed2020"


def test_preset_matches_seed_tables():
    inst = load_instrument("seed2020")
    a = inst.adm  # Table I
    assert (a.modulation_frequency_hz, a.signal_to_crosstalk_db, a.phase_noise_rad) == (4895e6, 65.0, 0.17e-3)
    assert (a.am_pm_m_per_db, a.power_variation_db, a.clock_ageing_per_year) == (-0.15e-6, 5.0, 1.5e-9)
    # Table III
    table3 = {"A": (190, 230, (-0.05, 0.12), (-0.09, 0.02), -1), "B": (310, 180, (0.07, 0.24), (-0.16, -0.03), -3),
              "C": (260, 170, (-0.11, 0.08), (-0.07, 0.05), 2), "D": (200, 320, (0.09, 0.29), (-0.08, 0.02), 3)}
    for name, (al, cl, alpha, gamma, toh) in table3.items():
        h = inst.heads[name]
        assert h.a_limit_m == pytest.approx(al * 1e-6) and h.c_limit_m == pytest.approx(cl * 1e-6)
        assert h.alpha_deg == alpha and h.gamma_deg == gamma
        assert h.toh_m == pytest.approx(toh * 1e-6) and h.toh_std_m == pytest.approx(2e-6)
    assert inst.head_common.beam_offset_m == (-320e-6, 320e-6)
    # Table IV (reading note: a' = -6, b' = 34, c' = -22 um, Tot = 11 um, all sigma 2 um)
    t = inst.target
    assert (t.a_m, t.b_m, t.c_m, t.tot_m) == (-6e-6, 34e-6, -22e-6, 11e-6)
    assert t.offset_std_m == t.tot_std_m == 2e-6
    # section 3.4: 0.2 m to 20.2 m by 0.8 m, 200 000 samples each (26 x 200 000 = 5.2 million)
    d = inst.budget.distances_m
    assert d.size == 26 and d[0] == pytest.approx(0.2) and d[-1] == pytest.approx(20.2)
    assert inst.budget.trials_per_distance * d.size == 5_200_000


def test_unknown_preset_lists_presets():
    with pytest.raises(MultilatError, match=r"unknown instrument preset 'nope'; presets: .*seed2020"):
        load_instrument("nope")


def test_unknown_head_lists_heads():
    with pytest.raises(MultilatError, match="unknown head 'Z'.*A, B, C, D"):
        load_instrument("seed2020").head("Z")


def _write(tmp_path, text):
    p = tmp_path / "inst.toml"
    p.write_text(text)
    return p


def test_file_round_trip(tmp_path):
    text = resources.files("multilat").joinpath("presets", "seed2020.toml").read_text()
    inst = load_instrument(_write(tmp_path, text.replace('name = "seed2020"', 'name = "mine"')))
    assert inst.name == "mine" and inst.heads["C"].toh_m == 2e-6


@pytest.mark.parametrize("edit, pattern", [
    (lambda d: d["heads"]["A"].update(toh_stdm=1e-6), r"heads\.A\.toh_stdm: unknown key"),
    (lambda d: d["target"].update(tot_std_m=-1e-6), r"target\.tot_std_m: must be >= 0"),
    (lambda d: d["adm"].update(phase_noise_rad=float("nan")), r"adm\.phase_noise_rad: .*finite"),
    (lambda d: d["adm"].update(modulation_frequency_hz=0.0), r"adm\.modulation_frequency_hz: must be > 0"),
    (lambda d: d["environment"].update(humidity_pct=120.0), r"environment\.humidity_pct: must lie in \[0, 100\]"),
    (lambda d: d["heads"]["B"].update(alpha_deg=[0.3, 0.1]), r"heads\.B\.alpha_deg: must be \[low, high\]"),
    (lambda d: d["heads"]["B"].pop("toh_m"), r"heads\.B\.toh_m: missing required key"),
    (lambda d: d["target"].update(misalignment_shape="disk"), r"target\.misalignment_shape"),
    (lambda d: d.update(budjet={}), r"budjet: unknown key"),
    (lambda d: d["budget"].update(trials_per_distance=1), r"budget\.trials_per_distance: must be >= 2"),
])
def test_bad_config_one_line(edit, pattern):
    d = _preset_dict()
    edit(d)
    with pytest.raises(MultilatError) as exc:
        parse_instrument(d, source="x.toml")
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith("x.toml: ")
    assert re.search(pattern, msg), msg


def test_malformed_toml_names_file(tmp_path):
    p = _write(tmp_path, "[adm]\nmodulation_frequency_hz = = 4\n")
    with pytest.raises(MultilatError) as exc:
        load_instrument(p)
    assert str(p) in str(exc.value) and "malformed TOML" in str(exc.value) and "\n" not in str(exc.value)


def test_missing_file():
    with pytest.raises(MultilatError, match="not found"):
        load_instrument("/nonexistent/inst.toml")


def test_nan_in_toml_file(tmp_path):
    text = resources.files("multilat").joinpath("presets", "seed2020.toml").read_text()
    p = _write(tmp_path, text.replace("toh_std_m = 2e-6", "toh_std_m = nan", 1))
    with pytest.raises(MultilatError, match=r"heads\.A\.toh_std_m"):
        load_instrument(p)
