"""End-to-end Monte Carlo through the adjustment (network.propagate) and ``multilat propagate``."""

from __future__ import annotations

import csv
import json
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.montecarlo import batched as bt
from multilat.network.synthetic.configs import small_volume
from multilat.network.montecarlo.propagate import chi2_3_95, problem_from_config, problem_from_truth, propagate


@pytest.fixture(scope="module")
def small_problem():
    return problem_from_config(small_volume(), sigma_m=4.7e-6, source="small-volume")


@pytest.fixture(scope="module")
def gaussian_run(small_problem):
    return propagate(small_problem, trials=20_000, rng=7, noise="gaussian")


def test_chi2_constant():
    from scipy.stats import chi2

    assert abs(chi2.ppf(0.95, 3) - chi2_3_95) < 1e-12


def test_gaussian_mc_std_agrees_with_linear_covariance(gaussian_run):
    """Near-linear model, gaussian inputs: MC std of every coordinate, offset and triplet distance equals
    the linear std within 4 MC standard errors of a std, sigma * sqrt(1 / (2 (n - 1)))."""
    r = gaussian_run
    assert r.n_failed == 0 and r.trials == 20_000
    se = r.lin_std * np.sqrt(1.0 / (2 * (r.trials - 1)))
    fixed = r.lin_std < 1e-15          # none in the free datum
    assert not fixed.any()
    assert np.all(np.abs(r.mc_std - r.lin_std) <= 4 * se), np.max(np.abs(r.mc_std - r.lin_std) / se)
    # means: unbiased to first order; the bias must be small against the std (4 standard errors of a mean)
    assert np.all(np.abs(r.mc_mean - r.nominal) <= 4 * r.lin_std / np.sqrt(r.trials))


def test_jcgm102_ellipsoids_cover_95_percent(gaussian_run):
    """The MC-covariance ellipsoid with the chi2_3 quantile covers 95 % of the trials (gaussian output):
    binomial standard error sqrt(0.95 * 0.05 / n), 4 sigma."""
    r = gaussian_run
    tol = 4 * np.sqrt(0.95 * 0.05 / r.trials)
    assert np.all(np.abs(r.ellipsoid_coverage_mc - 0.95) < tol)
    assert np.all(np.abs(r.ellipsoid_coverage_lin - 0.95) < tol + 0.005)   # + lin-vs-MC std differences


def test_coverage_intervals_bracket_the_estimate(gaussian_run):
    r = gaussian_run
    assert np.all(r.interval_symmetric[:, 0] < r.mc_mean) and np.all(r.mc_mean < r.interval_symmetric[:, 1])
    # gaussian output: half-width ~ 1.96 std (tolerance: quantile MC noise, a few %)
    half = 0.5 * (r.interval_symmetric[:, 1] - r.interval_symmetric[:, 0])
    np.testing.assert_allclose(half / r.mc_std, 1.96, rtol=0.04)


def test_model_noise_is_propagated(small_problem):
    """Distance-model (non-gaussian) errors: MC std vs the linear sandwich with the inputs' empirical std,
    within 4 MC standard errors (kurtosis-aware)."""
    r = propagate(small_problem, trials=6000, rng=3, noise="model", instrument="seed2020", chunk_size=3000)
    assert r.trials + r.n_failed == 6000
    assert np.all(np.abs(r.mc_std - r.lin_std) <= 4 * r.mc_std_se + 1e-3 * r.lin_std)
    assert 0.95 < r.input_std_ratio < 1.05


def _assert_same_run(a, b):
    """Bit-identical: samples and every statistic derived from them."""
    np.testing.assert_array_equal(a.samples, b.samples)
    for name in ("mc_mean", "mc_std", "mc_std_se", "lin_std", "interval_symmetric", "interval_shortest",
                 "point_cov_mc", "ellipsoid_coverage_mc", "ellipsoid_coverage_lin", "input_std_m"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert (a.trials, a.n_failed, a.sigma0_mean, a.sigma0_rms, a.input_std_ratio) == \
        (b.trials, b.n_failed, b.sigma0_mean, b.sigma0_rms, b.input_std_ratio)


def test_identical_for_any_chunk_size(small_problem):
    """Fixed blocks of BLOCK trials are the unit of seeding and solving; chunk_size only groups whole
    blocks: 1000, 3000 and 1700 (rounded up to 2 blocks; divides neither 3500 nor 2000) give the same
    bits, with a partial last block (3500 trials) and distance-model noise."""
    from multilat.network.montecarlo.propagate import BLOCK

    assert BLOCK == 1000
    runs = [propagate(small_problem, trials=3500, rng=9, noise="model", instrument="seed2020", chunk_size=c) for c in (1000, 3000, 1700)]
    for r in runs[1:]:
        _assert_same_run(runs[0], r)
    # the blocks do not depend on the run length: a shorter run is a prefix of a longer one
    # (no trial fails here, so row i of the samples is trial i)
    assert runs[0].n_failed == 0
    short = propagate(small_problem, trials=2000, rng=9, noise="model", instrument="seed2020", chunk_size=4000)
    np.testing.assert_array_equal(short.samples, runs[0].samples[:2000])


def test_in_process_threads_identical_to_one_thread(small_problem):
    """The default in-process run shares the blocks among threads (multilat.parallel.thread_map, one
    numba thread each, the draw kernel and the solver then run serially inside a block); the builtin
    map runs them one after the other with numba's threads inside each block: the same bits, for both
    noises, with a partial last block."""
    import builtins

    for noise in ("model", "gaussian"):
        a = propagate(small_problem, trials=5500, rng=21, noise=noise, instrument="seed2020")
        b = propagate(small_problem, trials=5500, rng=21, noise=noise, instrument="seed2020", map=builtins.map)
        _assert_same_run(a, b)
        np.testing.assert_array_equal(a.samples, b.samples)


def test_identical_whatever_the_map(small_problem):
    """A thread pool that runs chunks concurrently gives the same numbers as the in-process run."""
    a = propagate(small_problem, trials=4000, rng=11, noise="gaussian", chunk_size=1000)
    with ThreadPoolExecutor(2) as ex:
        b = propagate(small_problem, trials=4000, rng=11, noise="gaussian", chunk_size=2000, map=ex.map)
    _assert_same_run(a, b)
    c = propagate(small_problem, trials=4000, rng=12, noise="gaussian", chunk_size=1000)
    assert not np.array_equal(a.samples, c.samples)


def test_identical_on_dask_local_clusters_of_1_and_2_workers(small_problem):
    """Real LocalClusters (worker processes): 1 and 2 workers, 3 chunks, bit-identical to in-process."""
    from multilat.parallel import dask_map

    a = propagate(small_problem, trials=2500, rng=5, noise="model", instrument="seed2020", chunk_size=1000)
    for workers in (1, 2):
        with dask_map(workers=workers) as m:
            b = propagate(small_problem, trials=2500, rng=5, noise="model", instrument="seed2020", chunk_size=1000, map=m)
        _assert_same_run(a, b)


@pytest.mark.slow
def test_identical_on_a_dask_local_cluster(small_problem):
    from multilat.parallel import dask_map

    a = propagate(small_problem, trials=8000, rng=5, noise="model", instrument="seed2020", chunk_size=3000)
    with dask_map(workers=2) as m:
        b = propagate(small_problem, trials=8000, rng=5, noise="model", instrument="seed2020", chunk_size=1000, map=m)
    _assert_same_run(a, b)


def test_identical_in_a_process_pool(small_problem):
    from multilat.parallel import process_map

    a = propagate(small_problem, trials=2000, rng=6, noise="gaussian", chunk_size=2000)
    with process_map(2) as m:
        b = propagate(small_problem, trials=2000, rng=6, noise="gaussian", chunk_size=1000, map=m)
    _assert_same_run(a, b)


def _failing_every(step: int):
    """The batched solve with every ``step``-th trial marked as not converged."""
    orig = bt.BatchedNetwork.solve

    def flaky(self, d, **kw):
        sol = orig(self, d, **kw)
        conv = sol.converged.copy()
        conv[::step] = False
        return bt.BatchSolution(sol.station_xyz_m, sol.offset_m, sol.target_xyz_m, conv, sol.iterations,
                                sol.last_step_m, sol.sigma0)

    return flaky


def test_failed_trials_are_counted_and_dropped(small_problem, monkeypatch):
    monkeypatch.setattr(bt.BatchedNetwork, "solve", _failing_every(10))
    r = propagate(small_problem, trials=2000, rng=1, noise="gaussian", chunk_size=1000)
    assert r.n_failed == 200 and r.trials == 1800
    assert r.samples.shape[0] == 1800


@pytest.mark.skipif(not bt.numba_available(), reason="numba not installed")
def test_compiled_deviations_are_numpys_bits(small_problem, monkeypatch):
    """The deviations of the kept trials (coordinates, offsets, targets minus the nominal, then the
    interpoint distances, station and target points mixed), as float32, from the compiled pass and
    from numpy: the same bits; a dropped trial leaves no row."""
    from multilat.network.montecarlo import propagate as pr

    prob = problem_from_config(small_volume(), sigma_m=4.7e-6, pairs=[("A", "3"), ("1", "2"), ("B", "C")])
    net = prob.network
    spec = pr._ChunkSpec(net, prob.distance_m, prob.heads, pr._pair_columns(prob), "gaussian", None,
                         net.sigma_m, None)
    sol = net.solve(prob.distance_m + np.random.default_rng(3).normal(0, 1e-4, (50, net.n_obs)))
    keep = np.flatnonzero(np.arange(50) % 7 != 3)
    compiled = pr._deviations(spec, sol.station_xyz_m, sol.offset_m, sol.target_xyz_m, keep)
    monkeypatch.setattr(bt, "numba_available", lambda: False)
    plain = pr._deviations(spec, sol.station_xyz_m, sol.offset_m, sol.target_xyz_m, keep)
    assert compiled.dtype == np.float32 and compiled.shape == (len(keep), net.n_params + 3)
    assert np.array_equal(compiled, plain)
    r = keep[5]     # one value by hand: the distance A-3 of a kept trial minus the nominal one
    by_hand = (np.linalg.norm(sol.station_xyz_m[r, 0] - sol.target_xyz_m[r, 2])
               - np.linalg.norm(net.station_xyz_m[0] - net.target_xyz_m[2]))
    assert compiled[5, net.n_params] == np.float32(by_hand)


@pytest.fixture(scope="module")
def tetra_problem():
    rng = np.random.default_rng(4)
    h = np.array([[0.0, 0, 0], [1.0, 0, 0], [0.5, 0.9, 0], [0.5, 0.3, 0.8]])
    tg = rng.uniform(0.1, 0.8, (14, 3))
    si, ti = (a.ravel() for a in np.meshgrid(np.arange(4), np.arange(14), indexing="ij"))
    return problem_from_truth("ABCD", [f"P{j}" for j in range(14)], si, ti, np.full(56, 5e-6), h,
                              np.zeros(4), tg, pairs=[("P0", "P1")])


def _stops_by_hand(samples, h, ndigits, batch=10_000):
    """JCGM 101 §7.9 written out independently: after h batches of ``batch`` trials, is twice the standard
    deviation of the batch averages of y, u(y), y_low, y_high within delta(u(y) of all trials), everywhere?
    Symmetric interval by the §7.7 index rule on the sorted batch: q = floor(pM + 1/2), r = (M - q + 1) // 2."""
    from multilat.montecarlo import numerical_tolerance

    y = samples[: h * batch].astype(np.float64)
    m = batch
    q = int(np.floor(0.95 * m + 0.5))
    r = (m - q + 1) // 2
    stats = []
    for j in range(h):
        yb = np.sort(y[j * batch:(j + 1) * batch], axis=0)
        stats.append([yb.mean(axis=0), yb.std(axis=0, ddof=1), yb[r - 1], yb[r - 1 + q]])
    sd = np.std(np.array(stats), axis=0, ddof=1) / np.sqrt(h)          # (4, k)
    u = y.std(axis=0, ddof=1)
    delta = np.array([numerical_tolerance(v, ndigits) for v in u])
    return bool(np.all(2 * sd <= delta))


def test_adaptive_is_the_engines_procedure(tetra_problem):
    """The adaptive run checks after every batch of 10^4 trials (h >= 2) and stops at the first batch where the
    criterion written out by hand holds; its trials are those of a fixed run of the same length."""
    pb = tetra_problem
    r = propagate(pb, rng=2, noise="gaussian", adaptive=True, ndigits=1, max_trials=400_000)
    assert r.adaptive["converged"] and r.adaptive["batch_trials"] == 10_000
    h = r.adaptive["batches"]
    assert r.trials == 10_000 * h and r.n_failed == 0
    assert _stops_by_hand(r.samples, h, 1)
    assert not any(_stops_by_hand(r.samples, g, 1) for g in range(2, h))
    fixed = propagate(pb, rng=2, noise="gaussian", trials=r.trials, chunk_size=3000)
    _assert_same_run(r, fixed)
    # not converged within max_trials: every check failed, and the run stops at max_trials
    n = propagate(pb, rng=2, noise="gaussian", adaptive=True, ndigits=2, max_trials=40_000, chunk_size=1000)
    assert n.adaptive == {"converged": False, "batches": 4, "batch_trials": 10_000, "n_fixed_by_datum": 0,
                          "tolerance_m_min": n.adaptive["tolerance_m_min"]}
    assert n.trials == 40_000
    assert not any(_stops_by_hand(n.samples, g, 2) for g in range(2, 5))
    # the same decision whatever the chunk size, map and round size
    with ThreadPoolExecutor(2) as ex:
        n2 = propagate(pb, rng=2, noise="gaussian", adaptive=True, ndigits=2, max_trials=40_000, chunk_size=3000,
                       map=ex.map, batches_per_round=3)
    _assert_same_run(n, n2)
    assert n2.adaptive == n.adaptive


def test_bad_arguments(small_problem):
    with pytest.raises(MultilatError):
        propagate(small_problem, trials=1)
    with pytest.raises(MultilatError):
        propagate(small_problem, noise="uniform")
    with pytest.raises(MultilatError):
        problem_from_config(small_volume(), datum="control")
    with pytest.raises(MultilatError):
        problem_from_config(small_volume(), pairs=[("1", "nope")])


# --------------------------------------------------------------------------- CLI
def test_cli_json(capsys):
    rc = main(["propagate", "small-volume", "--trials", "3000", "--noise", "gaussian", "--seed", "3", "--json"])
    out = capsys.readouterr().out
    assert rc == 0
    doc = json.loads(out)
    assert doc["trials"] + doc["n_failed"] == 3000
    assert {"parameters", "distances", "points", "summary", "noise"} <= set(doc)
    labels = [r["label"] for r in doc["distances"]]
    assert "1-2" in labels and len(doc["points"]) == 4 + 14
    d12 = doc["distances"][labels.index("1-2")]
    assert abs(d12["reference_m"] - 0.150022) < 1e-9
    assert d12["std_mc_m"] > 0 and d12["std_lin_m"] > 0


def test_cli_human_and_out(tmp_path, capsys):
    rc = main(["propagate", "small-volume", "--trials", "2000", "--noise", "gaussian", "--out", str(tmp_path / "o")])
    assert rc == 0
    out = capsys.readouterr().out
    assert "Monte Carlo" in out and "ellipsoid" in out
    names = sorted(p.name for p in (tmp_path / "o").iterdir())
    assert names == ["clouds.png", "distances.csv", "parameters.csv", "points.csv", "summary.json"]
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["trials"] == 2000


def test_cli_errors(tmp_path, capsys):
    assert main(["propagate", "small-volume", "--noise", "uniform"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:")
    for opt in ("--chunk-size", "--trials"):
        assert main(["propagate", "small-volume", opt, "0"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("error:") and opt in err[0]
    assert main(["propagate", str(tmp_path / "missing.csv"), "--trials", "100"]) == 2
    bad = tmp_path / "bad.csv"
    bad.write_text("station,target,distance_m\nA,T1,-1\n")
    assert main(["propagate", str(bad), "--trials", "100"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert all(line.startswith("error:") for line in err)


def test_cli_interrupt_leaves_out_untouched(tmp_path, monkeypatch, capsys):
    """Ctrl-C while the figure is being written (after the CSVs): exit 130, OUT not created, no staging
    directory or partial file left beside it; an existing OUT keeps its old contents and gets no new file."""
    import matplotlib.figure

    def boom(self, fname, *a, **k):
        with open(fname, "wb") as f:
            f.write(b"\x89PNG half")
        raise KeyboardInterrupt

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", boom)
    out = tmp_path / "o"
    rc = main(["propagate", "small-volume", "--trials", "1000", "--noise", "gaussian", "--out", str(out)])
    assert rc == 130
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == []          # no .o.*.part staging directory
    out.mkdir()
    (out / "summary.json").write_text("old")
    rc = main(["propagate", "small-volume", "--trials", "1000", "--noise", "gaussian", "--out", str(out)])
    assert rc == 130
    assert sorted(p.name for p in out.iterdir()) == ["summary.json"]
    assert (out / "summary.json").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o"]


def _example_obs():
    from pathlib import Path

    return Path(__file__).resolve().parent.parent / "examples" / "network" / "small_volume_obs.csv"


def test_cli_unknown_reference_id_names_file_and_line(tmp_path, capsys):
    refs = tmp_path / "refs.csv"
    refs.write_text("target_a,target_b,length_m\n1,2,0.15\n1,99,0.2\n")
    assert main(["propagate", str(_example_obs()), "--trials", "100", "--references", str(refs)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:")
    assert str(refs) in err[0] and "'99'" in err[0]
    # the row with the unknown id (file line 3, data row 2) is named
    assert f"{refs}:3" in err[0] or "row 2" in err[0], err[0]


def test_measured_observations_sigma0_carries_the_nominal_residuals():
    """Trials centred on measured distances: each trial's residuals are the nominal residuals plus those
    of the drawn errors (residuals are linear in the distances, and the nominal residuals are orthogonal
    to the column space), so E[sigma0^2] = sigma0_nominal^2 + 1 for gaussian errors with the weights'
    sigma. sigma0^2 dof ~ noncentral chi2(dof, dof sigma0_nominal^2): the mean of n trials has standard
    error sqrt(2 dof + 4 dof sigma0_nom^2) / dof / sqrt(n); 4 of them."""
    from multilat.network.adjust.distance.adjust import adjust
    from multilat.network.io.files import read_observations
    from multilat.network.montecarlo.propagate import problem_from_observations

    obs = read_observations(_example_obs())
    adj = adjust(obs, snooping=False)
    pb = problem_from_observations(obs, adjustment=adj)
    assert pb.sigma0_nominal == pytest.approx(adj.sigma0, rel=1e-12)
    n = 4000
    r = propagate(pb, trials=n, rng=5, noise="gaussian", chunk_size=2000, keep_samples=False)
    dof, s0 = adj.dof, adj.sigma0
    se = np.sqrt(2 * dof + 4 * dof * s0**2) / dof / np.sqrt(n)
    assert abs(r.sigma0_rms**2 - (s0**2 + 1.0)) < 4 * se
    assert r.sigma0_mean > s0 and r.sigma0_nominal == pytest.approx(s0)
    # a known truth has sigma0_nominal 0: the trials' sigma0^2 averages 1
    t = propagate(problem_from_config(small_volume(), sigma_m=4.7e-6), trials=n, rng=5, noise="gaussian",
                  chunk_size=2000, keep_samples=False)
    dof_t = 4 * 14 - (4 * 4 + 3 * 14 - 6)
    assert t.sigma0_nominal == 0.0
    assert abs(t.sigma0_rms**2 - 1.0) < 4 * np.sqrt(2 / dof_t / n)


def test_cli_prints_nominal_sigma0(capsys):
    assert main(["propagate", str(_example_obs()), "--trials", "2000", "--noise", "gaussian"]) == 0
    out = " ".join(capsys.readouterr().out.split())        # undo rich's line wrapping
    assert "sigma0: nominal 1.199, trials' mean" in out
    assert "centred on the measured distances" in out


def test_321_datum_fixes_six_coordinates():
    pb = problem_from_config(small_volume(), sigma_m=4.7e-6, datum="321:B,D,C")
    r = propagate(pb, trials=3000, rng=2, noise="gaussian", chunk_size=1500)
    lab = list(r.labels)
    fixed = [lab.index(x) for x in ("B.x", "B.y", "B.z", "D.y", "D.z", "C.z")]
    assert sorted(np.flatnonzero(r.fixed)) == sorted(fixed)
    assert np.all(r.mc_std[fixed] < 1e-12)
    assert np.isnan(r.ellipsoid_coverage_mc[list(r.point_ids).index("B")])
    # C moves in a plane: its 2-dof region still covers 95 % (binomial s.e. 0.004, 4 sigma)
    assert abs(r.ellipsoid_coverage_mc[list(r.point_ids).index("C")] - 0.95) < 0.016
    assert r.agrees.all()
    # adaptive: the 6 datum-fixed coordinates (rounding noise, ~1e-20 m) are not watched by the criterion
    ad = propagate(pb, rng=2, noise="gaussian", adaptive=True, ndigits=1, max_trials=30_000, keep_samples=False)
    assert ad.adaptive["n_fixed_by_datum"] == 6 and ad.adaptive["tolerance_m_min"] >= 5e-7
    # datum-free quantities are the same as in the free datum, trial by trial
    f = propagate(problem_from_config(small_volume(), sigma_m=4.7e-6), trials=3000, rng=2, noise="gaussian",
                  chunk_size=1500)
    n_par = pb.network.n_params
    np.testing.assert_allclose(r.samples[:, n_par:], f.samples[:, n_par:], atol=2e-12)
    np.testing.assert_allclose(r.samples[:, 12:16], f.samples[:, 12:16], atol=2e-12)


def test_demo_section_quick():
    from multilat.report.propagate_demo import section

    sec = section(seed=3, quick=True)
    html = "".join(sec.blocks)
    assert html.count("<table>") == 2 and "<img" in html
    assert "6.6" in html                      # the paper's mean beside ours


def test_ellipsoid_fraction_is_the_row_sum_formula():
    """``_ellipsoid_fraction`` adds the columns of z^2 / ev left to right instead of np.sum(axis=1) over
    rows of 3 (slow in numpy): the same bits (numpy sums a row shorter than its pairwise block in
    order), for full and rank-deficient covariances and both memory layouts of the samples."""
    from multilat.network.montecarlo.propagate_summary import _ellipsoid_fraction
    from multilat.network.adjust.statistics import chi2_ppf

    def by_row_sums(dev3, center, cov):
        ev, vec = np.linalg.eigh(cov)
        keep = ev > 1e-9 * ev.max()
        z = (dev3 - center) @ vec[:, keep]
        d2 = np.sum(z * z / ev[keep], axis=1)
        return float(np.mean(d2 <= (chi2_3_95 if keep.sum() == 3 else chi2_ppf(0.95, int(keep.sum())))))

    rng = np.random.default_rng(5)
    w = rng.standard_normal((100_000, 3)) * [1.0, 1e-3, 3.0]
    for ww in (w, np.asfortranarray(w)):
        np.testing.assert_array_equal(np.sum(ww, axis=1), (ww[:, 0] + ww[:, 1]) + ww[:, 2])
    a = rng.standard_normal((3, 3)) * 1e-5
    for cov in (a @ a.T, np.diag([2e-10, 1e-10, 0.0]), np.diag([1e-10, 0.0, 0.0])):
        x = rng.multivariate_normal(np.zeros(3), cov, 50_000) * 1.3
        for dev3 in (x, np.asfortranarray(x)):
            for center in (np.zeros(3), x.mean(axis=0)):
                assert _ellipsoid_fraction(dev3, center, cov) == by_row_sums(dev3, center, cov)


def test_block_deviations_are_the_flattened_differences(small_problem, monkeypatch):
    """A block's float32 samples are float32(flatten(solution) - flatten(nominal)) and the pairs'
    distance deviations, computed here the plain way from the same draws; with trials dropped too."""
    from multilat.montecarlo import block_generator, resolve_seed

    net = small_problem.network
    for solve in (bt.BatchedNetwork.solve, _failing_every(7)):
        monkeypatch.setattr(bt.BatchedNetwork, "solve", solve)
        r = propagate(small_problem, trials=1000, rng=11, noise="gaussian")
        ss = resolve_seed(11)
        g = block_generator(ss.entropy, tuple(ss.spawn_key), 0)
        d = small_problem.distance_m + g.standard_normal((1000, net.n_obs)) * net.sigma_m
        sol = solve(net, d)
        ok = sol.converged
        x = bt.flatten(sol.station_xyz_m[ok], sol.offset_m[ok], sol.target_xyz_m[ok])
        x0 = bt.flatten(net.station_xyz_m, net.offset_m, net.target_xyz_m)
        pts = np.concatenate([sol.station_xyz_m[ok], sol.target_xyz_m[ok]], axis=1)
        p0 = np.concatenate([net.station_xyz_m, net.target_xyz_m])
        ids = small_problem.station_ids + small_problem.target_ids
        pa = [ids.index(a) for a, _ in small_problem.pairs]
        pb = [ids.index(b) for _, b in small_problem.pairs]
        dd = np.linalg.norm(pts[:, pa] - pts[:, pb], axis=2) - np.linalg.norm(p0[pa] - p0[pb], axis=1)
        want = np.concatenate([x - x0, dd], axis=1).astype(np.float32)
        assert r.samples.dtype == np.float32 and np.array_equal(r.samples, want)
        assert r.trials == int(ok.sum())


def test_summaries_in_two_threads_are_those_computed_in_order(small_problem, monkeypatch):
    """From 50 000 trials the column statistics run in two threads: the same numbers as in order."""
    from multilat.network.montecarlo import propagate_summary as ps

    in_threads = ps._in_two_threads
    seen = []
    monkeypatch.setattr(ps, "_in_two_threads", lambda tasks, n: (seen.append(n), in_threads(tasks, n)))
    a = propagate(small_problem, trials=50_000, rng=3, noise="gaussian", keep_samples=False)
    assert seen == [50_000]                                     # the threaded path was taken
    monkeypatch.setattr(ps, "_in_two_threads", lambda tasks, n: in_threads(tasks, 0))
    b = propagate(small_problem, trials=50_000, rng=3, noise="gaussian", keep_samples=False)
    for name in ("mc_mean", "mc_std", "mc_std_se", "interval_symmetric", "interval_shortest", "point_cov_mc",
                 "ellipsoid_coverage_mc", "ellipsoid_coverage_lin", "lin_std"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test_both_paths_give_points_as_one_id_map(tmp_path, capsys):
    """propagate/2: the distance path's ``points`` is an id map, as the general path's (and adjust's
    targets): the same ids on the same file, and the linear covariances of the two independent
    solvers (batched distance kernel vs the general layer's sparse Gauss-Newton) agree to 1e-6
    relative (they converge to the same minimum; measured 1e-9). ``points.csv`` of ``--out`` joins
    the document by id."""
    obs = str(_example_obs())
    args = ["propagate", obs, "--trials", "200", "--seed", "1"]
    docs = []
    for extra in ([], ["--model", "general"]):
        assert main([*args, *extra, "--json"]) == 0
        docs.append(json.loads(capsys.readouterr().out))
    dist, gen = docs
    assert dist["schema"] == "multilat.propagate/2" and gen["schema"] == "multilat.propagate-general/2"
    assert isinstance(dist["points"], dict) and isinstance(gen["points"], dict)
    assert set(dist["points"]) == set(gen["points"]) and len(dist["points"]) == 18
    for pid, p in dist["points"].items():
        np.testing.assert_allclose(p["cov_lin_m2"], gen["points"][pid]["cov_lin_m2"], rtol=1e-6, atol=1e-18,
                                   err_msg=pid)
    assert main([*args, "--out", str(tmp_path / "o")]) == 0
    capsys.readouterr()
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    with open(tmp_path / "o" / "points.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert [r["id"] for r in rows] == list(summary["points"])
    for r in rows:
        p = summary["points"][r["id"]]
        assert [float(r[f"semi_axis_{i}_95_m"]) for i in (1, 2, 3)] == p["semi_axes_95_m"], r["id"]
