"""Issue 26: can the general layer take over distance-only networks? The distance path's acceptance
study (``tests/test_minimum_search.py``, docs/network.md "The minimum search") run through both.

Population: ``synthetic_network(default_rng([2024, k]), population="field")`` (``multilat.network.synthetic.generator``: flat rings,
two-level rings, clustered and floor targets, 0-30 % unobserved pairs), the networks of the
distance path's 1000-network study. Each network is adjusted, without data snooping, by

* **distance**: ``multilat.network.adjust.distance.adjust.adjust(obs, snooping=False, rng=0)`` (what ``multilat
  adjust obs.csv`` runs: initial values, mirror sweep, the minimum search);
* **general**: ``network_from_tables(obs, rng=0)`` then ``adjust_network`` (what ``--model general``
  runs on the same CSV: no approximate coordinates given, the general chain places every point);
* **truth**: ``adjust(obs, initial=truth, snooping=False)``, the reference minimum.

Outcome of the general layer against the distance path: ``same`` (σ0 equal to ``SIGMA_REL``
relative and every point within ``XYZ_M`` after a rigid fit, no mirror), ``mirrored`` (σ0 equal, the
fit needs a reflection), ``worse`` / ``better`` (another σ0), ``refused`` (MultilatError, its
message), ``dist-refused`` (only the distance path refused); ``left out`` lists the points either
side excluded. Each outcome is also compared with the truth-start minimum.

``python benchmarks/study_general_acceptance.py [--networks N] [--first K] [--time]``; ``--time`` adds
8 x 2000 and 8 x 20000 distance-only networks timed whole from the observations (both paths, same
run, ratio, load average). Seeds: ``SeedSequence`` entropy 2024 spawn key k via ``default_rng([2024, k])``
(the distance study's networks, bit for bit).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from pathlib import Path

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import load_avg  # noqa: E402

#: σ0 equal to this relative difference: the same minimum (both solvers converge to ~1e-12)
SIGMA_REL = 1e-9
#: coordinates equal to this after a rigid fit (m): the same minimum (5 µm noise, networks of 2-20 m)
XYZ_M = 1e-6


def network(k: int):
    """Network ``k`` of the study (the distance path's acceptance population)."""
    from multilat.network.synthetic.generator import synthetic_network

    return synthetic_network(np.random.default_rng([2024, k]), population="field")


def _coords(ids, xyz, want):
    ix = {p: i for i, p in enumerate(ids)}
    return np.array([xyz[ix[p]] for p in want])


def _fit_gap(a, b, reflect: bool) -> float:
    """Largest point distance of ``a`` rigidly fitted onto ``b`` (m)."""
    from multilat.network.model.datum import apply_rigid, rigid_fit

    R, t = rigid_fit(a, b, allow_reflection=reflect)
    return float(np.linalg.norm(apply_rigid(R, t, a) - b, axis=1).max())


def _distance(obs, **kw):
    from multilat.errors import MultilatError
    from multilat.network.adjust.distance.adjust import adjust

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = adjust(obs, snooping=False, **kw)
    except MultilatError as e:
        return None, str(e)
    ids = r.obs.station_ids + r.obs.target_ids
    return {"sigma0": float(r.sigma0), "ids": ids, "xyz": np.vstack([r.station_xyz_m, r.target_xyz_m]),
            "out": tuple(sorted(e.id for e in r.excluded)),
            "warned": any("false minimum" in w for w in r.warnings)}, ""


def _general(obs):
    from multilat.errors import MultilatError
    from multilat.network.adjust.general import adjust_network
    from multilat.network.adjust.general.from_tables import network_from_tables
    from multilat.network.adjust.general.run import false_minimum_warning

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            net, opts = network_from_tables(obs, rng=0)
            adj = adjust_network(net, options=opts)
    except MultilatError as e:
        return None, str(e)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as e:   # not a one-line refusal: a defect
        return None, f"crashed: {type(e).__name__}: {e}"
    r = adj.result
    return {"sigma0": float(r.sigma0), "ids": tuple(r.ids), "xyz": np.asarray(r.xyz_m),
            "out": tuple(sorted(e["id"] for e in adj.excluded)), "reasons": {e["id"]: e["reason"] for e in adj.excluded},
            "warned": false_minimum_warning(adj) is not None}, ""


def compare(g, d) -> tuple[str, float, float]:
    """(outcome, σ0 relative difference, coordinate gap m) of solution ``g`` against ``d``."""
    rel = (g["sigma0"] - d["sigma0"]) / d["sigma0"]
    common = [p for p in d["ids"] if p in set(g["ids"])]
    a, b = _coords(g["ids"], g["xyz"], common), _coords(d["ids"], d["xyz"], common)
    gap, gap_m = _fit_gap(a, b, False), _fit_gap(a, b, True)
    if abs(rel) <= SIGMA_REL and gap <= XYZ_M:
        return "same", rel, gap
    if gap_m <= XYZ_M and gap > XYZ_M:
        return "mirrored", rel, gap_m
    if abs(rel) <= SIGMA_REL:
        return "same-sigma0-other-xyz", rel, gap
    return ("worse" if rel > 0 else "better"), rel, gap


def study_one(k: int) -> dict:
    """Every measured item of network ``k``."""
    net = network(k)
    t0 = time.process_time()
    d, d_err = _distance(net.obs, rng=0)
    t1 = time.process_time()
    g, g_err = _general(net.obs)
    t2 = time.process_time()
    ref, _ = _distance(net.obs, initial=net)
    row = {"k": k, "layout": f"{net.station_layout}/{net.target_layout}", "s": net.obs.n_stations,
           "t": net.obs.n_targets, "d_err": d_err, "g_err": g_err, "t_dist_s": t1 - t0, "t_gen_s": t2 - t1,
           "d_out": list(d["out"]) if d else None, "g_out": list(g["out"]) if g else None,
           "g_reasons": g["reasons"] if g else None, "d_warned": bool(d and d["warned"]),
           "g_warned": bool(g and g["warned"])}
    if g is None:
        row["outcome"] = "crashed" if g_err.startswith("crashed:") else "refused"
    elif d is None:
        row["outcome"] = "dist-refused"
    else:
        row["outcome"], row["rel"], row["gap_m"] = compare(g, d)
        row["rel"], row["gap_m"] = float(row["rel"]), float(row["gap_m"])
    for who, sol in (("g", g), ("d", d)):            # each against the truth-start minimum
        row[f"{who}_vs_truth"] = compare(sol, ref)[0] if sol is not None and ref is not None else None
    return row


def summarise(rows) -> str:
    from collections import Counter

    n = len(rows)
    out = [f"{n} networks (k = {rows[0]['k']}..{rows[-1]['k']}), load {load_avg():.2f}", "",
           "| general vs distance path | networks | examples (k) |", "|---|---|---|"]
    c = Counter(r["outcome"] for r in rows)
    for o, m in sorted(c.items(), key=lambda x: -x[1]):
        ex = [r["k"] for r in rows if r["outcome"] == o][:6]
        out.append(f"| {o} | {m} ({100 * m / n:.1f} %) | {', '.join(map(str, ex))} |")
    out += ["", "| vs truth-start minimum | distance path | general |", "|---|---|---|"]
    cd, cg = Counter(r["d_vs_truth"] for r in rows), Counter(r["g_vs_truth"] for r in rows)
    for o in sorted(set(cd) | set(cg), key=str):
        out.append(f"| {o} | {cd.get(o, 0)} | {cg.get(o, 0)} |")
    diff_out = [r for r in rows if r["d_out"] is not None and r["g_out"] is not None and r["d_out"] != r["g_out"]]
    out += ["", f"left out: distance path {sum(bool(r['d_out']) for r in rows if r['d_out'] is not None)} "
            f"networks, general {sum(bool(r['g_out']) for r in rows if r['g_out'] is not None)}; "
            f"different sets in {len(diff_out)}"]
    for r in diff_out[:5]:
        out.append(f"  k={r['k']}: distance {r['d_out']}, general {r['g_reasons']}")
    out.append(f"warned 'possible false minimum': distance path {sum(r['d_warned'] for r in rows)}, general "
               f"{sum(bool(r.get('g_warned')) for r in rows)} (of {sum('g_warned' in r for r in rows)} rows that record it)")
    for r in rows:
        if r["outcome"] != "same":
            extra = (f"rel {r['rel']:+.2e} gap {r['gap_m']:.2e} m" if "rel" in r
                     else (r["g_err"] or r["d_err"])[:160])
            out.append(f"  k={r['k']} {r['layout']} s={r['s']} t={r['t']}: {r['outcome']} "
                       f"(truth: dist {r['d_vs_truth']}, gen {r['g_vs_truth']}) {extra}")
    td, tg = sum(r["t_dist_s"] for r in rows), sum(r["t_gen_s"] for r in rows)
    out.append(f"CPU: distance path {td:.1f} s, general {tg:.1f} s (ratio {tg / td:.2f})")
    return "\n".join(out)


def _large(t: int, seed: int = 3):
    from multilat.network.model.data import Observations
    from multilat.network.synthetic.generator import synthetic_network    # large.synthetic_network(8, t, 7), bit for bit

    syn = synthetic_network(seed, population="rings", n_stations=8, n_targets=t, per_target=7)
    return Observations(tuple(f"S{i}" for i in range(8)), tuple(f"T{j}" for j in range(t)), syn.station_index,
                        syn.target_index, syn.distance_m, syn.sigma_m)


def timing(sizes=(2000, 20000), repeats: int = 3) -> str:
    """Both paths whole from the observations (approximate values, adjustment; no snooping): median
    CPU and wall s of ``repeats`` runs, alternating, after one warm-up of each on 8 x 200."""
    warm = _large(200)
    _distance(warm, rng=0), _general(warm)
    lines = ["| network | distance CPU / wall s | general CPU / wall s | ratio CPU / wall | σ0 rel diff | load |",
             "|---|---|---|---|---|---|"]
    for t in sizes:
        obs = _large(t)
        tm = {"d": [], "g": []}
        for _ in range(repeats):
            for who, fn in (("d", lambda: _distance(obs, rng=0)), ("g", lambda: _general(obs))):
                c0, w0 = time.process_time(), time.perf_counter()
                sol, err = fn()
                tm[who].append((time.process_time() - c0, time.perf_counter() - w0, sol, err))
        (dc, dw), (gc, gw) = ([float(np.median([x[i] for x in tm[w]])) for i in (0, 1)] for w in "dg")
        d, g = tm["d"][0][2], tm["g"][0][2]
        rel = (f"{(g['sigma0'] - d['sigma0']) / d['sigma0']:+.1e}" if d and g
               else f"refused: {tm['d'][0][3] or tm['g'][0][3]}"[:80])
        lines.append(f"| 8 x {t} | {dc:.2f} / {dw:.2f} | {gc:.2f} / {gw:.2f} | {gc / dc:.2f} / {gw / dw:.2f} "
                     f"| {rel} | {load_avg():.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--networks", type=int, default=200)
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--time", action="store_true", help="also the 8 x 2000 / 8 x 20000 timing")
    ap.add_argument("--jsonl", help="append each network's row to this file as it is done")
    ap.add_argument("--summarise", help="only print the table of the rows in this JSON-lines file")
    a = ap.parse_args(argv)
    if a.summarise:
        rows = [json.loads(line) for line in Path(a.summarise).read_text().splitlines() if line.strip()]
        print(summarise(sorted(rows, key=lambda r: r["k"])))
        return 0
    rows = []
    for k in range(a.first, a.first + a.networks):
        rows.append(study_one(k))
        r = rows[-1]
        print(f"{k} {r['outcome']} dist {r['t_dist_s']:.1f} s general {r['t_gen_s']:.1f} s", file=sys.stderr, flush=True)
        if a.jsonl:
            with open(a.jsonl, "a") as f:
                f.write(json.dumps(r) + "\n")
    if rows:
        print(summarise(rows))
    if a.time:
        print()
        print(timing())
    return 0


if __name__ == "__main__":
    sys.exit(main())
