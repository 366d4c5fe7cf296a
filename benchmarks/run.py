"""Run every benchmark: ``python benchmarks/run.py [--quick] [--only NAME ...]``.

Imports each ``benchmarks/bench_<area>.py``, calls its ``run(quick)`` (a list of dicts with
``name``, ``median_s``, ``baseline``, ``baseline_median_s``, ``ratio`` = baseline/ours, ``extra``),
prints one table with every figure beside its baseline, and writes ``benchmarks/results.json``
atomically. With ``--only``, the other areas' previous results in that file are kept.
A benchmark module that fails is reported (and makes the exit code 1) without stopping the others.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import importlib
import json
import os
import platform
import sys
import time
import traceback
from pathlib import Path

# Our dense systems are small (<= 240 x 120): OpenBLAS threads only cost time on a 2-core machine and
# leave spinning threads that steal the second core from numba kernels (BENCHMARKS.md, Notes). Set
# before numpy is imported by any benchmark module; an explicit setting by the user is kept.
for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
REQUIRED = ("name", "median_s", "baseline", "baseline_median_s", "ratio", "extra")


def machine_info() -> dict:
    import numpy as np

    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem_gib = None
    try:
        mem_gib = round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30, 1)
    except (ValueError, OSError, AttributeError):
        pass
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "memory_gib": mem_gib,
        "platform": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "load_avg_at_start": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    }


def discover(only: list[str] | None) -> list[str]:
    names = sorted(p.stem[len("bench_"):] for p in HERE.glob("bench_*.py"))
    if only:
        unknown = [o for o in only if o not in names]
        if unknown:
            raise SystemExit(f"error: unknown benchmark(s) {unknown}; known: {names}")
        names = [n for n in names if n in only]
    return names


def _fmt_s(v) -> str:
    if v is None:
        return "-"
    return f"{v * 1e3:.1f} ms" if v < 1 else f"{v:.2f} s"


def _fmt_extra(extra: dict) -> str:
    parts = []
    for k, v in (extra or {}).items():
        if isinstance(v, float):
            parts.append(f"{k}={v:.4g}")
        else:
            parts.append(f"{k}={v}")
    return ", ".join(parts)


def print_table(rows: list[tuple[str, dict]]) -> None:
    try:
        from rich.console import Console
        from rich.table import Table
    except ImportError:  # pragma: no cover
        for area, r in rows:
            print(area, r)
        return
    t = Table(title="multilat benchmarks (ratio = baseline / ours; > 1 means ours is faster)")
    for col in ("area", "benchmark", "ours (median)", "baseline", "baseline (median)", "ratio", "extra"):
        t.add_column(col, overflow="fold")
    for area, r in rows:
        ratio = "-" if r.get("ratio") is None else f"{r['ratio']:.2f}x"
        t.add_row(area, r["name"], _fmt_s(r.get("median_s")), str(r.get("baseline") or "-"),
                  _fmt_s(r.get("baseline_median_s")), ratio, _fmt_extra(r.get("extra")))
    Console(width=200).print(t)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller problems, fewer repeats")
    ap.add_argument("--only", nargs="+", metavar="NAME", help="run only bench_NAME.py (e.g. montecarlo)")
    ap.add_argument("--out", default=str(HERE / "results.json"), help="results file (JSON)")
    args = ap.parse_args(argv)

    sys.path.insert(0, str(HERE))  # bench modules importable by name (process pools re-import them)
    sys.path.insert(0, str(ROOT / "src"))
    from multilat.io import write_json_atomic

    names = discover(args.only)
    machine = machine_info()  # load average before anything runs
    out = Path(args.out)
    previous = {}
    if args.only and out.exists():
        try:
            previous = json.loads(out.read_text()).get("areas", {})
        except (OSError, ValueError):
            previous = {}
    areas = dict(previous)
    table, failed = [], []
    date = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    for name in names:
        t0 = time.perf_counter()
        print(f"running bench_{name} ({'quick' if args.quick else 'full'}) ...", file=sys.stderr, flush=True)
        try:
            mod = importlib.import_module(f"bench_{name}")
            results = list(mod.run(quick=args.quick))
            for r in results:
                missing = [k for k in REQUIRED if k not in r]
                if missing:
                    raise ValueError(f"result {r.get('name')!r} lacks keys {missing}")
        except Exception as exc:  # noqa: BLE001 - report and continue with the next area
            traceback.print_exc()
            failed.append(name)
            areas[name] = {"date": date, "quick": args.quick, "error": f"{type(exc).__name__}: {exc}"}
            continue
        areas[name] = {"date": date, "quick": args.quick, "wall_s": time.perf_counter() - t0, "results": results}
        table.extend((name, r) for r in results)
    print_table(table)
    write_json_atomic(out, {"date": date, "machine": machine, "areas": areas})
    print(f"wrote {out}", file=sys.stderr)
    if failed:
        print(f"error: benchmark(s) failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
