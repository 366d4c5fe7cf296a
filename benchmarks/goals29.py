"""Issue 29's goals measured, each beside its baseline in the same run:
``python benchmarks/goals29.py [--write] [--only KEY ...]`` (run it ``nice``: it is heavy).

Every row is one function below, keyed as in ``benchmarks/goals.json`` (section of issue 29); it
returns the measured value, the baseline measured right before or after it (interleaved where cheap),
the 1-minute load average when it started, and a note. ``--write`` stores them into goals.json
(numbers as measured, never typed), then ``python benchmarks/goals.py --write`` renders BENCHMARKS.md,
which computes the ratios and verdicts. A row that cannot run here (gama-local not installed) keeps
its ``why_not_measured``; ``make test`` is measured only on a quiet machine (``--only make_test``).

Rows (keys): small_adjust, adjust_20k, adjust_200k, adjust_200k_rss, adjust_200k_out, propagate_model,
propagate_gaussian, dask_scaling, first_command, make_test, growth_1k_4k / growth_4k_16k (one
measurement), gama (gama-local from $GAMA_LOCAL or PATH; ours only without it).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")          # as the CLI and run.py do

from bench_cli_large import ROOT, SEED, _env, _run, _write_csv  # noqa: E402
from common import load_avg  # noqa: E402

SRC = str(ROOT / "src")
SMALL = ROOT / "examples" / "network" / "small_volume_obs.csv"
DATA = HERE / "goals.json"
ISSUE = 29


def _wall(cmd, **env) -> float:
    """Wall time of a subprocess ``cmd`` (stdout discarded; fails loudly)."""
    t0 = time.perf_counter()
    p = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=_env(SRC, **env), timeout=3600)
    w = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))} failed: {p.stderr.decode()[-400:]}")
    return w


def _multilat(*args):
    return [sys.executable, "-c", "from multilat.cli import run; run()", *map(str, args)]


def _bytecode() -> str:
    """Write the tree's bytecode as ``make install``'s warm-up does (:func:`multilat.warmup.bytecode`):
    with ``PYTHONDONTWRITEBYTECODE`` set (as here) and no ``.pyc`` in the tree, every command would
    otherwise compile each of multilat's modules it imports, while numpy and scipy read pip's."""
    _wall([sys.executable, "-c", "from multilat import warmup; assert warmup.bytecode()"])
    return "bytecode written first, as make install's warm-up does"


def small_adjust(tmp: Path) -> dict:
    """Whole ``multilat adjust small_volume_obs.csv --json`` against ``python -c "import numpy,
    scipy.linalg"``, interleaved, medians of 7 (one warm-up each), after the warm-up's bytecode step."""
    base_cmd = [sys.executable, "-c", "import numpy, scipy.linalg"]
    ours_cmd = _multilat("adjust", SMALL, "--json")
    how = _bytecode()
    _wall(base_cmd), _wall(ours_cmd)
    load = load_avg()
    ours, base = [], []
    for _ in range(7):
        base.append(_wall(base_cmd))
        ours.append(_wall(ours_cmd))
    return dict(measured=statistics.median(ours), baseline_measured=statistics.median(base), load=load,
                note=f"medians of 7 interleaved (ours {min(ours):.3f}-{max(ours):.3f} s, baseline "
                     f"{min(base):.3f}-{max(base):.3f} s); {how}")


def _numpy_solve_alone(path: Path, stations: int, per_target: int, solver: str = "dense") -> float:
    """The first Gauss-Newton loop (``fit.gauss_newton``) of ``adjust(solver=...)`` from truth +
    N(0, 1 mm), in-process; the adjustment is stopped right after it (reading, statistics not timed)."""
    import warnings

    import numpy as np

    from multilat.network.adjust.distance import fit
    from multilat.network.adjust.distance.adjust import Start, adjust
    from multilat.network.io.files import read_observations
    from multilat.network.synthetic.generator import synthetic_network

    class _Done(Exception):
        pass

    obs = read_observations(path)
    t = obs.n_targets
    net = synthetic_network(SEED, population="rings", n_stations=stations, n_targets=t, per_target=per_target)
    rng = np.random.default_rng(SEED + 1)
    si = [int(x[1:]) for x in obs.station_ids]
    ti = np.array([int(x[1:]) for x in obs.target_ids])
    s = len(si)
    init = Start(net.station_xyz_m[si] + rng.normal(0, 1e-3, (s, 3)),
                 net.target_xyz_m[ti] + rng.normal(0, 1e-3, (t, 3)), net.offset_m[si] + rng.normal(0, 1e-3, s))
    spent, orig = [], fit.gauss_newton

    def timed(*a, **k):
        t0 = time.perf_counter()
        orig(*a, **k)
        spent.append(time.perf_counter() - t0)
        raise _Done

    fit.gauss_newton = timed
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            adjust(obs, initial=init, solver=solver, snooping=False)
    except _Done:
        pass
    finally:
        fit.gauss_newton = orig
    return spent[0]


def adjust_20k(tmp: Path) -> dict:
    """Whole ``multilat adjust`` 20 x 20 000 (160 000 distances) ``--json``, median of 3, against the
    numpy Schur-complement Gauss-Newton loop alone (``solver="dense"``) on the same file."""
    p = tmp / "net20x20000.csv"
    m = _write_csv(20_000, p)
    _run(["adjust", p, "--json"], SRC)
    load = load_avg()
    runs = [_run(["adjust", p, "--json"], SRC) for _ in range(3)]
    base = _numpy_solve_alone(p, 20, 8)
    return dict(measured=statistics.median(w for w, _ in runs), baseline_measured=base, load=load,
                note=f"{m} distances, median of 3 ({', '.join(f'{w:.2f}' for w, _ in runs)} s), peak RSS "
                     f"{max(r for _, r in runs):.0f} MiB; baseline once, in-process")


def adjust_200k(tmp: Path) -> list[dict]:
    """20 x 200 000 (1.6 M distances): ``--json`` (wall, peak RSS) and ``--out DIR`` once each, the
    numpy Schur solve alone once, reading the CSV with pyarrow.csv (the fastest reader here) once."""
    p = tmp / "net20x200000.csv"
    m = _write_csv(200_000, p)
    load = load_avg()
    w_json, rss = _run(["adjust", p, "--json"], SRC)
    load_out = load_avg()
    w_out, rss_out = _run(["adjust", p, "--out", tmp / "out200k"], SRC)
    load_base = load_avg()
    base = _numpy_solve_alone(p, 20, 8)
    read_s, reader = _fastest_read(p)
    mb = p.stat().st_size / 1e6
    return [dict(key="adjust_200k", measured=w_json, baseline_measured=base, load=load,
                 note=f"{m} distances, one run each (the baseline at load {load_base:.1f})"),
            dict(key="adjust_200k_rss", measured=rss * 2**20 / 1e6, baseline_measured=None, load=load,
                 note=f"peak RSS of the --json run ({rss:.0f} MiB, /usr/bin/time)"),
            dict(key="adjust_200k_out", measured=w_out, baseline_measured=read_s, load=load_out,
                 note=f"one run, peak RSS {rss_out:.0f} MiB; baseline {reader} of the {mb:.0f} MB CSV, "
                      "in-process")]


def _fastest_read(path: Path):
    """(seconds, name) of reading the CSV with pyarrow.csv when installed, else numpy's loadtxt."""
    try:
        import pyarrow.csv as pc
    except ImportError:
        import numpy as np

        t0 = time.perf_counter()
        np.loadtxt(path, delimiter=",", skiprows=1, usecols=(2, 3))
        return time.perf_counter() - t0, "numpy.loadtxt"
    pc.read_csv(path)                                             # file in the page cache, threads up
    t0 = time.perf_counter()
    pc.read_csv(path)
    return time.perf_counter() - t0, "pyarrow.csv.read_csv"


def _propagate_diff(noise_args) -> tuple[float, float, list]:
    """(trials/s without the start, load, walls): ``propagate small-volume`` at 20 000 and 220 000
    trials, interleaved, medians of 2; rate = 200 000 / (t(220 000) - t(20 000))."""
    cmd = lambda n: _multilat("propagate", "small-volume", "--trials", n, *noise_args, "--json")  # noqa: E731
    _wall(cmd(2000))
    load = load_avg()
    small, big = [], []
    for _ in range(2):
        small.append(_wall(cmd(20_000)))
        big.append(_wall(cmd(220_000)))
    dt = statistics.median(big) - statistics.median(small)
    return 200_000 / dt, load, (small, big)


def _walls(walls) -> str:
    small, big = walls
    return (f"walls at 20 000 trials {', '.join(f'{w:.2f}' for w in small)} s, at 220 000 "
            f"{', '.join(f'{w:.2f}' for w in big)} s")


def propagate_model(tmp: Path) -> dict:
    """Trials/s of the distance model's ``propagate`` without the start, against scipy
    ``least_squares(method="lm")`` per trial (100 trials, analytic Jacobian; bench_network)."""
    import numpy as np

    from bench_network import _scipy_lm_per_trial, _small_network

    rate, load, walls = _propagate_diff(())
    net = _small_network()
    d = net.nominal_distance_m() + np.random.default_rng(SEED).normal(0, 4.7e-6, (100, net.n_obs))
    _scipy_lm_per_trial(net, d[:5])
    t0 = time.perf_counter()
    _scipy_lm_per_trial(net, d)
    lm_rate = 100 / (time.perf_counter() - t0)
    return dict(measured=rate, baseline_measured=lm_rate, load=load,
                note=f"{_walls(walls)}; scipy lm {lm_rate:.0f} trials/s over 100 trials")


def propagate_gaussian(tmp: Path) -> dict:
    rate, load, walls = _propagate_diff(("--noise", "gaussian"))
    return dict(measured=rate, baseline_measured=None, load=load,
                note=_walls(walls))


def dask_scaling(tmp: Path) -> dict:
    """``propagate small-volume --trials 1000000 --workers 2`` against ``--workers 1``, once each."""
    cmd = lambda w: _multilat("propagate", "small-volume", "--trials", 1_000_000, "--workers", w, "--json")  # noqa: E731
    load = load_avg()
    t2 = _wall(cmd(2))
    t1 = _wall(cmd(1))
    return dict(measured=t2, baseline_measured=t1, load=load,
                note=f"one run each: 2 workers {t2:.1f} s, 1 worker {t1:.1f} s (load {load_avg():.1f} after)")


def first_command(tmp: Path) -> dict:
    """The first ``multilat adjust`` 20 x 20 000 ``--json`` after ``make install``'s warm-up against the
    same command run again: a fresh copy of the package (as a clone: no ``__pycache__``, so neither
    bytecode nor numba cache), a fresh ``NUMBA_CACHE_DIR``, ``python -m multilat.warmup``, then the
    command twice, without ``PYTHONDONTWRITEBYTECODE`` (a user's default)."""
    import shutil

    p = tmp / "net20x20000.csv"
    if not p.exists():
        _write_csv(20_000, p)
    fresh = tmp / "fresh_src"
    shutil.rmtree(fresh, ignore_errors=True)
    shutil.copytree(Path(SRC) / "multilat", fresh / "multilat", ignore=shutil.ignore_patterns("__pycache__"))
    cache = tmp / "numba_fresh"
    shutil.rmtree(cache, ignore_errors=True)
    cache.mkdir()
    env = {k: v for k, v in _env(str(fresh), NUMBA_CACHE_DIR=str(cache)).items() if k != "PYTHONDONTWRITEBYTECODE"}
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "multilat.warmup"], env=env, check=True, capture_output=True, timeout=3600)
    warm = time.perf_counter() - t0
    load = load_avg()
    cmd = _multilat("adjust", p, "--json")
    walls = []
    for _ in range(2):
        t0 = time.perf_counter()
        subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, timeout=3600)
        walls.append(time.perf_counter() - t0)
    return dict(measured=walls[0], baseline_measured=walls[1], load=load,
                note=f"a fresh copy of the package, warm-up {warm:.1f} s (bytecode and numba kernels); the "
                     "input read from disk by both (page cache not dropped)")


def growth(tmp: Path) -> list[dict]:
    """Whole ``adjust --json``, 8 stations x 1 000, 4 000, 16 000 targets (bench_adjust_growth)."""
    from bench_adjust_growth import run

    rows = run(sizes=[1000, 4000, 16000])
    out = []
    for a, b in zip(rows, rows[1:]):
        e = b["extra"]
        ta, tb = (int(r["name"].split("_t")[1].split("_")[0]) // 1000 for r in (a, b))
        out.append(dict(key=f"growth_{ta}k_{tb}k",
                        measured=b["median_s"], baseline_measured=a["median_s"], load=e["load_avg"],
                        note=f"medians of 3: {a['median_s']:.2f} s -> {b['median_s']:.2f} s "
                             f"({e['distances']} distances, peak RSS {e['peak_rss_mib']:.0f} MiB)"))
    return out


def _gama_local() -> str | None:
    """The gama-local executable: ``$GAMA_LOCAL``, else ``gama-local`` on PATH, else None."""
    import shutil

    exe = os.environ.get("GAMA_LOCAL") or shutil.which("gama-local")
    return exe if exe and os.access(exe, os.X_OK) else None


def gama(tmp: Path) -> dict:
    """Whole ``multilat adjust --json`` against whole ``gama-local`` on the same 4 000 distances
    (``synthetic_network`` "rings", 8 stations x 500 targets x 8 sights): the network exported by
    ``multilat export gama --result --fix S0,S1,S2`` (adjusted coordinates as approximate values, the
    stations' adjusted offsets subtracted, three stations fixed: gama-local 2.24's ``gso`` stops with "No
    unknowns have been defined" on the free network, whose every point is constrained), gama-local run with
    ``--algorithm gso --cov-band 2`` as in the issue (XML output). Ours median of 3, gama-local once (it takes minutes), interleaved after
    ours; both σ0 and dof are recorded (ours estimates 8 offsets more: dof differs by 8). gama-local from
    ``$GAMA_LOCAL`` or PATH; without it the row stays unjudged."""
    p = tmp / "net8x500.csv"
    m = _write_csv(500, p, stations=8, per_target=8)
    _run(["adjust", p, "--json"], SRC)
    load = load_avg()
    runs = [_run(["adjust", p, "--json"], SRC)[0] for _ in range(3)]
    exe = _gama_local()
    if exe is None:
        return dict(measured=statistics.median(runs), baseline_measured=None, load=load,
                    note=f"ours only, {m} distances, median of 3; gama-local not installed")
    res = tmp / "res8x500"
    _run(["adjust", p, "--out", res], SRC)
    gkf = tmp / "net8x500.gkf"
    _run(["export", "gama", p, "--result", res, "--fix", "S0,S1,S2", "--out", gkf], SRC)
    version = subprocess.run([exe, "--version"], capture_output=True, text=True).stdout.splitlines()[0]
    out = tmp / "gama8x500.xml"
    t0 = time.perf_counter()
    g = subprocess.run([exe, str(gkf), "--algorithm", "gso", "--cov-band", "2", "--xml", str(out)],
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, timeout=3600)
    wall = time.perf_counter() - t0
    if g.returncode != 0 or not out.exists():
        raise RuntimeError(f"gama-local failed: {g.stderr.decode()[-400:]}")
    from multilat.network.io.interop.gama_adjusted import read_gama_adjustment

    ga = read_gama_adjustment(out)
    s0, dof = ga.sigma_aposteriori / ga.sigma_apriori, ga.dof
    ours = json.loads(subprocess.run(_multilat("adjust", p, "--json"), capture_output=True, env=_env(SRC),
                                     check=True).stdout)
    return dict(measured=statistics.median(runs), baseline_measured=wall, load=load,
                note=f"{m} distances; ours median of 3 ({', '.join(f'{r:.2f}' for r in runs)} s), "
                     f"{version} once ({wall:.1f} s, --algorithm gso --cov-band 2); "
                     f"σ0 ours {ours['sigma0']:.4f} dof {ours['dof']}, gama-local {s0:.4f} dof {dof} "
                     f"(offsets held and S0, S1, S2 fixed there)")


def make_test(tmp: Path) -> dict:
    """``make test`` (two xdist workers), wall time; only on a quiet machine."""
    load = load_avg()
    t0 = time.perf_counter()
    subprocess.run(["make", "test"], cwd=ROOT, check=False, capture_output=True, timeout=3600)
    return dict(measured=time.perf_counter() - t0, baseline_measured=None, load=load, note="one run")


ROWS = {"small_adjust": small_adjust, "growth": growth, "adjust_20k": adjust_20k, "adjust_200k": adjust_200k,
        "propagate_model": propagate_model, "propagate_gaussian": propagate_gaussian,
        "dask_scaling": dask_scaling, "first_command": first_command, "gama": gama, "make_test": make_test}
DEFAULT = [k for k in ROWS if k != "make_test"]


def write(results: list[dict], path: Path = DATA) -> None:
    """Store the measured rows into goals.json's issue-29 section (by key), atomically."""
    data = json.loads(path.read_text(encoding="utf-8"))
    goals = {g["key"]: g for sec in data["sections"] if sec["issue"] == ISSUE for g in sec["goals"]}
    for r in results:
        g = goals[r["key"]]
        if r["baseline_measured"] is not None or g.get("ratio") is None:   # judged now
            g.pop("why_not_measured", None)
        g["measured"] = round(r["measured"], 4)
        g["baseline_measured"] = None if r["baseline_measured"] is None else round(r["baseline_measured"], 4)
        g["load"] = None if r["load"] is None else round(r["load"], 2)
        g["run"] = f"{r['date']}, goals29.py {r['row']}: {r['note']}"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    tmp.replace(path)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", choices=sorted(ROWS), help="these rows only")
    ap.add_argument("--write", action="store_true", help="store the results into benchmarks/goals.json")
    args = ap.parse_args(argv)
    sys.path.insert(0, SRC)
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.only or DEFAULT:
            date = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
            print(f"{date} {name} (load {load_avg():.1f}) ...", file=sys.stderr, flush=True)
            out = ROWS[name](Path(tmp))
            for r in out if isinstance(out, list) else [dict(out, key=name)]:
                r.update(date=date, row=name)
                print(json.dumps(r), flush=True)
                results.append(r)
            if args.write:                      # after each row: a later failure keeps the earlier ones
                write(results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
