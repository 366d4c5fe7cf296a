"""Where a Dask run of ``propagate small-volume`` spends its time: wall and CPU per phase, 1 and 2 workers.

Each run is a fresh process doing what ``multilat propagate small-volume --workers N`` does (gaussian
noise, chunks of 10 000 trials, the map of ``multilat.parallel.map_from_options(single_run=True)``):
``prep`` (imports, the problem), ``start`` (import of Dask, the cluster), ``work`` (the map: first
chunk submitted to last result received), ``summarise`` (the driver's statistics), ``close`` (what the
context's exit still waits for; the close itself starts when the last result is in) and ``total``.
CPU is the process's (worker threads included) and, with worker processes, ``children_cpu`` theirs.
Runs are interleaved (threads 1, 2, processes 1, 2, again); every row records the load average.

On this shared machine the kernel's autogroup gives each session an equal share of the cores, so at
load a run of 2 workers gets no more CPU than a run of 1: compare walls only on a quiet machine, and
the CPU per phase at any load.

    python benchmarks/bench_dask_phases.py --trials 1000000 --repeats 2 [--modes threads,processes]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

SRC = str(Path(__file__).resolve().parent.parent / "src")


def one(workers: int, trials: int, mode: str) -> dict:
    """One run in this process; the phases as ``name -> [wall s, CPU s]``."""
    t00, c00 = time.perf_counter(), time.process_time()
    import multilat.cli  # noqa: F401  (one BLAS thread, as the CLI)
    from multilat.cli.propagate_cmd import keep_freed_memory
    from multilat.network.montecarlo import propagate as pr
    from multilat.network.synthetic import configs
    from multilat.parallel import map_from_options

    keep_freed_memory()
    problem = pr.problem_from_config(configs.small_volume(), sigma_m=4.7e-6, source="small-volume")
    ph: dict = {}
    clock = [t00, c00]

    def mark(name):
        t, c = time.perf_counter(), time.process_time()
        ph[name] = [round(t - clock[0], 3), round(c - clock[1], 3)]
        clock[:] = t, c

    mark("prep")
    cm = map_from_options(workers=workers, processes=mode == "processes", single_run=True)
    m = cm.__enter__()
    mark("start")
    summarise = pr.summarise

    def timed(*args, **kw):
        mark("work")
        r = summarise(*args, **kw)
        mark("summarise")
        return r

    pr.summarise = timed
    pr.propagate(problem, trials=trials, rng=1, noise="gaussian", chunk_size=10_000, map=m, keep_samples=False)
    cm.__exit__(None, None, None)
    mark("close")
    ph["total"] = [round(time.perf_counter() - t00, 3), round(time.process_time() - c00, 3)]
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return dict(mode=mode, workers=workers, trials=trials, load=round(os.getloadavg()[0], 2),
                children_cpu=round(ru.ru_utime + ru.ru_stime, 3), **ph)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--modes", default="threads,processes")
    ap.add_argument("--one", nargs=2, metavar=("WORKERS", "MODE"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.one:
        print(json.dumps(one(int(a.one[0]), a.trials, a.one[1])))
        return 0
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    rows = []
    for _ in range(a.repeats):
        for mode in a.modes.split(","):
            for w in (1, 2):
                p = subprocess.run([sys.executable, __file__, "--trials", str(a.trials), "--one", str(w), mode],
                                   env=env, capture_output=True, text=True, timeout=3600, check=True)
                rows.append(json.loads(p.stdout.strip().splitlines()[-1]))
                print(json.dumps(rows[-1]), flush=True)
    for mode in a.modes.split(","):
        med = {w: statistics.median(r["total"][0] for r in rows if r["mode"] == mode and r["workers"] == w)
               for w in (1, 2)}
        print(f"{mode}: median total wall 1 worker {med[1]:.2f} s, 2 workers {med[2]:.2f} s, "
              f"ratio {med[1] / med[2]:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
