"""The design's pre-analysis on the general layer (issue 27 item 3): ``predict`` and ``evaluate_layout``.

Independent values:
* the general adjustment of the error-free observations, started away from the plan (1e-5 m, outside
  the datum's null space), must come back to it: its cofactor matrix and redundancy numbers equal the
  prediction to 1e-9 (relative to the largest entry; the solution returns to the plan to ~1e-12 m, so
  the Jacobians agree to ~1e-12 relative);
* the distance-only pre-analysis (``preanalyse``, its own Jacobian and pseudo-inverse), the search's
  fast evaluator (Schur complement), and the distance-only ``adjust`` of exact distances: the same
  covariances to 1e-9 on the design's distance-only layouts;
* a Monte Carlo of the general propagate on a tracker layout: every coordinate's standard deviation
  within 4 Monte Carlo standard errors of the prediction (``mc_std_se`` ≈ std / sqrt(2N), 1.1 % at
  N = 4000; 4 se keeps the family-wise false-alarm rate over the 36 coordinates below 0.3 %; the
  layout's non-linearity at µm noise is ~1e-6 relative, far below).
"""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.synthetic import configs
from multilat.network.adjust.distance.adjust import adjust as distance_adjust
from multilat.network.design.config import load_design_config, run_design
from multilat.network.design.evaluate import Design, design_from_layout, evaluate_layout
from multilat.network.design.preanalysis import Layout, layout_observations
from multilat.network.adjust.general import adjust_network, read_gama_input
from multilat.network.adjust.general.adjust import UndeterminedError, adjust
from multilat.network.adjust.approximate.general import approximate
from multilat.network.model.observations import Block, Network, without_points
from multilat.network.model.points import FREE, PointSet
from multilat.network.design.general_preanalysis import planned, predict
from multilat.network.montecarlo.general.propagate import propagate

ROOT = Path(__file__).resolve().parents[1]
GAMA3D = ROOT / "tests" / "data" / "gama3d"
NETWORKS = ["two_trackers", "partly_fixed", "heights", "traverse", "direction_sets", "angles_hdist",
            "height_differences", "vectors", "trilateration_fixed", "trilateration_free"]
SIG = 4.7e-6


def _rel(a, b):
    return float(np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(b).max())


# --- gama3d: the prediction equals the general adjustment of error-free observations ------------------
def _designed(name):
    """The gama3d network with its adjusted coordinates as the plan (the file's values are not used)."""
    net = approximate(read_gama_input(GAMA3D / f"{name}.xml"))
    res = adjust(net)
    return Network(net.points.with_xyz(res.xyz_m), net.blocks)


@pytest.mark.parametrize("name", NETWORKS)
def test_prediction_equals_adjust_of_error_free_observations(name):
    design = _designed(name)
    pred = predict(design)
    exact = planned(design)
    # start away from the plan, outside the datum's null space (B^T p = 0): the solution must return to it
    det = pred.result.determinability
    p = np.zeros(pred.system.n_free)
    cols = pred.system.layout.reduced[pred.system.layout.point_cols]          # (n, 3) free column or -1
    free = cols >= 0
    p[cols[free]] = np.random.default_rng(7).normal(0, 1e-5, int(free.sum()))
    if det.constraints is not None:
        B = det.constraints
        p -= B @ np.linalg.lstsq(B, p, rcond=None)[0]
    start = exact.points.xyz_m.copy()
    start[free] += p[cols[free]]
    res = adjust(Network(exact.points.with_xyz(start), exact.blocks))
    assert len(res.iterations) >= 2, name                      # it did adjust
    assert np.abs(res.xyz_m - design.points.xyz_m).max() < 1e-9, name
    assert res.free_names == pred.result.free_names
    assert _rel(pred.result.cofactor, res.cofactor) < 1e-9, name
    assert np.abs(pred.stats.redundancy - res.redundancy).max() < 1e-9, name
    assert pred.stats.redundancy.sum() == pytest.approx(pred.result.dof, abs=1e-9)
    assert np.abs(pred.result.residuals).max() < 1e-12             # the values are the model at the plan
    assert not pred.undetermined


# --- distance-only layouts: three back ends and the distance-only adjust ----------------------------
def _layouts():
    small = configs.small_volume()
    cube = load_design_config(ROOT / "examples" / "design" / "cube.toml")
    run = run_design(cube, base_dir=ROOT / "examples" / "design", rng=1, source="cube.toml")
    return {"small": (Layout(small.station_ids, small.station_xyz_m, small.target_ids, small.target_xyz_m), SIG),
            "cube": (run.best.layout, run.best.sigma_m)}


@pytest.fixture(scope="module")
def layouts():
    return _layouts()


@pytest.mark.parametrize("name,datum,offsets", [("small", "free", True), ("small", "free:1,2,3,4,5,A", True),
                                                ("small", "free", False), ("cube", "free", True)])
def test_back_ends_agree_and_equal_distance_adjust(layouts, name, datum, offsets):
    lay, sig = layouts[name]
    design = design_from_layout(lay, sig, offsets=offsets, datum=datum)
    gen, dist, fast = (evaluate_layout(design, b) for b in ("general", "distance", "fast"))
    assert gen.ids == dist.ids == lay.station_ids + lay.target_ids and fast.ids == lay.target_ids
    assert _rel(gen.cov_m2, dist.cov_m2) < 1e-9
    assert _rel(gen.cov_m2[lay.n_stations:], fast.cov_m2) < 1e-9
    assert np.abs(gen.redundancy - dist.redundancy).max() < 1e-9
    ok = np.isfinite(dist.mdb)
    assert np.array_equal(ok, np.isfinite(gen.mdb)) and np.array_equal(gen.weak, dist.weak)
    # MDB ∝ r^-1/2: an agreement of δr in r moves it by δr / (2 r) relative (r down to 1e-5 on the cube)
    assert np.all(np.abs(gen.mdb[ok] / dist.mdb[ok] - 1) <= 1e-9 + 1e-12 / dist.redundancy[ok])
    assert np.allclose(gen.semi_axes_95_m, dist.semi_axes_95_m, rtol=1e-8, atol=1e-15)
    # the distance-only adjust of the exact distances (σ0 a priori), started at the plan
    obs = layout_observations(lay, design.sigma_m)
    start = SimpleNamespace(station_xyz_m=lay.station_xyz_m, target_xyz_m=lay.target_xyz_m,
                            offset_m=np.zeros(lay.n_stations))
    r = distance_adjust(obs, initial=start, snooping=False, datum=datum,
                        **({} if offsets else {"offsets": 0.0}))
    assert _rel(gen.cov_m2[:lay.n_stations], r.station_cov_m2) < 1e-9
    assert _rel(gen.cov_m2[lay.n_stations:], r.target_cov_m2) < 1e-9


def test_distance_back_ends_refuse_a_general_design():
    design = design_from_layout(*_small_layout())
    other = type(design)(design.network)                       # no distance-only form
    with pytest.raises(MultilatError, match="distance-only layouts"):
        evaluate_layout(other, "fast")
    with pytest.raises(MultilatError, match="backend must be one of"):
        evaluate_layout(design, "dense")
    with pytest.raises(MultilatError, match="321"):
        design_from_layout(*_small_layout(), datum="321:1,2,3")


def _small_layout():
    c = configs.small_volume()
    return Layout(c.station_ids, c.station_xyz_m, c.target_ids, c.target_xyz_m), SIG


# --- a tracker layout: angles and distances from two levelled trackers --------------------------------
SIG_D, SIG_A = 10e-6, 20e-6


def tracker_design(extra_target: bool = False) -> Network:
    """Two levelled trackers (azimuth, elevation and distance to every target), a free network with
    inner constraints over the trackers and the ten targets; ``extra_target``: a target U with two
    distances only (not a datum point: inner constraints over it would fix its free circle, as
    minimum trace does for any datum point)."""
    rng = np.random.default_rng(3)
    trackers = np.array([[0.0, 0.0, 1.5], [6.0, 1.0, 1.6]])
    targets = rng.uniform([1, -2, 0], [5, 3, 3], (10, 3))
    ids = ["TA", "TB"] + [f"P{j}" for j in range(10)] + (["U"] if extra_target else [])
    xyz = np.vstack([trackers, targets] + ([[3.0, 0.5, 1.0]] if extra_target else []))
    n = len(ids)
    pts = PointSet.build(ids, xyz, status=np.full(n, FREE), constrained=np.arange(n) < 12)   # U: no datum point
    si, ti = np.repeat([0, 1], 10), np.tile(np.arange(10), 2) + 2
    fr, to = np.repeat(si, 2), np.repeat(ti, 2)
    blocks = [Block("tracker_angles", np.zeros(40), np.full(40, SIG_A), None,
                    {"from": fr, "to": to, "setup": fr, "component": np.tile([0, 1], 20)},
                    names={"setup": ("TA", "TB")}, options={"levelled": True}),
              Block("slope_distance", np.zeros(20), np.full(20, SIG_D), None, {"from": si, "to": ti})]
    if extra_target:
        blocks.append(Block("slope_distance", np.zeros(2), np.full(2, SIG_D), None,
                            {"from": np.array([0, 1]), "to": np.array([12, 12])}, labels=("TA-U", "TB-U")))
    return Network(pts, tuple(blocks))


def test_tracker_layout_prediction_matches_monte_carlo():
    design = tracker_design()
    pred = predict(design)
    assert pred.result.defect == 4                              # 3 translations and the rotation about z
    adj = adjust_network(planned(design))
    mc = propagate(adj.system, adj.result, trials=4000, rng=20261127, pairs=())
    assert mc.n_failed == 0
    std = np.sqrt(np.diag(pred.result.cofactor))
    k = [mc.labels.index(n) for n in pred.result.free_names if n[:2] in ("x:", "y:", "z:")]
    s = [i for i, n in enumerate(pred.result.free_names) if n[:2] in ("x:", "y:", "z:")]
    assert len(k) == 36
    z = (mc.mc_std[k] - std[s]) / mc.mc_std_se[k]
    assert np.abs(z).max() < 4.0, f"worst |z| {np.abs(z).max():.2f}"
    assert np.allclose(mc.lin_std[k], std[s], rtol=1e-9, atol=0)


def test_undetermined_point_named_and_the_rest_predicted():
    design = tracker_design(extra_target=True)
    pred = predict(design)
    assert [e["id"] for e in pred.undetermined] == ["U"]
    assert pred.undetermined[0]["n_obs"] == 2 and "not determined" in pred.undetermined[0]["reason"]
    assert "U" not in pred.result.ids
    ref = predict(without_points(design, ["U"])[0])
    assert _rel(pred.result.cofactor, ref.result.cofactor) < 1e-12
    with pytest.raises(UndeterminedError, match="'U'"):
        predict(design, strict=True)
    g = evaluate_layout(Design(design))
    assert g.backend == "general" and [e["id"] for e in g.undetermined] == ["U"]


def test_weak_rows_by_the_adjustments_thresholds():
    pred = predict(tracker_design())
    s = pred.stats
    assert np.array_equal(pred.weak, (s.redundancy < 0.1) | (s.mdb_sigma > 10.0))
    assert pred.r_min == 0.1 and pred.mdb_limit_sigma == 10.0


def test_planned_needs_every_coordinate():
    with pytest.raises(MultilatError, match="point 'S' has no planned coordinates"):
        predict(read_gama_input(GAMA3D / "station_control.xml"))


# --- CLI ----------------------------------------------------------------------------------------------
def _cli(capsys, args):
    from multilat.cli import main

    rc = main([str(a) for a in args])
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_cli_json_and_text(capsys):
    from multilat.vocabulary import document_problems

    xml = GAMA3D / "two_trackers.xml"
    rc, out, err = _cli(capsys, ["design", "--evaluate", xml, "--json"])
    assert rc == 0, err
    doc = json.loads(out)
    assert doc["schema"] == "multilat.design-general/1"
    assert not document_problems(doc)
    pred = predict(read_gama_input(xml))
    for i, p in enumerate(pred.result.ids):
        assert np.allclose(doc["points"][p]["xyz_std_m"], np.sqrt(np.diag(pred.stats.cov_m2[i])), rtol=1e-12)
    assert doc["reliability"]["n_weak"] == int(pred.weak.sum()) == len(doc["weak_rows"]) > 0
    assert doc["dof"] == pred.result.dof and doc["undetermined"] == []
    rc, out, err = _cli(capsys, ["design", xml])
    assert rc == 0 and "weak row(s)" in out and "P01" in out


@pytest.mark.parametrize("args,word", [(["--seed", "3"], "--seed does not apply"),
                                       (["--simulate", "10"], "--simulate does not apply")])
def test_cli_refuses_search_options(capsys, args, word):
    rc, out, err = _cli(capsys, ["design", "--evaluate", GAMA3D / "two_trackers.xml", *args])
    assert rc == 2 and word in err and err.count("\n") == 1


def test_cli_names_a_point_without_coordinates(capsys):
    rc, out, err = _cli(capsys, ["design", "--evaluate", GAMA3D / "station_control.xml"])
    assert rc == 2 and "station_control.xml: point 'S' has no planned coordinates" in err and not out


def test_cli_refuses_two_inputs(capsys, tmp_path):
    xml = GAMA3D / "two_trackers.xml"
    rc, out, err = _cli(capsys, ["design", xml, "--evaluate", xml])
    assert rc == 2 and "a planned network is evaluated on its own" in err and err.count("\n") == 1
    heads = tmp_path / "heads.csv"
    heads.write_text("point,x_m,y_m,z_m\nA,0,0,0\n")
    rc, out, err = _cli(capsys, ["design", xml, "--evaluate", heads])
    assert rc == 2 and "does not apply to a planned network" in err
    rc, out, err = _cli(capsys, ["design"])
    assert rc == 2 and "design needs a config TOML" in err
