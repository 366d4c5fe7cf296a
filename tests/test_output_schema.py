"""One vocabulary and a contract for every command's ``--json`` (issue 13 item 2, issue 27 item 5).

Every sample run of :data:`SAMPLES` (each command on the shipped examples, with the options and inputs
that add keys: blunders rejected and unlocatable, variance components, target selection, the adaptive
Monte Carlo, in Python: :func:`test_an_adaptive_propagation_follows_the_model`) must (a) carry ``"schema"`` first, equal to :func:`multilat.vocabulary.schema_id`,
(b) validate with its typed model (:mod:`multilat.schemas.models`, strict: undeclared keys and wrong
types refused) and against the shipped JSON Schema (jsonschema, draft 2020-12), and (c) use only names of
the convention (:func:`multilat.vocabulary.document_problems`). The shipped schema files are what the
models generate (regenerate with ``python tools/write_schemas.py``); a run with ``--out DIR`` has its
``DIR/result.json`` checked too. The mutation tests show that each check fails on the faults it is there for.
"""

from __future__ import annotations

import contextlib
import copy
import io
import json
import re
from pathlib import Path

import pytest
from pydantic import ValidationError

from multilat.cli import main
from multilat.schemas import COMMANDS, generate, load, schema_id
from multilat.schemas.models import MODELS, model
from multilat.vocabulary import RENAMED, document_problems, key_problems
from multilat.vocabulary import schema_id as stamped_id

ROOT = Path(__file__).resolve().parents[1]
_EX = ROOT / "examples"
_N = _EX / "network"
_G = ROOT / "tests" / "data" / "gama3d"
_INTEROP = ROOT / "tests" / "data" / "interop"

#: command -> argument lists of its sample runs (``{tmp}``: the run's directory; ``{NAME}``: an input
#: made there by :func:`_prepare`)
SAMPLES = {
    "adjust": [["adjust", f"{_N}/small_volume_obs.csv", "--references", f"{_N}/small_volume_refs.csv"],
               ["adjust", f"{_N}/sequential/obs.csv", "--variance-components", "head"],
               ["adjust", f"{_N}/mixed/obs.csv", "--variance-components", "kind"],
               ["adjust", str(ROOT / "tests" / "data" / "angles" / "mixed_azimuth_blunder.csv")],
               ["adjust", f"{_EX}/campaign/raw.csv", "-e", f"{_EX}/campaign/environment.csv", "--heights",
                f"{_EX}/campaign/heights.csv", "--average-repeats"],
               ["adjust", f"{_N}/small_volume_obs.csv", "--observations", "--out", "{tmp}/adj", "--tables", "csv"],
               ["adjust", str(ROOT / "tests" / "data" / "network" / "weak_target.csv")],
               ["adjust", "{blunder.csv}"],
               ["adjust", "{unlocated.csv}", "--points", f"{_N}/small_volume_points.csv"],
               ["adjust", f"{_N}/sequential/obs.csv", "--references", "{bars.csv}", "--scale-bars", "--points",
                "{ctrl.csv}", "--datum", "control", "--out", "{tmp}/bars"],
               ["adjust", f"{_N}/small_volume_obs.csv", "--references", f"{_N}/small_volume_refs.csv",
                "--scale-bars", "--scales", "--variance-factor", "unknown"],
               ["adjust", f"{_N}/small_volume_obs.csv", "--datum", "321:A,B,C", "--no-snooping", "--cost",
                "squared"],
               ["adjust", "{coplanar.csv}"]],
    "adjust-general": [["adjust", f"{_G}/direction_sets.xml"], ["adjust", f"{_G}/vectors.xml"],
                       ["adjust", f"{_G}/partly_fixed.xml", "--variance-factor", "unknown"],
                       ["adjust", f"{_G}/two_trackers.xml"],
                       ["adjust", f"{_EX}/general/station_control.xml", "--variance-components", "kind"],
                       ["adjust", f"{_EX}/general/station_control_files"],
                       ["adjust", f"{_EX}/general/two_trackers_csv/obs.csv", "--model", "general", "--levelled",
                        "T1,T2"],
                       ["adjust", f"{_N}/sequential/obs.csv", "--model", "general", "--variance-components",
                        "head"],
                       ["adjust", "{blunder.xml}"], ["adjust", "{unlocated.xml}"],
                       ["adjust", f"{_EX}/tutorial/obs_no_sigma.csv", "--model", "general", "--points",
                        f"{_EX}/tutorial/points.csv", "--instrument", f"{_EX}/instruments/heads_and_trackers.toml"]],
    "propagate": [["propagate", "small-volume", "--trials", "2000"],
                  ["propagate", f"{_N}/sequential/obs.csv", "--trials", "1000", "--noise", "gaussian"],
                  ["propagate", f"{_EX}/campaign/raw.csv", "-e", f"{_EX}/campaign/environment.csv",
                   "--heights", f"{_EX}/campaign/heights.csv", "--trials", "1000",
                   "--average-repeats", "--instrument", "seed2020"],
                  ["propagate", "small-volume", "--trials", "1000", "--instrument", "seed2020"]],
    "propagate-general": [["propagate", f"{_G}/direction_sets.xml", "--trials", "300"],
                          ["propagate", f"{_EX}/general/two_trackers.xml", "--trials", "300"],
                          ["propagate", f"{_EX}/general/two_trackers_csv/obs.csv", "--model", "general",
                           "--levelled", "T1,T2", "--trials", "300"]],
    "simulate": [["simulate", "small-volume", "--trials", "5"]],
    "design": [["design", f"{_EX}/design/cube.toml"], ["design", f"{_EX}/design/cube.toml", "--simulate", "500"],
               ["design", "{select.toml}"]],
    "design-general": [["design", "--evaluate", f"{_G}/two_trackers.xml"],
                       ["design", "--evaluate", f"{_G}/direction_sets.xml"],
                       ["design", "--evaluate", f"{_G}/vectors.xml"]],
    "budget": [["budget", "--trials", "2000"], ["budget", "--trials", "2000", "--air", "--seed", "3"]],
    "air": [["air"], ["air", "--instrument", "seed2020", "--dew-point-c", "5"]],
    "correct": [["correct", f"{_EX}/campaign/raw.csv", "-e", f"{_EX}/campaign/environment.csv", "--heights",
                 f"{_EX}/campaign/heights.csv"]],
    "two-face": [["two-face", f"{_EX}/campaign/two_face.csv"]],
    "lbb-trilaterate": [["lbb", "trilaterate", f"{_EX}/lbb/edges.csv"]],
    "lbb-simulate": [["lbb", "simulate", "--trials", "200"]],
    "lbb-compare": [["lbb", "compare", f"{_EX}/lbb/m60_edges.csv", f"{_EX}/lbb/m60_reference.csv"]],
    "export": [["export", "jag3d", f"{_N}/small_volume_obs.csv", "--points", f"{_N}/small_volume_points.csv",
                "-o", "{tmp}/x.txt"]],
    "import": [["import", "gama-adjusted", str(_INTEROP / "small_volume_gama_out.xml"), "-o", "{tmp}/imp"],
               ["import", "gama-adjusted", str(_INTEROP / "levelled_mixed_gama_out.xml"), "-o", "{tmp}/imp2"],
               ["import", "starnet", str(_INTEROP / "small_volume.dat"), "-o", "{tmp}/imp3"],
               ["import", "gama", f"{_G}/heights.xml", "-o", "{tmp}/imp4"],
               ["import", "gama", f"{_G}/two_trackers.xml", "-o", "{tmp}/imp5"]],
}


def _prepare(name: str, tmp: Path) -> Path:
    """An input made from a shipped one: ``blunder.xml`` (a slope distance of direction_sets.xml + 25 mm,
    20 σ: rejected by data snooping), ``unlocated.xml`` (a height difference of height_differences.xml
    + 20 mm: its w-test equals its neighbour's, not located), ``select.toml`` (cube.toml with the fewest
    targets for a wanted U95); for ``adjust``: ``blunder.csv`` (a distance of sequential/obs.csv + 100 µm,
    20 σ: rejected), ``unlocated.csv`` (C->9 of the small volume + 94 µm, 20 σ: its target's 4 w-tests
    are perfectly correlated, not located), ``bars.csv`` (two reference lengths of the sequential
    network, true to 1 µm, σ 3 µm), ``ctrl.csv`` (four of its points, true, σ 30 µm per axis) and
    ``coplanar.csv`` (6 stations, 20 targets in one plane: every station mirror-ambiguous)."""
    if name == "coplanar.csv":                  # every target in one plane: the stations mirror-ambiguous
        from test_ambiguous_geometry import _network

        from multilat.network.io.files import write_observations

        write_observations(tmp / name, _network()[0])
        return tmp / name
    if name in ("bars.csv", "ctrl.csv"):
        rows = {r.split(",")[0]: r for r in (_N / "sequential" / "truth.csv").read_text().splitlines()[1:]}
        text = ("target_a,target_b,length_m,u_m\nP1,P7,0.449172,3e-6\nP3,P12,0.933467,3e-6\n" if name == "bars.csv"
                else "point,x_m,y_m,z_m,sx_m,sy_m,sz_m\n" + "".join(rows[p] + ",3e-5,3e-5,3e-5\n"
                                                                    for p in ("S1", "S4", "S6", "P5")))
        (tmp / name).write_text(text, "utf-8")
        return tmp / name
    edits = {"blunder.xml": (_G / "direction_sets.xml", 'val="225.758826"', 'val="225.783826"'),
             "unlocated.xml": (_G / "height_differences.xml", 'val="1.300213"', 'val="1.320213"'),
             "select.toml": (_EX / "design" / "cube.toml", 'name = "max_u95"',
                             'name = "max_u95"\ntarget_u95_m = 1.0e-4'),
             "blunder.csv": (_N / "sequential" / "obs.csv", "S1,P2,T1,2.687464099,", "S1,P2,T1,2.687564099,"),
             "unlocated.csv": (_N / "small_volume_obs.csv", "C,9,0.5948152,", "C,9,0.5949092,")}
    src, old, new = edits[name]
    text = src.read_text("utf-8")
    assert text.count(old) == 1, (src, old)
    (tmp / name).write_text(text.replace(old, new), "utf-8")
    return tmp / name


def run_sample(args, tmp: Path) -> dict:
    """Run ``multilat ARGS --json`` in-process and return its document."""
    def arg(a):
        m = re.fullmatch(r"\{([\w.]+\.\w+)\}", a)
        return str(_prepare(m.group(1), tmp)) if m else a.replace("{tmp}", str(tmp))

    args = [arg(a) for a in args] + ["--json"]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(args)
    if rc != 0:
        raise RuntimeError(f"multilat {' '.join(args)} exited {rc}: {err.getvalue().strip()[-300:]}")
    return json.loads(out.getvalue())


_DOCS: dict = {}


def _doc(cmd, i, tmp_path):
    """The ``--json`` document of sample ``i`` of ``cmd``; a run with ``--out DIR`` also leaves
    ``DIR/result.json`` (``_DOCS[(cmd, i, "out")]``)."""
    if (cmd, i) not in _DOCS:
        d = tmp_path / f"{cmd}-{i}"
        d.mkdir()
        args = SAMPLES[cmd][i]
        _DOCS[(cmd, i)] = run_sample(args, d)
        if "--out" in args and cmd == "adjust":
            out = Path(args[args.index("--out") + 1].replace("{tmp}", str(d)))
            _DOCS[(cmd, i, "out")] = json.loads((out / "result.json").read_text("utf-8"))
    return _DOCS[(cmd, i)]


def _validator(cmd):
    jsonschema = pytest.importorskip("jsonschema")
    return jsonschema.Draft202012Validator(load(cmd))


CASES = [(c, i) for c in SAMPLES for i in range(len(SAMPLES[c]))]


@pytest.mark.parametrize("cmd,i", CASES, ids=[f"{c}-{i}" for c, i in CASES])
def test_every_command_json_follows_its_model_schema_and_the_vocabulary(cmd, i, tmp_path):
    docs = [_doc(cmd, i, tmp_path)] + ([_DOCS[(cmd, i, "out")]] if (cmd, i, "out") in _DOCS else [])
    for doc in docs:                                # stdout's and, with --out, DIR/result.json
        assert doc["schema"] == stamped_id(cmd)
        assert list(doc)[0] == "schema"
        model(cmd).model_validate(doc)              # strict: raises on an undeclared key or a wrong type
        errors = sorted(_validator(cmd).iter_errors(doc), key=lambda e: list(e.path))
        assert not errors, "; ".join(f"{list(e.path)}: {e.message[:120]}" for e in errors[:5])
        assert document_problems(doc) == []
    if len(docs) == 2:                              # the file is the printed document (both list the tables)
        assert docs[1]["tables"] and docs[1] == docs[0]


def test_the_samples_reach_the_optional_parts(tmp_path):
    """The samples exercise what only some runs write, so the models are checked on it."""
    ag = [_doc("adjust-general", i, tmp_path) for i in (4, 6, 8, 9)]
    assert ag[2]["outliers"] and ag[3]["unlocated"] and ag[0]["variance_components"]
    assert "azimuth_sense" in ag[1]
    assert "target_selection" in _doc("design", 2, tmp_path) and "simulation" in _doc("design", 1, tmp_path)
    assert "readings" in _doc("propagate", 2, tmp_path)
    ad = [_doc("adjust", i, tmp_path) for i in range(len(SAMPLES["adjust"]))]
    assert ad[0]["reference_lengths"] and ad[1]["variance_components"] and ad[2]["angles"]
    assert ad[3]["angle_outliers"] and ad[3]["azimuth_sense"] and ad[4]["with_correlations"] and ad[4]["repeats"]
    assert ad[5]["observation_counts"]["listing"] == "all" and ad[6]["excluded"] and ad[6]["excluded_observations"]
    assert ad[7]["outliers"] and ad[8]["unlocated"] and ad[8]["w_failures"]
    assert ad[9]["scale_bars"] and ad[9]["weighted_control"] and _DOCS[("adjust", 9, "out")]["tables"]
    assert ad[10]["tests"]["tau_critical"] is not None and "scale" in next(iter(ad[10]["stations"].values()))
    assert ad[11]["reliability"] is None and ad[11]["global_test"]["statistic"] is None and ad[12]["ambiguous"]
    assert {_doc("import", i, tmp_path)["format"] for i in (0, 2, 3)} == {"gama-adjusted", "starnet", "gama"}


def test_an_adaptive_propagation_follows_the_model(tmp_path):
    """``propagate --adaptive`` on the small volume takes ~40 s at ndigits 2: the same engine at ndigits 1
    (3 batches), its document written as the CLI writes it (the CLI's keys around it)."""
    from multilat.io import dumps_json
    from multilat.network.synthetic.configs import small_volume
    from multilat.network.montecarlo.propagate import problem_from_config, propagate

    res = propagate(problem_from_config(small_volume(), sigma_m=4.7e-6, source="small-volume"), adaptive=True,
                    ndigits=1, rng=3, noise="gaussian", keep_samples=False)
    doc = json.loads(dumps_json(dict(_doc("propagate", 1, tmp_path), **res.to_dict())))
    assert doc["adaptive"]["converged"] and doc["adaptive"]["batches"] >= 2
    model("propagate").model_validate(doc)
    assert _validator("propagate").is_valid(doc)
    doc["adaptive"]["batches"] = 2.5
    with pytest.raises(ValidationError):
        model("propagate").model_validate(doc)


def test_every_command_has_a_schema_a_model_and_a_sample():
    jsonschema = pytest.importorskip("jsonschema")
    assert set(SAMPLES) == set(COMMANDS)
    assert set(MODELS) == set(COMMANDS)
    for c in COMMANDS:
        s = load(c)
        assert s["$id"] == stamped_id(c)
        jsonschema.Draft202012Validator.check_schema(s)
    for c in MODELS:
        assert schema_id(model(c)) == stamped_id(c)


@pytest.mark.parametrize("cmd", sorted(MODELS))
def test_shipped_schemas_are_generated_from_the_models(cmd):
    """The shipped file is its model's schema (``python tools/write_schemas.py`` rewrites it)."""
    assert load(cmd) == generate(cmd), f"{cmd}.json differs from its model: run tools/write_schemas.py"
    assert generate(cmd).get("additionalProperties") is False or cmd == "import"     # import: one of 3


# the faults the contract must refuse: (command, path to an object, key, new value or _DROP)
_DROP = object()
FAULTS = [
    ("propagate-general", [], "new_thing", 1.0),                          # undeclared key, top level
    ("propagate-general", ["summary"], "n_agree", 3.5),                   # a fraction for a count
    ("propagate-general", ["summary"], "n_agree", 3.0),                   # a float for a count (model only)
    ("propagate-general", ["summary"], "n_agree", True),                  # a bool for a count
    ("propagate-general", ["parameters", 0], "std_mc", "1e-6"),           # a string for a number
    ("propagate-general", ["parameters", 0], "interval_shortest", [0.0]),  # an interval of one number
    ("propagate-general", [], "trials", _DROP),                           # a required key missing
    ("propagate-general", [], "schema", "multilat.propagate-general/1"),  # another version
    ("propagate", ["distances", 0], "lin_std_m", 1e-6),                   # undeclared key, nested
    ("propagate", ["points", "*"], "cov_mc_m2", [[0.0] * 3] * 2),           # a 2 x 3 covariance
    ("adjust-general", ["observations", 0], "label", None),               # null for a text
    ("adjust-general", ["points", "*"], "xyz_m", [0.0, 0.0]),             # two coordinates
    ("adjust-general", ["points", "*"], "sigma_0", 1.0),                  # undeclared key in an id map
    ("design-general", ["reliability"], "n_weak", "0"),
    ("design", ["stations", "*"], "head", 1),
    ("budget", [], "seed", 1.5),
    ("adjust-general", ["points", "*"], "cov_m2", [[None] * 3] * 3),     # null in a covariance
    ("air", ["inputs"], "co2_ppm", "450"),
    ("import", [], "format", "other"),
    ("import", [], "dof", 3),                                             # gama-adjusted's key on starnet
    ("adjust", [], "schema", "multilat.adjust/1"),                        # the document before the rows' split
    ("adjust", [], "schema", "multilat.adjust/2"),                        # the document before outliers' index
    ("propagate", [], "schema", "multilat.propagate/1"),                  # points a list, not an id map
    ("adjust", [], "observations", _DROP),
    ("adjust", ["targets", "*"], "n_obs", 4.5),
    ("adjust", ["targets", "*"], "n_obs", 4.0),
    ("adjust", ["global_test"], "dof", True),
    ("adjust", ["stations", "*"], "xyz_m", [0.0, 0.0]),
    ("adjust", ["stations", "*"], "cov_m2", [[0.0] * 3] * 2),
    ("adjust", ["targets", "*"], "cov_m2", [[None] * 3] * 3),
    ("adjust", ["targets", "*"], "sigma_0", 1.0),
    ("adjust", ["largest_w", 0], "u_m", 1e-6),                           # a replaced name in a row
    ("adjust", ["reference_lengths", 0], "length_std_m", "4e-6"),
    ("adjust", ["observation_counts"], "listing", "some"),
    ("adjust", ["initial"], "method", None),
]


def _at(doc, path):
    for p in path:
        doc = doc[next(iter(doc))] if p == "*" else doc[p]
    return doc


@pytest.mark.parametrize("cmd,path,key,value", FAULTS, ids=[f"{c}-{k}-{i}" for i, (c, _, k, _v) in enumerate(FAULTS)])
def test_the_contract_refuses_unknown_keys_and_wrong_types(cmd, path, key, value, tmp_path):
    i = 2 if cmd == "import" else 0                                       # import: the starnet document
    doc = copy.deepcopy(_doc(cmd, i, tmp_path))
    model(cmd).model_validate(doc)                                        # the document itself passes
    obj = _at(doc, path)
    if value is _DROP:
        del obj[key]
    else:
        obj[key] = value
    with pytest.raises(ValidationError):
        model(cmd).model_validate(doc)
    if not (type(value) is float and value.is_integer()):     # JSON Schema: 3.0 is an integer (draft 2020-12)
        assert not _validator(cmd).is_valid(doc)


def test_validate_names_the_key_that_breaks_the_contract(tmp_path):
    from multilat.errors import MultilatError
    from multilat.schemas import validate

    doc = copy.deepcopy(_doc("propagate-general", 0, tmp_path))
    validate(doc)                                                # the command from its "schema"
    doc["summary"]["n_agree"] = "all"
    with pytest.raises(MultilatError, match=r"^propagate-general document, key summary\.n_agree: Input should be "
                                            r"a valid integer"):
        validate(doc)
    with pytest.raises(MultilatError, match="not a multilat document"):
        validate({"schema": "other/1"})
    with pytest.raises(MultilatError, match="no document model for 'nothing'"):
        validate({"schema": "multilat.nothing/1"})
    doc = copy.deepcopy(_doc("adjust", 0, tmp_path))
    validate(doc)
    doc["observation_counts"]["n_listed"] = 1.5
    with pytest.raises(MultilatError, match=r"^adjust document, key observation_counts\.n_listed: "):
        validate(doc)


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
    allowed = {("u_m", "network/io/files.py"), ("u_m", "network/model/data.py")}
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
    assert doc["schema"] == stamped_id("adjust") == "multilat.adjust/3"
    assert _validator("adjust").is_valid(doc)
    model("adjust").model_validate(doc)
    assert main(["propagate", "small-volume", "--trials", "1000", "--out", str(tmp_path / "p")]) == 0
    doc = json.loads((tmp_path / "p" / "summary.json").read_text())
    assert doc["schema"] == stamped_id("propagate")
    assert _validator("propagate").is_valid(doc)
    model("propagate").model_validate(doc)
    assert main(["lbb", "simulate", "--trials", "200", "--out", str(tmp_path / "l")]) == 0
    doc = json.loads((tmp_path / "l" / "summary.json").read_text())
    assert _validator("lbb-simulate").is_valid(doc)
    model("lbb-simulate").model_validate(doc)
    xml = str(_G / "two_trackers.xml")                       # the general path's result.json
    assert main(["adjust", xml, "--out", str(tmp_path / "g")]) == 0
    model("adjust-general").model_validate(json.loads((tmp_path / "g" / "result.json").read_text()))
    assert main(["propagate", xml, "--trials", "200", "--out", str(tmp_path / "gp")]) == 0
    model("propagate-general").model_validate(json.loads((tmp_path / "gp" / "result.json").read_text()))
    capsys.readouterr()
    # and every CSV column written follows the same convention
    bad = []
    for csv in sorted(tmp_path.rglob("*.csv")):
        header = next(ln for ln in csv.read_text().splitlines() if ln and not ln.startswith("#"))
        bad += [f"{csv.name}: {p}" for col in header.split(",") for p in key_problems(col)]
    assert len(list(tmp_path.rglob("*.csv"))) >= 6 and bad == []


def _design_out(tmp_path, capsys):
    if "design-out" not in _DOCS:
        assert main(["design", str(_EX / "design" / "cube.toml"), "--out", str(tmp_path / "d")]) == 0
        capsys.readouterr()
        _DOCS["design-out"] = json.loads((tmp_path / "d" / "design.json").read_text())
    return _DOCS["design-out"]


def test_design_out_file_follows_the_model(tmp_path, capsys):
    doc = _design_out(tmp_path, capsys)
    model("design").model_validate(dict({"schema": stamped_id("design")}, **doc))


def test_design_out_file_carries_the_schema(tmp_path, capsys):
    """design.json under --out carries its schema first, like every other --out JSON (it did not)."""
    doc = _design_out(tmp_path, capsys)
    assert list(doc)[0] == "schema" and doc["schema"] == stamped_id("design")
    model("design").model_validate(doc)


def test_the_conventions_page_lists_every_replaced_name():
    text = (ROOT / "docs" / "conventions.md").read_text()
    rows = dict(re.findall(r"^\| `([a-z0-9_]+)` \| `([a-z0-9_]+)` \|$", text, flags=re.M))
    assert rows == RENAMED
