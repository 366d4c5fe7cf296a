"""Issue 26/29: the general network's sparse back end on distance-only networks of 8 stations x 1 000,
4 000, 16 000 targets (7 distances each, ``synthetic_network`` "rings"), beside the distance-only
path in the same run, and its growth between sizes (goal: each 4x step <= 5x).

Timed (one process, numba warm, medians of ``--repeats``):

* **general**: the whole general adjustment from the tables: ``network_from_tables`` (approximate
  coordinates given), ``adjust`` (``backend="auto"``: sparse at these sizes) and the statistics
  (``quality.statistics``: σ0, w-tests, MDBs, point ellipsoids);
* **distance**: ``multilat.network.adjust.distance.adjust.adjust`` (Schur on targets, its statistics), ``snooping=False``,
  from the same approximate coordinates.

Printed per size: both CPU times (and wall), their ratio, the growth over the previous size, the
load average.
``--command`` (issue 29's row): the **whole command** ``multilat adjust obs.csv --model general --json``
beside the distance path's ``multilat adjust obs.csv --json`` on the same CSV (written once per size),
each a fresh process: CPU time of the child (user + sys, ``getrusage``) and wall, the growth of each
over the previous size, the load average before each size (goal: each 4x step <= 5x).
The dense crossover (``SPARSE_ABOVE``) is measured with ``--crossover``: both back ends on 8 stations x
t targets for small t. ``python benchmarks/bench_general_sparse.py [--quick] [--command] [--crossover]``.
Results: ``benchmarks/bench_general_sparse.md``.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")      # one BLAS thread: CPU time is then the work, whatever the load

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import load_avg  # noqa: E402


def _networks(t: int, seed: int = 3):
    from multilat.network.model.data import Observations, Points
    from multilat.network.synthetic.generator import synthetic_network

    s = 8
    syn = synthetic_network(seed, population="rings", n_stations=s, n_targets=t, per_target=7)
    obs = Observations(tuple(f"S{i}" for i in range(s)), tuple(f"T{j}" for j in range(t)), syn.station_index,
                       syn.target_index, syn.distance_m, syn.sigma_m)
    pts = Points(obs.station_ids + obs.target_ids, np.vstack([syn.station_xyz_m, syn.target_xyz_m]))
    return syn, obs, pts


def _general(obs, pts, backend="auto"):
    from dataclasses import replace

    from multilat.network.adjust.general import quality
    from multilat.network.adjust.general.adjust import System, adjust
    from multilat.network.adjust.general.from_tables import network_from_tables

    net, opt = network_from_tables(obs, points=pts)
    res = adjust(net, options=replace(opt, backend=backend))
    quality.statistics(System(net), res)
    return res


def _distance(syn, obs):
    from multilat.network.adjust.distance.adjust import Start, adjust

    return adjust(obs, snooping=False, initial=Start(syn.station_xyz_m, syn.target_xyz_m, syn.offset_m))


def _median(fn, repeats):
    """Median CPU seconds of the process over ``repeats`` calls (and the median wall seconds): on
    this shared 2-core machine (load 8-14 during this session) wall times moved 20x between runs of
    the same call; with one BLAS thread the CPU time is the work."""
    cpu, wall = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    return float(np.median(cpu)), float(np.median(wall))


def run(quick: bool = False, repeats: int = 3) -> list[dict]:
    sizes = [1000, 4000] if quick else [1000, 4000, 16000]
    syn, obs, pts = _networks(200)
    _general(obs, pts), _distance(syn, obs)                     # warm: imports, numba
    rows, prev = [], None
    for t in sizes:
        syn, obs, pts = _networks(t)
        load = load_avg()
        g, gw = _median(lambda: _general(obs, pts), repeats)
        d, dw = _median(lambda: _distance(syn, obs), repeats)
        rows.append({"name": f"general_sparse_s8_t{t}", "median_s": g, "baseline": "distance-only adjust",
                     "baseline_median_s": d, "ratio": g / d,
                     "extra": {"rows": int(obs.distance_m.size), "load_avg": load, "wall_s": [round(gw, 3), round(dw, 3)],
                               "growth_vs_previous": None if prev is None else round(g / prev, 2)}})
        prev = g
    return rows


def _child(argv: list) -> tuple[float, float]:
    """(CPU s, wall s) of one command run to its end in a child process (output discarded)."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime), wall


def command(sizes=(1000, 4000, 16000), repeats: int = 1) -> list[dict]:
    """Issue 29's row: the whole ``multilat adjust obs.csv --model general --json`` beside the distance
    path's ``multilat adjust obs.csv --json``, same CSV, same run; medians of ``repeats``."""
    from multilat.network.io.files import write_observations

    cli = [sys.executable, "-c", "import sys; from multilat.cli import run; sys.exit(run())", "adjust"]
    rows, prev = [], None
    with tempfile.TemporaryDirectory() as tmp:
        for t in sizes:
            path = os.path.join(tmp, f"obs{t}.csv")
            write_observations(path, _networks(t)[1])
            load = load_avg()
            g = np.median([_child(cli + [path, "--model", "general", "--json"]) for _ in range(repeats)], axis=0)
            d = np.median([_child(cli + [path, "--json"]) for _ in range(repeats)], axis=0)
            rows.append({"name": f"general_command_s8_t{t}", "median_s": float(g[0]), "baseline": "distance-path command",
                         "baseline_median_s": float(d[0]), "ratio": float(g[0] / d[0]),
                         "extra": {"load_avg": load, "wall_s": [round(float(g[1]), 2), round(float(d[1]), 2)],
                                   "growth_vs_previous": None if prev is None else
                                   [round(float(g[0] / prev[0]), 2), round(float(d[0] / prev[1]), 2)]}})
            prev = (g[0], d[0])
    return rows


def crossover(sizes=(25, 50, 100, 200), repeats: int = 3) -> list[tuple]:
    """Dense and sparse back ends on the same networks (whole general adjustment)."""
    out = []
    for t in sizes:
        _, obs, pts = _networks(t)
        dn = _median(lambda: _general(obs, pts, "dense"), repeats)[0]
        sp = _median(lambda: _general(obs, pts, "sparse"), repeats)[0]
        out.append((t, 3 * (t + 8) + 8, dn, sp, load_avg()))
    return out


if __name__ == "__main__":
    if "--crossover" in sys.argv:
        for t, n, dn, sp, load in crossover():
            print(f"8 x {t:5d} targets ({n:5d} unknowns): dense {dn:7.3f} s CPU, sparse {sp:7.3f} s CPU, "
                  f"dense/sparse {dn / sp:5.2f}  (load {load})")
        sys.exit(0)
    if "--command" in sys.argv:
        for r in command((1000, 4000) if "--quick" in sys.argv else (1000, 4000, 16000)):
            e = r["extra"]
            print(f"{r['name']}: general command {r['median_s']:.2f} s CPU, distance command "
                  f"{r['baseline_median_s']:.2f} s CPU, ratio {r['ratio']:.2f}, growth (general, distance) "
                  f"{e['growth_vs_previous']}, wall {e['wall_s']}, load {e['load_avg']}")
        sys.exit(0)
    for r in run(quick="--quick" in sys.argv):
        e = r["extra"]
        print(f"{r['name']}: general {r['median_s']:.2f} s CPU, distance path {r['baseline_median_s']:.2f} s CPU, "
              f"ratio {r['ratio']:.2f}, growth {e['growth_vs_previous']}, rows {e['rows']}, wall {e['wall_s']}, "
              f"load {e['load_avg']}")
