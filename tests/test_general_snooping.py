"""Data snooping, external reliability and variance components on the general network
(multilat.network.adjust.general.snooping, .reliability, .variance), each against an independent value:

- a 20σ blunder planted in a direction, a slope distance, a zenith angle and a height difference of the
  gama3d reference networks (tests/data/gama3d) is found and rejected, and the re-adjusted solution
  equals that of the *file* with that line deleted (read and adjusted anew; 1e-9 m: both converge
  to a step of 1e-10, quadratically); a vector (a correlated 3-row block) is rejected as a block;
- on blunder-free networks (the reference designs with new gaussian noise) the rate of networks that
  lose a row is that of the family-wise α of Šidák's rule (0.01), within 3 Monte Carlo standard errors;
- the coordinate shift of each row's MDB (``∇x = Q Jᵀ P ∇l``) against re-adjusting with the MDB added to
  that row (central difference ±MDB: the second-order term of the network's curvature cancels),
  1e-6 relative;
- variance components: one group is σ0² exactly (the closed form); two kinds simulated with σ scaled by
  known factors give those factors in expectation over seeds (tolerance 4 Monte Carlo standard errors),
  and Helmert's standard error matches the spread over seeds;
- the distance path and the general layer on examples/network/mixed with a planted distance and azimuth
  blunder: the same rows rejected, the same w;
- the command line: --snooping/--no-snooping and --variance-components on a gama-local input, the
  document valid against the shipped schema.
"""

from __future__ import annotations

import csv
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from multilat.network.adjust import statistics as st
from multilat.network.adjust.general import adjust_network, read_gama_input
from multilat.network.adjust.general.adjust import System, adjust
from multilat.network.model.observations import Block, Network
from multilat.network.adjust.general.quality import statistics
from multilat.network.adjust.general.reliability import point_columns, whitened_jacobian
from multilat.network.adjust.general.snooping import snoop
from multilat.network.adjust.general.variance import estimate

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "gama3d"


def _with_value(net: Network, q: int, value) -> Network:
    blocks = list(net.blocks)
    blocks[q] = replace(blocks[q], value=np.asarray(value, float))
    return Network(net.points, tuple(blocks), net.notes)


def _row_to_plant(net: Network, kind: str) -> tuple[int, int]:
    """(block, row) of ``kind`` with the largest redundancy among the independent rows of that kind
    whose w-test is separable from every other (|ρ| < 0.9, ρ from the dense R = I - J_w Q J_wᵀ)."""
    adj = adjust_network(net)
    jw = whitened_jacobian(adj.system, adj.result)
    R = np.eye(jw.shape[0]) - jw @ adj.result.cofactor @ jw.T
    r = np.diag(R)
    ok = r > 0.05
    rho = np.zeros_like(R)
    rho[np.ix_(ok, ok)] = np.abs(R[np.ix_(ok, ok)]) / np.sqrt(np.outer(r[ok], r[ok]))
    np.fill_diagonal(rho, 0.0)
    best = None
    for q, (b, sl) in enumerate(zip(adj.system.blocks, adj.system.rows)):
        if b.kind == kind and b.cov is None and q < len(net.blocks):
            for k in range(b.n_rows):
                i = sl.start + k
                if ok[i] and rho[i].max() < 0.9 and (best is None or r[i] > best[2]):
                    best = (q, k, r[i])
    return best[0], best[1]


def _levelling_loops(tmp_path) -> Path:
    """height_differences.xml with 5 more height differences closing loops (the file's two lines alone
    leave every w-test of a segment perfectly correlated with its neighbour's: no blunder there can be
    located). Values: the stored truth plus seeded noise of their σ (0.8 mm)."""
    truth = {r["id"]: float(r["z_m"]) for r in csv.DictReader((DATA / "height_differences_truth.csv").read_text().splitlines())}
    rng = np.random.default_rng(11)
    extra = "".join(f'  <dh from="{a}" to="{b}" val="{truth[b] - truth[a] + 0.0008 * rng.standard_normal():.6f}" '
                    'stdev="0.80" />\n'
                    for a, b in (("A", "L2"), ("L1", "L3"), ("C", "L3"), ("L5", "L6"), ("B", "L6")))
    text = (DATA / "height_differences.xml").read_text()
    out = tmp_path / "height_differences.xml"
    out.write_text(text.replace("</points-observations>", f"<height-differences>\n{extra}</height-differences>\n"
                                                          "</points-observations>"))
    return out


@pytest.mark.parametrize("name,kind", [("direction_sets", "direction"), ("direction_sets", "slope_distance"),
                                       ("heights", "zenith_angle"), ("height_differences", "height_difference")])
def test_a_planted_blunder_is_rejected_and_the_rest_adjusted_as_without_it(name, kind, tmp_path):
    path = DATA / f"{name}.xml" if name != "height_differences" else _levelling_loops(tmp_path)
    net = read_gama_input(path)
    q, k = _row_to_plant(net, kind)
    b = net.blocks[q]
    value = b.value.copy()
    value[k] += 20.0 * b.sigma[k]
    sn = snoop(_with_value(net, q, value))
    assert len(sn.rejected) == 1, [r["label"] for r in sn.rejected]
    rej = sn.rejected[0]
    assert rej["label"] == b.labels[k] and rej["kind"] == kind and rej["n_rows"] == 1
    assert rej["round"] == 1 and abs(rej["w"]) > rej["critical"] and not sn.unlocated
    assert rej["residual"] == pytest.approx(20.0 * b.sigma[k], rel=0.25)   # the blunder, seen from the rest
    # the independent value: the file without that line, read and adjusted anew
    line = int(b.labels[k].rsplit(":", 1)[1])
    lines = path.read_text().splitlines(keepends=True)
    cut = tmp_path / path.name
    cut.write_text("".join(lines[:line - 1] + lines[line:]))
    ref = adjust_network(read_gama_input(cut))
    res = sn.adjustment.result
    assert res.ids == ref.result.ids and res.dof == ref.result.dof
    np.testing.assert_allclose(res.xyz_m, ref.result.xyz_m, rtol=0, atol=1e-9)
    assert res.sigma0 == pytest.approx(ref.result.sigma0, rel=1e-9)
    assert sn.steps[-1]["detection_passed"] is True                     # stopped because nothing fails


def test_a_vector_is_rejected_as_a_block():
    net = read_gama_input(DATA / "vectors.xml")
    b = net.blocks[0]
    value = b.value.copy()
    k = 13                                                           # the z of the 5th vector
    value[k] += 20.0 * b.sigma[k]
    sn = snoop(_with_value(net, 0, value))
    assert len(sn.rejected) == 1
    rej = sn.rejected[0]
    vec = np.flatnonzero((b.index["from"] == b.index["from"][k]) & (b.index["to"] == b.index["to"][k]))
    assert rej["n_rows"] == 3 and len(rej["block_rows"]) == 2 and len(rej["residual"]) == 3
    assert (rej["from"], rej["to"]) == (net.points.ids[b.index["from"][k]], net.points.ids[b.index["to"][k]])
    # independent: the block rebuilt without the vector's rows (its covariance restricted)
    keep = np.ones(b.n_rows, bool)
    keep[vec] = False
    sub = Block(b.kind, b.value[keep], b.sigma[keep], b.cov[np.ix_(keep, keep)],
                {key: v[keep] for key, v in b.index.items()}, labels=tuple(np.array(b.labels)[keep]))
    ref = adjust_network(Network(net.points, (sub,), ()))
    np.testing.assert_allclose(sn.adjustment.result.xyz_m, ref.result.xyz_m, rtol=0, atol=1e-9)


def test_perfectly_correlated_rows_are_not_rejected():
    """Two distances that are all a point's one free coordinate (z) has: redundancy 1, their w-tests
    perfectly correlated; snooping names both and rejects neither (as the distance path)."""
    from multilat.network.model.points import FIXED, FREE, PointSet

    pts = PointSet.build(["A", "B", "P"], [[0, 0, 0], [100, 0, 0], [50, 50, 30.0]],
                         status=[[FIXED] * 3, [FIXED] * 3, [FIXED, FIXED, FREE]])
    d = np.sqrt(50 ** 2 + 50 ** 2 + 30 ** 2)
    blk = Block("slope_distance", np.array([d + 0.02, d]), np.array([0.001, 0.001]),
                index={"from": np.array([0, 1]), "to": np.array([2, 2])}, labels=("f:1", "f:2"))
    sn = snoop(Network(pts, (blk,), ()), method="fixed", alpha_global=0.05)
    assert sn.rejected == () and len(sn.unlocated) >= 2
    assert "perfectly correlated" in sn.unlocated_reason


def _vector_to_new_point(strict=False):
    """vectors.xml plus a point X placed by one correlated vector from G1 (its x, y have no check) and
    two height differences (its z has redundancy 2); the vector's dz carries a 20σ blunder."""
    from multilat.network.model.points import FREE, PointSet

    net = read_gama_input(DATA / "vectors.xml")
    res = adjust_network(net).result
    g1, g2, g3 = (res.xyz_m[res.ids.index(p)] for p in ("G1", "G2", "G3"))
    x_true = g1 + np.array([120.0, -80.0, 15.0])
    pts = net.points
    P = PointSet(pts.ids + ("X",), np.vstack([res.xyz_m, x_true]), np.vstack([pts.status, [[FREE] * 3]]),
                 np.vstack([pts.sigma_m, [[np.nan] * 3]]), np.append(pts.constrained, False))
    ix = {p: i for i, p in enumerate(P.ids)}
    cov = np.array([[4.0, 1.0, 0.5], [1.0, 4.0, 0.8], [0.5, 0.8, 9.0]]) * 1e-6
    vec = Block("coordinate_difference", (x_true - g1) + np.array([0.0, 0.0, 20 * 3e-3]), np.sqrt(np.diag(cov)), cov,
                {"from": np.full(3, ix["G1"]), "to": np.full(3, ix["X"]), "axis": np.arange(3)},
                labels=("v:1", "v:1", "v:1"))
    dh = Block("height_difference", np.array([x_true[2] - g2[2], x_true[2] - g3[2]]), np.array([2e-3, 2e-3]),
               index={"from": np.array([ix["G2"], ix["G3"]]), "to": np.array([ix["X"], ix["X"]])},
               labels=("h:1", "h:2"))
    # the file's vectors at the adjusted values: the blunder is the only inconsistency
    r, _ = adjust_network(net).system.evaluate(res.parameters)
    b0 = replace(net.blocks[0], value=net.blocks[0].value - r)
    return snoop(Network(P, (b0, vec, dh), ()), strict=strict)


def test_a_block_that_was_all_a_point_had_takes_the_point_with_it():
    sn = _vector_to_new_point()
    (rej,) = sn.rejected
    assert rej["label"] == "v:1" and rej["n_rows"] == 3 and rej["points_left_out"] == ["X"]
    assert any(e["id"] == "X" and "once v:1 was rejected" in e["reason"] for e in sn.adjustment.excluded)
    assert "X" not in sn.adjustment.result.ids
    strict = _vector_to_new_point(strict=True)
    assert strict.rejected == () and "--strict" in strict.unlocated_reason and "'X'" in strict.unlocated_reason


def test_the_number_of_rejections_is_bounded():
    net = read_gama_input(DATA / "direction_sets.xml")
    b = net.blocks[1]
    value = b.value.copy()
    value[[2, 7]] += 20.0 * b.sigma[[2, 7]]
    sn = snoop(_with_value(net, 1, value), max_rejections=1)
    assert len(sn.rejected) == 1 and "bound of 1 rejection" in sn.note
    assert len(snoop(_with_value(net, 1, value)).rejected) == 2


# ------------------------------------------------------------------------------ false alarms
def _simulated(adj, rng, factors=None) -> Network:
    """The adjusted network's design with new observations: the model at the adjusted parameters
    plus gaussian noise of each block's covariance (× ``factors[kind]``)."""
    sysm = adj.system
    r, _ = sysm.evaluate(adj.result.parameters)
    blocks = []
    for b, sl in zip(adj.network.blocks, sysm.rows):
        f = 1.0 if factors is None else factors.get(b.kind, 1.0)
        L = np.linalg.cholesky(b.covariance)
        blocks.append(replace(b, value=b.value - r[sl] + np.sqrt(f) * (L @ rng.standard_normal(b.n_rows))))
    pts = adj.network.points.with_xyz(adj.result.xyz_m)
    return Network(pts, tuple(blocks), ())


@pytest.mark.parametrize("vf", ["known", "unknown"])
def test_false_rejections_match_the_family_wise_alpha(vf):
    """Šidák's rule (the default on these networks, > 10 tests): P(a blunder-free network loses a
    row) <= α_family = 0.01, close to it for weakly correlated tests; with the variance factor unknown
    the largest |τ| at the same α0. 3 designs × 200 seeds; measured 5/600 (known) and 6/600 (unknown),
    Monte Carlo SE 0.004."""
    rng = np.random.default_rng(20261127)
    n, lost = 0, 0
    for name in ("direction_sets", "two_trackers", "trilateration_fixed"):
        adj = adjust_network(read_gama_input(DATA / f"{name}.xml"))
        for _ in range(200):
            sn = snoop(_simulated(adj, rng), variance_factor=vf)
            assert sn.stats.levels.method == "sidak"
            n += 1
            lost += bool(sn.rejected)
    rate = lost / n
    se = np.sqrt(0.01 * 0.99 / n)                                   # Monte Carlo SE at the nominal rate
    assert rate <= 0.01 + 3 * se, (rate, se)
    assert rate >= 0.01 - 3 * se, (rate, se)                          # not an inert procedure either


# ------------------------------------------------------------------------------ external reliability
@pytest.mark.parametrize("name", ["direction_sets", "vectors", "two_trackers"])
def test_external_shift_equals_readjusting_with_the_mdb(name):
    """``∇x = Q Jᵀ P ∇l`` is the response of the linearised model; a re-adjustment also sees the
    residuals times the curvature of the model (a term Gauss-Newton leaves out: 6e-6 relative on
    direction_sets with its residuals). So the direct computation runs on the same design with
    consistent observations (the adjusted values: residuals 0, the same Q and J), where the two must
    agree up to the third-order term of ±MDB (central difference): 1e-6 relative."""
    real = adjust_network(read_gama_input(DATA / f"{name}.xml"))
    r, _ = real.system.evaluate(real.result.parameters)
    blocks = tuple(replace(b, value=b.value - r[sl]) for b, sl in zip(real.network.blocks, real.system.rows))
    adj = adjust_network(Network(real.network.points.with_xyz(real.result.xyz_m), blocks, ()))
    np.testing.assert_allclose(adj.result.xyz_m, real.result.xyz_m, atol=1e-6)
    stats = statistics(adj.system, adj.result)
    sysm, res = adj.system, adj.result
    jw = whitened_jacobian(sysm, res)
    cols = point_columns(res)
    lam = st.noncentrality(0.001, 0.80)
    rows = np.argsort(-np.where(np.isfinite(stats.shift_max_m), stats.shift_max_m, -1))[[0, 3, 10]]
    for i in rows:
        q = int(np.searchsorted([sl.stop for sl in sysm.rows], i, side="right"))
        b, k = sysm.blocks[q], int(i - sysm.rows[q].start)
        mdb_w = np.sqrt(lam / res.redundancy[i])                   # whitened MDB of the (decorrelated) row
        step = b.whitener()[:, k] * mdb_w                          # ∇l = L e_k MDB_w
        moved = []
        for sign in (1.0, -1.0):
            out = adjust(_with_value(adj.network, q, b.value + sign * step))
            moved.append(out.xyz_m)
        direct = (moved[0] - moved[1]) / 2.0
        # the predicted shift vector of every point
        pred = np.zeros(len(res.free_names) + 1)
        pred[:-1] = res.cofactor @ jw[i] * mdb_w
        pred = pred[cols]
        scale = np.linalg.norm(direct, axis=1).max()
        assert np.abs(pred - direct).max() <= 1e-6 * scale, (i, np.abs(pred - direct).max(), scale)
        j = int(np.argmax(np.linalg.norm(direct, axis=1)))
        assert stats.shift_max_m[i] == pytest.approx(np.linalg.norm(direct[j]), rel=1e-6)
        assert stats.shift_point[i] == res.ids[j]


def test_uncontrolled_rows_have_no_shift():
    adj = adjust_network(read_gama_input(DATA / "station_control.xml"))   # polar points: r = 0
    stats = statistics(adj.system, adj.result)
    zero = stats.redundancy <= st.R_ZERO
    assert zero.any() and np.all(np.isinf(stats.shift_max_m[zero])) and np.all(np.isfinite(stats.shift_max_m[~zero]))


# ------------------------------------------------------------------------------ variance components
def test_one_group_is_sigma0_squared():
    adj = adjust_network(read_gama_input(DATA / "trilateration_fixed.xml"))
    v = estimate(adj.network)
    (c,) = v.components
    assert c["variance_factor"] == pytest.approx(adj.result.sigma0 ** 2, rel=1e-9)
    assert c["redundancy"] == pytest.approx(adj.result.dof, rel=1e-9)
    # Helmert's S of one group is tr(R²) = tr(R) = dof (R idempotent): standard error θ sqrt(2 / dof)
    assert c["variance_factor_std"] == pytest.approx(c["variance_factor"] * np.sqrt(2.0 / adj.result.dof), rel=1e-6)


def _stations_and_targets(rng) -> tuple[Network, np.ndarray]:
    """4 fixed stations, 25 free targets; a slope distance (σ 1 mm) and a zenith angle (σ 0.3 mgon)
    from every station to every target: 200 rows, 75 unknowns, dof 125 (about 60 per kind). Returns
    the network with its values at the truth and the truth's parameter vector."""
    from multilat.network.model.points import FIXED, FREE, PointSet

    st_xyz = np.array([[0, 0, 1.5], [60, 0, 1.0], [60, 50, 2.0], [0, 50, 1.2]])
    tg = rng.uniform([5, 5, 0], [55, 45, 12], size=(25, 3))
    ids = [f"S{i}" for i in range(4)] + [f"T{j}" for j in range(25)]
    pts = PointSet.build(ids, np.vstack([st_xyz, tg]), status=[FIXED] * 4 + [FREE] * 25)
    fr, to = np.repeat(np.arange(4), 25), np.tile(np.arange(4, 29), 4)
    zeros = {"from_dh": np.zeros(100), "to_dh": np.zeros(100)}
    blocks = (Block("slope_distance", np.zeros(100), np.full(100, 1e-3), index={"from": fr, "to": to}, data=zeros),
              Block("zenith_angle", np.zeros(100), np.full(100, 0.3e-3 * np.pi / 200), index={"from": fr, "to": to},
                    data=zeros))
    net = Network(pts, blocks, ())
    sysm = System(net)
    x = sysm.layout.initial()
    r, _ = sysm.evaluate(x)
    return Network(pts, tuple(replace(b, value=-r[sl]) for b, sl in zip(blocks, sysm.rows)), ()), x


def test_two_kinds_scaled_by_known_factors():
    """The distances simulated with σ × 2 (variance factor 4), the zenith angles with σ × 0.5 (0.25):
    the mean estimate over 60 seeds equals the factors within 4 Monte Carlo standard errors, and the
    mean Helmert standard error (relative) equals the spread of the estimates within 25 % (the
    relative SE of a standard deviation from 60 samples is 9 %)."""
    rng = np.random.default_rng(7)
    net, _ = _stations_and_targets(rng)
    true = {"slope_distance": 4.0, "zenith_angle": 0.25}
    est, se = {k: [] for k in true}, {k: [] for k in true}
    for _ in range(60):
        noisy = tuple(replace(b, value=b.value + np.sqrt(true[b.kind]) * b.sigma * rng.standard_normal(b.n_rows))
                      for b in net.blocks)
        v = estimate(Network(net.points, noisy, ()), tol=1e-6)
        for c in v.components:
            est[c["group"]].append(c["variance_factor"])
            se[c["group"]].append(c["variance_factor_std"] / c["variance_factor"])   # relative
    for k, f in true.items():
        x = np.array(est[k])
        mc = x.std(ddof=1) / np.sqrt(x.size)
        assert abs(x.mean() - f) <= 4 * mc, (k, x.mean(), f, mc)
        rel_spread = (x / f).std(ddof=1)
        assert np.mean(se[k]) == pytest.approx(rel_spread, rel=0.25), (k, np.mean(se[k]), rel_spread)


def test_variance_components_by_head_on_a_csv_network():
    from multilat.cli.general_adjust import compute_tables

    params = {"observations": ROOT / "examples" / "network" / "mixed" / "obs.csv", "references": None,
              "points": None, "datum": "free"}
    doc, _, _ = compute_tables(params, alpha=0.001, variance_factor="known", strict=False,
                                 variance_components="head")
    groups = [c["group"] for c in doc["variance_components"]["components"]]
    assert any(g.startswith("slope_distance:") for g in groups) and "tracker_angles" in groups
    assert doc["variance_components"]["converged"]


# ------------------------------------------------------------------------------ against the distance path
def test_same_rejections_as_the_distance_path(tmp_path):
    from multilat.cli.general_adjust import compute_tables
    from multilat.network.adjust.distance.adjust import adjust as adjust_old
    from multilat.network.io.files import read_observations

    rows = list(csv.reader((ROOT / "examples" / "network" / "mixed" / "obs.csv").read_text().splitlines()))
    rows[10][2] = f"{float(rows[10][2]) + 20 * float(rows[10][3]):.9f}"            # H1->P10 distance
    ang = [i for i, r in enumerate(rows[1:], 1) if r[4]]
    a = rows[ang[3]]
    a[4] = f"{float(a[4]) + 20 * float(a[6]):.12f}"                               # AT1->P4 azimuth
    path = tmp_path / "obs.csv"
    with open(path, "w", newline="") as fh:
        csv.writer(fh).writerows(rows)
    old = adjust_old(read_observations(path))
    doc, _, _ = compute_tables({"observations": path, "references": None, "points": None, "datum": "free"},
                               alpha=0.001, variance_factor="known", strict=False)
    gen = {(o["from"], o["to"], o.get("component", "distance")): o["w"] for o in doc["outliers"]}
    ref = {(o.station, o.target, "distance"): o.w for o in old.outliers}
    ref.update({(o["station"], o["target"], o["kind"]): o["w"] for o in old.angle_outliers})
    assert set(gen) == set(ref) == {("H1", "P10", "distance"), ("AT1", "P4", "azimuth")}
    for key, w in ref.items():
        assert gen[key] == pytest.approx(w, rel=1e-6)


# ------------------------------------------------------------------------------ command line
def _cli(capsys, *args):
    from multilat.cli import main

    rc = main(["adjust"] + [str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def _blundered(tmp_path, rows=(3,)) -> tuple[Path, list[int]]:
    """direction_sets.xml with + 20 σ (σ 1.2 mm) on its slope distances ``rows``: the file, their lines."""
    path = DATA / "direction_sets.xml"
    text = path.read_text().splitlines(keepends=True)
    b = read_gama_input(path).blocks[1]                              # slope distances
    lines = [int(b.labels[k].rsplit(":", 1)[1]) for k in rows]
    for line in lines:
        old = text[line - 1]
        val = old.split('val="')[1].split('"')[0]
        text[line - 1] = old.replace(f'val="{val}"', f'val="{float(val) + 0.025:.6f}"')
    bad = tmp_path / "bad.xml"
    bad.write_text("".join(text))
    return bad, lines


def test_cli_snooping_and_variance_components(capsys, tmp_path):
    bad, (line,) = _blundered(tmp_path)
    rc, out, err = _cli(capsys, bad, "--json")
    assert rc == 0, err
    doc = json.loads(out)
    assert doc["snooping"] is True and [o["label"] for o in doc["outliers"]] == [f"{bad}:{line}"]
    assert doc["external_reliability"]["largest"][0]["shift_max_m"] == doc["external_reliability"]["shift_max_m"]
    _valid(doc)
    # with variance components the blunder is first absorbed by its group's factor (the estimation runs
    # without snooping, as on the distance path): the distances' factor is large and differs from 1
    rc, out, err = _cli(capsys, bad, "--json", "--variance-components", "kind")
    assert rc == 0, err
    doc = json.loads(out)
    vcs = {c["group"]: c for c in doc["variance_components"]["components"]}
    assert vcs["slope_distance"]["variance_factor"] > 5 and vcs["slope_distance"]["differs_from_1"]
    _valid(doc)
    rc, out, err = _cli(capsys, bad, "--json", "--no-snooping")
    assert rc == 0 and json.loads(out)["outliers"] == [] and json.loads(out)["tests"]["n_failed"] >= 1
    rc, out, err = _cli(capsys, bad)
    flat = " ".join(out.split())                  # the summary wraps at the console's width (80 off a terminal)
    assert rc == 0 and "rejected by data snooping, in order:" in flat and f"bad.xml:{line}" in "".join(out.split())
    assert "external reliability" in flat
    rc, out, err = _cli(capsys, bad, "--variance-components", "station")
    assert rc == 2 and err.startswith("error: ") and "grouping must be one of kind, head" in err


def _valid(doc):
    jsonschema = pytest.importorskip("jsonschema")
    schema = json.loads((ROOT / "src" / "multilat" / "schemas" / "adjust-general.json").read_text("utf-8"))
    errors = list(jsonschema.Draft202012Validator(schema).iter_errors(doc))
    assert not errors, errors[0].message[:300]


def test_outliers_and_steps_join_the_observations_table_by_index(capsys, tmp_path):
    """adjust-general/3 (issue 27): an outlier's ``index`` is its row of ``observations.csv`` under --out
    (the same residual and w), and the snooping step that identified it names that row by ``index`` and
    ``kind``, as the distance path's ``multilat.adjust/3``."""
    bad, (line,) = _blundered(tmp_path)
    out = tmp_path / "out"
    rc, _, err = _cli(capsys, bad, "--out", out, "--tables", "csv")
    assert rc == 0, err
    doc = json.loads((out / "result.json").read_text("utf-8"))
    table = list(csv.DictReader((out / "observations.csv").read_text("utf-8").splitlines()))
    assert doc["schema"] == "multilat.adjust-general/3" and len(doc["outliers"]) == 1
    o = doc["outliers"][0]
    row = table[o["index"]]
    assert int(row["index"]) == o["index"] and row["rejected"] == "True" and row["label"] == f"{bad}:{line}"
    assert (row["kind"], float(row["residual"]), float(row["w"])) == (o["kind"], o["residual"], o["w"])
    step = doc["tests"]["steps"][o["round"] - 1]
    assert step["action"] == "rejected" and (step["index"], step["kind"]) == (o["index"], "slope_distance")
    assert "row" not in step and [s.get("index") for s in doc["tests"]["steps"][1:]] == [None]
    _valid(doc)


def test_unlocated_rows_join_the_observations_table_by_index():
    """The two perfectly correlated distances of a point's one free coordinate: each ``unlocated``
    record's ``index`` is its row of the table (same label, residual, w), and the last step names it."""
    from multilat.network.model.points import FIXED, FREE, PointSet
    from multilat.network.adjust.general.report import list_observations, to_json

    pts = PointSet.build(["A", "B", "P"], [[0, 0, 0], [100, 0, 0], [50, 50, 30.0]],
                         status=[[FIXED] * 3, [FIXED] * 3, [FIXED, FIXED, FREE]])
    d = np.sqrt(50 ** 2 + 50 ** 2 + 30 ** 2)
    blk = Block("slope_distance", np.array([100.0, d + 0.02, d]), np.array([0.001, 0.001, 0.001]),
                index={"from": np.array([0, 0, 1]), "to": np.array([1, 2, 2])}, labels=("f:1", "f:2", "f:3"))
    sn = snoop(Network(pts, (blk,), ()), method="fixed", alpha_global=0.05)
    assert sn.rejected == () and len(sn.unlocated) == 2
    doc = list_observations(to_json(sn.adjustment, sn.stats, source="f", snooping=sn), "all")
    rows = doc["observations"]
    assert sorted(u["index"] for u in doc["unlocated"]) == [1, 2]        # f:1 (A->B, fixed ends) is row 0
    for u in doc["unlocated"]:
        r = rows[u["index"]]
        assert (r["index"], r["label"], r["residual"], r["w"]) == (u["index"], u["label"], u["residual"], u["w"])
    step = doc["tests"]["steps"][-1]
    assert (step["index"], step["kind"]) == (doc["unlocated"][0]["index"], "slope_distance")
