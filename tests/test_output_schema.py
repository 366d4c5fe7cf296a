"""One vocabulary and a schema for every command's ``--json`` (issue 13 item 2).

Every sample run of ``SAMPLES`` of ``tools/schema_infer.py`` (each command on the shipped examples, with
the options that add keys) must (a) carry ``"schema": "multilat.<command>/<version>"``, (b) validate
against the shipped JSON Schema (jsonschema, draft 2020-12: a renamed, removed or undeclared key fails),
and (c) use only names of the convention (:func:`multilat.vocabulary.document_problems`: statistic after
the quantity, no ``u``/``sd``/``sem``/``entropy`` tokens, none of the replaced names). The mutation
tests show that each check fails on the faults it is there for.
"""

from __future__ import annotations

import copy
import json
import re
import sys
from pathlib import Path

import pytest

jsonschema = pytest.importorskip("jsonschema")

from multilat.cli import main  # noqa: E402
from multilat.schemas import COMMANDS, load  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
from schema_infer import SAMPLES, infer, run_sample  # noqa: E402
from multilat.vocabulary import RENAMED, document_problems, key_problems, schema_version  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
_DOCS: dict = {}


def _doc(cmd, i, tmp_path):
    if (cmd, i) not in _DOCS:
        d = tmp_path / f"{cmd}-{i}"
        d.mkdir()
        _DOCS[(cmd, i)] = run_sample(SAMPLES[cmd][i], d)
    return _DOCS[(cmd, i)]


def _validator(cmd):
    return jsonschema.Draft202012Validator(load(cmd))


CASES = [(c, i) for c in SAMPLES for i in range(len(SAMPLES[c]))]


@pytest.mark.parametrize("cmd,i", CASES, ids=[f"{c}-{i}" for c, i in CASES])
def test_every_command_json_follows_its_schema_and_the_vocabulary(cmd, i, tmp_path):
    doc = _doc(cmd, i, tmp_path)
    assert doc["schema"] == f"multilat.{cmd}/{schema_version(cmd)}"
    assert list(doc)[0] == "schema"
    errors = sorted(_validator(cmd).iter_errors(doc), key=lambda e: list(e.path))
    assert not errors, "; ".join(f"{list(e.path)}: {e.message[:120]}" for e in errors[:5])
    assert document_problems(doc) == []


def test_every_command_has_a_schema_and_a_sample():
    assert set(SAMPLES) == set(COMMANDS)
    for c in COMMANDS:
        s = load(c)
        assert s["$id"] == f"multilat.{c}/{schema_version(c)}"
        jsonschema.Draft202012Validator.check_schema(s)


def test_shipped_schemas_are_what_the_samples_give(tmp_path):
    """The shipped files are the inference of the sample documents (regenerate with
    ``python tools/schema_infer.py`` and read the diff when an output changes)."""
    for cmd in ("budget", "lbb-simulate", "two-face", "simulate"):
        docs = [_doc(cmd, i, tmp_path) for i in range(len(SAMPLES[cmd]))]
        assert infer(cmd, docs) == load(cmd)


def test_a_renamed_or_undeclared_key_fails(tmp_path):
    doc = copy.deepcopy(_doc("adjust", 0, tmp_path))
    v = _validator("adjust")
    assert v.is_valid(doc)
    sid = next(iter(doc["stations"]))
    st = doc["stations"][sid]
    st["offset_u_m"] = st.pop("offset_std_m")               # an old name back
    assert not v.is_valid(doc)
    assert any("renamed 'offset_std_m'" in p for p in document_problems(doc))
    doc2 = copy.deepcopy(_doc("propagate", 0, tmp_path))
    doc2["parameters"][0]["lin_std_m"] = doc2["parameters"][0].pop("std_lin_m")
    assert not _validator("propagate").is_valid(doc2)
    doc3 = copy.deepcopy(_doc("budget", 0, tmp_path))
    doc3["new_thing_m"] = 1.0                                # undeclared
    assert not _validator("budget").is_valid(doc3)
    doc4 = copy.deepcopy(_doc("budget", 0, tmp_path))
    doc4["schema"] = "multilat.budget/0"                     # wrong version
    assert not _validator("budget").is_valid(doc4)


@pytest.mark.parametrize("key", ["offset_m", "offset_std_m", "xyz_m", "cov_m2", "u95_max_m", "std_mc_m",
                                 "std_lin_m", "std_mc_se_m", "cov_mc_m2", "semi_axes_95_m", "n_obs", "sigma0",
                                 "error_rms_m", "interpoint_std_se_m", "ellipsoid_coverage_lin_max", "seed",
                                 "sensitivity_um_per_m", "std_m", "mean_mc_m"])
def test_names_of_the_convention_pass(key):
    assert key_problems(key) == []


@pytest.mark.parametrize("key", ["lin_std_m", "mc_std_m", "u_offset_m", "offset_u_m", "combined_sd_m",
                                 "seed_entropy", "max_std_m", "mean_error_m", "rms_residual_m", "scale_u",
                                 "offsetStd", "sim_std_m", "std_offset_m", "interpoint_std_sem_m"])
def test_names_outside_the_convention_fail(key):
    assert key_problems(key)


def test_no_output_writes_a_replaced_name():
    """The replaced names are gone from the package's code (quoted as keys or CSV columns); the one
    exception is ``u_m``, the reference-length *input* column (its outputs are ``length_std_m``)."""
    allowed = {("u_m", "network/files.py"), ("u_m", "network/data.py")}
    hits = []
    for p in (ROOT / "src" / "multilat").rglob("*.py"):
        rel = p.relative_to(ROOT / "src" / "multilat").as_posix()
        if rel == "vocabulary.py":
            continue
        text = p.read_text()
        for old in RENAMED:
            if re.search(r"[\"']" + re.escape(old) + r"[\"']", text) and (old, rel) not in allowed:
                hits.append(f"{rel}: {old}")
    assert hits == []


def test_out_files_carry_the_schema(tmp_path, capsys):
    ex = ROOT / "examples" / "network"
    assert main(["adjust", str(ex / "small_volume_obs.csv"), "--out", str(tmp_path / "a"), "--tables", "csv"]) == 0
    doc = json.loads((tmp_path / "a" / "result.json").read_text())
    assert doc["schema"] == "multilat.adjust/2"
    assert _validator("adjust").is_valid(doc)
    assert main(["propagate", "small-volume", "--trials", "1000", "--out", str(tmp_path / "p")]) == 0
    doc = json.loads((tmp_path / "p" / "summary.json").read_text())
    assert doc["schema"] == f"multilat.propagate/{schema_version('propagate')}"
    assert _validator("propagate").is_valid(doc)
    assert main(["lbb", "simulate", "--trials", "200", "--out", str(tmp_path / "l")]) == 0
    doc = json.loads((tmp_path / "l" / "summary.json").read_text())
    assert _validator("lbb-simulate").is_valid(doc)
    capsys.readouterr()
    # and every CSV column written follows the same convention
    bad = []
    for csv in sorted(tmp_path.rglob("*.csv")):
        header = next(ln for ln in csv.read_text().splitlines() if ln and not ln.startswith("#"))
        bad += [f"{csv.name}: {p}" for col in header.split(",") for p in key_problems(col)]
    assert len(list(tmp_path.rglob("*.csv"))) >= 6 and bad == []


def test_the_conventions_page_lists_every_replaced_name():
    text = (ROOT / "docs" / "conventions.md").read_text()
    rows = dict(re.findall(r"^\| `([a-z0-9_]+)` \| `([a-z0-9_]+)` \|$", text, flags=re.M))
    assert rows == RENAMED
