"""``multilat adjust NET.xml`` and ``multilat adjust obs.csv --model general``: the general network
layer (:mod:`multilat.network.adjust.general`) from the command line: parse, call, print.

Reached from the ``adjust`` command (:mod:`multilat.cli.network_cmd`) when its input is a gama-local
file (suffix ``.xml`` / ``.gkf``, or a ``<gama-local>`` root element), or with ``--model general``
on multilat's own observation CSV (:mod:`multilat.network.adjust.general.from_tables`). For a gama-local
file the options that apply are ``--json``, ``--out DIR`` with ``--tables``, ``--observations``
(:mod:`multilat.cli.general_output`), ``--report FILE.html``
(:mod:`multilat.report.general_sections`), ``--alpha``, ``--variance-factor``, ``--test-method``,
``--alpha-global``, ``--backend`` and ``--strict``: the file itself carries the datum
(``fix=``/``adj=``), the σ (``stdev=`` and ``<points-observations>``) and the approximate
coordinates. A CSV network also takes ``--points``, ``--datum free|321|control``, ``--sigma-um``,
``--instrument``, ``--fix-offsets-um``, ``--scales``, ``--fixed-scale``, ``--references`` with
``--scale-bars``, ``--levelled``, ``--seed``, ``--no-snooping`` and a raw readings file with its
options (read by the distance path's reader). Every other option is refused in
one line naming it (never silently ignored). The model is never switched silently: the default
(distance) path's refusals by station counts say that ``--model general`` adjusts by what the
observations determine (:func:`refusal_hint`). Under ``--model auto`` (the default) such a refusal,
or polar points the distance path would leave out (decided on the tables before adjusting:
:func:`polar_switch`), takes the general path instead, said in one warning line and first in the
JSON's notes (:func:`fall_back`).
"""

from __future__ import annotations

import contextlib
import re
import warnings
from pathlib import Path

import numpy as np

from multilat.errors import MultilatError

__all__ = ["is_general_input", "wants_general", "refusal_hint", "run", "given_options", "option_name", "fall_back",
           "CountRuleRefusal", "polar_left_out", "polar_switch", "APPLIES", "APPLIES_CSV", "WHY_NOT",
           "WHY_NOT_CSV", "SCHEMA", "MODELS", "BACKENDS"]

#: the document's schema name: ``"schema": "multilat.adjust-general/3"`` (not the distance path's
#: ``multilat.adjust``: the keys differ, so a reader can tell them apart)
SCHEMA = "adjust-general"

#: the adjust command's parameters that the general path reads
APPLIES = ("observations", "as_json", "out", "alpha", "variance_factor", "strict", "alpha_global", "test_method",
           "alpha_family", "model", "snooping", "variance_components", "report", "tables", "backend",
           "all_observations")
#: ... and on a multilat CSV network (``--model general``)
APPLIES_CSV = APPLIES + ("points", "datum", "sigma_um", "instrument", "fix_offsets_um", "scales", "fixed_scale",
                         "scale_bar", "references", "levelled", "seed", "azimuth_sense",
                         "environment", "heights", "formula", "extrapolate", "max_gap_s")   # raw readings
#: the test procedures' names in the summary (statistics.test_levels)
_METHOD_NAMES = {"b-method": "B-method", "sidak": "Šidák", "fixed": "fixed α"}
#: ``--backend``: the general layer's back end (:attr:`multilat.network.adjust.general.adjust.AdjustOptions.backend`)
BACKENDS = ("auto", "dense", "sparse")
#: ``--model``: ``auto`` (the default: the distance-only self-calibrating path, and the general layer
#: for a network its counting rules refuse, said in a warning), the distance-only path alone, or the
#: general network layer
MODELS = ("auto", "multilateration", "general")
_OPTION = {"as_json": "--json", "all_observations": "--observations", "fix_offsets_um": "--fix-offsets-um",
           "scale_bar": "--scale-bars",
           "snooping": "--snooping/--no-snooping"}
#: why an option of the distance-only path is refused here (the default reason for the others)
WHY_NOT = {
    "datum": "the datum of a gama-local file is its fix=/adj= attributes (upper-case adj = datum points)",
    "points": "the file's <point> elements carry the coordinates", "sigma_um": "the σ are the file's stdev=",
    "instrument": "the σ are the file's stdev=",
}
#: why an option is refused with ``--model general`` on a CSV network (the default reason for the others)
WHY_NOT_CSV = {
    "cost": "the general path minimises the weighted distance residuals only",
    "solver": "the general path's back end is --backend auto|dense|sparse",
    "average_repeats": "repeated readings are kept as separate observations on the general path",
    "mdb_limit_sigma": "the general path lists every row's MDB in its table and names no poor targets yet",
    "distance_only": "the general path takes the angles that have a sigma as observations, whatever the station",
}
#: why an option is refused for a directory of multilat's files (``multilat adjust DIR``)
WHY_NOT_DIR = {"datum": "the datum is points.csv's fixed, sx_m.. and datum columns",
               "points": "the directory's points.csv carries the coordinates",
               "sigma_um": "the σ are observations.csv's sigma column", "instrument": "the σ are observations.csv's "
               "sigma column"}

#: the distance path's refusals by station or observation counts (its messages' text)
_COUNT_RULES = (re.compile(r"needs at least 3 stations"), re.compile(r"3 are needed to place it"),
                re.compile(r"unknowns need at least \d+"), re.compile(r"observation\(s\); it needs at least \d+"))
_HINT = ("; --model general adjusts a network by what its observations determine (angles, control points, "
         "polar points), not by station counts")


def wants_general(observations, model: str) -> bool:
    """Whether ``multilat adjust`` takes the general path: ``--model general``, or a gama-local input
    (which the distance path cannot read: ``--model multilateration`` on one is refused)."""
    if model not in MODELS:
        raise MultilatError(f"--model must be one of {', '.join(MODELS)}, got {model!r}")
    if is_general_input(observations):
        if model == "multilateration" and "model" in given_options({"model": model}):
            raise MultilatError(f"--model {model} does not read a gama-local input ({observations}): "
                                "it is adjusted by --model general")
        return True
    return model == "general"


class CountRuleRefusal(MultilatError):
    """The distance path refused the network by a counting rule, or would leave out polar points
    (``left_out``: their ids), under ``--model auto``: the caller adjusts it by the general layer
    instead (:func:`fall_back`)."""

    def __init__(self, message: str, *, left_out: tuple = ()):
        super().__init__(message)
        self.left_out = tuple(left_out)


def fall_back(params: dict, refusal: CountRuleRefusal):
    """``--model auto``: the network the distance path refuses by its counting rules (or whose polar
    points it would leave out) is adjusted by the general layer, said in one warning line and first
    in the JSON's ``notes``; refused (with the hint) when an option given has no meaning there."""
    params = {k: v for k, v in params.items() if k != "general_adjust"}
    other = [n for n in given_options(params) if n not in APPLIES_CSV]
    if other:
        raise MultilatError(f"{refusal}{_HINT} ({', '.join(option_name(n) for n in other)} "
                            "not available there)") from None
    params["model"] = "general"
    if refusal.left_out:
        n, ids = len(refusal.left_out), _names(refusal.left_out)
        params["fallback"] = (f"would leave out {n} polar point(s) ({ids}: {refusal}), which the general model "
                              "determines from their polar readings")
        says = "leaves them out"
    else:
        params["fallback"] = f"refused the network ({refusal})"
        says = "refuses it"
    warnings.warn(f"{params['observations']}: the self-calibrating model {params['fallback']}; adjusted by the "
                  f"general model (--model general, docs/general-network.md); --model multilateration {says}",
                  stacklevel=2)
    return run(**params)


def _names(ids, limit: int = 5) -> str:
    ids = list(ids)
    return ", ".join(ids[:limit]) + (f" and {len(ids) - limit} more" if len(ids) > limit else "")


#: the distance path's warnings of a point left out (:func:`multilat.network.adjust.distance.adjust.adjust`)
_LEFT_OUT = re.compile(r"^(target|station) '(.+?)' left out: ")


def polar_left_out(obs, messages) -> list[str]:
    """The targets the distance path left out by its counting rule (``messages``: its warnings) that
    carry a polar reading: a distance with its azimuth and elevation as observations (σ given) from a
    station it kept. Their three observations determine the point from the station's position and
    orientation (zero redundancy): the general layer keeps them (``--model auto``, :func:`refusal_hint`)."""
    if obs is None or obs.sigma_azimuth_rad is None or obs.sigma_elevation_rad is None:
        return []
    gone = {"station": set(), "target": set()}
    counted = []
    for msg in messages:
        if (m := _LEFT_OUT.match(msg)) is not None:
            gone[m.group(1)].add(m.group(2))
            if m.group(1) == "target" and _COUNT_RULES[1].search(msg):
                counted.append(m.group(2))
    if not counted:
        return []
    polar = (np.isfinite(obs.distance_m) & np.isfinite(obs.sigma_azimuth_rad) & np.isfinite(obs.sigma_elevation_rad)
             & (obs.sigma_azimuth_rad > 0) & (obs.sigma_elevation_rad > 0))
    sid, tid = np.asarray(obs.station_ids, object), np.asarray(obs.target_ids, object)
    read = {str(t) for t, s in zip(tid[obs.target_index[polar]], sid[obs.station_index[polar]])
            if s not in gone["station"]}
    return [t for t in counted if t in read]


def _general_takes(obs, backend: str | None = None) -> bool:
    """Whether the general layer's back end takes a network of ``obs``'s size: its free unknowns at
    most (3 per point, one constant per head, three angles per station with angles) within the limit of
    the back end chosen (``backend``; None: the command's ``--backend``): the dense one's
    :data:`~multilat.network.adjust.general.adjust.MAX_DENSE_UNKNOWNS` when it is forced or ``auto`` picks it,
    else the sparse one's reduced system (:data:`~multilat.network.adjust.general.sparse.MAX_REDUCED`): the
    unknowns less the targets', which it eliminates (no row joins two targets of a tracker network)."""
    from multilat.network.adjust.general.adjust import MAX_DENSE_UNKNOWNS, SPARSE_ABOVE

    if backend is None:
        from multilat.cli.report_opt import current_context

        ctx = current_context()
        backend = (ctx.params.get("backend") if ctx is not None else None) or "auto"
    n_angle = len(np.unique(obs.station_index[np.isfinite(obs.sigma_azimuth_rad)]))
    n = 3 * (obs.n_stations + obs.n_targets) + len(obs.head_ids) + 3 * n_angle
    if backend == "dense" or (backend == "auto" and n <= SPARSE_ABOVE):
        return n <= MAX_DENSE_UNKNOWNS
    from multilat.network.adjust.general.sparse import MAX_REDUCED

    return n - 3 * obs.n_targets <= MAX_REDUCED


def polar_switch(obs, opts, points=None) -> CountRuleRefusal | None:
    """``--model auto``, decided before any adjustment (each network is adjusted once): the
    :class:`CountRuleRefusal` for :func:`fall_back` when the distance path would leave out, by its
    counting rule, targets that carry a polar reading (:func:`polar_left_out`), every option given
    applies to the general layer (a ``--datum 321`` it can hold: :func:`~multilat.network.adjust.general.
    from_tables.check_321`) and its back end takes the network's size (:func:`_general_takes`); else
    None (the distance path adjusts it). The rule is the distance path's own first pass,
    :func:`multilat.network.adjust.distance.exclusion.exclude_weak_points` on the tables, with its held offsets,
    scales and control targets (``opts``: the prepared :class:`~multilat.network.adjust.distance.options.NetworkOptions`,
    ``points``: the ``--points`` table). Networks the distance path refuses outright (fewer than 3
    stations, ``--strict``) keep that route: the refusal comes before any solve."""
    if (obs.sigma_azimuth_rad is None or obs.sigma_elevation_rad is None or obs.n_stations < 3 or opts.strict
            or not all(n in APPLIES_CSV for n in given_options()) or not _general_takes(obs)):
        return None
    from multilat.network.adjust.distance.adjust import _fixed_offsets, _scale_flags
    from multilat.network.model.datum import parse_datum
    from multilat.network.adjust.distance.exclusion import exclude_weak_points
    from multilat.network.adjust.distance.fit import control_ids

    datum = parse_datum(opts.datum)
    if datum.kind == "control" and points is None:
        return None
    if datum.kind == "321":
        from multilat.network.adjust.general.from_tables import check_321

        try:
            check_321(obs, str(opts.datum))
        except MultilatError:
            return None
    off_free, _ = _fixed_offsets(opts.offsets_m, obs, opts.name("offsets_m"))
    sc_free = _scale_flags(opts.scale_heads(obs), obs, opts.name("scales"))
    ctrl = control_ids(obs, datum, points) if datum.kind == "control" else set()
    _, excluded = exclude_weak_points(obs, offset_free=off_free, scale_free=sc_free, fixed_targets=ctrl)
    said = {e.id: e.reason for e in excluded if e.kind == "target"}
    polar = polar_left_out(obs, [f"{e.kind} {e.id!r} left out: {e.reason}" for e in excluded])
    return CountRuleRefusal(said[polar[0]], left_out=polar) if polar else None


@contextlib.contextmanager
def refusal_hint(obs=None, *, auto: bool = False):
    """Around the distance path's adjustment: a refusal (or, on a network with angle observations, a
    left-out point) by one of its counting rules gets the hint that ``--model general``
    adjusts the network by what the observations determine. ``auto`` (``--model auto``): a
    counting-rule refusal raises :class:`CountRuleRefusal` instead, for :func:`fall_back` (polar
    points are decided before the adjustment: :func:`polar_switch`)."""
    seen: list = []
    try:
        with warnings.catch_warnings(record=True) as seen:      # held back, re-emitted below (outside)
            yield
    except MultilatError as e:
        msg = str(e)
        if any(r.search(msg) for r in _COUNT_RULES) and "--model general" not in msg:
            if auto:
                raise CountRuleRefusal(msg) from e
            raise MultilatError(msg + _HINT) from e
        raise
    finally:
        for w in seen:
            msg = str(w.message)
            if (obs is not None and obs.has_angle_observations and any(r.search(msg) for r in _COUNT_RULES)
                    and "--model general" not in msg):
                msg += _HINT
            warnings.warn_explicit(msg, w.category, w.filename, w.lineno)


def is_general_input(path) -> bool:
    """True for a gama-local XML input: suffix ``.xml`` or ``.gkf``, or a file whose first element is
    ``<gama-local>`` (a name without the suffix)."""
    p = Path(path)
    if p.suffix.lower() in (".xml", ".gkf") or p.is_dir():     # a directory: multilat's files (general/files.py)
        return True
    if not p.is_file():
        return False
    from multilat.io import read_input_head

    try:
        head = read_input_head(p, 4096).removeprefix(b"\xef\xbb\xbf").lstrip()
    except MultilatError:
        return False
    return head.startswith(b"<?xml") and b"<gama-local" in head or head.startswith(b"<gama-local")


def given_options(params: dict | None = None) -> list[str]:
    """The names of the parameters (of ``params``; None: every parameter of the running command) given
    on the command line (click's parameter source); [] outside a command."""
    from multilat.cli.report_opt import current_context

    ctx = current_context()
    if ctx is None:
        return []
    given = []
    for name in ctx.params if params is None else params:
        src = ctx.get_parameter_source(name)
        if src is not None and src.name not in ("DEFAULT", "DEFAULT_MAP"):
            given.append(name)
    return given


def option_name(name: str) -> str:
    """The command-line spelling of the parameter ``name`` (``as_json`` -> ``--json``)."""
    return _OPTION.get(name, "--" + name.replace("_", "-"))


#: the former private names (cli/general_propagate.py still imports one)
_given_options, _option_name = given_options, option_name


def run(**params) -> None:
    """The general path of ``multilat adjust`` (``params``: the adjust command's parameters)."""
    params.pop("general_adjust", None)                 # the hook's own import, passed with locals()
    fallback = params.pop("fallback", None)            # --model auto: the distance path's refusal
    listing = params.pop("listing", "flagged")         # --observations: "all"
    path, out = Path(params["observations"]), params["out"]
    xml = is_general_input(path)
    applies, why_not = (APPLIES, WHY_NOT) if xml else (APPLIES_CSV, WHY_NOT_CSV)
    what = "a gama-local input" if xml else "--model general"
    if path.is_dir():                                  # multilat's files for the general network
        why_not, what = {**why_not, **WHY_NOT_DIR}, "a network directory"
    for name in given_options(params):
        if name not in applies:
            why = why_not.get(name, "it belongs to the distance-only adjustment")
            raise MultilatError(f"{option_name(name)} does not apply to {what} ({path}): {why}")
    alpha, vf, a_glob, method = (params[k] for k in ("alpha", "variance_factor", "alpha_global", "test_method"))
    if method is None:
        method = "fixed" if a_glob is not None else "auto"
    from multilat.cli.network_cmd import _check_tests

    _check_tests(alpha, a_glob, method, vf, 10.0)        # the distance path's checks of the test options
    if method == "fixed" and a_glob is None:
        a_glob = 0.05                                      # as the distance path: fixed α_global default 0.05
    from multilat.cli import checks
    from multilat.io import check_output_dir

    checks.table_format(params.get("tables", "auto"), out)
    if params.get("backend", "auto") not in BACKENDS:
        raise MultilatError(f"--backend must be one of {', '.join(BACKENDS)}, got {params['backend']!r}")
    inputs = [path] + [params.get(k) for k in ("points", "references") if params.get(k) is not None]
    if out is not None:
        check_output_dir(out, inputs=inputs)
    from multilat.cli import report_opt

    report_opt.check_report_path(params.get("report"), inputs)
    tests = dict(alpha=alpha, variance_factor=vf, alpha_global=a_glob, strict=params["strict"], method=method,
                 alpha_family=params.get("alpha_family", 0.01), snooping=params.get("snooping", True),
                 variance_components=params.get("variance_components"), backend=params.get("backend", "auto"))
    from multilat.cli.app import progress
    from multilat.network.adjust.approximate.bounds import reporting

    with progress() as p:
        task = p.add_task(f"adjusting {path.name}", total=None)
        with reporting(lambda text: p.update(task, description=text)):
            if xml:
                doc, adj, stats = compute(path, **tests)
            else:
                doc, adj, stats = compute_tables(params, **tests)
    for w in doc["warnings"]:                           # under auto the distance path said them already
        if fallback is None or w.startswith("possible false minimum"):     # (not this one: the general layer's)
            warnings.warn(w, UserWarning, stacklevel=2)
    if fallback is not None:
        doc["notes"] = [f"--model auto: the self-calibrating model {fallback}; adjusted by the general model",
                        *doc["notes"]]
    for e in adj.excluded:
        warnings.warn(f"point {e['id']!r} left out: {e['reason']} ({e['n_obs']} observation row(s) removed)",
                      stacklevel=2)
    from multilat.cli.general_output import print_summary, write_out, write_report
    from multilat.network.adjust.general.report import list_observations

    full, doc = doc, list_observations(doc, listing)
    if out is not None:
        write_out(out, inputs, doc, full, params.get("tables", "auto"))
    write_report(params.get("report"), doc, full, adj, applies)
    from multilat.cli.app import emit_json

    if params["as_json"]:
        emit_json(doc, SCHEMA)
        return
    print_summary(full | {k: doc[k] for k in ("observation_counts", "tables") if k in doc}, adj, stats, out)


def compute(path, *, alpha: float, variance_factor: str, strict: bool, alpha_global: float | None = None,
            method: str | None = None, alpha_family: float = 0.01, snooping: bool = True,
            variance_components: str | None = None, backend: str = "auto"):
    """Read, adjust (undetermined points left out unless ``strict``), variance components if asked,
    data snooping (the default, as the distance path), statistics: (doc, adjustment, stats)."""
    from multilat.network.adjust.general import read_gama_input
    from multilat.network.io.general_files import is_network_dir, read_network_dir

    if is_network_dir(path):                           # `multilat adjust DIR` (multilat's files)
        src = {"kind": "file", "file": str(path), "description": "observations.csv's sigma column and the "
               "correlated blocks' covariances.csv"}
        return _finish(read_network_dir(path), None, str(path), alpha=alpha, variance_factor=variance_factor,
                       strict=strict, alpha_global=alpha_global, method=method, alpha_family=alpha_family,
                       fmt="multilat-files", sigma_source=src, snooping=snooping,
                       variance_components=variance_components, backend=backend)
    return _finish(read_gama_input(path), None, str(path), alpha=alpha, variance_factor=variance_factor,
                   strict=strict, alpha_global=alpha_global, method=method, alpha_family=alpha_family,
                   snooping=snooping, variance_components=variance_components, backend=backend)


def _finish(net, options, source, *, alpha, variance_factor, strict, alpha_global, fmt="gama-local",
            sigma_source=None, method=None, alpha_family=0.01, snooping=True, variance_components=None,
            backend="auto"):
    from multilat.network.adjust.general import adjust_network, to_json
    from multilat.network.adjust.general.snooping import snoop
    from multilat.network.adjust.general.variance import estimate
    from multilat.vocabulary import stamp

    if backend != "auto":                    # --backend dense|sparse (AdjustOptions.backend)
        import dataclasses

        from multilat.network.adjust.general.adjust import AdjustOptions

        options = AdjustOptions(backend=backend) if options is None else dataclasses.replace(options, backend=backend)
    adj = adjust_network(net, options=options, strict=strict)
    vcomp = None
    if variance_components is not None:      # snooping off during the estimation, as the distance path
        vcomp = estimate(adj.network, grouping=variance_components, options=options)
        again = adjust_network(vcomp.network, options=options, strict=strict)
        adj = type(adj)(again.network, again.system, again.result, net, tuple(adj.excluded) + tuple(again.excluded))
    sn = snoop(net, options=options, strict=strict, alpha=alpha, variance_factor=variance_factor, method=method,
               alpha_global=alpha_global, alpha_family=alpha_family, snooping=snooping, adjustment=adj)
    adj, stats = sn.adjustment, sn.stats
    doc = to_json(adj, stats, source=source, snooping=sn, variance=vcomp)
    from multilat.network.adjust.general.run import false_minimum_warning

    doc = {"model": "general", **doc, "format": fmt, "warnings": [w for w in (false_minimum_warning(adj),) if w]}
    if sigma_source is not None:
        doc["sigma_source"] = sigma_source
    return stamp(doc, SCHEMA), adj, stats


def compute_tables(params: dict, *, alpha: float, variance_factor: str, strict: bool,
                   alpha_global: float | None = None, method: str | None = None, alpha_family: float = 0.01,
                   snooping: bool = True, variance_components: str | None = None, backend: str = "auto"):
    """A multilat observation CSV (with ``--points``, ``--references`` ...) adjusted by the general
    layer: (doc, adjustment, stats). ``params``: the adjust command's parameters."""
    from multilat.cli import checks
    from multilat.cli.network_cmd import parse_fixed_offsets, with_levelled
    from multilat.network.io.files import read_points, read_reference_lengths
    from multilat.network.adjust.general.from_tables import network_from_tables
    from multilat.network.model.sigma_source import default_warning, describe

    path = Path(params["observations"])
    seed = params.get("seed", 0)
    checks.seed(seed)
    obs, corrected, src = _read_observations(path, params, variance_components)
    obs = with_levelled(obs, params.get("levelled"))
    refs = read_reference_lengths(params["references"]) if params.get("references") is not None else None
    if refs is not None and not params.get("scale_bar"):
        raise MultilatError("--references does not apply to --model general without --scale-bars: the "
                            "comparison with reference lengths is not done on the general path (give "
                            "--scale-bars to adjust them as observations)")
    if params.get("scale_bar") and refs is None:
        raise MultilatError("--scale-bars needs --references FILE (the bars' lengths with u_m)")
    pts = read_points(params["points"]) if params.get("points") is not None else None
    what = "station" if obs.station_heads is None else "head"
    fix = params.get("fix_offsets_um")
    offsets = None if fix is None else parse_fixed_offsets(fix, obs.head_ids, what=what)
    scales, fixed_scale = params.get("scales", False), params.get("fixed_scale")
    if fixed_scale is not None:
        if not scales:
            raise MultilatError("--fixed-scale goes with --scales")
        if fixed_scale not in obs.head_ids:
            raise MultilatError(f"--fixed-scale: unknown {what} id {fixed_scale!r} ({what}s: "
                                f"{', '.join(obs.head_ids)})")
        scales = [h for h in obs.head_ids if h != fixed_scale]
    def build(o):
        return network_from_tables(o, points=pts, datum=params.get("datum", "free"), offsets=offsets, scales=scales,
                                   scale_bars=refs, rng=seed, source=str(path), backend=backend)

    net, options = build(obs)
    src_doc = {"kind": str(src.get("kind", "file column")), "file": str(path),
               "description": describe(src) if src else "the file's sigma_m column"}
    from multilat.network.adjust.distance import azimuth_sense as _az

    sense = _az.resolve(params.get("azimuth_sense"), params.get("instrument"))
    tests = dict(alpha=alpha, variance_factor=variance_factor, alpha_global=alpha_global, method=method,
                 alpha_family=alpha_family)
    try:
        doc, adj, stats = _finish(net, options, str(path), strict=strict, fmt="multilat-csv", sigma_source=src_doc,
                                  snooping=snooping, variance_components=variance_components, backend=backend,
                                  **tests)
    except MultilatError as e:                       # refused, or snooping refused: azimuths of the other sense?
        if hint := _sense_hint(obs, sense, build, getattr(e, "sigma0", None), strict, tests):
            raise MultilatError(f"{e}; {hint}") from None
        raise
    if note := default_warning(src, path):           # the distance path's words and key (JSON "warnings")
        doc["warnings"] = [note, *doc["warnings"]]
    if corrected is not None:
        doc["notes"] = [*doc["notes"], f"raw readings corrected as by `multilat correct` ({obs.n_obs} distances); "
                        "adjusted with each distance's σ, as the distance path; the sensors' correlations "
                        "(with_correlations) are computed on the distance path only"]
    _datum_321_words(doc, params.get("datum", "free"))
    if doc["global_test"]["passed"] is False and (hint := _sense_hint(obs, sense, build, doc["sigma0"], strict, tests)):
        doc["warnings"] = [*doc["warnings"], hint]
    az_rec = _az.record(obs, *sense)
    if az_rec is not None:
        doc["azimuth_sense"] = az_rec
    return doc, adj, stats


def _read_observations(path: Path, params: dict, variance_components: str | None):
    """The observations as the distance path reads them (:func:`multilat.campaign.propagation.
    read_campaign`: an observation CSV, or raw readings corrected with ``--environment``, ``--heights``
    ...), with its rules (``--instrument`` applied or refused, no variance components on raw readings):
    (obs, corrected or None, the σ source record). ``params`` without the raw options is a caller
    other than ``adjust`` (``propagate --model general``): raw readings refused, ``--instrument`` its own."""
    from multilat.campaign.propagation import read_campaign
    from multilat.cli import checks
    from multilat.cli.network_cmd import _check_instrument_used

    sigma_um = params.get("sigma_um")
    checks.sigma_um(sigma_um)
    src: dict = {}
    raw = {k: params[k] for k in ("environment", "heights", "formula", "extrapolate", "max_gap_s") if k in params}
    if not raw:                                      # a caller without the raw options (propagate --model general)
        from multilat.campaign.raw import is_raw_file

        if is_raw_file(path):
            raise MultilatError(f"--model general does not apply to raw readings ({path}) here: correct them "
                                "first (multilat correct), or use the distance path")
    instrument = params.get("instrument")
    obs, corrected = read_campaign(path, sigma_m=None if sigma_um is None else sigma_um * 1e-6, instrument=instrument,
                                   sigma_source=src, azimuth_sense=params.get("azimuth_sense"), **raw)
    if corrected is not None:                        # raw readings: the distance path's reader and rules
        src["defaulted"] = instrument is None
        if variance_components is not None:
            raise MultilatError("--variance-components applies to an observation file: raw readings get "
                                "their σ from the distance model and the sensors")
    if raw:                                          # adjust's rule (propagate's --noise model uses it)
        _check_instrument_used(instrument, path, obs, src, corrected)
    return obs, corrected, src


def _sense_hint(obs, sense, build, sigma0, strict, tests) -> str | None:
    """On a network with azimuth observations whose sense nobody declared (``sense``: the resolved
    sense and its source), after an implausible adjustment (refused: ``sigma0`` None; snooping refused
    or the global test failed: its σ0), the hint naming ``--azimuth-sense cw`` when the azimuths
    negated fit clearly better (:func:`multilat.network.adjust.general.run.sense_hint`; one adjustment)."""
    from multilat.network.adjust.distance import azimuth_sense as _az
    from multilat.network.adjust.general.run import sense_hint

    if sense[1] != _az.UNDECLARED or obs.sigma_azimuth_rad is None or not np.isfinite(obs.sigma_azimuth_rad).any():
        return None
    try:
        with warnings.catch_warnings():              # the file's warnings were said on the first reading
            warnings.simplefilter("ignore")
            net, options = build(_az.apply(obs, "cw"))
    except MultilatError:
        return None
    return sense_hint(net, sigma0, options=options, strict=strict, **tests)


def _datum_321_words(doc: dict, datum: str) -> None:
    """``--datum 321:A,B,C``: the JSON's ``datum`` and ``frame`` in the distance path's words (the
    general layer holds the 6 coordinates as partly fixed points: :func:`.from_tables.in_frame_321`)."""
    from multilat.network.model.datum import parse_datum
    from multilat.network.model.frame_words import frame_words

    d = parse_datum(datum)
    if d.kind == "321":
        doc["datum"] = f"{d.describe()} (minimal constraints; the other datums' cofactors S-transformed onto it)"
        doc["frame"] = {**doc["frame"], **{k: v for k, v in frame_words(d).items() if k != "scale"}}
