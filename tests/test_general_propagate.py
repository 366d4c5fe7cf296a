"""The general Monte Carlo (``multilat.network.montecarlo.general.propagate``): the adjustment's system frozen at
its solution, against independent values.

* the kinds over a trial axis equal the kinds one trial at a time (bit for bit: the same arithmetic);
* the compiled kernel's model and Jacobian equal the kinds' (1e-12 relative), its solutions the numpy
  engine's (1e-12 m: both iterate to a 1e-10 step, from the same start, by the same rule);
* each trial's solution is the least-squares solution of its observations: ``adjust`` run on the
  trial's observations gives the same parameters (1e-9 m: the step tolerance 1e-10 and the
  conditioning of the normal equations);
* the MC covariance equals the adjustment's cofactor matrix Q (σ0 a priori = 1: the trials are drawn
  from the a-priori covariance, so no σ0² enters) within the Monte Carlo standard error: for a
  variance from N gaussian trials the relative standard error is sqrt(2/(N-1)), of a standard
  deviation sqrt(1/(2(N-1))); every standard deviation must agree within 4 of its standard errors
  (a 4σ bound, so that among ~100 quantities none fails by chance: P(|z|>4) = 6e-5 each), and the
  point covariances' correlations within 4/sqrt(N);
* the distance-only Monte Carlo of today (``multilat.network.montecarlo.propagate``, compiled) and this one give
  the same standard deviations on a network both take (examples/network/sequential, gaussian), within
  4 combined MC standard errors; the datum differs only at second order (the old path's Kabsch fit on
  all points against the minimum-trace inner constraints over all points: the same to first order);
* bit-identical results across chunk sizes and maps;
* the draws are ``σ e`` / ``L e`` of the generator's normals, the first-step gain is ``Q J^T P`` with
  ``System.evaluate``'s ``J``, the kernel's ``P`` is ``scipy.sparse.block_diag`` of the blocks' weights
  (bit for bit), and each point's MC covariance is the engine's ``summarize`` covariance of its
  samples (``np.cov`` to 1e-12 relative);
* a far trial (observations moved by 100 σ: metres, on this network of 0.1 m σ) goes to full Gauss-Newton and still equals ``adjust``.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from multilat.network.adjust.general import adjust_network, read_gama_input
from multilat.network.adjust.general.adjust import adjust
from multilat.network.model.kinds import KINDS
from multilat.network.model.observations import Network
from multilat.network.montecarlo.general.propagate import SCHEMA, draw, freeze, propagate, solve

sys.path.insert(0, str(Path(__file__).parent))
from general_tracker_network import tracker_network  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
GAMA = ROOT / "tests" / "data" / "gama3d"
NSIG = 4.0


def _gama(name):
    return adjust_network(read_gama_input(GAMA / f"{name}.xml"))


@pytest.fixture(scope="module")
def tracker():
    net, _ = tracker_network()
    return adjust_network(net)


def _with_observations(network: Network, obs: np.ndarray, system) -> Network:
    """The network with its blocks' values replaced by one trial's observations (system row order)."""
    blocks = []
    n = len(network.blocks)
    for b, sl in zip(system.blocks[:n], system.rows[:n]):
        blocks.append(dataclasses.replace(b, value=obs[sl]))
    pts = network.points
    if len(system.blocks) > n:                   # weighted coordinates: their observed values
        from multilat.network.model.points import WEIGHTED

        xyz = pts.xyz_m.copy()
        i, c = np.nonzero(pts.status == WEIGHTED)
        xyz[i, c] = obs[system.rows[n]]
        pts = dataclasses.replace(pts, xyz_m=xyz)
    return Network(pts, tuple(blocks), network.notes)


@pytest.mark.parametrize("name", ["two_trackers", "direction_sets", "angles_hdist", "heights", "vectors"])
def test_kinds_over_trial_axis_equal_one_at_a_time(name):
    adj = _gama(name)
    s = adj.system
    x = adj.result.parameters + np.random.default_rng(1).standard_normal((4, s.layout.n)) * 1e-4
    for b, cols in zip(s.blocks, s.cols):
        mod = KINDS[b.kind]
        f, v, c = mod.evaluate(b, s.layout, cols, x)
        assert f.shape == (4, b.n_rows) and v.shape[:2] == (4, b.n_rows)
        for t in range(4):
            f1, v1, c1 = mod.evaluate(b, s.layout, cols, x[t])
            assert np.array_equal(f[t], f1) and np.array_equal(v[t], v1) and np.array_equal(c, c1)
        assert np.array_equal(mod.evaluate(b, s.layout, cols, x, jacobian=False)[0], f)


@pytest.mark.parametrize("name", ["two_trackers", "station_control", "direction_sets", "angles_hdist",
                                  "heights", "height_differences", "vectors", "trilateration_free", "tracker"])
def test_compiled_rows_equal_the_kinds(name, tracker):
    from multilat.network.montecarlo.general._frozen_numba import model_rows

    adj = tracker if name == "tracker" else _gama(name)
    fr = freeze(adj.system, adj.result)
    p = fr.program
    x = fr.x_hat + np.random.default_rng(2).standard_normal(fr.x_hat.size) * 1e-3
    f, v = np.empty(fr.n_rows), np.zeros((fr.n_rows, 9))
    model_rows(p["code"], p["cols"], p["hz"], p["comp"], p["setup"], p["frames"], x, f, v)
    fp, vp = np.empty(fr.n_rows), np.zeros((fr.n_rows, 9))      # azimuth and elevation rows together
    model_rows(p["code"], p["cols"], p["hz"], p["comp"], p["setup"], p["frames"], x, fp, vp, p["pair"], p["ref"])
    assert (p["pair"] >= 0).sum() == (p["pair"] == -2).sum() == (28 if name == "tracker" else 0)
    s = adj.system
    for b, cols, sl in zip(s.blocks, s.cols, s.rows):
        f1, v1, _ = KINDS[b.kind].evaluate(b, s.layout, cols, x)
        for ff, vv in ((f, v), (fp, vp)):
            np.testing.assert_allclose(ff[sl], f1, rtol=1e-12, atol=1e-14)
            np.testing.assert_allclose(vv[sl, :v1.shape[1]], v1, rtol=1e-11, atol=1e-13 * np.abs(v1).max())
    obs = draw(fr, 300, np.random.default_rng(3))
    a, b = solve(fr, obs, engine="numpy"), solve(fr, obs, engine="numba")
    assert a.converged.all() and b.converged.all()
    assert np.abs(a.x - b.x).max() < 1e-12


def test_tracker_network_compiled_equals_numpy(tracker):
    fr = freeze(tracker.system, tracker.result)
    obs = draw(fr, 200, np.random.default_rng(4))
    a, b = solve(fr, obs, engine="numpy"), solve(fr, obs, engine="numba")
    assert a.converged.all() and b.converged.all() and not b.full_gauss_newton.any()
    assert np.abs(a.x - b.x).max() < 1e-12
    np.testing.assert_allclose(a.vtpv, b.vtpv, rtol=1e-9)


@pytest.mark.parametrize("name", ["tracker", "trilateration_free", "direction_sets"])
def test_each_trial_is_the_least_squares_solution(name, tracker):
    adj = tracker if name == "tracker" else _gama(name)
    fr = freeze(adj.system, adj.result)
    obs = draw(fr, 3, np.random.default_rng(5))
    sol = solve(fr, obs)
    from multilat.network.adjust.general.adjust import AdjustOptions

    datum = "free" if adj.result.determinability.constraints is not None else "fixed"
    for t in range(3):
        net = _started(_with_observations(adj.network, obs[t], adj.system), adj.result)
        if datum == "fixed":
            res = adjust(net)
            assert np.abs(res.parameters - sol.x[t]).max() < 1e-9
        else:
            # a free network: the same solution up to the datum; compare datum-free quantities (distances)
            res = adjust(net, options=AdjustOptions(datum="free"))
            xa = res.xyz_m
            xb = sol.x[t][adj.system.layout.point_cols]
            da = np.linalg.norm(xa[:, None] - xa[None], axis=-1)
            db = np.linalg.norm(xb[:, None] - xb[None], axis=-1)
            assert np.abs(da - db).max() < 1e-9
        assert abs(res.sigma0 ** 2 * res.dof - sol.vtpv[t]) < 1e-8 * max(1.0, sol.vtpv[t])


def _started(net: Network, result) -> Network:
    """The network with its free coordinates started at the adjusted ones (held and weighted as given)."""
    from multilat.network.model.points import FREE

    pts = net.points
    xyz = np.where(pts.status == FREE, result.xyz_m, pts.xyz_m)
    return Network(dataclasses.replace(pts, xyz_m=xyz), net.blocks, net.notes)


def _check_against_q(res, n):
    se_rel = np.sqrt(1.0 / (2 * (n - 1)))                          # of a standard deviation (gaussian)
    k = res.n_params
    z = (res.mc_std[:k] / res.lin_std[:k] - 1) / se_rel
    assert np.abs(z).max() < NSIG, (res.labels[int(np.argmax(np.abs(z)))], z.max(), z.min())
    assert np.all(np.abs(res.mc_std - res.lin_std) <= NSIG * res.mc_std_se)
    for c_mc, c_lin in zip(res.point_cov_mc, res.point_cov_lin):
        s = np.sqrt(np.diag(c_lin))
        keep = s > 0
        r_mc = c_mc[np.ix_(keep, keep)] / np.outer(s[keep], s[keep])
        r_lin = c_lin[np.ix_(keep, keep)] / np.outer(s[keep], s[keep])
        assert np.abs(r_mc - r_lin).max() < NSIG * 2.0 / np.sqrt(n)     # a covariance element: SE <= sqrt(2/N)


@pytest.mark.parametrize("name", ["two_trackers", "station_control", "partly_fixed", "heights", "traverse",
                                  "direction_sets", "angles_hdist", "height_differences", "vectors",
                                  "trilateration_fixed", "trilateration_free"])
def test_mc_covariance_equals_cofactor_gama3d(name):
    adj = _gama(name)
    n = 4000
    res = propagate(adj.system, adj.result, trials=n, rng=11)
    assert res.trials == n and res.n_failed == 0
    _check_against_q(res, n)
    # trials drawn from the a-priori covariance: E[vTPv] = dof, so sigma0_rms^2 ~ 1 within sqrt(2/(N dof))
    assert abs(res.sigma0_rms ** 2 - 1) < NSIG * np.sqrt(2.0 / (n * res.dof))


def test_mc_covariance_equals_cofactor_tracker_network(tracker):
    kinds = {b.kind for b in tracker.system.blocks}
    assert kinds == {"slope_distance", "tracker_angles", "observed_coordinates"}
    n = 6000
    res = propagate(tracker.system, tracker.result, trials=n, rng=12)
    assert res.n_failed == 0 and res.n_retried == 0
    assert {"offset:H1", "offset:H2", "kappa:A", "omega:D"} <= set(res.labels)
    _check_against_q(res, n)


def test_bit_identical_across_chunks_and_maps(tracker):
    from multilat.parallel import process_map

    kw = dict(trials=2500, rng=7, keep_samples=True)
    a = propagate(tracker.system, tracker.result, **kw)
    b = propagate(tracker.system, tracker.result, chunk_size=1, map=map, **kw)
    c = propagate(tracker.system, tracker.result, chunk_size=2000, map=map, **kw)
    with process_map(2) as pm:
        d = propagate(tracker.system, tracker.result, chunk_size=1000, map=pm, **kw)
    for other in (b, c, d):
        assert np.array_equal(a.samples, other.samples)
        assert np.array_equal(a.mc_std, other.mc_std) and np.array_equal(a.interval_shortest, other.interval_shortest)


def test_draws_are_sigma_or_cholesky_times_the_row_normals():
    """``draw`` is ``f(x̂) + σ e`` on independent rows and ``f(x̂) + L e`` on a correlated block, ``e``
    the generator's standard normals in row order: the same bits as scaling them block by block (a
    network with both: partly_fixed's correlated weighted coordinates beside its independent rows)."""
    adj = _gama("partly_fixed")
    s = adj.system
    assert {b.cov is None for b in s.blocks} == {True, False}
    fr = freeze(adj.system, adj.result)
    obs = draw(fr, 50, np.random.default_rng(3))
    e = np.random.default_rng(3).standard_normal((50, fr.n_rows))
    for L, b, sl in zip(s.chol, s.blocks, s.rows):
        want = e[:, sl] * b.sigma if b.cov is None else e[:, sl] @ L.T
        assert np.array_equal(obs[:, sl], want + fr.computed[sl])


def test_frozen_first_step_from_the_systems_jacobian(tracker):
    """``freeze`` evaluates each block once; its first-step gain ``K = Q J^T P`` is the one from
    :meth:`System.evaluate`'s Jacobian (bit for bit: the same values scattered the same way)."""
    fr = freeze(tracker.system, tracker.result)
    _, jac = tracker.system.evaluate(fr.x_hat)
    assert np.array_equal(fr.gain, fr.q @ fr.weighted(np.ascontiguousarray(jac.T)))
    assert np.array_equal(fr.program["kt"], fr.gain.T)


@pytest.mark.parametrize("name", ["partly_fixed", "vectors", "height_differences", "two_trackers"])
def test_kernel_weight_matrix_is_the_block_diagonal(name):
    """The kernel's ``P`` (CSR arrays of the program) is ``scipy.sparse.block_diag`` of the blocks'
    ``1/σ²`` and ``C⁻¹`` (a second construction), array for array; ``wdiag`` holds the rows whose
    only entry is their diagonal (networks with correlated blocks, and one without)."""
    import scipy.sparse

    adj = _gama(name)
    fr = freeze(adj.system, adj.result)
    p = scipy.sparse.block_diag([scipy.sparse.diags(w) if w.ndim == 1 else scipy.sparse.csr_matrix(w)
                                 for w in fr.weight], format="csr")
    prog = fr.program
    assert np.array_equal(prog["p_ptr"], p.indptr) and np.array_equal(prog["p_idx"], p.indices)
    assert np.array_equal(prog["p_val"], p.data)
    diag_only = np.array([p.indptr[i + 1] - p.indptr[i] == 1 and p.indices[p.indptr[i]] == i
                          for i in range(p.shape[0])])
    assert np.array_equal(prog["wdiag"] > 0, diag_only)
    assert np.array_equal(prog["wdiag"][diag_only], p.diagonal()[diag_only])


@pytest.mark.parametrize("name", ["tracker", "partly_fixed"])
def test_point_covariance_is_the_engines_summary(name, tracker):
    """Each point's MC covariance is the engine's streamed covariance (:func:`multilat.montecarlo.summarize`,
    the distance path's estimator) of its free columns' samples, bit for bit, zero where a coordinate is
    held; numpy's ``np.cov`` of the same samples (a second method: one BLAS product) agrees to 1e-12
    relative (float order only). The columns' std is that summary's too."""
    from multilat.montecarlo import summarize

    adj = tracker if name == "tracker" else _gama(name)
    res = propagate(adj.system, adj.result, trials=2500, rng=5, keep_samples=True, pairs=())
    labels = list(res.labels)
    partly = 0
    for pid, cov in zip(res.point_ids, res.point_cov_mc):
        have = np.array([f"{c}:{pid}" in labels for c in "xyz"])
        cols = [labels.index(f"{c}:{pid}") for c in "xyz" if f"{c}:{pid}" in labels]
        partly += not have.all()
        y = res.samples[:, cols].astype(np.float64)
        r = summarize(y)
        want = np.zeros((3, 3))
        want[np.ix_(have, have)] = r.cov
        assert np.array_equal(cov, want)
        assert np.array_equal(res.mc_std[cols], r.std)
        assert np.allclose(cov[np.ix_(have, have)], np.atleast_2d(np.cov(y, rowvar=False)), rtol=1e-12, atol=0)
    assert (partly > 0) == (name == "partly_fixed")      # a point with a held coordinate is covered


def test_far_trial_goes_to_full_gauss_newton():
    adj = _gama("trilateration_fixed")
    fr = freeze(adj.system, adj.result)
    obs = draw(fr, 4, np.random.default_rng(8))
    s = adj.system
    far = obs[1].copy()
    far += 100 * np.concatenate([b.sigma for b in s.blocks]) * np.random.default_rng(9).standard_normal(len(far))
    obs[1] = far
    sol = solve(fr, obs)
    assert sol.full_gauss_newton.tolist() == [False, True, False, False]
    assert sol.converged.all()
    res = adjust(_started(_with_observations(adj.network, far, s), adj.result))
    assert np.abs(res.parameters - sol.x[1]).max() < 1e-9
    assert abs(res.sigma0 ** 2 * res.dof - sol.vtpv[1]) < 1e-8 * sol.vtpv[1]


def test_equals_todays_propagate_on_a_network_both_take():
    from multilat.network.io.files import read_observations
    from multilat.network.adjust.general.from_tables import network_from_tables
    from multilat.network.montecarlo.propagate import problem_from_observations
    from multilat.network.montecarlo.propagate import propagate as old_propagate

    path = ROOT / "examples" / "network" / "sequential" / "obs.csv"
    obs = read_observations(path)
    net, opts = network_from_tables(obs, datum="free")
    adj = adjust_network(net, options=opts)
    n = 6000
    new = propagate(adj.system, adj.result, trials=n, rng=3, pairs=())
    old = old_propagate(problem_from_observations(obs, datum="free"), trials=n, rng=4, noise="gaussian")
    assert _agree_with_todays(new, old) >= 0.9 * new.n_params
    # one result record for both paths: the same class, the shared quantities under the same JSON keys
    from multilat.network.montecarlo.propagate_result import PropagationResult

    assert type(new) is type(old) is PropagationResult
    shared = {"trials", "n_failed", "n_retried", "noise", "seed", "sigma0_mean", "sigma0_rms", "elapsed_s",
              "parameters", "distances", "points", "summary"}
    d_new, d_old = new.to_dict(), old.to_dict()
    assert shared <= set(d_new) and shared <= set(d_old)
    assert {"n_quantities", "n_agree", "ratio_min", "ratio_max"} <= set(d_new["summary"]) & set(d_old["summary"])


def test_json_document(tracker):
    res = propagate(tracker.system, tracker.result, trials=1000, rng=1)
    doc = json.loads(json.dumps(res.to_dict()))
    assert doc["schema"] == SCHEMA and doc["model"] == "general" and doc["trials"] == 1000
    assert {"parameters", "distances", "points", "summary", "n_retried", "n_failed"} <= set(doc)
    p = doc["parameters"][0]
    assert {"label", "unit", "nominal", "std_mc", "std_mc_se", "std_lin", "interval_symmetric"} <= set(p)
    assert set(doc["points"]) == set(tracker.result.ids)


def _cli(*args, cwd=ROOT):
    import os
    import subprocess

    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    return subprocess.run([sys.executable, "-c", "from multilat.cli import run; run()", "propagate", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, env=env, timeout=600)


def test_cli_gama_local_and_csv(tmp_path):
    xml = ROOT / "examples" / "general" / "station_control.xml"
    p = _cli(xml, "--trials", "1500", "--seed", "3", "--json")
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)
    assert doc["schema"] == SCHEMA and doc["format"] == "gama-local" and doc["trials"] == 1500
    # the same numbers from Python (same seed, same blocks)
    res = propagate(*(lambda a: (a.system, a.result))(adjust_network(read_gama_input(xml))), trials=1500, rng=3)
    assert [r["std_mc"] for r in doc["parameters"]] == res.mc_std[:res.n_params].tolist()
    csv = ROOT / "examples" / "network" / "mixed" / "obs.csv"
    p = _cli(csv, "--model", "general", "--trials", "500", "--out", tmp_path / "o", "--json")
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)
    assert doc["format"] == "multilat-csv" and any(r["label"].startswith("kappa:") for r in doc["parameters"])
    assert sorted(x.name for x in (tmp_path / "o").iterdir()) == ["parameters.csv", "result.json"]


@pytest.mark.parametrize("args, start", [
    (("--adaptive",), "--adaptive does not apply"), (("--datum", "free"), "--datum does not apply"),
    (("--report", "r.html"), "--report does not apply"), (("--instrument", "seed2020"), "--instrument does not apply"),
    (("--noise", "model"), "--noise model draws from an instrument's distance model: name it with --instrument")])
def test_cli_refuses_what_does_not_apply(args, start, tmp_path):
    p = _cli(ROOT / "examples" / "general" / "station_control.xml", *args, cwd=tmp_path)
    assert p.returncode == 2 and p.stdout == ""
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {start}"), p.stderr


def _agree_with_todays(new, old) -> int:
    """Every coordinate and offset of today's distance-only result within NSIG combined MC standard
    errors of the general one's (labels ``A.x`` -> ``x:A``); returns how many were compared."""
    compared = 0
    for lab_old, s_old, se_old in zip(old.labels, old.mc_std, old.mc_std_se):
        pid, _, c = lab_old.rpartition(".")
        name = f"{c}:{pid}" if c in "xyz" else (f"offset:{pid}" if c == "offset" else None)
        if name not in new.labels:
            continue
        i = new.labels.index(name)
        assert abs(new.mc_std[i] - s_old) <= NSIG * np.hypot(new.mc_std_se[i], se_old), (name, new.mc_std[i], s_old)
        compared += 1
    return compared


def test_noise_model_equals_todays_propagate():
    """``noise="model"``: the small volume (distances only, heads A-D, free network) through both paths,
    the slope distances drawn from seed2020's distance model by the same compiled sampler; the MC
    standard deviations agree within 4 combined MC standard errors (the distance path's own test of its
    model noise holds them to the same bound), and the general linear std (``Q`` sandwiched with the
    model's σ) agrees with its MC std."""
    from multilat.errors import MultilatError
    from multilat.instrument import load_instrument
    from multilat.network.synthetic.configs import small_volume
    from multilat.network.adjust.general.adjust import AdjustOptions
    from multilat.network.montecarlo.propagate import problem_from_config
    from multilat.network.montecarlo.propagate import propagate as old_propagate

    adj = adjust_network(tracker_network(noise=False, extras=False)[0], options=AdjustOptions(datum="free"))
    n = 6000
    new = propagate(adj.system, adj.result, trials=n, rng=5, pairs=(), noise="model", instrument="seed2020")
    pb = problem_from_config(small_volume(), sigma_m=4.7e-6, datum="free", instrument=load_instrument("seed2020"))
    old = old_propagate(pb, trials=n, rng=6, noise="model", instrument="seed2020")
    assert new.noise == old.noise == "model" and new.to_dict()["noise"] == "model"
    assert _agree_with_todays(new, old) >= 0.9 * new.n_params
    assert new.agrees.mean() > 0.9
    gauss = propagate(adj.system, adj.result, trials=1000, rng=5, pairs=())
    assert not np.array_equal(gauss.mc_std, new.mc_std[:len(gauss.mc_std)])      # the model was drawn
    with pytest.raises(MultilatError, match="name it with instrument"):
        propagate(adj.system, adj.result, trials=100, noise="model")
