"""multilat's own CSV networks adjusted by the general layer (``multilat adjust obs.csv --model general``,
:mod:`multilat.network.adjust.general.from_tables`).

(a) On networks the default (distance) path accepts — examples/network/mixed (4 heads, 2 unlevelled
    trackers, angles), small_volume (--datum free), sequential (2 heads on 8 stations) — the general
    path equals the old one: σ0 to 1e-6 relative, dof equal, every interpoint distance to 1e-9 m
    (the coordinates differ by the free datum's frame: distances are datum-invariant). Measured:
    σ0 to ~1e-11 relative, distances to ~1e-13 m (both solvers converge to ~1e-12 m).
(b) The three tracker networks the old path refuses by its counting rules, written as CSVs from a
    known truth with seeded noise and adjusted by ``--model general`` (a subprocess): two levelled
    trackers on 15 common targets (free, defect 4); one unlevelled tracker on 5 hard control points
    and 10 polar targets (and the same on weighted control, σ 50 µm: the control's coordinates are
    observations here and in the independent solution); 4 distance-only heads, one levelled tracker
    and 5 polar points (free, defect 4). Against an independent solution written here
    (scipy.optimize.least_squares on closed-form residuals with its own rotation matrices, its own
    datum: the first tracker and its κ held): σ0 to 1e-9 relative, dof by counting, coordinates to 1e-8 m (free networks: after the
    4-parameter transformation, rotation about z and shift, that maps one datum onto the other —
    exact for two solutions of the same problem). Measured: ~1e-11 m.
(c) The CLI: each of these through ``multilat adjust ... --model general --json`` in a subprocess;
    the old path's refusals carry the hint ``--model general``; options the general layer cannot
    honour are refused by name; the JSON validates against the shipped schema
    (src/multilat/schemas/adjust-general.json) with ``points`` and ``parameters`` as id maps.
(d) ``--model auto``'s rule for polar points (docs/general-network.md, "Polar points under auto"):
    the polar network goes to the general layer (one warning line, first note, the same adjustment
    as --model general, checked in (b) against the independent solution); a 2-distance target alone,
    an option the general layer lacks, or a size above the dense bound keep the distance path; the
    default-σ warning in the general JSON's ``warnings``; the frame words in the summary.
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import least_squares

import multilat

ROOT = Path(__file__).resolve().parents[1]
SRC = Path(multilat.__file__).resolve().parents[1]
NET = ROOT / "examples" / "network"
SIG_D, SIG_A = 10e-6, 5e-6          # metres, radians


def _cli(*args, timeout=300):
    env = dict(os.environ, PYTHONPATH=str(SRC))
    return subprocess.run([sys.executable, "-c", "from multilat.cli import run; run()", "adjust", *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=timeout, cwd=ROOT)


def _dist(xyz):
    return np.linalg.norm(xyz[:, None] - xyz[None], axis=-1)


# ----------------------------------------------------------------------------- (a) both paths agree

EXAMPLES = [("mixed", NET / "mixed" / "obs.csv", ()),
            ("small_volume", NET / "small_volume_obs.csv", ("--datum", "free")),
            ("sequential", NET / "sequential" / "obs.csv", ())]


@pytest.mark.parametrize("name,path,opts", EXAMPLES, ids=[e[0] for e in EXAMPLES])
def test_general_equals_old_path_where_both_apply(name, path, opts):
    from multilat.network.adjust.distance.adjust import adjust
    from multilat.network.io.files import read_observations
    from multilat.network.adjust.general import adjust_network
    from multilat.network.adjust.general.from_tables import network_from_tables

    obs = read_observations(path)
    old = adjust(obs, snooping=False)
    assert not old.excluded
    net, options = network_from_tables(obs)
    adj = adjust_network(net, options=options)
    res = adj.result
    assert adj.excluded == ()
    assert res.dof == old.dof
    assert res.sigma0 == pytest.approx(old.sigma0, rel=1e-6)
    ids = list(old.station_ids) + list(old.target_ids)
    x_old = np.vstack([old.station_xyz_m, old.target_xyz_m])
    x_gen = np.array([res.xyz_m[res.ids.index(p)] for p in ids])
    assert np.abs(_dist(x_old) - _dist(x_gen)).max() < 1e-9
    # the heads' additive constants are datum-invariant too
    for h, v in zip(old.obs.head_ids, old.offset_m[np.unique(old.obs.head_index, return_index=True)[1]]):
        assert res.parameters[res.names.index(f"offset:{h}")] == pytest.approx(v, abs=1e-9)
    # the same through the CLI (subprocess)
    r = _cli(path, "--model", "general", "--json", *opts)
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["model"] == "general" and doc["format"] == "multilat-csv"
    assert doc["dof"] == old.dof and doc["sigma0"] == pytest.approx(old.sigma0, rel=1e-6)
    x_cli = np.array([doc["points"][p]["xyz_m"] for p in ids])
    assert np.abs(_dist(x_cli) - _dist(x_old)).max() < 1e-9


# ----------------------------------------------------------------------------- (b) tracker networks


def _rot(o, p, k):
    """Rz(k) Ry(p) Rx(o), written out here (independent of multilat.network.model.angles)."""
    co, so, cp, sp, ck, sk = np.cos(o), np.sin(o), np.cos(p), np.sin(p), np.cos(k), np.sin(k)
    rx = np.array([[1, 0, 0], [0, co, -so], [0, so, co]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[ck, -sk, 0], [sk, ck, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _reading(h, frame, t, c):
    """Distance (with the head's constant c), azimuth and elevation of target t from station h."""
    d = t - h
    if frame is None:
        return np.linalg.norm(d) + c, np.nan, np.nan
    v = _rot(*frame).T @ d
    return np.linalg.norm(d) + c, np.arctan2(v[1], v[0]), np.arctan2(v[2], np.hypot(v[0], v[1]))


class Case:
    """A known network: stations {id: xyz}, frames {id: (ω, φ, κ)} of the angle-reading ones,
    offsets {id: m}, targets {id: xyz}, pairs [(station, target)], control ids (hard, --points)."""

    def __init__(self, stations, frames, offsets, targets, pairs, control=(), levelled=(), control_sigma=None):
        self.stations, self.frames, self.offsets, self.targets = stations, frames, offsets, targets
        self.pairs, self.control, self.levelled = pairs, tuple(control), tuple(levelled)
        self.control_sigma = control_sigma          # weighted control (sx_m = sy_m = sz_m), else hard

    def simulate(self, rng):
        rows = []
        for s, t in self.pairs:
            d, az, el = _reading(self.stations[s], self.frames.get(s), self.targets[t], self.offsets[s])
            d += SIG_D * rng.standard_normal()
            if s in self.frames:
                az = float(np.angle(np.exp(1j * (az + SIG_A * rng.standard_normal()))))
                el += SIG_A * rng.standard_normal()
            rows.append((s, t, d, az, el))
        self.rows = rows
        sc = self.control_sigma or 0.0
        self.given = {p: self.targets[p] + sc * rng.standard_normal(3) for p in self.control}
        return self

    def write(self, tmp: Path) -> list:
        obs = tmp / "obs.csv"
        with open(obs, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["station", "target", "distance_m", "sigma_m", "azimuth_rad", "elevation_rad",
                        "sigma_azimuth_rad", "sigma_elevation_rad"])
            for s, t, d, az, el in self.rows:
                ang = ["", "", "", ""] if np.isnan(az) else [f"{az:.15g}", f"{el:.15g}", SIG_A, SIG_A]
                w.writerow([s, t, f"{d:.15g}", SIG_D, *ang])
        args = [obs]
        if self.control:
            pts = tmp / "points.csv"
            with open(pts, "w", newline="") as f:
                w = csv.writer(f)
                sc = self.control_sigma
                w.writerow(["point", "x_m", "y_m", "z_m"] + (["sx_m", "sy_m", "sz_m"] if sc else []))
                for p in self.control:
                    w.writerow([p, *(f"{v:.15g}" for v in self.given[p])] + ([sc] * 3 if sc else []))
            args += ["--points", pts, "--datum", "control"]
        if self.levelled:
            args += ["--levelled", ",".join(self.levelled)]
        return args

    def independent(self, hold: str | None):
        """least_squares on the closed-form residuals. Unknowns: every station's xyz, the frames
        (κ only for levelled stations), the offsets, the free targets; ``hold``: a station whose xyz and
        κ are held at the truth (the datum of a free network)."""
        weighted = self.control_sigma is not None
        st, tg = list(self.stations), [t for t in self.targets if weighted or t not in self.control]
        layout, p0 = [], []

        def add(name, v):
            layout.append(name)
            p0.extend(np.atleast_1d(v))

        for s in st:
            if s != hold:
                add(("H", s), self.stations[s] + 0.002)
            if s in self.frames:
                fr = self.frames[s]
                if s not in self.levelled:
                    add(("tilt", s), np.array(fr[:2]) * 0.5)
                if s != hold:
                    add(("kappa", s), fr[2] + 0.01)
            add(("c", s), 0.0)
        for t in tg:
            add(("T", t), self.targets[t] + 0.002)
        size = {"H": 3, "T": 3, "tilt": 2, "kappa": 1, "c": 1}
        starts = np.cumsum([0] + [size[n[0]] for n in layout])
        where = {n: slice(a, b) for n, a, b in zip(layout, starts[:-1], starts[1:])}

        def unpack(p):
            H = {s: (p[where[("H", s)]] if ("H", s) in where else self.stations[s]) for s in st}
            F = {}
            for s in self.frames:
                tilt = p[where[("tilt", s)]] if ("tilt", s) in where else np.zeros(2)
                k = p[where[("kappa", s)]][0] if ("kappa", s) in where else self.frames[s][2]
                F[s] = (tilt[0], tilt[1], k)
            T = {t: (p[where[("T", t)]] if ("T", t) in where else self.given[t]) for t in self.targets}
            C = {s: p[where[("c", s)]][0] for s in st}
            return H, F, T, C

        def fun(p):
            H, F, T, C = unpack(p)
            rd, ra = [], []
            for s, t, d, az, el in self.rows:
                dd, a, e = _reading(H[s], F.get(s), T[t], C[s])
                rd.append((d - dd) / SIG_D)
                if s in F:
                    ra += [np.angle(np.exp(1j * (az - a))) / SIG_A, (el - e) / SIG_A]
            rc = [(self.given[c] - T[c]) / self.control_sigma for c in self.control] if weighted else []
            return np.concatenate([rd, ra] + rc)

        sol = least_squares(fun, np.array(p0), xtol=1e-15, ftol=1e-15, gtol=1e-15, x_scale="jac")
        H, F, T, C = unpack(sol.x)
        dof = len(sol.fun) - len(sol.x)
        return {**H, **T}, C, float(np.sqrt(2 * sol.cost / dof)), dof


def _rng_box(rng, n, lo, hi):
    return [np.array([rng.uniform(lo[0], hi[0]), rng.uniform(lo[1], hi[1]), rng.uniform(lo[2], hi[2])])
            for _ in range(n)]


def two_trackers(rng):
    targets = {f"P{i:02d}": x for i, x in enumerate(_rng_box(rng, 15, (0, 2, -1), (6, 8, 2)))}
    stations = {"T1": np.array([0.0, 0.0, 0.0]), "T2": np.array([6.2, 0.4, 0.15])}
    frames = {"T1": (0.0, 0.0, 0.3), "T2": (0.0, 0.0, 2.1)}
    return Case(stations, frames, {"T1": 0.2e-3, "T2": -0.1e-3}, targets,
                [(s, t) for s in stations for t in targets], levelled=("T1", "T2"))


def tracker_on_control(rng):
    h = np.array([1.0, 2.0, 0.5])
    control = {f"K{i}": h + x for i, x in enumerate(_rng_box(rng, 5, (-8, -8, -1), (8, 8, 1)))}
    polar = {f"Q{i}": h + x for i, x in enumerate(_rng_box(rng, 10, (-8, -8, -1), (8, 8, 2)))}
    targets = {**control, **polar}
    return Case({"T": h}, {"T": (0.004, -0.003, -1.2)}, {"T": 0.3e-3}, targets,
                [("T", t) for t in targets], control=tuple(control))


def tracker_on_weighted_control(rng):
    case = tracker_on_control(rng)
    case.control_sigma = 50e-6
    return case


def heads_tracker_polar(rng):
    common = {f"P{i:02d}": x for i, x in enumerate(_rng_box(rng, 12, (0, 0, 0), (4, 3, 1.5)))}
    polar = {f"Q{i}": x for i, x in enumerate(_rng_box(rng, 5, (0, 0, 0), (4, 3, 1.5)))}
    stations = {"H1": np.array([-0.5, -0.4, 0.3]), "H2": np.array([4.5, -0.3, 1.6]),
                "H3": np.array([4.4, 3.4, 0.2]), "H4": np.array([-0.4, 3.3, 1.7]), "AT": np.array([2.0, -2.5, 0.8])}
    offsets = {"H1": 1.1e-3, "H2": -0.4e-3, "H3": 0.2e-3, "H4": 0.6e-3, "AT": 0.05e-3}
    pairs = [(s, t) for s in stations for t in common] + [("AT", q) for q in polar]
    return Case(stations, {"AT": (0.0, 0.0, 1.3)}, offsets, {**common, **polar}, pairs, levelled=("AT",))


def _fit_about_z(src, dst):
    """Rotation about z and shift mapping src (n, 3) onto dst (least squares)."""
    from multilat.network.model.datum import rigid_fit

    R, t = rigid_fit(src, dst, about_z=True)
    return src @ R.T + t


CASES = {"two_trackers": (two_trackers, 20261126, "T1"), "tracker_on_control": (tracker_on_control, 7, None),
         "tracker_on_weighted_control": (tracker_on_weighted_control, 8, None),
         "heads_tracker_polar": (heads_tracker_polar, 11, "AT")}


@pytest.mark.parametrize("name", list(CASES))
def test_refused_tracker_networks_against_independent_solution(name, tmp_path):
    make, seed, hold = CASES[name]
    case = make(np.random.default_rng(seed)).simulate(np.random.default_rng(seed + 1))
    args = case.write(tmp_path)
    r = _cli(*args, "--model", "general", "--json", "--observations")     # every row (adjust-general/2)
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["schema"] == "multilat.adjust-general/3" and doc["model"] == "general"
    assert doc["excluded"] == []
    xyz_ind, c_ind, s0_ind, dof_ind = case.independent(hold)
    assert doc["dof"] == dof_ind
    assert doc["defect"] == (4 if hold else 0)
    assert doc["sigma0"] == pytest.approx(s0_ind, rel=1e-9)
    ids = list(xyz_ind)
    gen = np.array([doc["points"][p]["xyz_m"] for p in ids])
    ind = np.array([xyz_ind[p] for p in ids])
    if hold:
        ind = _fit_about_z(ind, gen)
    assert np.abs(gen - ind).max() < 1e-8
    for s, c in c_ind.items():
        assert doc["parameters"][f"offset:{s}"]["value"] == pytest.approx(c, abs=1e-9)
    # polar points: kept, zero redundancy (one distance, azimuth, elevation for three unknowns)
    for o in doc["observations"]:
        if o.get("to", "").startswith("Q"):
            assert abs(o["redundancy"]) < 1e-8
    # the old path refuses (two trackers, one tracker) or leaves the polar points out, naming --model general
    old = _cli(*args, "--json", "--no-snooping", "--model", "multilateration")
    if name == "tracker_on_weighted_control":
        assert {doc["points"][k]["status"] for k in case.control} == {"weighted"}
    if name == "heads_tracker_polar":
        assert old.returncode == 0, old.stderr
        assert "Q0' left out: has 1 observation(s); 3 are needed" in old.stderr
        assert "--model general adjusts" in old.stderr
        # --model auto: the polar points are kept (the general layer), said in one warning line and
        # first in the notes; the same adjustment as --model general
        auto = _cli(*args, "--json")
        assert auto.returncode == 0, auto.stderr
        assert auto.stderr.strip().splitlines() == [ln for ln in auto.stderr.splitlines() if ln.strip()]
        said = auto.stderr.strip().splitlines()
        assert len(said) == 1 and "would leave out 5 polar point(s) (Q0, Q1, Q2, Q3, Q4" in said[0], auto.stderr
        adoc = json.loads(auto.stdout)
        assert adoc["model"] == "general" and adoc["notes"][0].startswith("--model auto: the self-calibrating "
                                                                         "model would leave out 5 polar point(s)")
        assert adoc["excluded"] == [] and adoc["dof"] == doc["dof"]
        assert adoc["sigma0"] == pytest.approx(doc["sigma0"], rel=1e-12)
        assert {p: v["xyz_m"] for p, v in adoc["points"].items()} == {p: v["xyz_m"] for p, v in doc["points"].items()}
    else:
        assert old.returncode == 2
        assert "needs at least 3 stations" in old.stderr and "--model general adjusts" in old.stderr
        assert len(old.stderr.strip().splitlines()) == 1
        # the default, --model auto: the general layer adjusts what the counting rules refuse, and says so
        auto = _cli(*args, "--json")
        assert auto.returncode == 0, auto.stderr
        said = [ln for ln in auto.stderr.splitlines() if "adjusted by the general model" in ln]
        assert len(said) == 1 and "needs at least 3 stations" in said[0]
        adoc = json.loads(auto.stdout)
        assert adoc["schema"].startswith("multilat.adjust-general/") and adoc["notes"][0].startswith("--model auto")
        assert adoc["dof"] == doc["dof"] and adoc["sigma0"] == pytest.approx(doc["sigma0"], rel=1e-12)


# ----------------------------------------------------------------------------- (c) options and schema


@pytest.mark.parametrize("opt", [["--cost", "squared"], ["--average-repeats"], ["--solver", "dense"],
                                 ["--references", str(NET / "small_volume_refs.csv")]])
def test_options_the_general_layer_cannot_honour_are_refused_by_name(opt, tmp_path):
    out = tmp_path / "res"
    r = _cli(NET / "mixed" / "obs.csv", "--model", "general", *opt, "--out", out)
    assert r.returncode == 2
    line = r.stderr.strip()
    assert line.startswith("error: ") and len(line.splitlines()) == 1
    assert opt[0] in line
    assert not out.exists()


def test_model_is_checked_and_never_switched(tmp_path):
    r = _cli(NET / "mixed" / "obs.csv", "--model", "gen")
    assert r.returncode == 2 and "--model must be one of auto, multilateration, general" in r.stderr
    r = _cli(NET / "mixed" / "obs.csv", "--json", "--no-snooping")          # the default path runs
    assert r.returncode == 0 and json.loads(r.stdout)["schema"] == "multilat.adjust/3"


def _schema():
    return json.loads((SRC / "multilat" / "schemas" / "adjust-general.json").read_text("utf-8"))


GENERAL_EXAMPLES = [[ROOT / "examples" / "general" / "two_trackers.xml"],
                    [ROOT / "examples" / "general" / "station_control.xml"],
                    [ROOT / "examples" / "general" / "two_trackers_csv" / "obs.csv", "--model", "general",
                     "--levelled", "T1,T2"]]


@pytest.mark.parametrize("args", GENERAL_EXAMPLES, ids=["two_trackers", "station_control", "two_trackers_csv"])
def test_general_documents_follow_the_shipped_schema(args):
    jsonschema = pytest.importorskip("jsonschema")
    from multilat.vocabulary import document_problems

    r = _cli(*args, "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    schema = _schema()
    assert schema["$id"] == doc["schema"] == "multilat.adjust-general/3"
    jsonschema.Draft202012Validator.check_schema(schema)
    errors = list(jsonschema.Draft202012Validator(schema).iter_errors(doc))
    assert not errors, errors[0].message[:200]
    assert document_problems(doc) == []
    bad = dict(doc, sigma_0=doc["sigma0"])                    # an undeclared key fails
    assert not jsonschema.Draft202012Validator(schema).is_valid(bad)


def test_shipped_csv_example_is_its_generator_output(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("gen", ROOT / "examples" / "general" / "two_trackers_csv" /
                                                  "generate.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    gen.main(tmp_path)
    shipped = ROOT / "examples" / "general" / "two_trackers_csv"
    for f in ("obs.csv", "truth.csv"):
        assert (tmp_path / f).read_text() == (shipped / f).read_text()


def test_refusal_hint_only_on_the_counting_rules():
    """The hint is added to the distance path's counting-rule refusals only (other errors pass
    unchanged), and to its left-out warnings only when the file has angle observations."""
    import warnings

    from multilat.cli.general_adjust import refusal_hint
    from multilat.errors import MultilatError
    from multilat.network.io.files import read_observations

    for msg, hinted in (("a self-calibrating network needs at least 3 stations, got 2 (T1, T2)", True),
                        ("target 'X' has 2 observation(s); it needs at least 3 (4 for redundancy)", True),
                        ("the network is disconnected into 2 parts", False)):
        with pytest.raises(MultilatError) as e, refusal_hint():
            raise MultilatError(msg)
        assert str(e.value).startswith(msg) and ("--model general adjusts" in str(e.value)) == hinted
    left = "target 'Q0' left out: has 1 observation(s); 3 are needed to place it"
    for path, hinted in ((NET / "mixed" / "obs.csv", True), (NET / "sequential" / "obs.csv", False)):
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            with refusal_hint(read_observations(path)):
                warnings.warn(left, UserWarning)
        assert [str(w.message).startswith(left) for w in seen] == [True]
        assert ("--model general adjusts" in str(seen[0].message)) == hinted


# ----------------------------------------------------------------------------- (d) --model auto's rule


def _polar_case(tmp_path, *, polar=True, two_distance=False, seed=11):
    """heads_tracker_polar's network: the 5 polar points (``polar``), and/or a target read by 2 heads
    only (``two_distance``, no angles: undetermined on either path)."""
    case = heads_tracker_polar(np.random.default_rng(seed))
    if not polar:
        case.pairs = [(s, t) for s, t in case.pairs if not t.startswith("Q")]
        case.targets = {k: v for k, v in case.targets.items() if not k.startswith("Q")}
    if two_distance:
        case.targets["W"] = np.array([2.0, 1.5, 0.7])
        case.pairs += [("H1", "W"), ("H2", "W")]
    case.simulate(np.random.default_rng(seed + 1))
    return case.write(tmp_path)


def test_auto_stays_on_the_distance_path_without_polar_points(tmp_path):
    """A target left out for lack of distances, with no polar reading, is left out by the general layer
    too: the distance path's result stands (with the hint), the model is not switched."""
    r = _cli(*_polar_case(tmp_path, polar=False, two_distance=True), "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["schema"].startswith("multilat.adjust/")
    assert "target 'W' left out: has 2 observation(s); 3 are needed" in r.stderr
    assert "--model general adjusts" in r.stderr and "adjusted by the general model" not in r.stderr


def test_auto_keeps_polar_points_and_names_the_undetermined(tmp_path):
    """Polar points and a 2-distance target: the general layer keeps the polar points, flags them
    (zero redundancy, in the summary), and leaves the 2-distance target out, named."""
    args = _polar_case(tmp_path, two_distance=True)
    r = _cli(*args, "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["model"] == "general" and [e["id"] for e in doc["excluded"]] == ["W"]
    assert {f"Q{i}" for i in range(5)} <= set(doc["points"])
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 2 and "5 polar point(s)" in lines[0] and "point 'W' left out" in lines[1]
    text = _cli(*args)
    assert text.returncode == 0, text.stderr
    flat = " ".join(text.stdout.split())          # rich wraps long lines
    assert "kept without control (every row r = 0, e.g. one polar reading; a blunder cannot show): " \
           "Q0, Q1, Q2, Q3, Q4" in flat


def test_auto_keeps_the_distance_path_when_an_option_has_no_meaning_there(tmp_path):
    """An accepted network stays on the distance path when a given option does not apply to the
    general layer (here --mdb-limit-sigma): never a refusal where there was a result."""
    r = _cli(*_polar_case(tmp_path), "--json", "--mdb-limit-sigma", "8")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["schema"].startswith("multilat.adjust/")
    assert "Q0' left out: has 1 observation(s)" in r.stderr and "--model general adjusts" in r.stderr


def test_auto_keeps_the_distance_path_above_the_dense_bound(tmp_path, monkeypatch, capsys):
    """Polar points in a network larger than the general back end takes: the distance path's result
    (points left out, with the hint), not the general layer's refusal."""
    import importlib

    from multilat.cli.app import main

    gadjust = importlib.import_module("multilat.network.adjust.general.adjust")
    args = _polar_case(tmp_path)
    monkeypatch.setattr(gadjust, "MAX_DENSE_UNKNOWNS", 60)     # this network: 22 points, 66+ unknowns
    assert main(["adjust", *map(str, args), "--json"]) == 0
    out = capsys.readouterr()
    assert json.loads(out.out)["schema"].startswith("multilat.adjust/")
    assert "Q0' left out" in out.err and "adjusted by the general model" not in out.err


def test_default_sigma_warning_is_in_the_general_json(tmp_path):
    """No sigma_m column, no --sigma-um, no --instrument: the default-σ warning is in the general
    JSON's ``warnings`` (the distance path's key and words) under --model general and auto, and on
    stderr once."""
    from multilat.network.model.sigma_source import default_warning

    src = ROOT / "examples" / "general" / "two_trackers_csv" / "obs.csv"
    with open(src, newline="") as f:
        rows = list(csv.DictReader(f))
    obs = tmp_path / "obs.csv"
    with open(obs, "w", newline="") as f:
        w = csv.DictWriter(f, [c for c in rows[0] if c != "sigma_m"], extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    expected = default_warning({"kind": "distance model", "defaulted": True, "instrument": "seed2020"}, obs)
    for model in ("general", "auto"):
        r = _cli(obs, "--levelled", "T1,T2", "--json", "--model", model)
        assert r.returncode == 0, r.stderr
        doc = json.loads(r.stdout)
        assert doc["model"] == "general" and doc["warnings"] == [expected]
        assert r.stderr.count(expected) == 1
    sig = json.loads(_cli(src, "--levelled", "T1,T2", "--json", "--model", "general").stdout)
    assert sig["warnings"] == []                       # a sigma_m column: no warning


def test_general_summary_prints_the_frame_words():
    r = _cli(ROOT / "examples" / "general" / "two_trackers_csv" / "obs.csv", "--levelled", "T1,T2", "--model",
             "general")
    assert r.returncode == 0, r.stderr
    doc = json.loads(_cli(ROOT / "examples" / "general" / "two_trackers_csv" / "obs.csv", "--levelled", "T1,T2",
                          "--model", "general", "--json").stdout)
    flat = " ".join(r.stdout.split())
    assert "frame: " + " ".join(doc["frame"]["axes"].split()) in flat
    assert "scale: " + doc["frame"]["scale"] in flat
