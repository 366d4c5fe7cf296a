"""The frame of each datum in words, worded once (:mod:`multilat.network.model.frame_words`) and the same
string in the JSON (``frame``), the terminal summary and the HTML report; and the default σ named:
a file without ``sigma_m`` adjusted without ``--sigma-um`` or ``--instrument`` gets one ``warning:``
line (stderr and the JSON ``warnings``), a file with a σ source none.

On the small-volume example (4 heads, 14 targets): free over all points, free over a subset, 3-2-1
with scale factors and scale bars, weighted control with the truth's coordinates (+ N(0, 30 µm)).
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np
import pytest

from test_job_report import _run

EX = Path(__file__).resolve().parents[1] / "examples" / "network"
OBS, REFS, TRUTH = EX / "small_volume_obs.csv", EX / "small_volume_refs.csv", EX / "small_volume_truth.csv"


def _control(tmp: Path) -> Path:
    """Three stations and a target as weighted control: truth + N(0, 30 µm), σ 30 µm, seed 3."""
    from multilat.network.io.files import read_points

    t = read_points(TRUTH)
    rng = np.random.default_rng(3)
    rows = ["point,x_m,y_m,z_m,sx_m,sy_m,sz_m"]
    for p in ("A", "B", "C", "5"):
        rows.append(p + "," + ",".join(f"{v:.9f}" for v in t.get(p) + rng.normal(0, 30e-6, 3)) + ",3e-5,3e-5,3e-5")
    (tmp / "ctrl.csv").write_text("\n".join(rows) + "\n")
    return tmp / "ctrl.csv"


def _without_sigma(tmp: Path) -> Path:
    """The example's observations without the sigma_m column."""
    lines = [ln for ln in OBS.read_text().splitlines() if not ln.startswith("#")]
    (tmp / "nosigma.csv").write_text("\n".join(ln.rsplit(",", 1)[0] for ln in lines) + "\n")
    return tmp / "nosigma.csv"


CASES = {
    "free": ([], "free", "that of the initial values (distances"),
    "free-subset": (["--datum", "free:1,5,9,14"], "free", "over the datum points 1, 5, 9, 14"),
    "321-bars": (["--datum", "321:A,B,C", "--scales", "--references", str(REFS), "--scale-bars"], "321",
                 "A is the origin, B is on the +x axis, C is in the xy-plane (y > 0)"),
    "control": (["--datum", "control", "--points", "CTRL"], "control", "the frame of the control coordinates"),
}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """{case: (doc, summary stdout, report text)}: each case run once with --json --report and once
    for the terminal summary."""
    tmp = tmp_path_factory.mktemp("frame")
    ctrl = _control(tmp)
    got = {}
    for name, (args, _, _) in CASES.items():
        args = [str(ctrl) if a == "CTRL" else a for a in args]
        page = tmp / f"{name}.html"
        rc, out, err = _run(["adjust", str(OBS), *args, "--json", "--report", str(page)])
        assert rc == 0, (name, err)
        rc, summary, err2 = _run(["adjust", str(OBS), *args])
        assert rc == 0, (name, err2)
        got[name] = (json.loads(out), summary, html.unescape(page.read_text(encoding="utf-8")))
    return got


def _line(text: str, key: str) -> str:
    """The summary item ``  key: ...``: its line and the lines the console wrapped it onto (at a
    space, or after a hyphen; unindented), joined again."""
    lines = text.splitlines()
    hits = [k for k, ln in enumerate(lines) if ln.startswith(f"  {key}: ")]
    assert len(hits) == 1, (key, text[:2000])
    k = hits[0]
    out = [lines[k][len(f"  {key}: "):]]
    for ln in lines[k + 1:]:
        if not ln or ln.startswith(" "):
            break
        out.append(ln)
    # a wrapped line keeps its trailing space, except where it filled the width (then it was dropped)
    return "".join(p + ("" if p.endswith(("-", " ")) or k == len(out) - 1 else " ")
                   for k, p in enumerate(out))


@pytest.mark.parametrize("name", list(CASES))
def test_frame_words_equal_in_json_summary_and_report(runs, name):
    doc, summary, page = runs[name]
    _, kind, words = CASES[name]
    fr = doc["frame"]
    assert fr["kind"] == kind and words in fr["axes"], fr
    assert _line(summary, "frame") == fr["axes"] and _line(summary, "scale") == fr["scale"]
    assert f"frame: {fr['axes']}" in page and f"scale: {fr['scale']}" in page
    if kind != "control":       # the datum choice moves the coordinates, not the distances (said so)
        assert "distances between points, offsets, scales and σ0 do not" in fr["axes"]


def test_frame_words_say_what_the_numbers_do(runs):
    """The words are true of the coordinates: 3-2-1 puts A at the origin, B on +x, C in the xy-plane;
    the scale with scale factors comes from the bars; without bars, from the distances."""
    doc = runs["321-bars"][0]
    a, b, c = (np.array(doc["stations"][s]["xyz_m"]) for s in "ABC")
    assert np.allclose(a, 0, atol=1e-12) and np.allclose(b[1:], 0, atol=1e-12) and abs(c[2]) < 1e-12
    assert b[0] > 0 and c[1] > 0
    assert "scale factors estimated for heads A, B, C, D" in doc["frame"]["scale"]
    assert doc["frame"]["scale"] != runs["free"][0]["frame"]["scale"]
    assert runs["free"][0]["frame"]["scale"] == "the distances (no head has a scale factor)"
    assert "free network, inner constraints over 1, 5, 9, 14" == runs["free-subset"][0]["datum"]


SIGMA_WARNING = "no σ given (no sigma_m column, no --sigma-um, no --instrument)"


@pytest.mark.parametrize("extra, warned", [([], True), (["--sigma-um", "4.7"], False),
                                           (["--instrument", "seed2020"], False), (None, False)])
def test_default_sigma_is_named_once(tmp_path, extra, warned):
    """The default instrument's distance model weights a file without sigma_m only with a warning
    naming --sigma-um and --instrument; with a σ source (the option, the instrument, the file's
    column: ``None`` runs the file with sigma_m) there is none. The σ are the same numbers either way
    (seed2020's model), only said."""
    path = OBS if extra is None else _without_sigma(tmp_path)
    rc, out, err = _run(["adjust", str(path), *(extra or []), "--json"])
    assert rc == 0, err
    doc = json.loads(out)
    lines = [ln for ln in err.splitlines() if SIGMA_WARNING in ln]
    assert len(lines) == (1 if warned else 0), err
    if warned:
        assert lines[0].startswith("warning: ") and "--sigma-um" in lines[0] and "--instrument" in lines[0]
        assert "'seed2020'" in lines[0] and doc["sigma_source"]["defaulted"] is True
    assert sum(SIGMA_WARNING in w for w in doc["warnings"]) == (1 if warned else 0)
    rc, out, err = _run(["adjust", str(path), *(extra or [])])          # the summary run: once too
    assert rc == 0 and sum(SIGMA_WARNING in ln for ln in err.splitlines()) == (1 if warned else 0)


GAMA = Path(__file__).resolve().parent / "data" / "gama3d"


@pytest.mark.parametrize("name, kind, words", [
    ("trilateration_free", "free", "approximate coordinates given for the datum points"),
    ("trilateration_fixed", "control", "the frame of the given coordinates (datum given by"),
])
def test_general_path_frame_in_the_same_vocabulary(name, kind, words):
    """The general path's JSON carries ``frame`` with the same keys, worded in frame_words.py; its
    ``datum`` sentence is the one of the control words (not a second wording)."""
    rc, out, err = _run(["adjust", str(GAMA / f"{name}.xml"), "--json"])
    assert rc == 0, err
    doc = json.loads(out)
    assert set(doc["frame"]) == {"kind", "axes", "scale"} and doc["frame"]["kind"] == kind
    assert words in doc["frame"]["axes"], doc["frame"]
    if kind == "control":
        assert doc["frame"]["axes"].endswith(f"(datum {doc['datum']})")
    schema = json.loads((Path(__file__).resolve().parents[1] / "src" / "multilat" / "schemas"
                         / "adjust-general.json").read_text("utf-8"))
    assert "frame" in schema["required"]
    jsonschema = pytest.importorskip("jsonschema")
    jsonschema.validate(doc, schema)
