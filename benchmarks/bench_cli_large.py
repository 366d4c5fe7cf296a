"""Issue 12, the large-network rows, as whole commands (``python benchmarks/bench_cli_large.py``).

Rows (each the user's command in a subprocess, wall time and the child's peak RSS from ``/usr/bin/time``):

* ``cli12_adjust_20k_json``: ``multilat adjust big20k.csv --json > /dev/null`` (20 stations x 20 000
  targets, 160 000 distances, the default command: data snooping on, this blunder-free network
  passes the global test). Baseline, same run: the numpy Schur solve alone (``solver="dense"``'s
  Gauss-Newton loop, in-process, from truth + N(0, 1 mm)) — the issue's "a numpy Schur solve alone".
* ``cli12_adjust_200k_json`` (full mode): the same at 20 x 200 000 (1.6 M distances). Baseline: the
  sparse solver's Gauss-Newton loop alone on the same distances, in-process.
* ``cli12_adjust_200k_out``: ``multilat adjust big200k.csv --out DIR`` (CSVs, figures, result.json).
* ``cli12_first_command``: the 20k ``--json`` command in a fresh numba cache (``NUMBA_CACHE_DIR`` an
  empty directory) right after ``python -m multilat.warmup`` (what ``make install`` runs), against
  the same command with a cold cache (what a first command paid before); ``extra`` has the steady
  (second) run, so "more" = first - steady.

With ``BENCH_BASELINE_SRC=/path/to/old/src`` every command also runs on that source tree (same files,
same run) and ``extra`` holds its figures as ``before_*``: the before/after of BENCHMARKS.md.
``--quick``: 20k rows only. ``BENCH_NETWORK_MAX_TARGETS=20000`` also skips the 200k rows.
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

from common import load_avg as _load

ROOT = Path(__file__).resolve().parent.parent
SEED = 20200613
MAX_TARGETS = int(os.environ.get("BENCH_NETWORK_MAX_TARGETS", "200000"))
BASE_SRC = os.environ.get("BENCH_BASELINE_SRC")


def _write_csv(t: int, path: Path, *, stations: int = 20, per_target: int = 8) -> int:
    """``synthetic_network`` "rings" (stations, t, per_target) as an observation CSV (σ 5 µm); its row count."""
    from multilat.network.synthetic.generator import synthetic_network

    net = synthetic_network(SEED, population="rings", n_stations=stations, n_targets=t, per_target=per_target)
    s = np.char.add("S", net.station_index.astype(str))
    tg = np.char.add("T", net.target_index.astype(str))
    dd = np.char.mod("%.9f", net.distance_m)
    body = np.char.add(np.char.add(np.char.add(np.char.add(np.char.add(s, ","), tg), ","), dd), ",5e-06")
    path.write_text("station,target,distance_m,sigma_m\n" + "\n".join(body.tolist()) + "\n")
    return len(body)


def _exe():
    exe = Path(sys.executable).with_name("multilat")
    return [str(exe)] if exe.exists() else [sys.executable, "-c", "from multilat.cli import run; run()"]


def _env(src: str, **extra) -> dict:
    pp = os.environ.get("PYTHONPATH")
    env = dict(os.environ, PYTHONPATH=src if not pp else src + os.pathsep + pp)
    env.update(extra)
    return env


def _run(args, src, **env):
    """(wall s, peak RSS MiB) of ``multilat ARGS`` with ``src`` first on PYTHONPATH, stdout to
    /dev/null; the peak RSS from ``/usr/bin/time -f %M`` (None without it)."""
    timer = ["/usr/bin/time", "-f", "%M"] if os.path.exists("/usr/bin/time") else []
    t0 = time.perf_counter()
    p = subprocess.run(timer + _exe() + list(args), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                       env=_env(src, **env), timeout=1800)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(f"multilat {' '.join(map(str, args))} failed: {p.stderr.decode()[-400:]}")
    return wall, (int(p.stderr.decode().strip().splitlines()[-1]) / 1024 if timer else None)


def _median_runs(args, src, reps, **env):
    runs = [_run(args, src, **env) for _ in range(reps)]
    rss = [r for _, r in runs if r is not None]
    return statistics.median(w for w, _ in runs), max(rss, default=None), [w for w, _ in runs]


def _solve_alone(path: Path, solver: str) -> float:
    """The Gauss-Newton loop alone (``fit.gauss_newton``) inside ``adjust(solver=...)`` from truth +
    N(0, 1 mm), in-process (the reader and statistics not counted)."""
    import warnings

    from multilat.network.adjust.distance import fit
    from multilat.network.adjust.distance.adjust import Start, adjust
    from multilat.network.io.files import read_observations
    from multilat.network.synthetic.generator import synthetic_network

    obs = read_observations(path)
    t = obs.n_targets
    net = synthetic_network(SEED, population="rings", n_stations=20, n_targets=t, per_target=8)
    rng = np.random.default_rng(SEED + 1)
    si = [int(x[1:]) for x in obs.station_ids]
    ti = np.array([int(x[1:]) for x in obs.target_ids])
    init = Start(net.station_xyz_m[si] + rng.normal(0, 1e-3, (20, 3)),
                 net.target_xyz_m[ti] + rng.normal(0, 1e-3, (t, 3)), net.offset_m[si] + rng.normal(0, 1e-3, 20))
    spent = []
    orig = fit.gauss_newton

    def timed(*a, **k):
        t0 = time.perf_counter()
        try:
            return orig(*a, **k)
        finally:
            spent.append(time.perf_counter() - t0)

    fit.gauss_newton = timed
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            adjust(obs, initial=init, solver=solver, snooping=False)
    finally:
        fit.gauss_newton = orig
    return sum(spent)


def run(quick: bool = False) -> list[dict]:
    new = str(ROOT / "src")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        p20 = tmp / "big20k.csv"
        n20 = _write_csv(20_000, p20)
        srcs = [("", new)] + ([("before_", BASE_SRC)] if BASE_SRC else [])
        for _, src in srcs:                                        # .pyc and numba caches warm
            _run(["adjust", str(p20), "--json"], src)
        # --- 20k --json
        load = _load()
        extra = {"command": "multilat adjust big20k.csv --json > /dev/null", "distances": n20,
                 "csv_mib": p20.stat().st_size / 2**20, "load_avg_1min": load, "goal": "<= 0.6 s"}
        med = None
        for tag, src in srcs:
            m, rss, ws = _median_runs(["adjust", str(p20), "--json"], src, 2 if quick else 3)
            extra.update({f"{tag}wall_s": m, f"{tag}runs_s": ws, f"{tag}peak_rss_mib": rss})
            med = m if tag == "" else med
        base = _solve_alone(p20, "dense")
        extra["sparse_solve_alone_s"] = _solve_alone(p20, "sparse")
        rows.append({"name": "cli12_adjust_20k_json", "median_s": med,
                     "baseline": "numpy Schur solve alone (solver='dense' Gauss-Newton loop, in-process)",
                     "baseline_median_s": base, "ratio": base / med, "extra": extra})
        # --- first command after install
        load = _load()
        cold = tmp / "nc_cold"
        warm = tmp / "nc_warm"
        cold.mkdir()
        warm.mkdir()
        extra = {"command": "multilat adjust big20k.csv --json in a fresh NUMBA_CACHE_DIR", "load_avg_1min": load}
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "multilat.warmup"], env=_env(new, NUMBA_CACHE_DIR=str(warm)),
                       check=True, capture_output=True, timeout=1800)
        extra["warmup_install_s"] = time.perf_counter() - t0
        first, _ = _run(["adjust", str(p20), "--json"], new, NUMBA_CACHE_DIR=str(warm))
        steady, _ = _run(["adjust", str(p20), "--json"], new, NUMBA_CACHE_DIR=str(warm))
        cold_first, _ = _run(["adjust", str(p20), "--json"], new, NUMBA_CACHE_DIR=str(cold))
        extra.update(first_after_warmup_s=first, steady_s=steady, more_after_warmup_s=first - steady,
                     first_cold_cache_s=cold_first, more_cold_cache_s=cold_first - steady)
        if BASE_SRC:
            bc = tmp / "nc_before"
            bc.mkdir()
            b_first, _ = _run(["adjust", str(p20), "--json"], BASE_SRC, NUMBA_CACHE_DIR=str(bc))
            b_steady, _ = _run(["adjust", str(p20), "--json"], BASE_SRC, NUMBA_CACHE_DIR=str(bc))
            extra.update(before_first_s=b_first, before_steady_s=b_steady, before_more_s=b_first - b_steady)
        rows.append({"name": "cli12_first_command", "median_s": first,
                     "baseline": "the same first command with a cold numba cache (no warm-up)",
                     "baseline_median_s": cold_first, "ratio": cold_first / first, "extra": extra})
        if quick or MAX_TARGETS < 200_000:
            return rows
        p200 = tmp / "big200k.csv"
        n200 = _write_csv(200_000, p200)
        load = _load()
        extra = {"command": "multilat adjust big200k.csv --json > /dev/null", "distances": n200,
                 "csv_mib": p200.stat().st_size / 2**20, "load_avg_1min": load, "goal": "<= 3 s, <= 1 GB"}
        for tag, src in srcs:
            m, rss, ws = _median_runs(["adjust", str(p200), "--json"], src, 2)
            extra.update({f"{tag}wall_s": m, f"{tag}runs_s": ws, f"{tag}peak_rss_mib": rss})
            med = m if tag == "" else med
        base = _solve_alone(p200, "sparse")
        rows.append({"name": "cli12_adjust_200k_json", "median_s": extra["wall_s"],
                     "baseline": "sparse solve alone (Gauss-Newton loop, in-process)",
                     "baseline_median_s": base, "ratio": base / extra["wall_s"], "extra": extra})
        load = _load()
        extra = {"command": "multilat adjust big200k.csv --out DIR", "load_avg_1min": load, "goal": "<= 2.5 s"}
        for tag, src in srcs:
            out = tmp / f"out{tag}"
            m, rss, ws = _median_runs(["adjust", str(p200), "--out", str(out)], src, 1)
            extra.update({f"{tag}wall_s": m, f"{tag}peak_rss_mib": rss})
        rows.append({"name": "cli12_adjust_200k_out", "median_s": extra["wall_s"],
                     "baseline": "sparse solve alone (row above)", "baseline_median_s": base,
                     "ratio": base / extra["wall_s"], "extra": extra})
    return rows


if __name__ == "__main__":
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    for r in run("--quick" in sys.argv):
        print(json.dumps(r, default=float))
