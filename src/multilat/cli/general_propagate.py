"""``multilat propagate NET.xml`` and ``multilat propagate obs.csv --model general``: the Monte Carlo
of the general network layer (:mod:`multilat.network.montecarlo.general.propagate`) from the command line.

Reached from the ``propagate`` command (:mod:`multilat.cli.propagate_cmd`) when its input is a
gama-local file or ``--model general`` is given (:func:`multilat.cli.general_adjust.wants_general`,
the same rule as ``adjust``). The network is read and adjusted as ``multilat adjust`` does it
(undetermined points left out and named), then propagated through the adjustment's frozen system:
every observation drawn gaussian from its a-priori covariance, or with ``--noise model`` the slope
distances from the distance model of the instrument named by ``--instrument`` (refused without it).
Options that apply: ``--trials``, ``--seed``, ``--chunk-size``, ``--workers``, ``--scheduler``,
``--json``, ``--out``, ``--noise``, ``--instrument`` with ``--noise model``; on a CSV network also
``--points``, ``--datum``, ``--sigma-um``, ``--instrument``, ``--scales``, ``--references`` with
``--scale-bars`` and ``--levelled``, as ``adjust --model general`` reads them. Every other option
is refused in one line that names it.
"""

from __future__ import annotations

import warnings
from pathlib import Path

from multilat.errors import MultilatError

__all__ = ["run", "APPLIES", "APPLIES_CSV", "SCHEMA"]

#: ``"schema": "multilat.propagate-general/2"``
SCHEMA = "propagate-general"
APPLIES = ("source", "trials", "seed", "chunk_size", "workers", "scheduler", "as_json", "out", "model", "noise")
APPLIES_CSV = APPLIES + ("points", "datum", "sigma_um", "instrument", "scales", "scale_bars", "references",
                         "levelled")
WHY_NOT = {
    "adaptive": "the general Monte Carlo runs a fixed number of trials (--trials)",
    "report": "the HTML report is built from the distance path's result",
    "cloud_points": "the clouds figure is drawn from the distance path's result",
    "datum": "the datum of a gama-local file is its fix=/adj= attributes",
    "points": "the file's <point> elements carry the coordinates",
    "sigma_um": "the σ are the file's stdev=",
    "instrument": "the σ are the file's stdev= (--instrument names the distance model of --noise model)",
}
for _raw in ("environment", "heights", "formula", "extrapolate", "max_gap_s", "average_repeats"):
    WHY_NOT[_raw] = "raw readings are corrected and propagated on the distance path only"
_OPTION = {"as_json": "--json", "scale_bars": "--scale-bars"}


def run(**params) -> None:
    """The general path of ``multilat propagate`` (``params``: the propagate command's parameters)."""
    from multilat.cli import checks
    from multilat.cli.app import console, emit_json, progress
    from multilat.cli.general_adjust import _given_options, is_general_input
    from multilat.network.montecarlo.general.propagate import propagate
    from multilat.parallel import map_from_options

    params.pop("general_propagate", None)             # the hook's own imports, passed with locals()
    params.pop("general_adjust", None)
    from multilat.network.montecarlo.propagate import noise_choice

    path, out = Path(params["source"]), params.get("out")
    xml = is_general_input(path)
    given = _given_options(params)
    noise = params.get("noise") if "noise" in given else "gaussian"      # the distance model only when asked
    applies = (APPLIES + (("instrument",) if noise == "model" else ())) if xml else APPLIES_CSV
    what = "a gama-local input" if xml else "--model general"
    for name in given:
        if name not in applies:
            why = WHY_NOT.get(name, "it belongs to the distance-only Monte Carlo")
            raise MultilatError(f"{_OPTION.get(name, '--' + name.replace('_', '-'))} does not apply to {what} "
                                f"({path}): {why}")
    noise, instrument = noise_choice(noise, params.get("instrument") if noise == "model" else None, cli=True)
    checks.seed(params["seed"])
    checks.trials(params["trials"], lo=2)
    checks.count(params["chunk_size"], "--chunk-size", hi=10**8)
    checks.count(params.get("workers"), "--workers", hi=4096)
    if not path.exists():
        raise MultilatError(f"{path}: no such file")
    inputs = [path] + [params.get(k) for k in ("points", "references") if params.get(k) is not None]
    if out is not None:
        from multilat.io import check_output_dir

        check_output_dir(out, inputs=inputs)
    adj, fmt = _adjusted(path, xml, params)
    for e in adj.excluded:
        warnings.warn(f"point {e['id']!r} left out: {e['reason']} ({e['n_obs']} observation row(s) removed)",
                      stacklevel=2)
    with map_from_options(workers=params.get("workers"), scheduler=params.get("scheduler")) as m, \
            progress() as bar:
        task = bar.add_task("Monte Carlo (general)", total=params["trials"])
        res = propagate(adj.system, adj.result, trials=params["trials"], rng=params["seed"],
                        chunk_size=params["chunk_size"], map=m, progress=lambda n: bar.update(task, completed=n),
                        noise=noise, instrument=instrument)
    source = ("the a-priori covariance of every observation (the adjustment's weights)" if noise == "gaussian" else
              f"the slope distances from the distance model of {instrument}, the other observations from their "
              "a-priori covariance")
    doc = {**res.to_dict(), "input": str(path), "format": fmt, "noise_source": source, "excluded": list(adj.excluded)}
    if out is not None:
        _write(out, inputs, doc)
    if params["as_json"]:
        emit_json(doc, SCHEMA)
        return
    _print(console, doc, out)


def _adjusted(path: Path, xml: bool, params: dict):
    """The adjusted network (:class:`~multilat.network.adjust.general.run.NetworkAdjustment`) and its format."""
    from multilat.network.adjust.general import adjust_network, read_gama_input

    if xml:
        return adjust_network(read_gama_input(path)), "gama-local"
    from multilat.cli.general_adjust import compute_tables

    tables = {"observations": path, "points": params.get("points"), "references": params.get("references"),
              "scale_bar": params.get("scale_bars"), "datum": params.get("datum") or "free",
              "sigma_um": params.get("sigma_um"), "instrument": params.get("instrument"),
              "scales": params.get("scales", False), "levelled": params.get("levelled"), "seed": 0}
    _, adj, _ = compute_tables(tables, alpha=0.001, variance_factor="known", strict=False)
    return adj, "multilat-csv"


def _write(out: Path, inputs, doc) -> None:
    """``result.json`` and ``parameters.csv`` (parameters, then distances), whole or not at all."""
    from multilat.io import staging_dir, write_csv_atomic, write_json_atomic
    from multilat.vocabulary import stamp

    hdr = ["label", "unit", "nominal", "mean_mc", "std_mc", "std_mc_se", "std_lin", "ratio", "agrees",
           "low_95", "high_95", "short_low_95", "short_high_95"]
    rows = ([r["label"], r["unit"], r["nominal"], r["mean_mc"], r["std_mc"], r["std_mc_se"], r["std_lin"],
             "" if r["ratio"] is None else r["ratio"], r["agrees"], *r["interval_symmetric"], *r["interval_shortest"]]
            for r in doc["parameters"] + doc["distances"])
    with staging_dir(Path(out), inputs=inputs) as tmp:
        write_csv_atomic(Path(tmp) / "parameters.csv", hdr, rows)
        write_json_atomic(Path(tmp) / "result.json", stamp(doc, SCHEMA))


def _print(console, doc, out) -> None:
    s = doc["summary"]
    console.print(f"Monte Carlo through the general adjustment ({doc['input']}, {doc['format']}): {doc['trials']} "
                  f"trials kept, {doc['n_failed']} failed to converge, {doc['n_retried']} re-solved by "
                  f"full Gauss-Newton; {doc['chord_steps_mean']:.2f} chord steps per trial; {doc['elapsed_s']:.1f} s",
                  markup=False)
    console.print(f"observations drawn from {doc['noise_source']}; sigma0 of the trials: rms "
                  f"{doc['sigma0_rms']:.3f} (dof {doc['dof']}; 1 expected for gaussian inputs)", markup=False)
    from rich.table import Table

    t = Table(title="Points: standard deviations (um), Monte Carlo vs linear (the adjustment's Q)")
    for c in ("point", "x MC", "y MC", "z MC", "x lin", "y lin", "z lin"):
        t.add_column(c, justify="right")
    for pid, p in doc["points"].items():
        t.add_row(pid, *(f"{v * 1e6:.2f}" for v in p["std_mc_m"]), *(f"{v * 1e6:.2f}" for v in p["std_lin_m"]))
    console.print(t)
    ratio = "" if s["ratio_min"] is None else f" (ratio {s['ratio_min']:.3f}..{s['ratio_max']:.3f})"
    console.print(f"{s['n_agree']}/{s['n_quantities']} standard deviations agree with the linear ones within 3 MC "
                  f"standard errors{ratio}", markup=False)
    if out is not None:
        console.print(f"results written to {out}", markup=False)
