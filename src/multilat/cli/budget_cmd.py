"""``multilat budget``: Monte Carlo uncertainty of one measured distance (seed 000, section 3.4)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from multilat.cli import checks, report_opt
from multilat.cli.app import app, console, emit_json, progress
from multilat.errors import MultilatError

PAPER_UM = {"telemetric": 2.1, "head": 1.4, "target": 3.9, "combined": 4.7}


@app.command("budget")
def budget_command(
    instrument: str = typer.Option("seed2020", "--instrument", "-i",
                                   help="Preset name (seed2020) or path to an instrument TOML file."),
    head: str = typer.Option("A", "--head", help="Measurement head (A-D for seed2020)."),
    trials: Optional[int] = typer.Option(None, "--trials", "-n",
                                         help="Trials per distance (default from the instrument: 200000)."),
    seed: Optional[int] = typer.Option(None, "--seed", help="Random seed (default: fresh entropy, reported "
                                                            "in --json so the run can be repeated)."),
    air: Optional[bool] = typer.Option(None, "--air/--no-air",
                                       help="Include the air-index group in the combined error "
                                            "(default from the instrument; the seed excludes it)."),
    input_trials: Optional[int] = typer.Option(
        None, "--input-trials", help="Trials per distance of the per-input budget (each one-at-a-time run and "
                                     "each pick-freeze evaluation; default the smaller of --trials and 2000)."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of a table."),
    plot: Optional[str] = typer.Option(None, "--plot", help="Write the error histograms (Figs. 9-10) to this PNG."),
    report: Optional[Path] = typer.Option(None, "--report", help=report_opt.HELP),
) -> None:
    """Uncertainty of one distance measurement by Monte Carlo: telemetric, head and target groups
    (and optionally air), pooled over the instrument's budget distances (the budget table of its TOML;
    0.2 m to 20.2 m for seed2020, seed paper section 3.4)."""
    from multilat import budget as bmod
    from multilat.instrument import load_instrument

    checks.seed(seed)
    checks.trials(trials, lo=2)
    checks.trials(input_trials, "--input-trials", lo=16)
    report_opt.check_report_path(report, [instrument if str(instrument).endswith(".toml") else None])
    if plot is not None:
        from multilat.io import check_not_input

        check_not_input(plot, [instrument if str(instrument).endswith(".toml") else None], "--plot")
    inst = load_instrument(instrument)
    inst.head(head)
    if seed is None:          # fresh entropy, drawn here so that the seed reported reproduces the run
        import secrets        # (63 bits: JSON integers are exact to 64 bits in orjson and most readers)

        seed = secrets.randbits(63)
    n = inst.budget.trials_per_distance if trials is None else trials
    total = n * inst.budget.distances_m.size
    with progress(disable=total < 500_000) as bar:
        task = bar.add_task("Monte Carlo", total=total)
        res = bmod.distance_budget(inst, head=head, trials=n, rng=seed, include_air=air,
                                   keep_samples=plot is not None or report is not None,
                                   progress=lambda done, tot: bar.update(task, completed=done))
    from multilat.budget_inputs import input_budget

    n_in = max(16, min(n, 2000)) if input_trials is None else input_trials
    inputs = input_budget(inst, head=head, trials=n_in, rng=seed, include_air=air)
    if plot is not None:
        from multilat.io import atomic_path
        from multilat.report.distance_figures import plot_budget

        fig = plot_budget(res, paper_um=PAPER_UM if inst.name == "seed2020" else None)
        import matplotlib.pyplot as plt

        try:
            with atomic_path(plot) as tmp:
                fig.savefig(tmp, format="png", dpi=110)
        except OSError as exc:
            raise MultilatError(f"cannot write --plot {plot}: {exc.strerror or exc}") from None
        finally:
            plt.close(fig)
    if as_json or report is not None:
        d = res.to_dict()
        d["seed"] = seed
        d["plot"] = plot
        d["unit"] = "m"
        d["input_budget"] = inputs.to_dict()
        d["definition"] = ("standard uncertainty = sqrt(mean^2 + variance) of the error (uncorrected "
                           "biases count, seed section 3.4); coverage_95_m: probabilistically symmetric "
                           "interval of the combined error")
        report_opt.write_report(report, "budget", d, result=res)
        if as_json:
            emit_json(d, "budget")
            return
    t = Table(title=f"distance budget: {res.instrument}, head {res.head}, {res.trials:,} trials "
                    f"({res.distances_m.size} distances {res.distances_m[0]:g}-{res.distances_m[-1]:g} m), k = 1",
              title_justify="left")
    t.add_column("group")
    t.add_column("u (µm)", justify="right")
    t.add_column("mean (µm)", justify="right")
    t.add_column("std (µm)", justify="right")
    paper = inst.name == "seed2020"
    if paper:
        t.add_column("paper (µm)", justify="right")
    for g in ("telemetric", "head", "target", "air"):
        if g == "air" and not res.include_air and not inst.environment.u_temperature_c:
            continue
        label = g + ("" if g != "air" or res.include_air else " (not in total)")
        row = [label, f"{res.components[g] * 1e6:.2f}", f"{res.means[g] * 1e6:+.2f}", f"{res.stds[g] * 1e6:.2f}"]
        if paper:
            row.append(f"{PAPER_UM[g]:.1f}" if g in PAPER_UM else "-")
        t.add_row(*row)
    row = ["combined" + (" (incl. air)" if res.include_air else ""), f"{res.error_rms_m * 1e6:.2f}",
           f"{res.error_mean_m * 1e6:+.2f}", f"{res.error_std_m * 1e6:.2f}"]
    if paper:
        row.append("- (excl. air: 4.7)" if res.include_air else f"{PAPER_UM['combined']:.1f}")
    t.add_row(*row)
    console.print(t)
    _print_inputs(inputs, paper)
    lo, hi = res.coverage_95_m
    console.print(f"95 % coverage interval of the combined error: [{lo * 1e6:.2f}, {hi * 1e6:.2f}] µm")
    if plot is not None:
        console.print(f"figure written to {plot}")


def _print_inputs(ib, paper: bool) -> None:
    """The per-input table, largest share first, and the groups as sums of its rows."""
    from rich import box

    from multilat.budget_inputs import row_text

    t = Table(title=f"per input ({ib.trials_per_distance:,} trials per distance), largest first; µm, k = 1: "
                    "|c|u first order, MC this input alone; the squared shares of a group add up to its u²", title_justify="left",
              box=box.SIMPLE_HEAD, pad_edge=False)
    for c in ("input", "distribution", "c (µm/unit)", "|c|u", "MC", "share"):
        t.add_column(c, justify="left" if c in ("input", "distribution") else "right")
    for r in ib.ranked():
        x = row_text(r)
        t.add_row(x["short"], x["dist_short"], x["sens_short"], x["u_gum"], x["u_mc"], x["u_share"])
    console.print(t)
    parts = [f"{g} {v['error_rms_m'] * 1e6:.2f}" + (f" (paper {PAPER_UM[g]:.1f})" if paper else "")
             for g, v in ib.groups.items() if g != "air" or ib.include_air]
    console.print("rows summed (root of the sum of shares²): " + ", ".join(parts) + f", combined "
                  f"{ib.error_rms_m * 1e6:.2f}" + (f" (paper {PAPER_UM['combined']:.1f})" if paper and
                                                    not ib.include_air else "") + " µm", markup=False)
