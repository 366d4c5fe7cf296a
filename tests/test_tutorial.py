"""docs/tutorial.md ("Your own network") cannot go stale: every command of its ```` ```bash run ````
blocks is run, in order, in a copy of examples/tutorial/, and must exit 0; every number the page quotes
is rendered here from the JSON those commands wrote, at the precision the page quotes it, and must
appear in the page's text (whitespace-normalised). The installed entry point runs one command in a
subprocess; the example files are their generator's output; the README keeps its set-up lines and links.

Independent values beside the page's: dof by counting unknowns, the control datum's 6 extra dof,
the JAG3D round trip equal to the direct adjustment, the Monte Carlo's linear σ of an offset equal to
`adjust`'s. The commands run in-process (``multilat.cli.main``) so the whole module takes ~20 s.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import multilat
from multilat.cli import main

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "tutorial.md"
EX = ROOT / "examples" / "tutorial"
SRC = Path(multilat.__file__).resolve().parents[1]
CONTROL = "P01,P02,P05,P09"


def commands(text: str) -> list[str]:
    """The command lines of every ```bash run block, continuation lines (trailing backslash) joined."""
    out = []
    for block in re.findall(r"^```bash run\n(.*?)^```", text, flags=re.S | re.M):
        for line in block.replace("\\\n", " ").splitlines():
            if line.strip() and not line.lstrip().startswith("#"):
                out.append(line.strip())
    return out


def _run(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(argv)
    return rc, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def ran(tmp_path_factory):
    """Copy the example, run every command of the page in it; (directory, {command: stdout})."""
    root = tmp_path_factory.mktemp("tutorial")  # the reader's checkout: my-network beside examples/
    work = root / "my-network"
    shutil.copytree(EX, work, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(ROOT / "examples" / "instruments", root / "examples" / "instruments")
    cwd = os.getcwd()
    os.chdir(work)
    outputs = {}
    try:
        for cmd in commands(PAGE.read_text(encoding="utf-8")):
            argv = shlex.split(cmd)
            assert argv[0] == "multilat", f"not a multilat command: {cmd}"
            rc, out, err = _run(argv[1:])
            assert rc == 0, f"{cmd}: exit {rc}\n{err}"
            outputs[cmd] = out
    finally:
        os.chdir(cwd)
    return work, outputs


def _page() -> str:
    return " ".join(PAGE.read_text(encoding="utf-8").split())


def _said(text: str) -> None:
    """The page says ``text`` (whitespace-normalised)."""
    assert " ".join(text.split()) in _page(), f"docs/tutorial.md does not say (any more): {text!r}"


def _json(work: Path, rel: str) -> dict:
    return json.loads((work / rel).read_text(encoding="utf-8"))


def _um(x_m: float) -> float:
    return x_m * 1e6


def test_page_has_the_commands_of_every_step():
    cmds = commands(PAGE.read_text(encoding="utf-8"))
    words = " ".join(cmds)
    for needed in ("multilat adjust obs.csv", "--report", "--json", "--datum control", "--model general",
                   "multilat propagate", "multilat design", "multilat export", "multilat import"):
        assert needed in words, needed
    assert len(cmds) >= 12


def test_every_command_runs_and_the_outputs_exist(ran):
    work, outputs = ran
    assert set(commands(PAGE.read_text(encoding="utf-8"))) == set(outputs)
    from multilat.network.io.files import table_format

    for rel in ("free/result.json", f"free/observations.{table_format('observations', 'auto')}", "hall/result.json", "trackers/result.json",
                "mc/summary.json", "design-now/design.json", "design-next/stations.csv", "net.txt",
                "net-points.txt", "back/distances.csv", "net.xml", "net.dat", "adjust.html"):
        assert (work / rel).is_file(), rel
    doc = json.loads(outputs["multilat adjust obs.csv --json"])
    assert doc["sigma0"] == pytest.approx(_json(work, "free/result.json")["sigma0"], rel=1e-12)


def _sigma0_printed(stdout: str) -> str:
    return re.search(r"σ0 = (\S+) \(ratio", stdout).group(1)


def test_step1_sigma_sources(ran):
    work, outputs = ran
    free = _json(work, "free/result.json")
    out = " ".join(outputs["multilat adjust obs_no_sigma.csv --sigma-um 5"].split())
    assert "σ: 5 µm for every distance (--sigma-um)" in out
    _said("The first says `σ: 5 µm for every distance (--sigma-um)` and gives the σ0 of step 2")
    assert _sigma0_printed(out) == f"{free['sigma0']:.3f}"  # the file's sigma_m column is 5 µm throughout
    out = " ".join(outputs["multilat adjust obs_no_sigma.csv --instrument "
                           "../examples/instruments/heads_and_trackers.toml"].split())
    assert "σ: distance model of instrument" in out and "H6→H6" in out
    _said(f"gives σ0 = {_sigma0_printed(out)}.")
    rc, out, err = _run(["adjust", str(work / "obs.csv"), "--sigma-um", "10", "--json"])
    assert rc == 0 and "ignoring the sigma option" in err
    assert json.loads(out)["sigma0"] == pytest.approx(free["sigma0"], rel=1e-12)


def test_step2_free_network_numbers(ran):
    work, _ = ran
    d = _json(work, "free/result.json")
    g = d["global_test"]
    _said(f"adjusted 6 stations, 15 targets from {d['n_used']}/{d['n_obs']} distances")
    _said(f"σ0 = {d['sigma0']:.3f} ..., dof = {d['dof']}; global χ² test: {g['statistic']:.2f} in "
          f"[{g['critical_low']:.2f}, {g['critical']:.2f}] ...: passed")
    assert g["passed"] and d["datum"].startswith("free network")
    n_unknowns = 6 * 3 + 6 + 15 * 3 - 6  # stations, one offset per head, targets, minus the free datum
    assert d["dof"] == d["n_obs"] - n_unknowns
    _said(f"dof = {d['n_obs']} distances − (6 × 3 + 6 offsets + 15 × 3 − 6 datum) = {d['dof']}")
    poor = d["reliability"]["poor_targets"]
    _said(f"poorly controlled ...: {len(poor)} target(s)")
    _said(f"Worst here is `{poor[0]['id']}`, redundancy {poor[0]['redundancy_min']:.3f}")
    h = d["heads"]
    _said(f"`H1` {_um(h['H1']['offset_m']):+.1f} ± {_um(h['H1']['offset_std_m']):.1f} µm, "
          f"`H2` {_um(h['H2']['offset_m']):+.1f} ± {_um(h['H2']['offset_std_m']):.1f} µm")
    ratio = sorted(v["offset_std_m"] / 5e-6 for v in h.values())
    _said(f"their u is here {ratio[0]:.0f} to {ratio[-1]:.0f} times the distances' σ")
    # the frame of three heads: H1 at the origin, H2 on +x, H4 in the xy-plane
    s = {k: np.array(v["xyz_m"]) for k, v in d["stations"].items()}
    assert np.abs(s["H1"]).max() < 1e-9 and np.abs(s["H2"][1:]).max() < 1e-9 and abs(s["H4"][2]) < 1e-9
    _said(f"(x = {s['H2'][0]:.3f} m)")
    z = [d["targets"][p]["xyz_m"][2] for p in ("P01", "P02", "P03", "P04")]
    _said(f"floor targets come out at z = {min(z):.2f} to {max(z):.2f} m")


def test_step3_report_sections(ran):
    work, _ = ran
    html = (work / "adjust.html").read_text(encoding="utf-8")
    for key, words in (("verdicts", "Verdicts and key numbers"), ("reliability", "Reliability"), ("heads", "Heads"),
                       ("angles", "Angles and orientations"), ("bars", "Scale bars and control"),
                       ("frame", "Frame and datum"), ("coordinates", "Coordinates"), ("run", None)):
        assert f'<h2 id="{key}">' in html, key
        if words:
            _said(f"**{words}**")


def test_step4_control_numbers(ran):
    work, _ = ran
    d, free = _json(work, "hall/result.json"), _json(work, "free/result.json")
    assert d["datum"] == f"fixed control points {CONTROL.replace(',', ', ')}"
    _said(f"The summary now says `{d['datum']}`")
    x, y, z = d["stations"]["H1"]["xyz_m"]
    h1 = d["heads"]["H1"]
    _said(f"`H1` comes out at ({x:.3f}, {y:.3f}, {z:.3f}) m, where it stood, with offset "
          f"{_um(h1['offset_m']):+.1f} ± {_um(h1['offset_std_m']):.1f} µm. σ0 = {d['sigma0']:.3f} on dof = {d['dof']}:")
    truth = {r[0]: np.array(r[1:], float) for r in
             (line.split(",") for line in (EX / "truth.csv").read_text().splitlines()[1:])}
    assert np.abs(np.array([x, y, z]) - truth["H1"]).max() < 3e-4  # where it stood (its 95 % semi-axis ~0.16 mm)
    assert d["dof"] - free["dof"] == 6  # 12 control coordinates, 6 of them the datum


def test_step4_control_alone_gives_the_hall_as_the_page_says(ran, tmp_path):
    """The page's note: the four control points alone (no rough coordinates of the rest) give the same
    network, in the right hand: the distances' initial values are fitted onto the points as they are
    and as their mirror image, the smaller misfit taken (before the fix: refused as 'inconsistent ...
    P01 342.82 mm', and H1 at z = -5.93 m under the free datum)."""
    work, _ = ran
    lines = (work / "points.csv").read_text().splitlines()
    (tmp_path / "control.csv").write_text("\n".join(lines[:5]) + "\n")
    rc, _, err = _run(["adjust", str(work / "obs.csv"), "--points", str(tmp_path / "control.csv"),
                       "--datum", f"control:{CONTROL}", "--out", str(tmp_path / "ctl")])
    assert rc == 0, err
    c = _json(tmp_path, "ctl/result.json")
    truth = {r[0]: np.array(r[1:], float) for r in
             (line.split(",") for line in (EX / "truth.csv").read_text().splitlines()[1:])}
    for sid, st in c["stations"].items():   # where they stood, within 4 u (the hall's frame held)
        u = np.sqrt(np.diag(st["cov_m2"]))
        assert np.all(np.abs(np.array(st["xyz_m"]) - truth[sid]) < 4 * u + 1e-9), sid
    h = c["initial"]["handedness"]
    assert h["decided"] and h["points"] == CONTROL.split(",") and not c["ambiguous"]
    _said(f"the right hand fits them to {h['misfit_rms_m'] * 1e6:.1f} µm RMS, its mirror image to "
          f"{h['mirror_misfit_rms_m'] * 1e3:.0f} mm")
    x, y, z = c["stations"]["H1"]["xyz_m"]
    _said(f"`H1` at ({x:.3f}, {y:.3f}, {z:.3f}) m as before")


def test_step5_trackers_numbers(ran):
    work, _ = ran
    d = _json(work, "trackers/result.json")
    p = d["parameters"]
    o1, o2 = p["offset:T1"], p["offset:T2"]
    _said(f"σ0 = {d['sigma0']:.3f}, dof = {d['dof']}; the additive constants are "
          f"T1 {_um(o1['value']):+.1f} ± {_um(o1['std']):.1f} µm and T2 {_um(o2['value']):+.1f} ± {_um(o2['std']):.1f} µm")
    truth = dict(line.split(",") for line in (EX / "offsets_truth.csv").read_text().splitlines()[1:])
    _said(f"simulated {float(truth['T1']):+.0f} and {float(truth['T2']):.0f} µm: T1 is "
          f"{abs(_um(o1['value']) - float(truth['T1'])) / _um(o1['std']):.1f} u off")
    _said(f"T2's heading relative to T1 is {p['kappa:T2']['value'] - p['kappa:T1']['value']:.5f} rad")
    c = _json(work, "trackers-hall/result.json")
    t1 = c["parameters"]["offset:T1"]
    assert c["datum"] == f"given by 4 fixed point(s) ({CONTROL.replace(',', ', ')})"
    _said(f"hall's frame: `{c['datum'].split(' (')[0]}` in the `datum:` line, dof = {c['dof']}, "
          f"T1 {_um(t1['value']):+.1f} ± {_um(t1['std']):.1f} µm")
    assert c["dof"] - d["dof"] == 12 - 4  # 12 control coordinates; the free datum's defect was 4
    for p_id, xyz in (line.split(",", 1) for line in (EX / "points.csv").read_text().splitlines()[1:5]):
        assert c["points"][p_id]["xyz_m"] == pytest.approx([float(v) for v in xyz.split(",")], abs=1e-12)
    assert np.abs(d["points"]["T1"]["xyz_m"]).max() < 1e-3  # T1's frame (minimum trace moves it by µm)
    assert d["global_test"]["passed"]


def test_step6_monte_carlo_numbers(ran):
    work, _ = ran
    d, hall = _json(work, "mc/summary.json"), _json(work, "hall/result.json")
    s = d["summary"]
    _said(f"{s['n_agree']}/{s['n_quantities']} agree within 3 Monte Carlo standard errors")
    off = next(q for q in d["parameters"] if q["label"] == "H1.offset")
    _said(f"`H1`'s offset: {_um(off['std_mc_m']):.1f} µm by Monte Carlo, {_um(off['std_lin_m']):.1f} µm linear")
    assert off["std_lin_m"] == pytest.approx(hall["heads"]["H1"]["offset_std_m"], rel=1e-6)  # same model as adjust
    assert d["trials"] == 500 and d["noise"] == "gaussian"


def test_step7_design_numbers(ran):
    work, _ = ran
    now, nxt = _json(work, "design-now/design.json"), _json(work, "design-next/design.json")
    n_t = len(nxt["targets"])
    _said(f"{_um(now['criterion_m']):.2f} µm where the heads stood this time, {_um(nxt['criterion_m']):.2f} µm "
          f"where the search puts them; poorly controlled targets drop from "
          f"{now['poorly_controlled']['n_targets']} to {nxt['poorly_controlled']['n_targets']} of {n_t}")
    assert nxt["criterion_m"] < now["criterion_m"]


def test_step8_jag3d_round_trip_keeps_the_network(ran):
    work, _ = ran
    back, free = _json(work, "back-adjusted/result.json"), _json(work, "free/result.json")
    assert back["dof"] == free["dof"]
    # JAG3D's file holds the distances to 10 nm: a rounding error δ of rms 10 nm / √12 = 2.9 nm each.
    # An offset is a linear function g·d of the distances with |g| = u(offset) / σ, so it moves by
    # rms |g| × 2.9 nm; Ω = Σ w² by rms 2 √Ω × 2.9 nm / σ, σ0 by half that relative. 5 rms each.
    rms = 1e-8 / np.sqrt(12)
    sigma = 5e-6
    rel = 0.5 * 2 * np.sqrt(free["sigma0"] ** 2 * free["dof"]) * rms / sigma / (free["sigma0"] ** 2 * free["dof"])
    assert back["sigma0"] == pytest.approx(free["sigma0"], rel=5 * rel)
    for h, v in free["heads"].items():
        assert back["heads"][h]["offset_m"] == pytest.approx(v["offset_m"], abs=5 * v["offset_std_m"] / sigma * rms)
    _said(f"the same σ0 = {back['sigma0']:.3f} and dof = {back['dof']}")


def test_installed_entry_point_runs_the_first_command(ran, tmp_path):
    """The README's way: the console script of the environment (else the same entry function)."""
    work, _ = ran
    script = Path(sys.executable).with_name("multilat")
    argv = [str(script)] if script.is_file() else [sys.executable, "-c", "from multilat.cli import run; run()"]
    env = dict(os.environ, PYTHONPATH=str(SRC), OPENBLAS_NUM_THREADS="1")
    r = subprocess.run([*argv, "adjust", "obs.csv", "--json"], capture_output=True, text=True, env=env,
                       cwd=work, timeout=300)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["sigma0"] == pytest.approx(_json(work, "free/result.json")["sigma0"], rel=1e-12)


def test_example_files_are_the_generators_output(tmp_path):
    spec = importlib.util.spec_from_file_location("tutorial_generate", EX / "generate.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main(tmp_path)
    written = sorted(p.name for p in tmp_path.iterdir())
    assert written == sorted(p.name for p in EX.glob("*.csv"))
    for name in written:
        assert (tmp_path / name).read_bytes() == (EX / name).read_bytes(), name


def test_readme_says_how_to_run_and_links_the_pages():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    for line in ("make demo", "make test", ". .venv/bin/activate", ".venv/bin/multilat"):
        assert line in readme, line
    for link in ("docs/tutorial.md", "docs/config-reference.md", "docs/architecture.md"):
        assert f"]({link})" in readme, link
        assert (ROOT / link).is_file()
    assert (ROOT / "Makefile").read_text().count("demo:") >= 1
