"""``multilat propagate``: full Monte Carlo of a network's uncertainty through the adjustment."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.table import Table

from multilat.cli import checks, report_opt
from multilat.cli.app import app, console, emit_json, progress
from multilat.errors import MultilatError
from multilat.network.adjust.distance.azimuth_sense import HELP as AZIMUTH_SENSE_HELP

BUILTIN = ("small-volume", "large-volume")


def load_problem(source: str, opts, *, noise: str | None, instrument: str | None, sigma_um: float | None,
                 references: Path | None, environment: Path | None = None, heights: Path | None = None,
                 formula: str = "ciddor", extrapolate: bool = False, max_gap_s: float | None = None,
                 average_repeats: bool = False, sigma_source: dict | None = None,
                 points: Path | None = None, fix_offsets_um: str | None = None, pairs: str | None = None):
    """``(problem, noise)``: the propagation problem for ``source`` — a built-in configuration name, or
    what ``adjust`` reads (an observations CSV, or raw readings with their environment log; repeated
    readings kept or averaged), :func:`multilat.campaign.propagation.campaign_problem` — with the network
    model ``opts`` (:class:`~multilat.network.adjust.distance.options.NetworkOptions`, as ``adjust`` takes it), and the
    noise drawn (:func:`multilat.network.montecarlo.propagate.noise_choice`: the distance model only with an
    instrument named; otherwise gaussian with the σ the file gives). A file whose σ would come from an
    instrument nobody named (no ``sigma_m`` column, no ``--sigma-um``; raw readings) is refused in one
    line naming the options. ``sigma_source`` (a dict) is filled with where the weights' σ came from."""
    from multilat import instrument as _inst
    from multilat.network.montecarlo import propagate as pr
    from multilat.network.model import sigma_source as ss

    src = {} if sigma_source is None else sigma_source
    noise, _ = pr.noise_choice(noise, instrument, cli=True)
    inst = None if instrument is None else _inst.load_instrument(instrument)
    pair_list = None if pairs is None else pr.parse_pairs(pairs)
    if source in BUILTIN:
        used = [o for o, v in (("--environment", environment), ("--heights", heights), ("--extrapolate", extrapolate),
                               ("--max-gap-s", max_gap_s), ("--average-repeats", average_repeats),
                               ("--points", points), ("--fix-offsets-um", fix_offsets_um)) if v]
        used += [opts.name(f) for f in opts.non_default() if f not in ("datum", "instrument", "sigma_m")]
        if used:
            raise MultilatError(f"{used[0]}: the model and file options apply to a campaign file, not to the "
                                f"built-in {source!r}")
        try:
            from multilat.network.synthetic import configs
        except ImportError:
            raise MultilatError("built-in configurations are not available (multilat.network.synthetic.configs)") from None
        cfg = configs.small_volume() if source == "small-volume" else configs.large_volume()
        sigma = None if noise == "model" else (sigma_um * 1e-6 if sigma_um else ss.DEFAULT_SIGMA_M)
        src.update(ss.distance_model(cfg.station_ids, inst) if sigma is None else
                   ss.option(sigma, "--sigma-um" if sigma_um else "default 4.7 µm (the paper's σ)"))
        return pr.problem_from_config(cfg, sigma_m=sigma, instrument=inst, datum=opts.datum, source=source,
                                      pairs=pair_list, pairs_option="--pairs"), noise
    from multilat.campaign.propagation import campaign_problem
    from multilat.campaign.raw import is_raw_file
    from multilat.cli.network_cmd import with_fixed_offsets
    from multilat.network.io.files import read_points, read_reference_lengths

    if not Path(source).exists():
        raise MultilatError(f"{source}: no such file (and not a built-in: {', '.join(BUILTIN)})")
    # a file that does not read whole is named by the reader (FILE:LINE) before the σ is asked for
    if (inst is None and sigma_um is None and not is_raw_file(source) and "sigma_m" not in (_header(source) or ())
            and _reads_whole(source)):
        raise MultilatError(f"{source}: no sigma_m column: give --sigma-um, or --instrument for the σ of its distance "
                            "model (a Monte Carlo never draws from an instrument nobody named)")
    refs = read_reference_lengths(references) if references is not None else None
    opts = with_fixed_offsets(opts, fix_offsets_um, None)      # head ids checked by the adjustment
    problem, _ = campaign_problem(source, opts, references=refs, instrument=inst,
                                  sigma_m=None if sigma_um is None else sigma_um * 1e-6,
                                  environment=environment, heights=heights, formula=formula,
                                  extrapolate=extrapolate, max_gap_s=max_gap_s, average=average_repeats,
                                  sigma_source=src, points=read_points(points) if points is not None else None,
                                  pairs=pair_list, pairs_option="--pairs")
    if inst is None and src.get("kind") == "raw readings":    # after the reader's own checks of the file
        raise MultilatError(f"{source}: raw readings are corrected and weighted by an instrument's distance model: "
                            "name it with --instrument (e.g. seed2020)")
    if src.get("kind") == "distance model" and src.get("defaulted"):
        raise MultilatError(f"{source}: no sigma_m column: give --sigma-um, or --instrument for the σ of its distance "
                            "model (a Monte Carlo never draws from an instrument nobody named)")
    return problem, noise


def _header(path) -> list[str] | None:
    """The column names of a CSV file (its first line that is not a ``#`` comment, read alone); None
    when unreadable (the reader then names the fault)."""
    import csv

    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            for row in csv.reader(fh):
                if row and not row[0].lstrip().startswith("#"):
                    return [c.strip() for c in row]
    except (OSError, UnicodeDecodeError, csv.Error):
        return None
    return []


def _reads_whole(path) -> bool:
    """Whether the file decodes as UTF-8 to its end (read in 1 MiB pieces; only on the refusal's path)."""
    try:
        with open(path, encoding="utf-8-sig") as fh:
            while fh.read(1 << 20):
                pass
    except (OSError, UnicodeDecodeError):
        return False
    return True


def keep_freed_memory() -> None:
    """Let the C library's allocator keep freed memory for reuse (glibc ``mallopt``; this process only).

    Every block of trials allocates and frees a few MB of arrays. With glibc's defaults (arrays above
    128 kB mapped and unmapped one by one until its adaptive threshold catches up, the heap trimmed
    whenever a few hundred kB are free) each block writes to fresh pages: ~80 000 page faults, ~0.2 s
    of a 200 000-trial run. Mapping only above 32 MB and trimming only above 256 MB free keeps those
    pages for the next block. Only the time changes, never a number; nothing happens where the C
    library has no ``mallopt`` (macOS, Windows).
    """
    try:
        import ctypes

        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError, TypeError):
        return
    mallopt(-3, 32 << 20)     # M_MMAP_THRESHOLD
    mallopt(-1, 256 << 20)    # M_TRIM_THRESHOLD


@app.command("propagate")
def propagate_cmd(
    source: str = typer.Argument(..., help="What `adjust` reads (observations CSV, or raw readings with "
                                           "--environment), or small-volume / large-volume."),
    trials: int = typer.Option(100_000, "--trials", help="Monte Carlo trials (fixed-size run)."),
    adaptive: bool = typer.Option(False, "--adaptive", help="JCGM 101 7.9 adaptive number of trials."),
    seed: int = typer.Option(1, "--seed",
                             help="Root seed (fixed blocks of 1000 trials get SeedSequence spawn children)."),
    instrument: Optional[str] = typer.Option(None, "--instrument",
                                             help="Instrument preset or TOML file: its distance model gives the "
                                                  "errors drawn (--noise model, the default with it) and the σ a "
                                                  "file without sigma_m lacks. Default: none (errors gaussian "
                                                  "with the file's σ)."),
    azimuth_sense: Optional[str] = typer.Option(None, "--azimuth-sense", help=AZIMUTH_SENSE_HELP),
    noise: Optional[str] = typer.Option(None, "--noise",
                                        help="model (the --instrument's distance model, non-gaussian) or "
                                             "gaussian (the weights' σ). Default: model with --instrument, "
                                             "else gaussian."),
    sigma_um: Optional[float] = typer.Option(None, "--sigma-um",
                                             help="σ of every distance in µm, for a file without sigma_m "
                                                  "(built-ins: default 4.7, the paper's)."),
    datum: str = typer.Option("free", "--datum", help="free[:P,..], 321:A,B,C or control[:P,..] (--points; "
                                                      "the same in every trial)."),
    references: Optional[Path] = typer.Option(None, "--references", help="Reference lengths CSV."),
    scale_bars: bool = typer.Option(False, "--scale-bars", "--scale-bar",
                                    help="The --references are scale bars: observations weighted by their "
                                         "u_m, drawn from it in every trial (with --scales: the scale datum)."),
    scales: bool = typer.Option(False, "--scales", help="Estimate a scale per head (needs --scale-bars or "
                                "--fixed-scale)."),
    fixed_scale: Optional[str] = typer.Option(None, "--fixed-scale",
                                              help="With --scales: hold this head's scale (as in `adjust`)."),
    fix_offsets_um: Optional[str] = typer.Option(None, "--fix-offsets-um",
                                                 help="Hold head offsets fixed, µm: one value for every head, or "
                                                      "A=1234,B=-871 (as in `adjust`); held in every trial."),
    distance_only: Optional[str] = typer.Option(None, "--distance-only",
                                                help="Stations that read no angles, ID,ID,... (as in `adjust`)."),
    strict: bool = typer.Option(False, "--strict", help="Refuse a weakly observed point instead of leaving "
                                "it out (as in `adjust`; a propagation refuses a network with points left out)."),
    pairs: Optional[str] = typer.Option(None, "--pairs",
                                        help="Interpoint distances to report: P1-P2,P3-P4,... or a CSV file "
                                             "point_a,point_b. Default: the --references pairs, else every "
                                             "target pair (up to 20 targets), else consecutive targets."),
    levelled: Optional[str] = typer.Option(None, "--levelled", help="Stations on their level (κ only; their "
                                           "angles observe the vertical), ID,ID,... as in `adjust`."),
    points: Optional[Path] = typer.Option(None, "--points",
                                          help="Points CSV: point,x_m,y_m,z_m[,sx_m,sy_m,sz_m]: approximate, or "
                                               "control under --datum control (weighted rows drawn in every "
                                               "trial, the others held)."),
    environment: Optional[Path] = typer.Option(None, "--environment", "-e",
                                               help="Raw readings only: environment log CSV; each trial "
                                                    "draws every sensor's error once (as `adjust RAW`)."),
    heights: Optional[Path] = typer.Option(None, "--heights", help="Raw readings only: heights file."),
    formula: str = typer.Option("ciddor", "--formula", help="Raw readings only: ciddor or edlen."),
    extrapolate: bool = typer.Option(False, "--extrapolate",
                                     help="Raw readings only: extrapolate the environment (warned)."),
    max_gap_s: Optional[float] = typer.Option(None, "--max-gap-s",
                                              help="Raw readings only: longest sensor-log gap bridged, s."),
    average_repeats: bool = typer.Option(False, "--average-repeats",
                                         help="Average repeated readings of a pair (weighted means; the "
                                              "scatter per pair reported) instead of keeping them."),
    chunk_size: int = typer.Option(10_000, "--chunk-size",
                                   help="Trials per unit of parallel work (whole blocks; no effect on the numbers)."),
    workers: Optional[int] = typer.Option(None, "--workers", help="Start a local Dask cluster of N workers."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Address of an existing Dask scheduler."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Directory for CSVs, JSON and the figure."),
    cloud_points: Optional[str] = typer.Option(None, "--cloud-points",
                                               help="Points whose Monte Carlo clouds clouds.png (and the "
                                                    "report) show, ID,ID,... (default: the stations and "
                                                    "the targets with the largest ellipsoids)."),
    report: Optional[Path] = typer.Option(None, "--report", help=report_opt.HELP),
    model: str = typer.Option("multilateration", "--model", help="multilateration (distance path) or general "
                              "(the general network layer; a gama-local XML input always)."),
) -> None:
    """Monte Carlo (JCGM 101/102) of stations, offsets, targets and interpoint distances."""
    from multilat.cli import general_adjust, general_propagate
    if general_adjust.wants_general(source, model):     # --model general, or a gama-local XML input
        return general_propagate.run(**locals())
    from multilat.network.montecarlo.propagate import propagate
    from multilat.parallel import map_from_options

    checks.sigma_um(sigma_um)
    checks.seed(seed)
    checks.trials(trials, lo=2)
    report_opt.check_report_path(report, [source, references, environment, heights, points])
    checks.count(chunk_size, "--chunk-size", hi=10**8)
    checks.count(workers, "--workers", hi=4096)
    if scheduler is not None:
        from multilat.parallel import parse_scheduler_address

        parse_scheduler_address(scheduler)
    if out is not None:
        from multilat.io import check_output_dir

        check_output_dir(out, inputs=[source, references, environment, heights, points])
    from multilat.cli.network_cmd import model_options

    opts = model_options(locals())        # the network model, as `adjust` takes it
    keep_freed_memory()
    src: dict = {}
    problem, noise = load_problem(source, opts, noise=noise, instrument=instrument, sigma_um=sigma_um,
                                  references=references, environment=environment, heights=heights,
                                  formula=formula, extrapolate=extrapolate, max_gap_s=max_gap_s,
                                  average_repeats=average_repeats, sigma_source=src, points=points,
                                  fix_offsets_um=fix_offsets_um, pairs=pairs)
    total = None if adaptive else trials
    with map_from_options(workers=workers, scheduler=scheduler, single_run=True) as m, progress() as bar:
        task = bar.add_task("Monte Carlo", total=total)
        res = propagate(problem, trials=trials, rng=seed, noise=noise, instrument=instrument,
                        adaptive=adaptive, chunk_size=chunk_size, map=m,
                        progress=lambda n: bar.update(task, completed=n), keep_samples=out is not None or report is not None)
    from multilat.vocabulary import stamp

    doc = stamp(res.to_dict(), "propagate")
    if problem.readings is not None:
        doc["readings"] = problem.readings.to_json()
    doc["sigma_source"] = src
    if source not in BUILTIN and "azimuth_rad" in (_header(source) or ()):
        from multilat.network.adjust.distance.azimuth_sense import as_json, resolve

        doc["azimuth_sense"] = as_json(*resolve(opts.azimuth_sense, instrument))
    doc["noise_source"] = ({"kind": "distance model", "instrument": str(instrument)} if noise == "model"
                           else {"kind": "gaussian", "sigma": "the weights' σ (sigma_source)"})
    if out is not None:
        from multilat.io import staging_dir

        # all or nothing: files go to a temporary directory beside OUT, moved in only on success
        with staging_dir(out, inputs=[source, references, environment, heights, points]) as tmp:
            write_outputs(res, doc, tmp, cloud_points=cloud_points)
    report_opt.write_report(report, "propagate", doc, result=res)
    if as_json:
        emit_json(doc, "propagate")
        return
    _print(res, doc, out)


def write_outputs(res, doc, out: Path, *, cloud_points: str | None = None) -> None:
    """Write ``summary.json``, ``parameters.csv``, ``distances.csv``, ``points.csv``, ``clouds.png``
    into ``out`` (the command passes a :func:`multilat.io.staging_dir`, so the set appears in
    ``--out`` whole or not at all)."""
    from multilat.io import atomic_path, write_csv_atomic, write_json_atomic
    from multilat.report.propagate_figures import clouds_figure

    out = Path(out)
    hdr = ["label", "nominal_m", "mean_mc_m", "std_mc_m", "std_mc_se_m", "std_lin_m", "ratio", "agrees",
           "low_m", "high_m", "short_low_m", "short_high_m"]

    def rows(items):
        for r in items:
            yield [r["label"], r["nominal_m"], r["mean_mc_m"], r["std_mc_m"], r["std_mc_se_m"], r["std_lin_m"],
                   r["ratio"] if r["ratio"] is not None else "", r["agrees"], *r["interval_symmetric_m"],
                   *r["interval_shortest_m"]]

    write_csv_atomic(out / "parameters.csv", hdr, rows(doc["parameters"]))
    write_csv_atomic(out / "distances.csv", hdr, rows(doc["distances"]))
    write_csv_atomic(out / "points.csv",
                     ["id", "semi_axis_1_95_m", "semi_axis_2_95_m", "semi_axis_3_95_m", "ellipsoid_coverage_mc", "ellipsoid_coverage_lin"],
                     ([pid, *p["semi_axes_95_m"], p["ellipsoid_coverage_mc"], p["ellipsoid_coverage_lin"]]
                      for pid, p in doc["points"].items()))
    fig = clouds_figure(res, points=[s.strip() for s in cloud_points.split(",") if s.strip()]
                        if cloud_points else None)
    with atomic_path(out / "clouds.png") as tmp:
        fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(fig)
    reps = (doc.get("readings") or {}).get("repeats")
    if reps:
        write_csv_atomic(out / "repeats.csv", ["station", "target", "n", "mean_m", "std_m"],
                         ([r["station"], r["target"], r["n"], r["mean_m"], "" if r["std_m"] is None else r["std_m"]]
                          for r in reps))
    write_json_atomic(out / "summary.json", doc)


def _um(v):
    return f"{v * 1e6:.2f}"


def _print(res, doc, out) -> None:
    s = doc["summary"]
    console.print(f"Monte Carlo through the adjustment ({doc['source']}): {doc['trials']} trials "
                  f"kept, {doc['n_failed']} failed to converge ({doc['n_retried']} re-solved by full "
                  f"Gauss-Newton), noise={doc['noise']}, {doc['elapsed_s']:.1f} s")
    console.print(f"sigma0: nominal {doc['sigma0_nominal']:.3f}, trials' mean {doc['sigma0_mean']:.3f} "
                  f"(rms {doc['sigma0_rms']:.3f}; drawn errors alone {doc['sigma0_noise_only']:.3f})")
    from multilat.network.model.sigma_source import describe

    ns = doc["noise_source"]
    console.print("  " + describe(doc["sigma_source"]) + (f"; errors drawn from the distance model of "
                  f"{ns['instrument']!r}" if ns["kind"] == "distance model" else
                  "; errors drawn gaussian with these σ"), markup=False)
    if doc["sigma0_nominal"] > 0:
        console.print("  trials are centred on the measured distances, so each carries the nominal residuals "
                      "as well: sigma0_trial^2 ~ sigma0_nominal^2 + (errors alone)^2")
    rd = doc.get("readings")
    if rd:
        console.print(f"readings: {rd['n_readings']} behind {rd['n_observations']} observations"
                      + (f"; {rd['n_sensor_errors']} sensor errors ({', '.join(rd['sensors'])}) drawn once per "
                         "trial and applied to every reading they serve (linearised sensitivities)"
                         if rd["n_sensor_errors"] else ""), markup=False)
        if rd["repeats"]:
            many = [r for r in rd["repeats"] if r["n"] > 1]
            if many:
                sd = np.array([r["std_m"] for r in many])
                console.print(f"repeats averaged: {len(many)} pairs of {min(r['n'] for r in many)}.."
                              f"{max(r['n'] for r in many)} readings, scatter (std) {_um(sd.min())}.."
                              f"{_um(sd.max())} um (median {_um(float(np.median(sd)))})", markup=False)
    if doc["adaptive"]:
        a = doc["adaptive"]
        console.print(f"adaptive (JCGM 101 7.9): converged={a['converged']} after {a['batches']} batches "
                      f"of {a['batch_trials']} trials")
    t = Table(title="Points: standard uncertainties (um), MC vs linear; 95 % ellipsoid coverage")
    for c in ("point", "u_x MC", "u_y MC", "u_z MC", "u_x lin", "u_y lin", "u_z lin", "cov MC ell.",
              "MC in lin ell."):
        t.add_column(c, justify="right")
    labels = res.labels
    for q, pid in enumerate(res.point_ids):
        idx = [labels.index(f"{pid}.{c}") for c in "xyz"]
        t.add_row(pid, *[_um(res.mc_std[i]) for i in idx], *[_um(res.lin_std[i]) for i in idx],
                  f"{res.ellipsoid_coverage_mc[q]:.3f}", f"{res.ellipsoid_coverage_lin[q]:.3f}")
    console.print(t)
    t = Table(title="Offsets and interpoint distances (um)")
    for c in ("quantity", "MC std", "+-MC se", "lin std", "ratio", "95 % interval (dev. from nominal)", "agrees"):
        t.add_column(c, justify="right")
    for r in [r for r in doc["parameters"] if r["label"].endswith(".offset")] + doc["distances"]:
        lo, hi = r["interval_symmetric_m"]
        t.add_row(r["label"], _um(r["std_mc_m"]), _um(r["std_mc_se_m"]), _um(r["std_lin_m"]),
                  f"{r['ratio']:.3f}" if r["ratio"] else "-",
                  f"[{_um(lo - r['nominal_m'])}, {_um(hi - r['nominal_m'])}]", "yes" if r["agrees"] else "NO")
    console.print(t)
    console.print(f"{s['n_agree']}/{s['n_quantities']} standard deviations agree with the linear covariance "
                  f"within 3 MC standard errors (ratio {s['ratio_min']:.3f}..{s['ratio_max']:.3f})")
    if out is not None:
        console.print(f"results and figure written to {out}")
