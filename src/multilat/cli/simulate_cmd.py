"""``multilat simulate``: the algorithm's own uncertainty by simulation (seed 000 §4.4)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.table import Table

from multilat.cli import checks, report_opt
from multilat.cli.app import app, console, emit_json, progress
from multilat.errors import MultilatError


@app.command("simulate")
def simulate_cmd(
    source: str = typer.Argument(..., help="small-volume, large-volume, or a configuration file "
                                 "(.toml or .csv of stations and targets; see docs/network-simulation.md)."),
    trials: int = typer.Option(50, "--trials", help="Number of simulations (the paper: 50)."),
    noise: str = typer.Option("gaussian", "--noise", help="gaussian (sigma, as the paper) or model "
                              "(each error drawn from the distance model, non-gaussian)."),
    sigma_um: Optional[float] = typer.Option(None, "--sigma-um",
                                             help="Gaussian standard deviation in um (default 4.7, the paper's)."),
    instrument: Optional[str] = typer.Option(None, "--instrument",
                                             help="Instrument preset or TOML (--noise model; default seed2020)."),
    cost: str = typer.Option("distance", "--cost", help="distance (weighted) or squared (the paper's eq. 6)."),
    start: str = typer.Option("distances", "--start", help="distances (initial values from the distances "
                              "alone) or truth."),
    seed: int = typer.Option(2020, "--seed", help="Root seed (each simulation gets a SeedSequence child)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
    report: Optional[Path] = typer.Option(None, "--report", help=report_opt.HELP),
) -> None:
    """Simulate distances of a configuration (truth + offsets + noise), adjust them, and report the
    standard deviation of the interpoint-distance errors per simulation: min/mean/max beside the paper."""
    from multilat.network.montecarlo.simulate import NOISES, load_config, simulate

    if noise not in NOISES:
        raise MultilatError(f"--noise must be one of {', '.join(NOISES)}, got {noise!r}")
    checks.sigma_um(sigma_um)
    from multilat.network.model import sigma_source as ss

    given_sigma = sigma_um is not None
    sigma_um = ss.DEFAULT_SIGMA_M * 1e6 if sigma_um is None else sigma_um
    inst_name = instrument or "seed2020"
    checks.count(trials, "--trials", hi=10**6)   # each trial is a whole adjustment
    checks.seed(seed)
    report_opt.check_report_path(report, [source])
    from multilat.instrument import load_instrument

    load_instrument(inst_name)          # a bad --instrument is an error even when --noise ignores it
    if cost not in ("distance", "squared"):
        raise MultilatError(f"--cost must be distance or squared, got {cost!r}")
    if start not in ("distances", "truth"):
        raise MultilatError(f"--start must be distances or truth, got {start!r}")
    cfg = load_config(source)
    with progress() as bar:
        task = bar.add_task(f"simulate {cfg.name}", total=trials)
        res = simulate(cfg, trials=trials, noise=noise, sigma_m=sigma_um * 1e-6, instrument=inst_name,
                       rng=seed, cost=cost, initial=start, callback=lambda n: bar.advance(task, n))
    s = res.summary()
    if noise == "model":
        src = ss.distance_model(res.station_ids, inst_name)
        src["defaulted"] = instrument is None
    else:
        src = ss.option(sigma_um * 1e-6, "--sigma-um" if given_sigma else "default 4.7 µm (the paper's σ)")
    paper = res.paper
    doc = {
        "config": res.config, "trials": res.trials, "converged": int(len(res.interpoint_std_m)),
        "n_failed": res.n_failed, "noise": res.noise,
        "sigma_m": None if noise == "model" else res.sigma_m, "cost": cost, "start": start, "seed": seed,
        "pairs": [list(p) for p in res.pairs],
        "interpoint_std_m": {k: s[k] for k in ("min", "mean", "max")},
        "interpoint_std_se_m": s["sem"], "interpoint_std_rms_m": s["rms"],
        "interpoint_std_lin_rms_m": res.predicted_rms_std_m,
        "paper_m": None if paper is None else {"min": paper.min_m, "mean": paper.mean_m,
                                               "max": paper.max_m, "trials": paper.trials},
        "pair_error_rms_m": {f"{a}-{b}": float(v) for (a, b), v in
                             zip(res.pairs, np.sqrt(np.mean(res.errors_m ** 2, axis=0)))},
        "offset_error_rms_m": dict(zip(res.station_ids,
                                       np.sqrt(np.mean(res.offset_error_m ** 2, axis=0)).tolist())),
        "sigma0_mean": float(np.mean(res.sigma0)),
        "sigma_source": src,
        "per_simulation_std_m": res.interpoint_std_m,
    }
    report_opt.write_report(report, "simulate", doc, result=res)
    if as_json:
        emit_json(doc, "simulate")
        return
    console.print(f"Simulation of the self-calibrating adjustment ({res.config}): "
                  f"{doc['converged']} of {res.trials} simulations converged, noise={noise}"
                  + (f" {sigma_um:g} um" if noise == "gaussian" else " (distance model)")
                  + f", cost={cost}, {len(res.pairs)} interpoint pairs, mean sigma0={doc['sigma0_mean']:.2f}")
    console.print(ss.describe(src) + " (the errors drawn and the weights)", markup=False)
    t = Table(title="Std of the interpoint-distance errors per simulation (um)")
    for c in ("", "min", "mean", "max", "+-se(mean)"):
        t.add_column(c, justify="right")
    t.add_row("multilat", f"{s['min'] * 1e6:.1f}", f"{s['mean'] * 1e6:.1f}", f"{s['max'] * 1e6:.1f}",
              f"{s['sem'] * 1e6:.2f}")
    if paper is not None:
        t.add_row(f"paper ({paper.trials} sims)", f"{paper.min_m * 1e6:.1f}", f"{paper.mean_m * 1e6:.1f}",
                  f"{paper.max_m * 1e6:.1f}", "")
    console.print(t)
    console.print(f"first-order prediction of the rms per-simulation std: {res.predicted_rms_std_m * 1e6:.2f} um "
                  f"(Monte Carlo rms: {s['rms'] * 1e6:.2f} um)")

