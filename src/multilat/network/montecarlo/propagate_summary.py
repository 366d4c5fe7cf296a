"""The summaries of a network Monte Carlo (:func:`multilat.network.montecarlo.propagate.propagate`): the blocks'
float32 deviations reduced to the engine's statistics (:func:`multilat.montecarlo.summarize`, JCGM 101
§7.6-7.7) per coordinate, offset and distance, each point's 3x3 covariance and the coverage of its 95 %
ellipsoid, beside the linear propagation (the same network's linear covariance) of the same inputs.
"""

from __future__ import annotations

import math
import time

import numpy as np

from multilat.errors import MultilatError
from multilat.montecarlo import summarize
from multilat.network.montecarlo import batched as bt
from multilat.network.montecarlo.propagate_result import PropagationResult, chi2_3_95
from multilat.network.model.distance import line_of_sight

__all__ = ["summarise", "linear_std"]


def _labels(problem):
    lab = [f"{s}.{c}" for s in problem.station_ids for c in "xyz"]
    lab += [f"{s}.offset" for s in problem.station_ids]
    lab += [f"{t}.{c}" for t in problem.target_ids for c in "xyz"]
    lab += [f"{a}-{b}" for a, b in problem.pairs]
    return tuple(lab)




def linear_std(problem, noise_std, obs_cov=None):
    """Linear std of every reported quantity and the 3x3 covariance of each point (``obs_cov``: the
    observations' full covariance, correlated readings)."""
    net = problem.network
    q = net.linear_covariance(sigma_m=noise_std) if obs_cov is None else net.linear_covariance(cov_m2=obs_cov)
    std = list(np.sqrt(np.clip(np.diag(q), 0, None)))
    for a, b in problem.pairs:
        ra, rb = problem.param_rows(a), problem.param_rows(b)
        _, g = line_of_sight(problem.point_xyz(a) - problem.point_xyz(b))
        rows = np.concatenate([ra, rb])
        c = q[np.ix_(rows, rows)]
        gg = np.concatenate([g, -g])
        std.append(math.sqrt(max(gg @ c @ gg, 0.0)))
    pids = problem.station_ids + problem.target_ids
    pc = np.array([q[np.ix_(problem.param_rows(p), problem.param_rows(p))] for p in pids])
    return np.array(std), pc


def _ellipsoid_fraction(dev3, center, cov):
    """Fraction of rows of dev3 (n, 3) inside the 95 % ellipsoid of (center, cov).

    Full rank: ``chi2_3(0.95)``. A datum-fixed coordinate (3-2-1) leaves a rank-r covariance: the
    region is the r-dimensional ellipsoid in its range with the ``chi2_r(0.95)`` quantile; NaN for
    a fixed point (r = 0).
    """
    from multilat.network.adjust.statistics import chi2_ppf

    ev, vec = np.linalg.eigh(np.asarray(cov, float))
    if not np.all(np.isfinite(ev)) or ev.max() <= 0:
        return float("nan")
    keep = ev > 1e-9 * ev.max()
    r = int(keep.sum())
    vk, evk = vec[:, keep], ev[keep]
    y = [dev3[:, a] - center[a] for a in range(3)]
    d2 = None
    for c in range(r):       # z = y @ vk column by column, in elementwise numpy (no BLAS: the tasks of
        z = y[0] * vk[0, c]  # summarise run in two threads, BLAS has threads of its own); np.sum(z * z /
        z += y[1] * vk[1, c]  # ev, axis=1) column by column: numpy adds rows this short in order, without
        z += y[2] * vk[2, c]  # its slow reduction over rows of 3 (tests/test_propagate.py)
        z *= z
        z /= evk[c]
        d2 = z if d2 is None else d2 + z
    q = chi2_3_95 if r == 3 else chi2_ppf(0.95, r)
    return np.count_nonzero(d2 <= q) / len(d2)     # = np.mean(d2 <= q): an exact count over n


def _kurtosis(y: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """Sample kurtosis m4 / m2^2 per column (3 where a column is constant)."""
    c2 = y - mean
    c2 *= c2
    m2 = np.mean(c2, axis=0)
    c2 *= c2
    m4 = np.mean(c2, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(m2 > 0, m4 / np.where(m2 > 0, m2, 1.0) ** 2, 3.0)


def _in_two_threads(tasks, n: int) -> None:
    """Run independent tasks, each writing its own entries of the summaries, in two threads from 50 000
    trials (in order, here, below): numpy releases the GIL in their sorts and reductions. None calls
    BLAS, whose own threads would compete for the cores; the threads change the time, not a bit."""
    if n < 50_000:
        for task in tasks:
            task()
        return
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(2) as ex:
        for f in [ex.submit(task) for task in tasks]:
            f.result()


def summarise(problem, blocks, k, noise, noise_std, ss, adaptive_info, t0, keep_samples, done, obs_cov=None):
    """Statistics of all blocks' deviations (the engine's :func:`summarize`: JCGM 101 §7.6-7.7)."""
    net = problem.network
    # float32 deviations kept once; statistics point by point / column block by column block in float64.
    # Column-major: each point's or block's columns are gathered ~15x faster than from rows of k values
    # (the gathered float64 copies are column-major either way: the same arrays, the same bits)
    dev = np.empty((sum(len(b["dev"]) for b in blocks), k), np.float32, order="F")
    if blocks:
        np.concatenate([b["dev"] for b in blocks], out=dev)
    for b in blocks:
        b["dev"] = None
    n_failed = int(sum(b["n_failed"] for b in blocks))
    n_retried = int(sum(b["n_retried"] for b in blocks))
    n = dev.shape[0]
    if n < 2:
        raise MultilatError(f"only {n} of {done} trials converged: the network is too weak for a "
                            "Monte Carlo from its nominal solution")
    sig0_all = np.concatenate([b["sigma0"] for b in blocks])
    sig0 = float(np.mean(sig0_all))
    sig0_rms = float(np.sqrt(np.mean(sig0_all**2)))
    x0 = np.concatenate([bt.flatten(net.station_xyz_m, net.offset_m, net.target_xyz_m),
                         [np.linalg.norm(problem.point_xyz(a) - problem.point_xyz(b)) for a, b in problem.pairs]])
    mean_dev, std, kurt = np.empty(k), np.empty(k), np.empty(k)
    iv_sym, iv_short = np.empty((k, 2)), np.empty((k, 2))
    pids = problem.station_ids + problem.target_ids
    pc_mc = np.empty((len(pids), 3, 3))

    def put(cols, y):
        r = summarize(y, 0.95)
        mean_dev[cols], std[cols] = r.estimate, r.std
        iv_sym[cols], iv_short[cols] = r.interval_symmetric, r.interval_shortest
        kurt[cols] = _kurtosis(y, r.estimate)
        return r

    if noise == "model" or obs_cov is not None:
        # the linear sandwich uses the input errors' empirical std over all trials drawn, so that the
        # comparison tests the propagation, not the distance model's own (MC-estimated) std
        n_all = sum(b["n"] for b in blocks)
        es = sum(b["e_sum"] for b in blocks)
        e2 = sum(b["e2_sum"] for b in blocks)
        emp_std = np.sqrt(np.maximum(e2 / n_all - (es / n_all) ** 2, 0.0) * n_all / (n_all - 1))
        input_std_ratio = float(np.mean(emp_std / noise_std))
        if obs_cov is None:       # correlated readings: the analytic covariance (its diagonal alone
            noise_std = emp_std   # would drop the sensors' correlations)
    else:
        input_std_ratio = 1.0
    lin_std, pc_lin = linear_std(problem, noise_std, obs_cov)
    cov_mc_frac = np.empty(len(pids))
    cov_lin_frac = np.empty(len(pids))
    rest = np.concatenate([net.reported_layout.station_columns("offset"), np.arange(net.n_params, k)])   # offsets, distances

    def point(q):
        rows = problem.param_rows(pids[q])
        d3 = dev[:, rows].astype(np.float64)                  # one float64 copy per point (not written to)
        pc_mc[q] = put(rows, d3).cov
        cov_mc_frac[q] = _ellipsoid_fraction(d3, mean_dev[rows], pc_mc[q])
        cov_lin_frac[q] = _ellipsoid_fraction(d3, np.zeros(3), pc_lin[q])

    _in_two_threads([lambda c=rest[c0:c0 + 8]: put(c, dev[:, c].astype(np.float64))
                     for c0 in range(0, len(rest), 8)] + [lambda q=q: point(q) for q in range(len(pids))], n)
    iv_sym += x0[:, None]
    iv_short += x0[:, None]
    se = std * np.sqrt(np.maximum(kurt - 1.0, 0.0) / (4.0 * n))
    return PropagationResult(
        problem=problem, labels=_labels(problem), nominal=x0, mc_mean=x0 + mean_dev, mc_std=std,
        mc_std_se=se, lin_std=lin_std, interval_symmetric=iv_sym, interval_shortest=iv_short,
        point_ids=pids, point_cov_mc=pc_mc, point_cov_lin=pc_lin, ellipsoid_coverage_mc=cov_mc_frac,
        ellipsoid_coverage_lin=cov_lin_frac, trials=n, n_failed=n_failed, sigma0_mean=sig0, noise=noise,
        seed_entropy=int(ss.entropy), adaptive=adaptive_info, elapsed_s=time.perf_counter() - t0,
        input_std_m=noise_std, input_std_ratio=input_std_ratio, n_retried=n_retried,
        samples=dev if keep_samples else None, sigma0_rms=sig0_rms)
