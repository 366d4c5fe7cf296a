"""Issue 29, the growth row: whole ``multilat adjust NET.csv --json > /dev/null`` on 8 stations x
1 000, 4 000, 16 000 (and 200 000 in full mode) targets, 7 distances per target
(``synthetic_network`` "rings", 8 stations, 7 per target), medians of 3 (1 at 200 000), and the growth between successive
sizes (goal: each 4x step <= 5x). Before issue 29 the external reliability made one covariance product
per observation, O(m^2): 8 x 2 000 (14 000 distances) took 89 s at load 6 (37 s quiet), 2.9 s after.

Each row after the first has ``growth_vs_previous`` (its median over the previous size's) and, for a
4x step, ``growth_goal_met`` (growth <= ``GROWTH_LIMIT``); the 16 000 -> 200 000 step (12.5x) is
printed, not judged. With ``BENCH_BASELINE_SRC=/path/to/old/src`` each size also runs on that tree
(``extra["before_s"]``). ``python benchmarks/bench_adjust_growth.py [--quick]`` (quick: 1 000 and
4 000); ``benchmarks/goals29.py`` runs 1 000, 4 000 and 16 000 for issue 29's goals table.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


from bench_cli_large import BASE_SRC, ROOT, _median_runs, _write_csv
from common import load_avg as _load


def _write(t: int, path: Path) -> int:
    return _write_csv(t, path, stations=8, per_target=7)


#: issue 29's goal: each 4x step in targets costs at most this factor in whole-command wall time
GROWTH_LIMIT = 5.0


def run(quick: bool = False, sizes=None) -> list[dict]:
    sizes = sizes or ([1000, 4000] if quick else [1000, 4000, 16000, 200000])
    new = str(ROOT / "src")
    rows, prev = [], None
    with tempfile.TemporaryDirectory() as tmp:
        for t in sizes:
            p = Path(tmp) / f"net8x{t}.csv"
            m = _write(t, p)
            reps = 1 if t > 20000 else 3
            _median_runs(["adjust", str(p), "--json"], new, 1)                 # caches warm
            load = _load()
            med, rss, runs = _median_runs(["adjust", str(p), "--json"], new, reps)
            growth = None if prev is None else med / prev[1]
            extra = {"command": f"multilat adjust net8x{t}.csv --json > /dev/null", "distances": m,
                     "runs_s": [round(w, 3) for w in runs], "peak_rss_mib": rss, "load_avg": load,
                     "growth_vs_previous": None if growth is None else round(growth, 2),
                     "targets_ratio": None if prev is None else t / prev[0],
                     "growth_goal_met": (growth <= GROWTH_LIMIT) if prev is not None and t == 4 * prev[0] else None}
            if BASE_SRC and t <= 20000:
                extra["before_s"] = round(_median_runs(["adjust", str(p), "--json"], BASE_SRC, reps)[0], 3)
            rows.append({"name": f"adjust_growth_s8_t{t}_json", "median_s": med,
                         "baseline": None if prev is None else f"the same command at {prev[0]} targets",
                         "baseline_median_s": None if prev is None else prev[1],
                         "ratio": None if prev is None else prev[1] / med, "extra": extra})
            prev = (t, med)
    return rows


if __name__ == "__main__":
    import sys

    os.chdir(Path(__file__).resolve().parent)
    for r in run(quick="--quick" in sys.argv):
        e = r["extra"]
        step = "" if e["growth_vs_previous"] is None else (
            f"  x{e['growth_vs_previous']} for {e['targets_ratio']:g}x the targets"
            + ("" if e["growth_goal_met"] is None else
               f" (goal <= {GROWTH_LIMIT:g}x: {'met' if e['growth_goal_met'] else 'NOT met'})"))
        print(r["name"], f"{r['median_s']:.2f} s{step}", e)
