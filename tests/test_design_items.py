"""Issue 28's design items: named heads, the poorly controlled targets' warning, the crew's stations
file, the obstruction in the maps, and the search record's unsolvable starts."""

from __future__ import annotations

import csv
import json
from importlib import resources

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.design import Layout, SigmaModel, preanalyse
from multilat.network.design.config import parse_design_config, run_design
from multilat.network.design.search import PENALTY_M, visibility

NAMES = {"A": "north", "B": "east", "C": "south", "D": "west"}


def _named_instrument(tmp_path):
    """seed2020 with its heads A-D renamed north, east, south, west (same parameters)."""
    text = resources.files("multilat").joinpath("presets", "seed2020.toml").read_text(encoding="utf-8")
    for a, b in NAMES.items():
        text = text.replace(f"[heads.{a}]", f"[heads.{b}]")
    p = tmp_path / "named.toml"
    p.write_text(text, encoding="utf-8")
    return p


def _cube_cfg(instrument: dict, count=4, **extra):
    cfg = {"targets": {"box_min_m": [0, 0, 0], "box_max_m": [1, 1, 1], "grid": [3, 3, 2]},
           "heads": {"count": count, "box_min_m": [-1.5, -1.5, 0], "box_max_m": [2.5, 2.5, 2.0]},
           "instrument": instrument, "search": {"starts": 1, "max_evaluations": 60}}
    cfg.update(extra)
    return cfg


def _run(capsys, args):
    rc = main(args)
    out = capsys.readouterr()
    return rc, out.out, out.err


# ------------------------------------------------------------------------------------------ 1
def test_named_heads_accepted_with_their_own_distance_model(tmp_path):
    """Before: ``unknown head 'A'``. Each station is named after its head and its distances carry
    that head's σ: equal to seed2020's head of the same parameters (A for north, ...), to the
    table's interpolation precision (1e-6 relative, SigmaModel)."""
    from multilat import budget
    from multilat.instrument import load_instrument

    inst_path = _named_instrument(tmp_path)
    cfg = parse_design_config(_cube_cfg({"file": inst_path.name}))
    run = run_design(cfg, base_dir=tmp_path, rng=3)
    assert run.best.station_ids == ("north", "east", "south", "west")
    assert run.heads == run.best.station_ids
    seed = load_instrument("seed2020")
    b = run.best
    for i, name in enumerate(b.station_ids):
        k = b.station_index == i
        ref = budget.distance_std_m(seed, b.distance_m[k], head={v: a for a, v in NAMES.items()}[name])
        np.testing.assert_allclose(b.sigma_m[k], ref, rtol=1e-6)
    # heads differ (seed2020's tilts and beam-offset limits): the test can tell them apart
    assert abs(budget.distance_std_m(seed, 2.0, head="A") - budget.distance_std_m(seed, 2.0, head="D")) > 1e-9


def test_named_heads_count_beyond_the_instrument_is_one_line(tmp_path):
    inst_path = _named_instrument(tmp_path)
    cfg = parse_design_config(_cube_cfg({"file": inst_path.name}, count=5))
    with pytest.raises(MultilatError, match=r"cfg.toml: heads.count: station 'A' is not a head of instrument "
                                            r"'seed2020' \(heads: north, east, south, west\)"):
        run_design(cfg, base_dir=tmp_path, rng=3, source="cfg.toml")


def test_fixed_heads_not_named_after_the_instrument_are_refused(tmp_path):
    inst_path = _named_instrument(tmp_path)
    (tmp_path / "h.csv").write_text("point,x_m,y_m,z_m\nS1,-1,-1,0\nS2,2,-1,1.5\nS3,2,2,0\nS4,-1,2,1.5\n")
    cfg = _cube_cfg({"file": inst_path.name})
    cfg["heads"] = {"fixed": "h.csv"}
    with pytest.raises(MultilatError, match=r"^d.toml: heads.fixed: station 'S1' is not a head of instrument"):
        run_design(parse_design_config(cfg), base_dir=tmp_path, source="d.toml")


def test_named_heads_candidates_carry_the_head(tmp_path):
    """Candidate positions: the i-th chosen position holds the i-th head; σ follows that head."""
    from multilat import budget
    from multilat.instrument import load_instrument

    inst_path = _named_instrument(tmp_path)
    cand = np.array([[-1, -1, 0.2], [2, -1, 1.5], [2, 2, 0.3], [-1, 2, 1.8], [0.5, -1.2, 2.0]])
    (tmp_path / "cand.csv").write_text("point,x_m,y_m,z_m\n" + "".join(
        f"P{i + 1},{x},{y},{z}\n" for i, (x, y, z) in enumerate(cand)))
    cfg = _cube_cfg({"file": inst_path.name})
    cfg["heads"] = {"count": 4, "file": "cand.csv"}
    run = run_design(parse_design_config(cfg), base_dir=tmp_path, rng=1)
    assert run.heads == ("north", "east", "south", "west")
    assert all(s.startswith("P") for s in run.best.station_ids)
    seed = load_instrument("seed2020")
    b = run.best
    for i, head in enumerate(run.heads):
        k = b.station_index == i
        np.testing.assert_allclose(b.sigma_m[k], budget.distance_std_m(seed, b.distance_m[k], head="ABCD"[i]),
                                   rtol=1e-6)


# ------------------------------------------------------------------------------------------ 2
def _fixed_cfg(tmp_path, heads_xyz, hidden=None, occluders=()):
    (tmp_path / "heads.csv").write_text("point,x_m,y_m,z_m\n" + "".join(
        f"{n},{x},{y},{z}\n" for n, (x, y, z) in heads_xyz.items()))
    cfg = {"targets": {"box_min_m": [0, 0, 0], "box_max_m": [1, 1, 1], "grid": [3, 3, 2]},
           "heads": {"fixed": "heads.csv", **({"hidden": hidden} if hidden else {})},
           "instrument": {"sigma_um": 4.7}}
    if occluders:
        cfg["occluders"] = [{"box_min_m": lo, "box_max_m": hi} for lo, hi in occluders]
    p = tmp_path / "d.toml"
    p.write_text(_toml(cfg))
    return p


def _toml(cfg: dict) -> str:
    """The few shapes these configs use: tables of scalars, lists, and flat inline tables."""
    def val(v):
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {val(x)}" for k, x in v.items()) + " }"
        return json.dumps(v)

    out = []
    for name, tab in cfg.items():
        for t in (tab if isinstance(tab, list) else [tab]):
            out.append(f"[[{name}]]" if isinstance(tab, list) else f"[{name}]")
            out += [f"{k} = {val(v)}" for k, v in t.items()]
    return "\n".join(out) + "\n"


EIGHT = {n: xyz for n, xyz in zip("ABCDEFGH", [(-1.5, -1.5, -0.5), (2.5, -1.5, 1.5), (2.5, 2.5, -0.5),
                                                  (-1.5, 2.5, 1.5), (0.5, -1.8, 2.2), (0.5, 2.8, 2.2),
                                                  (-1.8, 0.5, 2.0), (2.8, 0.5, 2.0)])}


def test_target_seen_by_three_heads_is_warned_everywhere(tmp_path, capsys):
    """A target seen by exactly 3 heads is determined by its 3 distances alone: their redundancy
    numbers are 0 (closed form), a blunder in them cannot show. With 8 heads around the volume every
    other target is well controlled; hiding T1 from 5 heads leaves it 3 -> the warning names T1 only,
    in the terminal, the JSON and the HTML report."""
    p = _fixed_cfg(tmp_path, EIGHT)
    rc, out, err = _run(capsys, ["design", str(p), "--json"])
    assert rc == 0, err
    assert json.loads(out)["poorly_controlled"]["n_targets"] == 0        # the control case: no warning
    p = _fixed_cfg(tmp_path, EIGHT, hidden={h: ["T1"] for h in "DEFGH"})
    rc, out, err = _run(capsys, ["design", str(p), "--json"])
    line = [s for s in err.replace("\n", " ").split("warning: ")[1:]]      # stderr, with --json too
    assert len(line) == 1 and "1 of 18 targets poorly controlled" in line[0] and "T1 (r " in line[0]
    doc = json.loads(out)
    pc = doc["poorly_controlled"]
    assert pc["r_min"] == 0.1 and pc["mdb_limit_sigma"] == 10.0
    assert [t["id"] for t in pc["targets"]] == ["T1"]
    assert pc["targets"][0]["n_obs"] == 3 and pc["targets"][0]["redundancy"] < 1e-9
    rc, out, err = _run(capsys, ["design", str(p), "--report", str(tmp_path / "r.html")])
    assert rc == 0, err
    html = (tmp_path / "r.html").read_text(encoding="utf-8")
    assert "targets poorly controlled" in html and ">T1<" in html


def test_poorly_controlled_matches_adjust_notion():
    """The same thresholds as the adjustment's reliability (r < 0.1 or MDB > 10 σ)."""
    import inspect

    from multilat.network.design.config import poorly_controlled_targets
    from multilat.network.adjust.distance.reliability import MDB_LIMIT_SIGMA, R_MIN, reliability

    sig = inspect.signature(reliability).parameters
    assert sig["r_min"].default == R_MIN == 0.1 and sig["mdb_limit_sigma"].default == MDB_LIMIT_SIGMA == 10.0
    tx = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [0.5, 0.5, 0.2]], float)
    sx = np.array(list(EIGHT.values()), float)[:6]
    lay = Layout(tuple("ABCDEF"), sx, tuple(f"T{i}" for i in range(6)), tx)
    pa = preanalyse(lay, SigmaModel(4.7e-6))
    got = {t["id"] for t in poorly_controlled_targets(pa, r_min=0.5)}
    want = {lay.target_ids[j] for j in pa.target_index[pa.redundancy < 0.5]}
    assert got == want and got


# ------------------------------------------------------------------------------------------ 3
def test_stations_csv_for_the_crew(tmp_path, capsys):
    p = _fixed_cfg(tmp_path, EIGHT, hidden={"A": ["T2", "T5"]})
    out = tmp_path / "out"
    rc, o, err = _run(capsys, ["design", str(p), "--out", str(out)])
    assert rc == 0, err
    doc = json.loads((out / "design.json").read_text())
    rows = list(csv.DictReader((out / "stations.csv").open(encoding="utf-8")))
    assert [r["station"] for r in rows] == list("ABCDEFGH") and [r["head"] for r in rows] == list("ABCDEFGH")
    for r in rows:
        np.testing.assert_allclose([float(r[k]) for k in ("x_m", "y_m", "z_m")], EIGHT[r["station"]], atol=5e-5)
        assert r["targets"].split() == doc["stations"][r["station"]]["targets"]
        assert int(r["n_targets"]) == len(r["targets"].split())
    a = rows[0]["targets"].split()
    assert "T2" not in a and "T5" not in a and len(a) == 16


def test_out_written_whole_or_not_at_all(tmp_path, capsys, monkeypatch):
    import multilat.report.design_figures as df

    def boom(*a, **k):
        raise MultilatError("figures failed")

    monkeypatch.setattr(df, "save_design_figures", boom)
    p = _fixed_cfg(tmp_path, EIGHT)
    rc, o, err = _run(capsys, ["design", str(p), "--out", str(tmp_path / "out")])
    assert rc != 0 and not (tmp_path / "out").exists()


# ------------------------------------------------------------------------------------------ 4
WALL = ([0.9, -0.5, -1.0], [1.1, 0.5, 3.0])     # a wall in the plane x = 1, |y| <= 0.5


def test_occluder_blocks_the_known_sights():
    """Head at (2, 0, 1), targets on the plane x = 0: the sight to (0, y, z) crosses x = 0.9..1.1 at
    |y| * (0.45..0.55) and z within the wall's height -> blocked iff |y| * 0.45 <= 0.5 (the near
    face), i.e. |y| <= 1.11 for every z in [0, 1]."""
    ys = np.array([-2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0])
    tx = np.array([[0.0, y, z] for y in ys for z in (0.0, 1.0)])
    vis = visibility([[2.0, 0.0, 1.0]], tx, occluders=[WALL])[0]
    np.testing.assert_array_equal(~vis, np.abs(tx[:, 1]) <= 1.0 + 1e-12)


def test_occluder_used_in_the_maps_and_drawn(tmp_path):
    """A map point behind the wall from head H1 is measured by the other heads only: its predicted
    covariance equals the probe with H1 masked out by hand, and differs from the unobstructed one."""
    from multilat.report import design_figures as df

    sx = np.array([[2.0, 0.0, 1.0], [-1.5, -1.5, 0.0], [-1.5, 1.5, 2.0], [-1.0, 0.0, 2.5], [0.0, -2.0, 1.0],
                   [0.0, 2.0, -0.5], [2.0, 2.5, 2.0]])
    tx = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-1.5, -1, 0, 1, 1.5) for z in (0, 1)], float)
    lay = Layout(tuple(f"H{i + 1}" for i in range(7)), sx, tuple(f"T{j}" for j in range(len(tx))), tx,
                 visibility(sx, tx, occluders=[WALL]))
    pa = preanalyse(lay, SigmaModel(4.7e-6))
    assert (~lay.visible[0]).sum() >= 4
    assert pa.dof == int(lay.visible.sum()) - (4 * 7 + 3 * len(tx) - 6)   # blocked sights not counted
    p = np.array([[0.0, 0.0, 1.0]])
    mask = np.array([[False] + [True] * 6])
    want = pa.probe_cov_m2(p, visible=mask)
    open_ = pa.probe_cov_m2(p)
    got = pa.probe_cov_m2(p, visible=visibility(sx, p, occluders=[WALL]).T)
    np.testing.assert_allclose(got, want, rtol=1e-12)
    assert np.abs(open_ - want).max() > 1e-3 * np.abs(want).max()
    axes = df.plot_slice_maps(pa, [-1, -1, 0], [1, 1, 1], n_slices=2, n_grid=5, occluders=[WALL])
    for ax in axes:
        assert [q.get_gid() for q in ax.patches] == ["occluder"]
        assert ax.patches[0].get_hatch() == "///"                # both slices cut the wall
    df.save_design_figures(pa, tmp_path, box_min_m=[-1, -1, 0], box_max_m=[1, 1, 1], occluders=[WALL])
    assert (tmp_path / "uncertainty_slices.png").stat().st_size > 0


# ------------------------------------------------------------------------------------------ 5
def test_search_record_names_unsolvable_starts_not_a_penalty(tmp_path, capsys):
    """Random starts in a box whose heads see a target by fewer than 3 (range limit 1.6 m) are
    unsolvable: the search scores them PENALTY_M (1 km), which the record showed as their criterion
    value. Now: None and ``start_unsolvable``; the history never holds the penalty."""
    cfg = _cube_cfg({"sigma_um": 4.7})
    cfg["heads"].update(max_range_m=2.6)
    cfg["search"] = {"starts": 4, "max_evaluations": 400}
    p = tmp_path / "d.toml"
    p.write_text(_toml(cfg))
    rc, out, err = _run(capsys, ["design", str(p), "--json", "--seed", "1"])
    assert rc == 0, err
    s = json.loads(out)["search"]
    bad = [r for r in s["starts"] if r["start_unsolvable"]]
    assert bad, "the case must have an unsolvable start"
    for r in s["starts"]:
        for k in ("start_criterion_m", "end_criterion_m"):
            assert r[k] is None or r[k] < 1.0
        assert (r["start_criterion_m"] is None) == r["start_unsolvable"]
    assert all(v is None or v < PENALTY_M for v in s["history_m"])


# ------------------------------------------------------------------------------------------ 4b
PILLAR = ([2.0, 0.45, -0.5], [2.2, 0.55, 2.5])     # between head H (2.8, 0.5, 2.0) and the targets


def _box_of(points) -> tuple:
    """(min, max) corners of the points' bounding box."""
    p = np.asarray(points, float).reshape(-1, 3)
    return tuple(p.min(axis=0)), tuple(p.max(axis=0))


def test_obstruction_in_the_3d_views(tmp_path):
    """The 3-D views draw each declared box (issue 28: the maps did, the 3-D figure did not). Checked
    on the figures' data, not their text: the static view's box is a collection of six faces whose
    corners are the box's 8 corners, each face flat on one side of the box; the interactive view's
    Mesh3d has the 8 corners and 12 triangles covering the box's surface (total area checked)."""
    from multilat.report import design_figures as df
    from multilat.report import view3d

    from multilat.network.design.config import load_design_config

    run = run_design(load_design_config(_fixed_cfg(tmp_path, EIGHT, occluders=[PILLAR])), base_dir=tmp_path)
    assert run.occluders == (PILLAR,)
    assert not run.best.layout.visible[7].all()                   # the pillar hides targets from H
    lo, hi = np.array(PILLAR[0]), np.array(PILLAR[1])
    ax = df.plot_layout_3d(run.best, run.occluders)
    boxes = [c for c in ax.collections if c.get_gid() == "occluder"]
    assert len(boxes) == 1
    faces = np.asarray(boxes[0]._faces)                           # the 3-D polygons as given (matplotlib 3.x)
    assert faces.shape == (6, 4, 3)
    assert _box_of(faces) == (tuple(lo), tuple(hi))
    assert sorted(map(tuple, np.unique(faces.reshape(-1, 3), axis=0))) == sorted(
        (x, y, z) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2]))
    for f in faces:                                               # every face on one side of the box
        assert any(np.all(f[:, k] == v) for k in range(3) for v in (lo[k], hi[k])), f
    lim = np.array([ax.get_xlim3d(), ax.get_ylim3d(), ax.get_zlim3d()])
    assert np.all(lim[:, 0] <= lo) and np.all(lim[:, 1] >= hi)   # the box inside the view
    if not view3d.available():
        pytest.skip("plotly (the 'report' extra) not installed")
    fig = view3d.figure(run.best, occluders=run.occluders)
    mesh = [t for t in fig.data if t.type == "mesh3d"]
    assert len(mesh) == 1 and mesh[0].name == "obstruction"
    m = mesh[0]
    c = np.column_stack([m.x, m.y, m.z])
    assert _box_of(c) == (tuple(lo), tuple(hi)) and len(np.unique(c, axis=0)) == 8
    tri = c[np.column_stack([m.i, m.j, m.k])]                      # (12, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
    e = hi - lo
    assert len(tri) == 12 and area == pytest.approx(2 * (e[0] * e[1] + e[1] * e[2] + e[0] * e[2]), rel=1e-12)
    assert not [t for t in view3d.figure(run.best).data if t.type == "mesh3d"]   # none declared: none drawn


def test_design_report_and_out_draw_the_obstruction(tmp_path, capsys, monkeypatch):
    """``design --report`` hands the declared boxes to the 3-D view and the top view; ``--out``'s
    layout_3d.png is drawn with them (the figure functions are wrapped to record their input)."""
    from multilat.report import design_figures as df
    from multilat.report import view3d

    seen = {"view": [], "static": []}
    real_layout = df.plot_layout_3d

    def fragment(result, occluders=()):        # record, then fall back to the static view
        seen["view"].append(occluders)

    def layout(pre, occluders=(), ax=None):
        seen["static"].append(occluders)
        return real_layout(pre, occluders, ax)

    monkeypatch.setattr(view3d, "html_fragment", fragment)
    monkeypatch.setattr(df, "plot_layout_3d", layout)
    p = _fixed_cfg(tmp_path, EIGHT, occluders=[PILLAR])
    rc, _, err = _run(capsys, ["design", str(p), "--report", str(tmp_path / "r.html"), "--out", str(tmp_path / "o")])
    assert rc == 0, err
    want = (tuple(map(float, PILLAR[0])), tuple(map(float, PILLAR[1])))
    def boxes(calls):
        return [[(tuple(map(float, lo)), tuple(map(float, hi))) for lo, hi in occ] for occ in calls]

    assert boxes(seen["view"]) == [[want]]
    assert boxes(seen["static"]) == [[want], [want]]            # --out's layout_3d.png, the report's view
    assert (tmp_path / "o" / "layout_3d.png").stat().st_size > 0
