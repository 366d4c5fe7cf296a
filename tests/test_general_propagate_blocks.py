"""The general Monte Carlo on networks the sparse back end adjusts without a dense ``Q``
(``multilat.network.montecarlo.general.propagate_blocks``: every chord step's ``Q g`` through the Schur blocks).

Against independent values:

* the dense path (``Q`` and the gain ``K`` formed, :mod:`.propagate`) on the same network: the same
  trials (same seed, same draws) solved to the same least-squares solutions (1e-9 m: both iterate to a
  1e-10 step from x̂, with ``Q`` in two algebras equal to ~1e-14 relative), so the MC standard deviations
  agree far inside their MC standard error; the linear std and point covariances (the blocks'
  diagonal, ``g Q gᵀ`` per pair, the model's sandwich ``K_m (S² - C_m) K_mᵀ``) equal the dense ones to
  1e-9 relative (rounding of two algebras);
* the numpy engine's gradients equal the compiled kernel's (1e-12 m on the solutions);
* bit-identical across chunk sizes and maps (threads, processes);
* a far trial goes to full Gauss-Newton by the sparse step and equals ``adjust`` on its observations;
* a distance-only network of 8 x 1 000 targets (3 032 unknowns: no dense ``Q``; before this module the
  Monte Carlo failed there with a numpy ValueError): MC std against the linear std within 5 MC standard
  errors (5σ: ~4 000 quantities, P(|z|>5) = 6e-7 each);
* runs past the limits are refused in one line before any trial.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.adjust.general import adjust_network, read_gama_input
from multilat.network.adjust.general.adjust import AdjustOptions, adjust
from multilat.network.montecarlo.general.propagate import draw, freeze, propagate, solve

sys.path.insert(0, str(Path(__file__).parent))
from general_tracker_network import tracker_network  # noqa: E402
from test_general_propagate import _started, _with_observations  # noqa: E402

GAMA = Path(__file__).resolve().parent / "data" / "gama3d"
gadjust = importlib.import_module("multilat.network.adjust.general.adjust")
blocks_mod = importlib.import_module("multilat.network.montecarlo.general.propagate_blocks")


def _pair(net, monkeypatch, datum="auto"):
    """The network adjusted by the dense back end, and by the sparse one with ``Q`` kept in blocks."""
    dense = adjust_network(net, options=AdjustOptions(datum=datum, backend="dense"))
    with monkeypatch.context() as m:
        m.setattr(gadjust, "MAX_DENSE_UNKNOWNS", 0)
        m.setattr(gadjust, "SPARSE_ABOVE", 0)          # run.adjust_network checks the size with auto
        sparse = adjust_network(net, options=AdjustOptions(datum=datum, backend="sparse"))
    assert dense.result.cofactor is not None and sparse.result.cofactor is None
    return dense, sparse


@pytest.mark.parametrize("datum", ["auto", "free"])
def test_blocks_equal_the_dense_path(datum, monkeypatch):
    dense, sparse = _pair(tracker_network(5)[0], monkeypatch, datum)
    fd, fs = freeze(dense.system, dense.result), freeze(sparse.system, sparse.result)
    assert fd.q is not None and fs.q is None and fs.gain is None
    obs = draw(fd, 300, np.random.default_rng(3))
    a, b = solve(fd, obs), solve(fs, obs)
    assert a.converged.all() and b.converged.all()
    assert np.abs(a.x - b.x).max() < 1e-9
    assert np.abs(a.vtpv - b.vtpv).max() < 1e-9 * a.vtpv.max()
    c = solve(fs, obs, engine="numpy")
    assert np.abs(b.x - c.x).max() < 1e-12
    n = 3000
    ra = propagate(dense.system, dense.result, trials=n, rng=4)
    rb = propagate(sparse.system, sparse.result, trials=n, rng=4)
    assert ra.labels == rb.labels and rb.n_failed == 0
    assert np.all(np.abs(ra.mc_std - rb.mc_std) <= 1e-3 * ra.mc_std_se)
    assert np.abs(rb.lin_std / ra.lin_std - 1).max() < 1e-9
    assert np.abs(rb.point_cov_lin - ra.point_cov_lin).max() < 1e-9 * np.abs(ra.point_cov_lin).max()


def test_noise_model_linear_sandwich_equals_the_dense_one(monkeypatch):
    """The model's sandwich through the blocks (a batch of 7 rows at a time: several batches) equals
    ``Q + K_m (S² - C_m) K_mᵀ`` formed densely; a free network (datum terms)."""
    dense, sparse = _pair(tracker_network(noise=False, extras=False)[0], monkeypatch, "free")
    kw = dict(trials=200, rng=5, noise="model", instrument="seed2020")
    ra = propagate(dense.system, dense.result, **kw)
    fs = freeze(sparse.system, sparse.result)
    pairs = np.array([[0, 5], [4, 17], [2, 3]])
    from multilat.network.montecarlo.general.propagate import _noise_cofactor, distance_noise
    from multilat.network.montecarlo.general.propagate_result import _linear

    fd = freeze(dense.system, dense.result)
    lin_d, pts_d = _linear(fd, pairs, _noise_cofactor(fd, distance_noise(fd, "seed2020")))
    lin_b, pts_b = blocks_mod.linear(fs, pairs, distance_noise(fs, "seed2020"), batch=7)
    assert np.abs(lin_b / lin_d - 1).max() < 1e-9
    assert np.abs(pts_b - pts_d).max() < 1e-9 * np.abs(pts_d).max()
    rb = propagate(sparse.system, sparse.result, **kw)
    assert np.abs(rb.lin_std / ra.lin_std - 1).max() < 1e-9
    assert np.all(np.abs(ra.mc_std - rb.mc_std) <= 1e-3 * ra.mc_std_se)


def test_bit_identical_across_chunks_and_maps(monkeypatch):
    from multilat.parallel import process_map

    _, sparse = _pair(tracker_network(5)[0], monkeypatch)
    kw = dict(trials=2500, rng=7, keep_samples=True)
    a = propagate(sparse.system, sparse.result, **kw)
    b = propagate(sparse.system, sparse.result, chunk_size=1, map=map, **kw)
    with process_map(2) as pm:
        d = propagate(sparse.system, sparse.result, chunk_size=2000, map=pm, **kw)
    for other in (b, d):
        assert np.array_equal(a.samples, other.samples)
        assert np.array_equal(a.mc_std, other.mc_std) and np.array_equal(a.interval_shortest, other.interval_shortest)


def test_far_trial_by_the_sparse_gauss_newton(monkeypatch):
    with monkeypatch.context() as m:
        m.setattr(gadjust, "MAX_DENSE_UNKNOWNS", 0)
        m.setattr(gadjust, "SPARSE_ABOVE", 0)          # run.adjust_network checks the size with auto
        adj = adjust_network(read_gama_input(GAMA / "trilateration_fixed.xml"),
                             options=AdjustOptions(backend="sparse"))
    fr = freeze(adj.system, adj.result)
    assert fr.q is None
    obs = draw(fr, 4, np.random.default_rng(8))
    far = obs[1] + 100 * np.concatenate([b.sigma for b in adj.system.blocks]) * \
        np.random.default_rng(9).standard_normal(obs.shape[1])
    obs[1] = far
    sol = solve(fr, obs)
    assert sol.full_gauss_newton.tolist() == [False, True, False, False]
    assert sol.converged.all()
    res = adjust(_started(_with_observations(adj.network, far, adj.system), adj.result))
    assert np.abs(res.parameters - sol.x[1]).max() < 1e-9
    assert abs(res.sigma0 ** 2 * res.dof - sol.vtpv[1]) < 1e-8 * sol.vtpv[1]


@pytest.fixture(scope="module")
def large():
    from multilat.network.model.data import Observations, Points
    from multilat.network.adjust.general.from_tables import network_from_tables
    from multilat.network.synthetic.generator import synthetic_network

    s, t = 8, 1000
    syn = synthetic_network(3, population="rings", n_stations=s, n_targets=t, per_target=7)
    obs = Observations(tuple(f"S{i}" for i in range(s)), tuple(f"T{j}" for j in range(t)), syn.station_index,
                       syn.target_index, syn.distance_m, syn.sigma_m)
    pts = Points(obs.station_ids + obs.target_ids, np.vstack([syn.station_xyz_m, syn.target_xyz_m]))
    net, opt = network_from_tables(obs, points=pts)
    return adjust_network(net, options=opt)


def test_large_distance_network_without_a_dense_q(large):
    assert large.result.cofactor is None and len(large.result.free_names) == 3032
    n = 1000
    res = propagate(large.system, large.result, trials=n, rng=2)
    assert res.trials == n and res.n_failed == 0 and res.n_retried == 0
    assert np.all(np.abs(res.mc_std - res.lin_std) <= 5.0 * res.mc_std_se)
    assert abs(res.sigma0_rms ** 2 - 1) < 5.0 * np.sqrt(2.0 / (n * res.dof))


def test_limits_refused_in_one_line_before_any_trial(large, monkeypatch):
    seen = []
    monkeypatch.setattr(blocks_mod, "MAX_WORK", 1e9)
    with pytest.raises(MultilatError) as e:
        propagate(large.system, large.result, trials=10_000, rng=1, progress=seen.append)
    msg = str(e.value)
    assert "\n" not in msg and not seen
    assert "3032 unknowns, 7000 observation rows" in msg and "the limit is 1e+09" in msg
    allowed = int(msg.rsplit("run at most ", 1)[1].split()[0])
    propagate(large.system, large.result, trials=allowed, rng=1)          # what it names runs
    monkeypatch.setattr(blocks_mod, "MAX_SAMPLE_BYTES", 1e7)
    with pytest.raises(MultilatError, match=r"keeps 1000 trials x \d+ outputs .* the limit is 0.01 GB") as e:
        propagate(large.system, large.result, trials=1000, rng=1, progress=seen.append)
    assert not seen


def test_cli_refuses_past_the_sample_limit_in_one_line(tmp_path):
    """From the command line: exit 2, one ``error:`` line naming the size, the limit and the trials
    that would pass, nothing written (the deviations of 1e8 trials x 89 outputs: 35.6 GB > 4 GB)."""
    from test_general_propagate import ROOT, _cli

    p = _cli(ROOT / "examples" / "general" / "station_control.xml", "--trials", "100000000", "--out", tmp_path / "o",
             cwd=tmp_path)
    assert p.returncode == 2 and p.stdout == ""
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: the general Monte Carlo keeps 100000000 trials x 89 "), \
        p.stderr
    assert "the limit is 4 GB: run at most 11235955 trials" in lines[0]
    assert not (tmp_path / "o").exists()
