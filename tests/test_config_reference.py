"""docs/config-reference.md is the pydantic models' own description (tools/config_reference.py): the page
equals what the tool renders, every key is described, every stated numeric bound is the model's."""

from __future__ import annotations

import copy
import importlib.util
import re
import sys
import tomllib
from importlib import resources
from pathlib import Path

import pytest
from pydantic import ValidationError

ROOT = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location("config_reference", ROOT / "tools" / "config_reference.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["config_reference"] = mod
    spec.loader.exec_module(mod)
    return mod


def test_reference_page_is_generated_from_the_models():
    """Fails when a model changed and the page was not regenerated (python tools/config_reference.py)."""
    page = ROOT / "docs" / "config-reference.md"
    assert page.is_file(), "docs/config-reference.md missing: run python tools/config_reference.py"
    assert page.read_text(encoding="utf-8") == _tool().render()


def test_every_key_is_described_with_type_default_and_unit():
    tool = _tool()
    n = 0
    for _, _, model, _ in tool._files():
        for path, m, rows in tool.rows(model):
            for key, typ, unit, default, constraint, desc in rows:
                n += 1
                assert desc.strip(), f"{m.__name__}.{key}: no description (Field(description=...))"
                assert typ and default, (m.__name__, key)
    assert n > 150


#: float keys without a unit suffix, because they have no unit
DIMENSIONLESS = {"min_height_ratio", "std_per_mpe"}


def test_every_number_has_a_unit_or_is_dimensionless():
    tool = _tool()
    for _, _, model, _ in tool._files():
        for path, m, rows in tool.rows(model):
            for key, typ, unit, *_ in rows:
                if typ.startswith("number") or typ == "array of 2 number":
                    assert unit != "-" or key in DIMENSIONLESS, f"{m.__name__}.{key}: a number without a unit"


def _bases():
    """A valid document of each file with every optional table present (so every key can be probed)."""
    inst = tomllib.loads(resources.files("multilat").joinpath("presets", "seed2020.toml").read_text("utf-8"))
    inst["trackers"] = {"T1": {"adm_a_um": 15.0, "adm_b_um_per_m": 6.0, "transverse_a_um": 15.0,
                               "transverse_b_um_per_m": 6.0}}
    inst["head_types"] = {"X": copy.deepcopy(inst["heads"]["A"])}
    design = {"targets": {"box_min_m": [0, 0, 0], "box_max_m": [1, 1, 1], "grid": [3, 3, 3]},
              "heads": {"count": 4, "box_min_m": [-1, -1, 0], "box_max_m": [2, 2, 2], "min_range_m": 0.1},
              "occluders": [{"box_min_m": [0, 0, 0], "box_max_m": [1, 1, 1]}],
              "instrument": {"sigma_um": 4.7}, "criterion": {"target_u95_m": 3e-5},
              "network": {"scale_bars": [{"a": "T1", "b": "T2", "u_um": 1.0}],
                          "control": [{"point": "T1", "s_um": [1, 1, 1]}]},
              "search": {"starts": 2, "max_evaluations": 100}}
    from multilat.lbb.config import DEFAULT_CONFIG

    lbb = tomllib.loads(DEFAULT_CONFIG.read_text(encoding="utf-8"))
    return {"instrument": inst, "design": design, "lbb": lbb}


def _slot(doc, path):
    """The dict holding the keys of table ``path`` ("heads.NAME", "occluders", ...) in ``doc``."""
    d = doc
    for part in [p for p in path.split(".") if p]:
        d = next(iter(d.values())) if part == "NAME" else d[part]
        if isinstance(d, list):
            d = d[0]
    return d


def test_numeric_constraints_are_the_models():
    """Each stated ``> N`` / ``>= N`` bound: a value just across it is refused by the model (from a valid
    document); the unrelated keys' values stay valid."""
    tool = _tool()
    bases = _bases()
    checked = []
    for anchor, _, model, _ in tool._files():
        model.model_validate(bases[anchor])                      # the base is valid
        for path, m, rows in tool.rows(model):
            for key, typ, unit, default, constraint, desc in rows:
                hit = re.match(r"^(>=|>) (-?[0-9.e+-]+)(;|$)", constraint)
                if not hit:
                    continue
                op, bound = hit.group(1), float(hit.group(2))
                doc = copy.deepcopy(bases[anchor])
                slot = _slot(doc, path)
                integer = typ.startswith("integer")
                across = bound if op == ">" else (bound - 1 if integer else bound - 1e-9 * max(1.0, abs(bound)))
                slot[key] = int(across) if integer else across
                with pytest.raises(ValidationError):
                    model.model_validate(doc)
                checked.append(f"{anchor}:{path}.{key}")
    assert len(checked) >= 60, checked


def test_tool_check_mode(tmp_path, monkeypatch):
    tool = _tool()
    monkeypatch.setattr(tool, "OUT", tmp_path / "ref.md")
    assert tool.main(["--check"]) == 1
    assert tool.main([]) == 0 and tool.main(["--check"]) == 0
