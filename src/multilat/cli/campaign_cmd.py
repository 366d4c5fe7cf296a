"""``multilat correct`` (raw readings -> observation file) and ``multilat two-face``."""

from __future__ import annotations

from enum import Enum
from pathlib import Path

import typer

from multilat.cli import report_opt
from multilat.cli.app import app, console, emit_json


class _Formula(str, Enum):
    ciddor = "ciddor"
    edlen = "edlen"


@app.command("correct")
def correct_cmd(
    raw: Path = typer.Argument(..., help="Raw readings CSV (station,target, optical_path_m or "
                               "phase_rad,frequency_hz[,k], time, elevation_rad, ...)."),
    environment: Path = typer.Option(None, "--environment", "-e", help="Environment log CSV "
                                     "(time,sensor,height_m,temperature_c,pressure_hpa,humidity_pct[,co2_ppm])."),
    instrument: str = typer.Option("seed2020", "--instrument", help="Instrument preset name or TOML file."),
    formula: _Formula = typer.Option(_Formula.ciddor, "--formula", help="Group index formula "
                                     "(edlen = Bönsch-Potulski 1998)."),
    heights: Path = typer.Option(None, "--heights", help="Station/target heights: id,height_m or a "
                                 "points file id,x_m,y_m,z_m (z = height in the sensors' frame)."),
    extrapolate: bool = typer.Option(False, "--extrapolate", help="Extrapolate the environment "
                                     "outside the log's time span (warned) instead of refusing."),
    max_gap_s: float = typer.Option(None, "--max-gap-s", help="Longest gap of a sensor's log "
                                    "interpolated across, s (default: 3x its median logging interval)."),
    out: Path = typer.Option(None, "--out", "-o", help="Write the observation file "
                             "(station,target,distance_m,sigma_m[,azimuth_rad,elevation_rad])."),
    cov: Path = typer.Option(None, "--cov", help="Also write the full covariance matrix (m², CSV)."),
    plot: Path = typer.Option(None, "--plot", help="Write a PNG: environment per sensor and the "
                              "per-observation index correction with its uncertainty."),
    as_json: bool = typer.Option(False, "--json", help="Print the full result as JSON."),
    report: Path = typer.Option(None, "--report", help=report_opt.HELP),
) -> None:
    """Correct raw readings (air group index, transit offsets) into distances with sigma_m."""
    from multilat.campaign.correct import correct_file, write_covariance, write_observations
    from multilat.campaign.environment import read_environment
    from multilat.errors import MultilatError
    from multilat.io import atomic_paths, check_not_input

    inputs = [raw, environment, heights, instrument if str(instrument).endswith(".toml") else None]
    outputs = {"--out": out, "--cov": cov, "--plot": plot}
    for opt, path in outputs.items():
        check_not_input(path, inputs, opt)
    given = [(o, p) for o, p in outputs.items() if p is not None]
    report_opt.check_report_path(report, inputs + [p for _, p in given])
    for i, (o, p) in enumerate(given):
        for o2, p2 in given[i + 1:]:
            if Path(p).resolve() == Path(p2).resolve():
                raise MultilatError(f"{o} and {o2} name the same file {p}")
    if max_gap_s is not None:
        from multilat.cli import checks

        checks.quantity(max_gap_s, "--max-gap-s", lo=0.0, hi=1e9, unit="s")
    log = read_environment(environment) if environment is not None else None
    res = correct_file(raw, environment=log, instrument=instrument, formula=formula.value,
                       heights=heights, extrapolate=extrapolate, max_gap_s=max_gap_s)
    # --out, --cov and --plot all or nothing: each written to a temporary file, renamed together
    with atomic_paths(*(p for _, p in given)) as tmps:
        tmp = dict(zip((o for o, _ in given), tmps))
        if plot is not None:
            from multilat.report.campaign_figures import save_correction_figure

            save_correction_figure(tmp["--plot"], res, log)
        if cov is not None:
            write_covariance(tmp["--cov"], res)
        if out is not None:
            write_observations(tmp["--out"], res)
    report_opt.write_report(report, "correct", res, result=(res, log))
    if as_json:
        emit_json(res, "correct")
        return
    from rich.table import Table

    tab = Table(title=f"corrected distances ({res.formula} group index)")
    for h in ("head", "target", "T/°C", "air/µm", "transit/µm", "distance/m", "σ air/µm", "σ/µm"):
        tab.add_column(h, justify="right", no_wrap=True)
    for i in range(res.distance_m.size):
        tab.add_row(res.station_ids[i], res.target_ids[i], f"{res.environment['temperature_c'][i]:.3f}",
                    f"{res.index_correction_m[i] * 1e6:.1f}",
                    f"{(res.head_transit_correction_m[i] + res.target_transit_correction_m[i]) * 1e6:.2f}",
                    f"{res.distance_m[i]:.7f}", f"{res.sigma_air_m[i] * 1e6:.2f}", f"{res.sigma_m[i] * 1e6:.2f}")
    console.print(tab)
    console.print("T: beam temperature; air: D - L (index correction); transit: eq. (2) head + target; "
                  "σ air: sensor part (correlated, see --cov/--json)", markup=False)
    for n in res.notes:
        console.print(f"note: {n}", markup=False)
    if out is not None:
        console.print(f"wrote {out}", markup=False)


@app.command("two-face")
def two_face_cmd(
    file: Path = typer.Argument(..., help="Two-face CSV: target,face,distance_m,elevation_rad"
                                "[,sigma_m][,reference_distance_m][,head]; face I or II."),
    sigma_um: float = typer.Option(None, "--sigma-um", help="Standard uncertainty of every distance "
                                   "(µm), overriding the file's sigma_m."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Estimate a head's transit offset (and, with reference distances, its additive constant) from
    distances measured in face I and face II (double-centering)."""
    from multilat.campaign.twoface import estimate_two_face, read_two_face

    from multilat.cli import checks

    checks.sigma_um(sigma_um)
    data = read_two_face(file)
    sig = None
    if sigma_um is not None:
        sig = sigma_um * 1e-6
    res = estimate_two_face(data, sigma_m=sig)
    if as_json:
        emit_json(res, "two-face")
        return
    head = f" of head {res.head}" if res.head else ""
    console.print(f"transit offset{head}: Toh = {res.transit_offset_m * 1e6:.2f} ± "
                  f"{res.transit_offset_std_m * 1e6:.2f} µm (k=1)", markup=False)
    if res.constant_m is not None:
        console.print(f"additive constant (beam-offset term + instrument constant): C = "
                      f"{res.constant_m * 1e6:.2f} ± {res.constant_std_m * 1e6:.2f} µm", markup=False)
    else:
        console.print("additive constant: not observable (no reference_distance_m)", markup=False)
    console.print(f"chi2 = {res.chi2:.2f} for {res.dof} dof, sigma0 = {res.sigma0:.3f}"
                  + (" (covariance scaled by sigma0², no sigma_m given)" if res.scaled else ""),
                  markup=False)
    for t, d, s in zip(res.target_ids, res.target_distance_m, res.target_distance_std_m):
        console.print(f"  {t}: face-mean distance {d:.7f} m ± {s * 1e6:.2f} µm", markup=False)
