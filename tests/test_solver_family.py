"""One network core: dense and sparse back ends give the same result (keys and numbers), the
convergence record is explicit, and the stopping rule reaches the minimum to the limits of float64."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from multilat.cli.app import main
from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import Start, adjust
from multilat.network.model.data import Observations
from multilat.network.io.files import read_observations
from multilat.network.synthetic.generator import synthetic_network

EX = Path(__file__).resolve().parents[1] / "examples" / "network"
OBS = EX / "small_volume_obs.csv"


def _run(capsys, args):
    rc = main(args)
    out = capsys.readouterr()
    return rc, out.out, out.err


def _blundered(tmp_path) -> Path:
    """A 8-station, 60-target network (6 stations per target) with a 40-sigma blunder on one distance."""
    net = synthetic_network(3, population="rings", n_stations=8, n_targets=60, per_target=6, size_m=8.0)
    d = net.distance_m.copy()
    d[100] += 40 * net.sigma_m[100]
    p = tmp_path / "blunder.csv"
    rows = [f"S{i},T{j},{float(x)!r},{float(sg)!r}" for i, j, x, sg in zip(net.station_index, net.target_index, d, net.sigma_m)]
    p.write_text("station,target,distance_m,sigma_m\n" + "\n".join(rows) + "\n")
    return p


def _tolerance(path: str, a: float) -> float:
    """Lengths to 1e-12 m (the float64 floor of a 10 m network is ~1e-15 m, each back end stops
    within a few of it); covariances (m^2) to 1e-7 relative; dimensionless statistics (w,
    redundancy, sigma0, ...) to 1e-9 relative or 1e-8 absolute (a w of 1e-8 is a residual of
    5e-14 m at sigma 5 µm)."""
    key = path.rsplit(".", 1)[-1].split("[")[0]
    if key.endswith("_m2"):
        return 1e-7 * abs(a) + 1e-22
    if key.endswith("_m") or key == "xyz_m":
        return 1e-12
    return max(1e-8, 1e-9 * abs(a))


def _same(a, b, path="$"):
    """Same keys everywhere; numbers equal within :func:`_tolerance`."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), f"{path}: keys {set(a) ^ set(b)}"
        for k in a:
            if k in ("solver", "initial"):
                continue
            _same(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        if np.isnan(a):
            assert np.isnan(b), path
        else:
            assert abs(a - b) <= _tolerance(path, a), f"{path}: {a!r} vs {b!r}"
    elif path.endswith(".iterations") or ".convergence." in path:
        pass                                     # how each back end got there may differ
    else:
        assert a == b, f"{path}: {a!r} vs {b!r}"


def test_dense_and_sparse_identical_with_a_blunder(capsys, tmp_path):
    """The whole --json document (statistics, data snooping, reference lengths, ellipsoids via
    covariances) is the same from both back ends on a network with a blunder."""
    p = _blundered(tmp_path)
    rc, out, err = _run(capsys, ["adjust", str(p), "--solver", "dense", "--json"])
    assert rc == 0, err
    dense = json.loads(out)
    rc, out, err = _run(capsys, ["adjust", str(p), "--solver", "sparse", "--json"])
    assert rc == 0, err
    sparse = json.loads(out)
    assert (dense["solver"], sparse["solver"]) == ("dense", "sparse")
    assert len(dense["outliers"]) == 1 and dense["outliers"][0]["target"] == sparse["outliers"][0]["target"]
    assert dense["convergence"]["converged"] and sparse["convergence"]["converged"]
    _same(dense, sparse)


def test_auto_switches_and_sparse_refuses_what_it_cannot_do(capsys, monkeypatch):
    from multilat.network.adjust.solve import loop

    monkeypatch.setattr(loop, "SPARSE_ABOVE_OBS", 10)
    rc, out, err = _run(capsys, ["adjust", str(OBS), "--json"])
    assert rc == 0 and json.loads(out)["solver"] == "sparse"
    rc, out, err = _run(capsys, ["adjust", str(OBS), "--cost", "squared", "--json"])
    assert rc == 0 and json.loads(out)["solver"] == "dense"          # auto: dense where sparse cannot
    rc, _, err = _run(capsys, ["adjust", str(OBS), "--solver", "sparse", "--cost", "squared"])
    assert rc == 2 and err.strip().count("\n") == 0 and "--solver dense" in err and "squared" in err


def test_sparse_equals_dense_on_a_large_network():
    """1 000 targets x 8 of 12 stations, from initial values 1 mm off: the same minimum (1e-9 m) and
    the same statistics from both back ends."""
    net = synthetic_network(5, population="rings", n_stations=12, n_targets=1000, per_target=8)
    obs = Observations(tuple(f"S{i}" for i in range(12)), tuple(f"T{j}" for j in range(1000)),
                       net.station_index, net.target_index, net.distance_m, net.sigma_m)
    rng = np.random.default_rng(6)
    start = Start(net.station_xyz_m + rng.normal(0, 1e-3, (12, 3)),
                  net.target_xyz_m + rng.normal(0, 1e-3, (1000, 3)), net.offset_m + rng.normal(0, 1e-3, 12))
    d = adjust(obs, initial=start, solver="dense", snooping=False)
    s = adjust(obs, initial=start, solver="sparse", snooping=False)
    assert d.solver == "dense" and s.solver == "sparse"
    assert np.abs(d.target_xyz_m - s.target_xyz_m).max() < 1e-9
    assert np.abs(d.offset_m - s.offset_m).max() < 1e-12
    assert s.sigma0 == pytest.approx(d.sigma0, rel=1e-10)
    np.testing.assert_allclose(s.redundancy, d.redundancy, atol=1e-9)
    np.testing.assert_allclose(s.target_cov_m2, d.target_cov_m2, rtol=1e-7, atol=1e-20)
    # and against the truth: the offsets' errors are consistent with their covariance
    e = s.offset_m - net.offset_m
    z = e / s.offset_std_m
    assert np.sqrt(np.mean(z**2)) < 3.0


@pytest.mark.parametrize("solver", ["dense", "sparse"])
def test_convergence_reaches_the_minimum_of_a_solver_started_from_the_truth(solver):
    """Started 5 mm off or at the truth, the solver ends at the same point to the float64 floor
    (a few 1e-15 m at a few metres), and the record says converged."""
    net = synthetic_network(9, population="rings", n_stations=8, n_targets=300, per_target=6, size_m=6.0)
    obs = Observations(tuple(f"S{i}" for i in range(8)), tuple(f"T{j}" for j in range(300)),
                       net.station_index, net.target_index, net.distance_m, net.sigma_m)
    truth = Start(net.station_xyz_m, net.target_xyz_m, net.offset_m)
    rng = np.random.default_rng(1)
    far = Start(net.station_xyz_m + rng.normal(0, 5e-3, (8, 3)), net.target_xyz_m + rng.normal(0, 5e-3, (300, 3)),
                net.offset_m)
    a = adjust(obs, initial=truth, solver=solver, snooping=False)
    b = adjust(obs, initial=far, solver=solver, snooping=False, datum="free:" + ",".join(obs.station_ids))
    a2 = adjust(obs, initial=truth, solver=solver, snooping=False, datum="free:" + ",".join(obs.station_ids))
    assert a.convergence.converged and b.convergence.converged
    assert b.convergence.last_step_sigma < 1e-4
    # datum-free quantities: offsets and sigma0
    assert np.abs(a.offset_m - b.offset_m).max() < 1e-13
    # sigma0: the cost itself is known to ~2 sqrt(cost) eps L / sigma ~ 1e-11 relative here
    assert b.sigma0 == pytest.approx(a.sigma0, rel=1e-10)
    # interpoint distances (datum-free) between far-apart targets
    for i, j in [(0, 299), (10, 200), (50, 51)]:
        da = np.linalg.norm(a2.target_xyz_m[i] - a2.target_xyz_m[j])
        db = np.linalg.norm(b.target_xyz_m[i] - b.target_xyz_m[j])
        assert abs(da - db) < 1e-13


def test_no_silent_exit_iteration_limit_is_an_error():
    """A solver stopped by its iteration limit is not a result: one-line error with the record."""
    obs = read_observations(OBS)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(MultilatError, match="did not converge \\(iteration limit after 1 iterations"):
            adjust(obs, max_iter=1)


@pytest.mark.parametrize("solver", ["dense", "sparse"])
def test_statistics_equal_an_independent_dense_implementation(solver):
    """σ0, redundancy numbers, w-tests and MDBs from either back end against a second method: the
    whole whitened Jacobian in one dense matrix, its pseudo-inverse (SVD) and Baarda's formulas
    written out here. Datum-free quantities: 1e-9 relative, redundancy 1e-9 absolute. w and the MDB
    divide by sqrt(r): a redundancy number known to 1e-9 gives them to 1e-9/(2r) relative; the sparse
    back end's compiled assembly sums in another order, which the condition number of the reduced
    system (~1e6 here) turns into ~1e-9 on r: w and MDB to 1e-7 relative there (the residuals agree
    to 4e-15 m)."""
    from scipy import stats

    from multilat.network.model.distance import dense_jacobian, residuals_and_jacobian

    net = synthetic_network(21, population="rings", n_stations=6, n_targets=40, per_target=5, size_m=6.0)
    obs = Observations(tuple(f"S{i}" for i in range(6)), tuple(f"T{j}" for j in range(40)),
                       net.station_index, net.target_index, net.distance_m, net.sigma_m)
    res = adjust(obs, initial=Start(net.station_xyz_m, net.target_xyz_m, net.offset_m), solver=solver,
                 snooping=False)
    o = obs
    r, Js, Jt = residuals_and_jacobian(o.distance_m, res.station_xyz_m, res.target_xyz_m, res.offset_m,
                                       res.scale, o.station_index, o.target_index)
    A = dense_jacobian(Js, Jt, o.station_index, o.target_index, 6, 40) / o.sigma_m[:, None]
    A = np.delete(A, np.arange(4, 5 * 6, 5), axis=1)               # no scales
    v = r / o.sigma_m
    U, sv, _ = np.linalg.svd(A, full_matrices=False)
    rank = int(np.sum(sv > 1e-10 * sv[0]))
    assert rank == A.shape[1] - 6
    h = np.sum(U[:, :rank] ** 2, axis=1)                             # hat matrix diagonal
    red = 1.0 - h
    dof = o.n_obs - rank
    sigma0 = np.sqrt(v @ v / dof)
    w = v / np.sqrt(red)
    delta = stats.norm.isf(0.001 / 2) + stats.norm.ppf(0.80)
    mdb = delta * o.sigma_m / np.sqrt(red)
    assert res.dof == dof
    assert res.sigma0 == pytest.approx(sigma0, rel=1e-9)
    np.testing.assert_allclose(res.redundancy, red, rtol=0, atol=1e-9)
    tol = 1e-9 if solver == "dense" else 1e-7
    np.testing.assert_allclose(res.w, w, rtol=tol, atol=1e-9)
    np.testing.assert_allclose(res.mdb_m, mdb, rtol=tol)


def test_no_snooping_while_the_global_test_passes():
    """Detection first (a fixed global test at α = 0.05): on a blunder-free network of 12 000 distances
    about α·m = 12 w-tests fail by chance at α = 0.001; the global test passes, so none is rejected —
    each is listed in w_failures. A 30σ blunder added to the same data fails the global test and is the
    one rejected. (The default B-method would set α_global = 0.75 at these 5 944 dof: see
    test_reliability.py.)"""
    net = synthetic_network(17, population="rings", n_stations=12, n_targets=2000, per_target=6, size_m=10.0)
    obs = Observations(tuple(f"S{i}" for i in range(12)), tuple(f"T{j}" for j in range(2000)),
                       net.station_index, net.target_index, net.distance_m, net.sigma_m)
    start = Start(net.station_xyz_m, net.target_xyz_m, net.offset_m)
    res = adjust(obs, initial=start, solver="sparse", alpha_global=0.05)
    n_fail = sum(len(g) for g in res.w_failure_groups)
    assert res.global_test.passed and res.outliers == () and res.used.all()
    assert 2 <= n_fail <= 30                                 # Poisson(12): 99.99 % inside
    d = net.distance_m.copy()
    d[123] += 30 * net.sigma_m[123]
    bad = adjust(obs.with_distances(d), initial=start, solver="sparse", alpha_global=0.05)
    assert [f"{o.station}->{o.target}" for o in bad.outliers] == [obs.label(123)] and bad.global_test.passed
    assert bad.initial["search"]["tried"][0]["label"].startswith("not searched") and not bad.warnings


def test_weak_target_left_out_from_the_cli_and_strict_refuses(capsys, tmp_path):
    """A target with 2 distances: left out with a warning and listed in `excluded`; --strict: one line."""
    lines = OBS.read_text().splitlines()
    keep = [ln for ln in lines if not (ln.startswith("C,3,") or ln.startswith("D,3,"))]
    p = tmp_path / "weak.csv"
    p.write_text("\n".join(keep) + "\n")
    rc, out, err = _run(capsys, ["adjust", str(p), "--json"])
    assert rc == 0, err
    doc = json.loads(out)
    assert doc["excluded"] == [{"id": "3", "kind": "target", "reason": "has 2 observation(s); 3 are needed "
                                "to place it", "n_obs": 2}]
    assert "3" not in doc["targets"] and "warning: target '3' left out" in err
    rc, out, err = _run(capsys, ["adjust", str(p), "--strict"])
    assert rc == 2 and "target '3' has 2 observation(s)" in err and "--strict" in err


def test_initial_values_carry_their_refinement_record():
    """The initial values' own least squares does not end silently: its record is in the result."""
    from multilat.network.adjust.approximate.initial import initial_values

    obs = read_observations(OBS)
    iv = initial_values(obs, rng=0)
    assert iv.refinement is not None and iv.refinement.converged and iv.refinement.iterations >= 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = adjust(obs, rng=0)
    assert res.initial["refinement"]["converged"] is True
