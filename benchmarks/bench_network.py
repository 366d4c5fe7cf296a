"""Network benchmarks (issue 5 items 2 and 3): batched Monte Carlo solver, large sparse networks, fast CSV.

* ``batched_small_volume``: trials/s of :meth:`BatchedNetwork.solve` (frozen Schur complement, numba
  kernel) on the paper's small volume (4 heads x 14 targets, gaussian 4.7 um distances), against
  ``scipy.optimize.least_squares(method="lm")`` per trial in a loop (analytic Jacobian, minimal 3-2-1
  parametrisation, started from the nominal solution like ours), same run. Goal >= 1e5 trials/s and
  >= 50x. Extra: the plain-numpy path's trials/s.
* ``propagate_small_volume``: end to end (distance-model errors drawn + solved + summarised), trials/s.
* ``sparse_{2k,20k,200k}``: the one entry point, ``adjust(obs, solver="sparse", initial=truth +
  N(0, 1 mm), snooping=False)``, on 20 stations x t targets, 8 stations per target (1.6 M distances at
  200k): the whole call (solve + every statistic). Baseline, same run, interleaved: the same call with
  ``solver="dense"`` (2k and 20k; too slow at 200k). ``extra`` splits the wall time (timers wrapped
  around ``fit.gauss_newton`` = the solve, and the statistics parts: hat diagonal, ``build_result``,
  w-test groups); at 2k the issue-5 scipy ``trf``/lsmr figure (no statistics); for the largest size the
  peak RSS of a fresh process doing generation + ``adjust``.
* ``large_{20k,200k}_from_distances``: ``adjust(obs, solver="sparse", snooping=False)`` with no
  coordinates (initial values by ``large_initial_values`` inside ``adjust``: seed network +
  multilateration). Baseline, same run: the same call from truth + N(0, 1 mm) (ratio < 1: the price of
  finding the initial values). Extra: the split, errors vs truth after a rigid fit, mean per-target chi2.
* ``cli_adjust_20k_json_no_snooping``: the whole command ``multilat adjust big.csv --solver sparse --json
  --no-snooping > /dev/null`` (20 x 20 000, a CSV written once in a temp dir), subprocess wall time,
  against the library ``adjust(solver="sparse", snooping=False)`` on the same file in-process (reader,
  result_to_json and JSON text timed apart in extra). ``cli_adjust_20k_json`` (full run only): the
  user's default command (data snooping on), once, under a 120 s limit.
* ``csv_read_1.6M``: :func:`fastio.read_observations_fast` on a 1.6 M-row file, against
  ``network.files.read_observations`` (the strict general reader) on its first 100 000 rows,
  scaled x16 (stated in extra). Goal <= 2 s.

The machine is shared: each row records the 1-minute load average before it ran. Each section runs in
a fresh process with ``OPENBLAS_NUM_THREADS=1`` (see :func:`run`).
Quick mode: fewer repeats, 20k trials, sparse 2k/20k only, large 20k, CLI without the default
(snooping) command, CSV 200k rows.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from common import load_avg as _load, median_time

ROOT = Path(__file__).resolve().parent.parent
SEED = 20200613
# Largest network of the sparse/large rows (full mode: 200 000 targets). Lower it to skip the 200k rows:
# BENCH_NETWORK_MAX_TARGETS=20000 (each adjust call at 200k took minutes on the code of 2026-11-23,
# see network.md).
MAX_TARGETS = int(os.environ.get("BENCH_NETWORK_MAX_TARGETS", "200000"))




_median_time = median_time


def _small_network():
    from multilat.network.montecarlo.batched import BatchedNetwork
    from multilat.network.synthetic.configs import small_volume

    cfg = small_volume()
    s, t = len(cfg.station_ids), len(cfg.target_ids)
    si, ti = (a.ravel() for a in np.meshgrid(np.arange(s), np.arange(t), indexing="ij"))
    return BatchedNetwork(si, ti, np.full(len(si), 4.7e-6), cfg.station_xyz_m, cfg.offset_m, cfg.target_xyz_m)


def _scipy_lm_per_trial(net, d):
    """Baseline: scipy LM per trial, analytic Jacobian, 3-2-1 minimal constraints (B xyz, D yz, C y)."""
    from scipy.optimize import least_squares

    from multilat.network.montecarlo.batched import flatten

    s, t = net.n_stations, net.n_targets
    x0 = flatten(net.station_xyz_m, net.offset_m, net.target_xyz_m)
    fixed = np.zeros(len(x0), bool)
    fixed[[3, 4, 5, 10, 11, 7]] = True
    free = ~fixed
    w = 1 / net.sigma_m
    si, ti = net.station_index, net.target_index
    k = np.arange(len(si))

    def unpack(p):
        x = x0.copy()
        x[free] = p
        return x[: 3 * s].reshape(s, 3), x[3 * s: 4 * s], x[4 * s:].reshape(t, 3)

    def jac(p):
        h, o, tg = unpack(p)
        diff = h[si] - tg[ti]
        u = diff / np.linalg.norm(diff, axis=1)[:, None]
        j = np.zeros((len(si), len(x0)))
        for c in range(3):
            j[k, 3 * si + c] = u[:, c]
            j[k, 4 * s + 3 * ti + c] = -u[:, c]
        j[k, 3 * s + si] = 1.0
        return -(w[:, None] * j)[:, free]

    out = []
    for row in d:
        def fun(p, row=row):
            h, o, tg = unpack(p)
            return w * (row - np.linalg.norm(h[si] - tg[ti], axis=1) - o[si])
        r = least_squares(fun, x0[free], jac=jac, method="lm", xtol=1e-12, ftol=1e-12)
        out.append(r.x)
    return out


def bench_batched(quick):
    net = _small_network()
    n = 20_000 if quick else 100_000
    rng = np.random.default_rng(SEED)
    d = net.nominal_distance_m() + rng.normal(0, 4.7e-6, (n, net.n_obs))
    net.solve(d[:10])                                  # compile / warm up
    load = _load()
    med, _ = _median_time(lambda: net.solve(d), 3 if quick else 5)
    sol = net.solve(d)
    n_np = 2000 if quick else 10_000
    med_np, _ = _median_time(lambda: net.solve(d[:n_np], engine="numpy"), 3)
    n_lm = 20 if quick else 100
    med_lm, _ = _median_time(lambda: _scipy_lm_per_trial(net, d[:n_lm]), 1 if quick else 3)
    ours_per = med / n
    lm_per = med_lm / n_lm
    return {"name": "batched_small_volume", "median_s": med, "baseline": "scipy least_squares lm per trial",
            "baseline_median_s": lm_per * n, "ratio": lm_per / ours_per,
            "extra": {"trials": n, "trials_per_s": n / med, "numpy_path_trials_per_s": n_np / med_np,
                      "scipy_lm_trials_per_s": 1 / lm_per, "scipy_lm_trials_timed": n_lm,
                      "failed": sol.n_failed, "iterations_max": int(sol.iterations.max()),
                      "load_avg_1min": load, "goal": ">= 1e5 trials/s and >= 50x"}}


def bench_propagate(quick):
    from multilat.network.synthetic.configs import small_volume
    from multilat.network.montecarlo.propagate import problem_from_config, propagate

    pb = problem_from_config(small_volume(), sigma_m=4.7e-6)
    n = 20_000 if quick else 100_000
    propagate(pb, trials=2000, rng=1)
    load = _load()
    med, _ = _median_time(lambda: propagate(pb, trials=n, rng=SEED, keep_samples=False), 1 if quick else 3)
    return {"name": "propagate_small_volume", "median_s": med, "baseline": None, "baseline_median_s": None,
            "ratio": None, "extra": {"trials": n, "trials_per_s": n / med, "noise": "model",
                                     "load_avg_1min": load,
                                     "note": "includes drawing the distance-model errors"}}


def _observations(net, t):
    from multilat.network.model.data import Observations

    return Observations(tuple(f"S{i}" for i in range(len(net.offset_m))), tuple(f"T{j}" for j in range(t)),
                        net.station_index, net.target_index, net.distance_m, net.sigma_m)


def _sparse_problem(t, seed=SEED):
    """20 stations x t targets, 8 stations per target: (truth, Observations, initial values =
    truth + N(0, 1 mm) on every coordinate and offset)."""
    from types import SimpleNamespace

    from multilat.network.synthetic.generator import synthetic_network

    net = synthetic_network(seed, population="rings", n_stations=20, n_targets=t, per_target=8)
    rng = np.random.default_rng(seed + 1)
    init = SimpleNamespace(station_xyz_m=net.station_xyz_m + rng.normal(0, 1e-3, net.station_xyz_m.shape),
                           offset_m=net.offset_m + rng.normal(0, 1e-3, net.offset_m.shape),
                           target_xyz_m=net.target_xyz_m + rng.normal(0, 1e-3, net.target_xyz_m.shape))
    return net, _observations(net, t), init


# Where the time of one ``adjust`` call goes: these functions are wrapped by timers while it runs
# (module attribute, wrapped in place and restored). ``solve`` is the Gauss-Newton loop alone (every
# call, also those of a minimum search); ``initial`` the initial values from distances; the rest are
# statistics: ``redundancy`` (hat-matrix diagonal), ``result`` (build_result: point covariances,
# w-tests, MDBs), ``w_groups`` (grouping the failing w-tests by correlation).
_PARTS = (("multilat.network.adjust.distance.fit", "gauss_newton", "solve"),
          ("multilat.network.adjust.distance.adjust", "initial_for", "initial"),
          ("multilat.network.adjust.covariance", "NetworkCovariance.hat_diagonal", "redundancy"),
          ("multilat.network.adjust.distance.adjust", "build_result", "result"),
          ("multilat.network.adjust.distance.adjust", "_w_failure_groups", "w_groups"))


class _Split:
    """Context manager: wraps the functions of ``_PARTS`` with timers; ``times`` accumulates seconds."""

    def __enter__(self):
        import functools
        import importlib

        self.times = {key: 0.0 for _, _, key in _PARTS}
        self._undo = []
        for mod, attr, key in _PARTS:
            owner = importlib.import_module(mod)
            *path, name = attr.split(".")
            for p in path:
                owner = getattr(owner, p)
            orig = owner.__dict__[name]

            def wrapper(*a, _f=orig, _k=key, **kw):
                t0 = time.perf_counter()
                try:
                    return _f(*a, **kw)
                finally:
                    self.times[_k] += time.perf_counter() - t0

            setattr(owner, name, functools.wraps(orig)(wrapper))
            self._undo.append((owner, name, orig))
        return self

    def __exit__(self, *exc):
        for owner, name, orig in reversed(self._undo):
            setattr(owner, name, orig)
        return False


def _timed_adjust(obs, **kw):
    """(result, wall seconds, split dict) of one ``adjust(obs, **kw)``; split has the parts of
    ``_PARTS`` and ``statistics`` = wall - solve - initial (final assembly, covariances, redundancy
    numbers, w-tests, result building, checks)."""
    import warnings

    from multilat.network.adjust.distance.adjust import adjust

    with _Split() as sp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        res = adjust(obs, **kw)
        wall = time.perf_counter() - t0
    split = dict(sp.times)
    split["statistics"] = wall - split["solve"] - split["initial"]
    return res, wall, split


def _median_split(splits):
    return {k: statistics.median(s[k] for s in splits) for k in splits[0]}


def _scipy_trf_sparse(net, init):
    from scipy.optimize import least_squares
    from scipy.sparse import csr_matrix

    h0, o0, t0 = init.station_xyz_m, init.offset_m, init.target_xyz_m
    s, t, m = len(h0), len(t0), len(net.distance_m)
    si, ti = net.station_index, net.target_index
    w = 1 / net.sigma_m
    x0 = np.concatenate([h0.ravel(), o0, t0.ravel()])
    rows = np.repeat(np.arange(m), 7)

    def split(x):
        return x[: 3 * s].reshape(s, 3), x[3 * s: 4 * s], x[4 * s:].reshape(t, 3)

    def fun(x):
        h, o, tg = split(x)
        return w * (net.distance_m - np.linalg.norm(h[si] - tg[ti], axis=1) - o[si])

    cols = np.stack([3 * si, 3 * si + 1, 3 * si + 2, 3 * s + si, 4 * s + 3 * ti, 4 * s + 3 * ti + 1,
                     4 * s + 3 * ti + 2], axis=1).ravel()

    def jac(x):
        h, o, tg = split(x)
        diff = h[si] - tg[ti]
        u = diff / np.linalg.norm(diff, axis=1)[:, None]
        v = -w[:, None] * np.concatenate([u, np.ones((m, 1)), -u], axis=1)
        return csr_matrix((v.ravel(), (rows, cols)), shape=(m, len(x0)))

    r = least_squares(fun, x0, jac=jac, method="trf", tr_solver="lsmr", x_scale="jac", max_nfev=50)
    return r


_PEAK_CHILD = r"""
import json, sys, time
sys.path.insert(0, %r)
import numpy as np
from bench_network import _sparse_problem
from multilat.network.adjust.distance.adjust import adjust
net, obs, init = _sparse_problem(%d)
t0 = time.perf_counter()
res = adjust(obs, solver="sparse", initial=init, snooping=False)
wall = time.perf_counter() - t0
hwm = 0
for line in open("/proc/self/status"):
    if line.startswith("VmHWM"):
        hwm = int(line.split()[1]) / 1024
print(json.dumps({"peak_rss_mib": hwm, "first_adjust_s": wall}))
"""


def _warm_up():
    """Compile / load the numba kernels and import everything on a small network (not timed)."""
    _, obs, init = _sparse_problem(500, seed=SEED + 7)
    for solver in ("sparse", "dense"):
        _timed_adjust(obs, solver=solver, initial=init, snooping=False)
    _timed_adjust(obs, solver="sparse", snooping=False, rng=1)


def bench_sparse(quick):
    """``adjust(obs, solver="sparse", initial=truth + N(0, 1 mm), snooping=False)`` against the same
    call with ``solver="dense"`` (2k, 20k), same run, interleaved."""
    sizes = [n for n in ([2000, 20_000] if quick else [2000, 20_000, 200_000]) if n <= max(MAX_TARGETS, 2000)]
    _warm_up()
    out = []
    for t in sizes:
        net, obs, init = _sparse_problem(t)
        reps = 3 if quick else {2000: 5, 20_000: 3, 200_000: 2}[t]
        do_dense = t <= 20_000
        load = _load()
        sp, dn, cpu = [], [], []
        for _ in range(reps):
            c0 = time.process_time()
            sp.append(_timed_adjust(obs, solver="sparse", initial=init, snooping=False))
            cpu.append(time.process_time() - c0)       # CPU seconds of all threads
            if do_dense:
                dn.append(_timed_adjust(obs, solver="dense", initial=init, snooping=False))
        med = statistics.median(w for _, w, _ in sp)
        r0 = sp[0][0]
        split = _median_split([s for _, _, s in sp])
        extra = {"targets": t, "distances": obs.n_obs, "what": "adjust(solver='sparse', snooping=False), "
                 "initial = truth + N(0, 1 mm)", "reps": reps,
                 "solve_s": split["solve"], "statistics_s": split["statistics"],
                 "redundancy_s": split["redundancy"], "result_s": split["result"],
                 "w_groups_s": split["w_groups"], "best_s": min(w for _, w, _ in sp),
                 "cpu_s": statistics.median(cpu), "iterations": r0.iterations,
                 "converged": bool(r0.convergence.converged), "solver": r0.solver, "sigma0": r0.sigma0,
                 "failing_w_tests": int(np.sum(np.abs(r0.w) > _w_crit(r0.alpha))),
                 "max_offset_error_m": float(np.abs(r0.offset_m - net.offset_m).max()),
                 "load_avg_1min": load}
        row = {"name": f"sparse_{t // 1000}k", "median_s": med, "baseline": None, "baseline_median_s": None,
               "ratio": None, "extra": extra}
        if do_dense:
            dmed = statistics.median(w for _, w, _ in dn)
            dsplit = _median_split([s for _, _, s in dn])
            d0 = dn[0][0]
            row.update(baseline="adjust(solver='dense'), same call", baseline_median_s=dmed, ratio=dmed / med)
            extra.update(dense_solve_s=dsplit["solve"], dense_statistics_s=dsplit["statistics"],
                         dense_vs_sparse_max_offset_diff_m=float(np.abs(d0.offset_m - r0.offset_m).max()),
                         dense_vs_sparse_sigma0_rel_diff=abs(d0.sigma0 / r0.sigma0 - 1))
        if t == 2000:
            t0 = time.perf_counter()
            lr = _scipy_trf_sparse(net, init)
            extra["scipy_trf_lsmr_s"] = time.perf_counter() - t0      # the issue-5 baseline, no statistics
            extra["scipy_trf_nfev"] = int(lr.nfev)
        if t == max(sizes):
            p = subprocess.run([sys.executable, "-c", _PEAK_CHILD % (str(Path(__file__).parent), t)],
                               capture_output=True, text=True, timeout=1200)
            if p.returncode == 0:
                extra["fresh_process"] = json.loads(p.stdout.strip().splitlines()[-1])
            else:  # pragma: no cover
                extra["fresh_process_error"] = p.stderr.strip().splitlines()[-1:]
        out.append(row)
    return out


def _w_crit(alpha):
    from multilat.network.adjust.statistics import w_critical

    return w_critical(alpha)


def bench_csv(quick):
    from multilat.network.io.fastio import read_observations_fast
    from multilat.network.io.files import read_observations
    from multilat.network.synthetic.generator import synthetic_network

    t = 25_000 if quick else 200_000
    net = synthetic_network(SEED, population="rings", n_stations=20, n_targets=t, per_target=8)
    s = np.char.add("S", net.station_index.astype(str))
    tg = np.char.add("T", net.target_index.astype(str))
    dd = np.char.mod("%.9f", net.distance_m)
    body = np.char.add(np.char.add(np.char.add(np.char.add(np.char.add(s, ","), tg), ","), dd), ",5e-06")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "obs.csv"
        path.write_text("station,target,distance_m,sigma_m\n" + "\n".join(body.tolist()) + "\n")
        part = Path(tmp) / "obs_part.csv"
        nb = min(100_000, len(body))
        part.write_text("station,target,distance_m,sigma_m\n" + "\n".join(body[:nb].tolist()) + "\n")
        load = _load()
        med, _ = _median_time(lambda: read_observations_fast(path), 3)
        fo = read_observations_fast(path)
        # the strict reader itself: read_observations hands files of >= 1 MiB in the plain format to
        # the vectorised reader, so the size test is stood down for the baseline
        from multilat.network.io import files as F

        big = F._large_file
        F._large_file = lambda _p: False
        try:
            tb, _ = _median_time(lambda: read_observations(part), 1)
        finally:
            F._large_file = big
        scale = len(body) / nb
        ok = bool(np.allclose(fo.distance_m, net.distance_m, atol=1e-9))
    return {"name": f"csv_read_{len(body) / 1e6:.1f}M", "median_s": med,
            "baseline": "network.files.read_observations (strict reader), scaled from 1e5 rows",
            "baseline_median_s": tb * scale, "ratio": tb * scale / med,
            "extra": {"rows": len(body), "baseline_rows_timed": nb, "values_ok": ok, "load_avg_1min": load}}


def bench_large(quick):
    """Targets from distances alone: ``adjust(obs, solver="sparse", snooping=False)`` (initial values by
    :func:`multilat.network.adjust.approximate.large.large_initial_values` inside ``adjust``, solve, statistics) against
    the same call given truth + N(0, 1 mm) as initial values, same run, interleaved."""
    from multilat.network.model.datum import rigid_fit

    t = 20_000 if quick else min(200_000, max(MAX_TARGETS, 20_000))
    reps = 3 if quick else 2
    _warm_up()
    net, obs, init = _sparse_problem(t)
    load = _load()
    res, base = [], []
    for k in range(reps):
        res.append(_timed_adjust(obs, solver="sparse", snooping=False, rng=1 + k))
        base.append(_timed_adjust(obs, solver="sparse", initial=init, snooping=False))
    med = statistics.median(w for _, w, _ in res)
    bmed = statistics.median(w for _, w, _ in base)
    split = _median_split([s for _, _, s in res])
    r0 = res[0][0]
    R, tr = rigid_fit(net.station_xyz_m, r0.station_xyz_m, allow_reflection=True)
    et = r0.target_xyz_m - (net.target_xyz_m @ R.T + tr)
    chi = np.einsum("ti,ti->t", et, np.linalg.solve(r0.target_cov_m2, et[:, :, None])[:, :, 0])
    hwm = 0.0
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM"):
            hwm = int(line.split()[1]) / 1024
    ini = r0.initial
    search = ini.get("search") or {}
    return {"name": f"large_{t // 1000}k_from_distances", "median_s": med,
            "baseline": "adjust(solver='sparse') from truth + N(0, 1 mm) (no initial values to find)",
            "baseline_median_s": bmed, "ratio": bmed / med,
            "extra": {"what": f"adjust(solver='sparse', snooping=False), {t // 1000}k targets from distances "
                              "alone", "targets": t, "distances": obs.n_obs, "reps": reps,
                      "initial_s": split["initial"], "solve_s": split["solve"],
                      "statistics_s": split["statistics"], "redundancy_s": split["redundancy"],
                      "result_s": split["result"], "w_groups_s": split["w_groups"],
                      "baseline_solve_s": _median_split([s for _, _, s in base])["solve"],
                      "iterations": r0.iterations, "initial_method": ini.get("method"),
                      "seed_targets": ini.get("seed_targets"),
                      "multilateration_rms_m": ini.get("multilateration_rms_m"),
                      "search_candidates": len(search.get("candidates", ())) if isinstance(search, dict) else None,
                      "sigma0": r0.sigma0, "max_offset_error_m": float(np.abs(r0.offset_m - net.offset_m).max()),
                      "max_target_error_m": float(np.abs(et).max()), "mean_target_chi2_3": float(chi.mean()),
                      "peak_rss_mib_section": hwm, "load_avg_1min": load}}


def _write_csv(net, path):
    s = np.char.add("S", net.station_index.astype(str))
    tg = np.char.add("T", net.target_index.astype(str))
    dd = np.char.mod("%.9f", net.distance_m)
    body = np.char.add(np.char.add(np.char.add(np.char.add(np.char.add(s, ","), tg), ","), dd), ",5e-06")
    Path(path).write_text("station,target,distance_m,sigma_m\n" + "\n".join(body.tolist()) + "\n")
    return len(body)


def _cli_cmd(*args):
    exe = Path(sys.executable).with_name("multilat")
    if exe.exists():
        return [str(exe), *args]
    return [sys.executable, "-c", "from multilat.cli import run; run()", *args]  # pragma: no cover


def _cli_env():
    src = str(ROOT / "src")
    pp = os.environ.get("PYTHONPATH")
    return dict(os.environ, PYTHONPATH=src if not pp else src + os.pathsep + pp)


def _run_cli(args, timeout):
    t0 = time.perf_counter()
    p = subprocess.run(_cli_cmd(*args), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                       env=_cli_env(), timeout=timeout)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(f"multilat {' '.join(args)} failed: {p.stderr.strip()[-400:]}")
    return wall


def bench_cli(quick):
    """The user's command, whole: ``multilat adjust big.csv --solver sparse --json > /dev/null`` on
    20 stations x 20 000 targets (160 000 distances), wall time of the subprocess; beside it, the
    library path on the same file in this process (reader + ``adjust`` + ``result_to_json`` + JSON text),
    each part timed. ``--no-snooping`` is measured against ``snooping=False``; the default command
    (data snooping on) once, under a time limit, in the full run only."""
    import resource
    import warnings

    from multilat.cli.app import to_jsonable
    from multilat.network.io.files import read_observations
    from multilat.network.synthetic.generator import synthetic_network
    from multilat.network.adjust.distance.result import result_to_json

    t = 20_000
    reps = 2 if quick else 3
    _warm_up()
    net = synthetic_network(SEED, population="rings", n_stations=20, n_targets=t, per_target=8)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "big.csv"
        n = _write_csv(net, path)
        _run_cli(["--help"], 120)                               # numba cache / .pyc warm, not timed
        load = _load()
        startup = statistics.median(_run_cli(["--help"], 120) for _ in range(reps))
        cli, lib = [], []
        for _ in range(reps):
            cli.append(_run_cli(["adjust", str(path), "--solver", "sparse", "--json", "--no-snooping"], 1200))
            t0 = time.perf_counter()
            obs = read_observations(path)
            t1 = time.perf_counter()
            res, wall, split = _timed_adjust(obs, solver="sparse", snooping=False, rng=0)
            t2 = time.perf_counter()
            doc = result_to_json(res)
            t3 = time.perf_counter()
            text = json.dumps(to_jsonable(doc), indent=2)
            t4 = time.perf_counter()
            lib.append({"read": t1 - t0, "adjust": wall, "solve": split["solve"], "initial": split["initial"],
                        "statistics": split["statistics"], "result_to_json": t3 - t2, "json_text": t4 - t3,
                        "total": t4 - t0})
        peak_children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        med = statistics.median(cli)
        lm = _median_split(lib)
        failing = int(np.sum(np.abs(res.w) > _w_crit(res.alpha)))
        rows.append({"name": "cli_adjust_20k_json_no_snooping", "median_s": med,
                     "baseline": "library in-process: adjust(solver='sparse', snooping=False) alone",
                     "baseline_median_s": lm["adjust"], "ratio": lm["adjust"] / med,
                     "extra": {"command": "multilat adjust big.csv --solver sparse --json --no-snooping "
                                          "> /dev/null", "targets": t, "distances": n, "reps": reps,
                               "csv_mib": path.stat().st_size / 2**20, "cli_startup_help_s": startup,
                               "lib_read_s": lm["read"], "lib_initial_s": lm["initial"],
                               "lib_solve_s": lm["solve"], "lib_statistics_s": lm["statistics"],
                               "lib_result_to_json_s": lm["result_to_json"], "lib_json_text_s": lm["json_text"],
                               "lib_total_s": lm["total"], "json_mib": len(text) / 2**20,
                               "peak_rss_mib_largest_child": peak_children,
                               "failing_w_tests_without_snooping": failing, "load_avg_1min": load,
                               "goal_issue_12": "<= 0.6 s (whole CLI, --json)"}})
        if not quick:
            limit = 120
            load = _load()
            try:
                wall = _run_cli(["adjust", str(path), "--solver", "sparse", "--json"], limit)
                note = "finished"
            except subprocess.TimeoutExpired:
                wall, note = None, f"not finished after {limit} s (killed)"
            rows.append({"name": "cli_adjust_20k_json", "median_s": wall,
                         "baseline": "the same command with --no-snooping (row above, median)",
                         "baseline_median_s": med, "ratio": None if wall is None else med / wall,
                         "extra": {"command": "multilat adjust big.csv --solver sparse --json > /dev/null "
                                              "(the default: data snooping on)", "runs": 1, "note": note,
                                   "time_limit_s": limit, "failing_w_tests_before_snooping": failing,
                                   "load_avg_1min": load}})
        else:
            warnings.warn("quick mode: the default command (data snooping on) is not run", stacklevel=1)
    return rows


_SECTIONS = {"batched": lambda q: [bench_batched(q)], "propagate": lambda q: [bench_propagate(q)],
             "sparse": bench_sparse, "csv": lambda q: [bench_csv(q)], "large": lambda q: [bench_large(q)],
             "cli": bench_cli}


def run(quick: bool = False, sections=("batched", "propagate", "sparse", "large", "cli", "csv")) -> list[dict]:
    """Each section in a fresh process with ``OPENBLAS_NUM_THREADS=1``: OpenBLAS worker threads left
    spinning by a BLAS-heavy baseline (scipy LM) otherwise steal the second core from the numba
    kernels measured next (seen: 10x slower sparse solves after the LM baseline in one process)."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    rows = []
    for name in sections:
        cmd = [sys.executable, str(Path(__file__).resolve()), "--section", name] + (["--quick"] if quick else [])
        p = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=3600)
        if p.returncode != 0:
            raise RuntimeError(f"bench_network section {name} failed: {p.stderr.strip()[-500:]}")
        rows += [json.loads(line) for line in p.stdout.splitlines() if line.startswith("{")]
    return rows


if __name__ == "__main__":
    quick = "--quick" in sys.argv
    if "--section" in sys.argv:
        out = _SECTIONS[sys.argv[sys.argv.index("--section") + 1]](quick)
    elif "--sections" in sys.argv:
        out = run(quick, sections=tuple(sys.argv[sys.argv.index("--sections") + 1].split(",")))
    elif "--sparse" in sys.argv:
        out = run(quick, sections=("sparse",))
    elif "--large" in sys.argv:
        out = run(quick, sections=("large",))
    elif "--cli" in sys.argv:
        out = run(quick, sections=("cli",))
    else:
        out = run(quick)
    for r in out:
        print(json.dumps(r, default=float))
