"""``multilat adjust``: self-calibrating multilateration adjustment of a distance file."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from multilat.cli.app import app, progress
from multilat.errors import MultilatError
from multilat.cli import checks, report_opt
from multilat.io import check_output_dir
from multilat.network.adjust.distance.azimuth_sense import HELP as AZIMUTH_SENSE_HELP


#: The CLI parameters of ``adjust`` (and ``propagate``) that are fields of :class:`NetworkOptions`
#: under another name.
_CLI_FIELDS = {"scale_bar": "scale_bars"}
_MODEL_FIELDS = ("datum", "cost", "scales", "fixed_scale", "levelled", "distance_only", "scale_bar", "scale_bars",
                 "instrument", "azimuth_sense",
                 "alpha", "alpha_global", "test_method", "alpha_family", "variance_factor", "mdb_limit_sigma",
                 "snooping", "strict", "variance_components", "solver")


def model_options(params: dict):
    """The :class:`~multilat.network.adjust.distance.options.NetworkOptions` of a command's parameters (``locals()``
    of ``adjust`` or ``propagate``; the ones a command lacks keep their defaults), validated before any
    file is read: a bad value is one line naming the option. ``--fix-offsets-um`` names heads of the
    file: added by :func:`with_fixed_offsets` once it is read."""
    from multilat.network.adjust.distance.options import NetworkOptions

    fields = {_CLI_FIELDS.get(k, k): params[k] for k in _MODEL_FIELDS if params.get(k) is not None}
    if params.get("sigma_um") is not None:
        fields["sigma_m"] = params["sigma_um"] * 1e-6
    return NetworkOptions.from_cli(**fields)


def with_fixed_offsets(opts, text: str | None, obs):
    """``opts`` with ``--fix-offsets-um TEXT`` parsed against the heads of ``obs`` (None: the ids are
    checked by the adjustment, which names the option)."""
    if text is None:
        return opts
    what = "station" if obs is None or obs.station_heads is None else "head"
    return type(opts).of(opts, offsets_m=parse_fixed_offsets(text, None if obs is None else obs.head_ids,
                                                             what=what))


def with_levelled(obs, levelled: str | None):
    """``obs`` with the stations of ``--levelled ID,ID,...`` levelled too (one-line error for an unknown id)."""
    if not levelled:
        return obs
    from multilat.network.adjust.distance.options import NetworkOptions

    return NetworkOptions.from_cli(levelled=levelled).prepare(obs)


def parse_fixed_offsets(text: str, station_ids, *, what: str = "station") -> float | dict:
    """``--fix-offsets-um``: ``"X"`` (every head, µm) -> metres; ``"A=1234,B=-871"`` -> {head id: metres}.

    ``station_ids`` are the ids that may be named (the head ids; a head is its station when the
    observations name no heads; None: not checked here). Raises :class:`MultilatError` (one line) on a
    malformed value or an unknown id.
    """
    text = text.strip()
    if "=" not in text:
        try:
            v = float(text)
        except ValueError:
            raise MultilatError(f"--fix-offsets-um: expected a number of µm or STATION=µm,..., "
                                f"got {text!r}") from None
        checks.offset_um(v)
        return v * 1e-6
    out = {}
    for item in text.split(","):
        key, sep, val = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise MultilatError(f"--fix-offsets-um: expected STATION=µm, got {item.strip()!r}")
        if station_ids is not None and key not in station_ids:
            raise MultilatError(f"--fix-offsets-um: unknown {what} id {key!r} "
                                f"({what}s: {', '.join(station_ids)})")
        if key in out:
            raise MultilatError(f"--fix-offsets-um: {what} {key!r} given twice")
        try:
            v = float(val)
        except ValueError:
            raise MultilatError(f"--fix-offsets-um: {key}: not a number of µm: {val.strip()!r}") from None
        checks.offset_um(v, f"--fix-offsets-um {key}")
        out[key] = v * 1e-6
    return out


@app.command("adjust")
def adjust_command(
    observations: Path = typer.Argument(..., help="Observations CSV: station,target,distance_m"
                                                  "[,sigma_m][,head][,azimuth_rad,elevation_rad] (head: "
                                                  "the head on the station, default the station id; "
                                                  "offsets and scales belong to heads); or a raw "
                                                  "readings file (optical_path_m or phase_rad, "
                                                  "frequency_hz), corrected first as by `multilat correct`."),
    references: Optional[Path] = typer.Option(None, "--references",
                                              help="Reference lengths CSV: target_a,target_b,length_m[,u_m]."),
    points: Optional[Path] = typer.Option(None, "--points",
                                          help="Points CSV: point,x_m,y_m,z_m[,sx_m,sy_m,sz_m] (approximate "
                                               "or control; rows with sx_m,sy_m,sz_m are weighted control "
                                               "under --datum control)."),
    datum: str = typer.Option("free", "--datum",
                              help="free[:P1,P2,..] (inner constraints, default), 321:A,B,C "
                                   "(A origin, B on +x, C in xy-plane) or control[:P1,..] (--points fixed)."),
    sigma_um: Optional[float] = typer.Option(None, "--sigma-um",
                                             help="A-priori standard uncertainty of every distance, µm "
                                                  "(when the file has no sigma_m column)."),
    instrument: Optional[str] = typer.Option(None, "--instrument",
                                             help="Instrument preset or TOML for the distance model's "
                                                  "uncertainties (default seed2020) when no sigma is given."),
    azimuth_sense: Optional[str] = typer.Option(None, "--azimuth-sense",
                                                help=AZIMUTH_SENSE_HELP),
    alpha: float = typer.Option(0.001, "--alpha", help="alpha0: significance of each observation's test "
                                "(w-test; τ-test with --variance-factor unknown); an upper bound under "
                                "--test-method auto."),
    alpha_family: float = typer.Option(0.01, "--alpha-family",
                                       help="Family-wise significance of a network's w-tests (auto, sidak): "
                                            "the most often a blunder-free network may lose an observation."),
    alpha_global: Optional[float] = typer.Option(None, "--alpha-global",
                                                 help="Significance of the global χ² test (with "
                                                      "--test-method fixed; default there 0.05)."),
    test_method: Optional[str] = typer.Option(None, "--test-method",
                                              help="auto (the default: the B-method while its w-tests' "
                                                   "family-wise α is at most --alpha-family, else sidak), "
                                                   "b-method (Baarda: the global test's α derived from --alpha "
                                                   "and power 80 % for equal power), sidak (w-tests at Šidák's "
                                                   "α0 for --alpha-family, detection by the largest |w|) or "
                                                   "fixed (the default when --alpha-global is given)."),
    variance_factor: str = typer.Option("known", "--variance-factor",
                                        help="known (the a-priori σ are right: global χ² test, w-tests) or "
                                             "unknown (σ0 estimated: Pope's τ-test, covariances scaled "
                                             "by σ0²)."),
    mdb_limit_sigma: float = typer.Option(10.0, "--mdb-limit-sigma",
                                          help="Name observations and targets whose MDB exceeds this "
                                               "multiple of σ (or with redundancy below 0.1)."),
    cost: str = typer.Option("distance", "--cost",
                             help="distance (weighted, default) or squared (the paper's eq. 6, unweighted)."),
    fix_offsets_um: Optional[str] = typer.Option(None, "--fix-offsets-um",
                                                 help="Hold head offsets fixed, µm: one value for "
                                                      "every head (e.g. 0), or per head "
                                                      "A=1234,B=-871 (the others stay estimated; a head "
                                                      "is its station without a head column). "
                                                      "Default: estimate them all."),
    scales: bool = typer.Option(False, "--scales",
                                help="Also estimate a scale per head; the network's scale then needs "
                                     "a datum: --fixed-scale HEAD or --scale-bar."),
    fixed_scale: Optional[str] = typer.Option(None, "--fixed-scale",
                                              help="With --scales: hold this head's scale (the scale "
                                                   "datum); the others are estimated."),
    scale_bar: bool = typer.Option(False, "--scale-bars", "--scale-bar",
                                   help="Use the reference lengths of --references as observations (scale "
                                        "bars, each weighted by its u_m > 0); with --scales they are the "
                                        "scale datum."),
    snooping: bool = typer.Option(True, "--snooping/--no-snooping",
                                  help="Iteratively reject the worst w-test failure."),
    seed: int = typer.Option(0, "--seed", help="Seed for the initial-value search (if used)."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of a summary."),
    out: Optional[Path] = typer.Option(None, "--out", "-o",
                                       help="Directory for result CSVs and figures (written atomically)."),
    tables: str = typer.Option("auto", "--tables",
                               help="With --out: the tables (stations, targets, observations, reference "
                                    "lengths) as csv or parquet (needs pyarrow: pip install "
                                    "'multilat\\[parquet]'; compact and fast for 10^5-10^6 rows); auto (the "
                                    "default): the observations as parquet when pyarrow is installed, "
                                    "else csv, the others as csv."),
    all_observations: bool = typer.Option(False, "--observations",
                                          help="List every observation's row in the JSON (--json, "
                                               "result.json), not only those that matter (rejected, "
                                               "failing w-tests, poorly controlled, left out): for small "
                                               "networks; the --out table holds them all."),
    environment: Optional[Path] = typer.Option(None, "--environment", "-e",
                                               help="Raw readings only: environment log CSV "
                                                    "(as `multilat correct --environment`)."),
    heights: Optional[Path] = typer.Option(None, "--heights",
                                           help="Raw readings only: station/target heights "
                                                "(as `multilat correct --heights`)."),
    formula: str = typer.Option("ciddor", "--formula",
                                help="Raw readings only: group index formula, ciddor or edlen."),
    extrapolate: bool = typer.Option(False, "--extrapolate",
                                     help="Raw readings only: extrapolate the environment outside "
                                          "the log's time span (warned) instead of refusing."),
    max_gap_s: Optional[float] = typer.Option(None, "--max-gap-s",
                                              help="Raw readings only: longest gap of a sensor's log "
                                                   "interpolated across, s (as `multilat correct`)."),
    solver: str = typer.Option("auto", "--solver",
                               help="Linear-algebra back end, a choice of speed only (same results and "
                                    "statistics): dense (numpy; every option), sparse (compiled kernels "
                                    "for 10^5-10^6 distances; not with --scales, --cost squared or "
                                    "--datum control) or auto (sparse above 20 000 distances where it "
                                    "applies)."),
    average_repeats: bool = typer.Option(False, "--average-repeats",
                                         help="Average repeated readings of a pair into one observation "
                                              "(weighted mean; scatter per pair in the JSON 'repeats'); "
                                              "default: keep them as separate observations."),
    strict: bool = typer.Option(False, "--strict",
                                help="Refuse the network when a point is too weakly observed, instead "
                                     "of leaving it out with a warning, or placed only up to a mirror "
                                     "(ambiguous geometry)."),
    levelled: Optional[str] = typer.Option(None, "--levelled",
                                           help="Stations on their own level (vertical axis = the world's z): "
                                                "one orientation angle (κ) for their angle observations, "
                                                "ID,ID,... (trackers with levelled = true in --instrument are "
                                                "levelled too)."),
    distance_only: Optional[str] = typer.Option(None, "--distance-only",
                                                help="Stations that read no angles (heads without encoders), "
                                                     "ID,ID,...: an angle observation on one of them is an "
                                                     "error in the file."),
    variance_components: Optional[str] = typer.Option(None, "--variance-components",
                                                      help="Estimate one variance factor per group, by head, "
                                                           "station or kind (distances, angles; angles are "
                                                           "always a group of their own), Förstner's iterated "
                                                           "estimator, and adjust with the re-weighted σ."),
    report: Optional[Path] = typer.Option(None, "--report", help=report_opt.HELP),
    backend: str = typer.Option("auto", "--backend",
                                help="General model only: its back end, dense, sparse (Schur complement, large "
                                     "networks) or auto (sparse above 200 unknowns)."),
    model: str = typer.Option("auto", "--model",
                              help="auto (the default): multilateration, and general for a network its counting "
                                   "rules refuse or whose polar points (distance, azimuth, elevation from one "
                                   "station) they would leave out (said in a warning); multilateration "
                                   "(self-calibrating, "
                                   "distance-only rules, any size); general (any point in any role, by what the "
                                   "observations determine: docs/general-network.md)."),
) -> None:
    """Adjust a self-calibrating multilateration network: station and target coordinates and the
    stations' offsets from distances alone, with σ0, the global test, data snooping, 95 %
    ellipsoids and reference-length comparisons."""
    from multilat.cli import adjust_output, general_adjust
    listing = adjust_output.check_listing(all_observations, as_json, out)
    given = {k: v for k, v in locals().items() if k not in ("all_observations", "adjust_output")}
    if general_adjust.wants_general(observations, model):  # --model general, or a gama-local XML input
        return general_adjust.run(**given)
    from multilat.network.io.files import read_points, read_reference_lengths

    if backend != "auto":
        raise MultilatError("--backend applies to the general model (--model general); the distance path's "
                            "back end is --solver")
    checks.table_format(tables, out)
    checks.sigma_um(sigma_um)
    checks.seed(seed)
    report_opt.check_report_path(report, [observations, references, points, environment, heights])
    opts = model_options(locals())
    if out is not None:
        check_output_dir(out, inputs=[observations, references, points, environment, heights])
    from multilat.campaign.propagation import read_campaign

    src: dict = {}
    obs, corrected = read_campaign(observations, sigma_m=opts.sigma_m, instrument=instrument,
                                   environment=environment, heights=heights, formula=formula,
                                   extrapolate=extrapolate, max_gap_s=max_gap_s, sigma_source=src,
                                   azimuth_sense=opts.azimuth_sense)
    if corrected is not None:
        src["defaulted"] = instrument is None
    _check_instrument_used(instrument, observations, obs, src, corrected)
    import warnings

    from multilat.network.model.sigma_source import default_warning

    sigma_note = default_warning(src, observations)      # the default σ is said, once
    if sigma_note:
        warnings.warn(sigma_note, UserWarning, stacklevel=1)
    averaged = None
    if average_repeats:
        from multilat.network.model.repeats import average_repeats as _average

        averaged = _average(obs)
        obs = averaged.obs
    obs = opts.prepare(obs, source=str(observations))
    refs = read_reference_lengths(references) if references is not None else None
    if refs is not None:
        refs.check_ids(obs.station_ids + obs.target_ids, what=str(references))
    pts = read_points(points) if points is not None else None
    opts = with_fixed_offsets(opts, fix_offsets_um, obs)
    if opts.scale_bars and refs is None:
        raise MultilatError("--scale-bars needs --references FILE (the bars' lengths with u_m)")
    opts.scale_heads(obs)                       # --fixed-scale names a head of the file
    if opts.variance_components is not None and corrected is not None:
        raise MultilatError("--variance-components applies to an observation file: raw readings get "
                            "their σ from the distance model and the sensors")
    data = dict(points=pts, references=refs, sigma_source=src, rng=seed)
    try:
        # auto: the general layer can do better only with what the counting rules do not count: angles
        # or control (a distance-only network it cannot place either keeps the old refusal)
        auto = model == "auto" and (obs.has_angle_observations or pts is not None)
        if auto and (polar := general_adjust.polar_switch(obs, opts, pts)) is not None:
            raise polar                                   # decided on the tables: adjusted once, there
        res, vc = _adjust_with_progress(obs, opts, data, auto=auto, files=(observations, points))
    except general_adjust.CountRuleRefusal as refusal:     # --model auto: the general layer adjusts it
        return general_adjust.fall_back(given, refusal)
    except MultilatError as exc:                          # a mirrored hall (cw azimuths read ccw)? named
        hint = _mirror_hint(obs, None, opts, data, instrument)
        raise (MultilatError(f"{exc}; {hint}") if hint else exc) from None
    if getattr(res.global_test, "passed", True) is False and (hint := _mirror_hint(obs, res.sigma0, opts, data,
                                                                                   instrument)):
        import warnings

        warnings.warn(hint, UserWarning, stacklevel=1)
    doc = adjust_output.adjust_document(res, refs, obs, opts, instrument, sigma_note, vc, corrected, averaged,
                                        listing=listing)
    adjust_output.finish(res, doc, refs, out=out, tables=tables, report=report, as_json=as_json, vc=vc,
                         inputs=[observations, references, points, environment, heights])


def _mirror_hint(obs, sigma0, opts, data, instrument):
    """:func:`multilat.network.adjust.distance.azimuth_sense.mirror_hint` when the sense was not declared (else None)."""
    from multilat.network.adjust.distance import azimuth_sense as _az

    if opts.azimuth_sense is not None or _az.resolve(None, instrument)[1] != _az.UNDECLARED:
        return None
    return _az.mirror_hint(obs, sigma0, opts, data)


def _adjust_with_progress(obs, opts, data, *, auto: bool, files):
    """The distance path's adjustment (and variance components) under a progress line: (result, vc).
    A counting-rule refusal names ``--model general`` (or, ``auto``, raises ``CountRuleRefusal``)."""
    from rich.markup import escape

    from multilat.cli import general_adjust
    from multilat.errors import printable
    from multilat.network.adjust.distance.adjust import adjust
    from multilat.network.adjust.approximate.bounds import reporting
    from multilat.network.adjust.distance.unit_slip import UnitSlipError

    vc = None
    with progress() as p, general_adjust.refusal_hint(obs, auto=auto):  # count-rule refusals: --model general
        what = f"adjusting {obs.n_obs:,} distances"
        task = p.add_task(what, total=None)

        def step(text):      # the search's current start (ids from the files: shown literally)
            p.update(task, description=f"{what}: {escape(printable(text, keep_newlines=False))}")

        try:
            with reporting(step):
                if opts.variance_components is None:
                    res = adjust(obs, opts, **data)
                else:
                    from multilat.network.adjust.distance.variance_components import estimate_variance_components

                    vc = estimate_variance_components(obs, grouping=opts.variance_components, options=opts,
                                                      snooping=opts.snooping, **data)
                    res = vc.result
        except UnitSlipError as exc:      # name the file at fault
            raise MultilatError(f"{files[1] if exc.source == 'points' else files[0]}: {exc}") from None
    return res, vc


def _check_tests(alpha, alpha_global, test_method, variance_factor, mdb_limit_sigma, alpha_family=0.01):
    """The test options, before any work (the checks of :class:`NetworkOptions`)."""
    from multilat.network.adjust.distance.options import NetworkOptions

    NetworkOptions.from_cli(alpha=alpha, alpha_global=alpha_global, test_method=test_method,
                            variance_factor=variance_factor, mdb_limit_sigma=mdb_limit_sigma,
                            alpha_family=alpha_family)


def _check_instrument_used(instrument, path, obs, src, corrected) -> None:
    """``--instrument`` is applied or refused, never dropped: with a raw file it corrects the readings,
    without a ``sigma_m`` column its distance model gives the σ, with angles it says which stations
    are levelled trackers and their angles' σ. A file that gives σ for every distance and no angles
    uses none of it: refused, naming both (the TOML is still loaded first, so a broken file is named
    for what it is)."""
    if instrument is None or corrected is not None or obs.azimuth_rad is not None:
        return
    if src.get("kind") != "file column":
        return
    from multilat import instrument as _inst

    _inst.load_instrument(instrument)
    raise MultilatError(f"--instrument {instrument}: not used: {path} gives sigma_m for every distance and no "
                        "angles (drop --instrument, or drop the sigma_m column to take σ from the instrument's "
                        "distance model)")
