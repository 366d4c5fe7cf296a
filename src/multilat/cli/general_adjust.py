"""``multilat adjust NET.xml``: a gama-local XML input adjusted by the general network layer
(:mod:`multilat.network.general`): parse, call, print.

Reached from the ``adjust`` command (:mod:`multilat.cli.network_cmd`) when its input is a gama-local
file (suffix ``.xml`` / ``.gkf``, or a ``<gama-local>`` root element). The options that apply are
``--json``, ``--out DIR``, ``--alpha``, ``--variance-factor``, ``--test-method``, ``--alpha-global``
and ``--strict``; every other option of
the distance-only path is refused in one line naming it (never silently ignored): the file itself
carries the datum (``fix=``/``adj=``), the σ (``stdev=`` and ``<points-observations>``) and the
approximate coordinates.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from multilat.errors import MultilatError

__all__ = ["is_general_input", "run", "APPLIES", "WHY_NOT", "SCHEMA"]

#: the document's schema name: ``"schema": "multilat.adjust-general/1"`` (not the distance path's
#: ``multilat.adjust``: the keys differ, so a reader can tell them apart)
SCHEMA = "adjust-general"

#: the adjust command's parameters that the general path reads
APPLIES = ("observations", "as_json", "out", "alpha", "variance_factor", "strict", "alpha_global", "test_method")
_OPTION = {"as_json": "--json", "fix_offsets_um": "--fix-offsets-um", "scale_bar": "--scale-bars",
           "snooping": "--snooping/--no-snooping"}
#: why an option of the distance-only path is refused here (the default reason for the others)
WHY_NOT = {
    "datum": "the datum of a gama-local file is its fix=/adj= attributes (upper-case adj = datum points)",
    "points": "the file's <point> elements carry the coordinates", "sigma_um": "the σ are the file's stdev=",
    "instrument": "the σ are the file's stdev=", "snooping": "data snooping is not done on the general path yet",
    "report": "the HTML report is built from the distance path's result",
}


def is_general_input(path) -> bool:
    """True for a gama-local XML input: suffix ``.xml`` or ``.gkf``, or a file whose first element is
    ``<gama-local>`` (a name without the suffix)."""
    p = Path(path)
    if p.suffix.lower() in (".xml", ".gkf"):
        return True
    if not p.is_file():
        return False
    from multilat.io import read_input_head

    try:
        head = read_input_head(p, 4096).removeprefix(b"\xef\xbb\xbf").lstrip()
    except MultilatError:
        return False
    return head.startswith(b"<?xml") and b"<gama-local" in head or head.startswith(b"<gama-local")


def _given_options(params: dict) -> list[str]:
    """The names of the parameters given on the command line (click's parameter source)."""
    from multilat.cli.report_opt import _current_context

    ctx = _current_context()
    if ctx is None:
        return []
    given = []
    for name in params:
        src = ctx.get_parameter_source(name)
        if src is not None and src.name not in ("DEFAULT", "DEFAULT_MAP"):
            given.append(name)
    return given


def _option_name(name: str) -> str:
    return _OPTION.get(name, "--" + name.replace("_", "-"))


def run(**params) -> None:
    """The general path of ``multilat adjust`` (``params``: the adjust command's parameters)."""
    params.pop("general_adjust", None)                 # the hook's own import, passed with locals()
    for name in _given_options(params):
        if name not in APPLIES:
            why = WHY_NOT.get(name, "it belongs to the distance-only adjustment")
            raise MultilatError(f"{_option_name(name)} does not apply to a gama-local input "
                                f"({params['observations']}): {why}")
    path, out = Path(params["observations"]), params["out"]
    alpha, vf, a_glob, method = (params[k] for k in ("alpha", "variance_factor", "alpha_global", "test_method"))
    if method is None:
        method = "fixed" if a_glob is not None else "b-method"
    from multilat.cli.network_cmd import _check_tests

    _check_tests(alpha, a_glob, method, vf, 10.0)        # the distance path's checks of the test options
    if method == "fixed" and a_glob is None:
        a_glob = 0.05                                      # as the distance path: fixed α_global default 0.05
    from multilat.io import check_output_dir

    if out is not None:
        check_output_dir(out, inputs=[path])
    doc, adj, stats = compute(path, alpha=alpha, variance_factor=vf, alpha_global=a_glob, strict=params["strict"])
    for e in adj.excluded:
        warnings.warn(f"point {e['id']!r} left out: {e['reason']} ({e['n_obs']} observation row(s) removed)",
                      stacklevel=2)
    if out is not None:
        write_out(out, path, doc)
    from multilat.cli.app import emit_json

    if params["as_json"]:
        emit_json(doc, SCHEMA)
        return
    print_summary(doc, adj, stats, out)


def compute(path, *, alpha: float, variance_factor: str, strict: bool, alpha_global: float | None = None):
    """Read, adjust (undetermined points left out unless ``strict``), statistics: (doc, adjustment, stats)."""
    from multilat.network.general import adjust_network, read_gama_input, statistics, to_json
    from multilat.vocabulary import stamp

    net = read_gama_input(path)
    adj = adjust_network(net, strict=strict)
    stats = statistics(adj.system, adj.result, alpha=alpha, variance_factor=variance_factor,
                       alpha_global=alpha_global)
    return stamp(to_json(adj, stats, source=str(path)), SCHEMA), adj, stats


def write_out(out, path, doc) -> None:
    """``result.json`` and ``points.csv`` into ``out``, all or nothing (:func:`multilat.io.staging_dir`)."""
    from multilat.io import staging_dir, write_csv_atomic, write_json_atomic

    with staging_dir(out, inputs=[path]) as tmp:
        write_json_atomic(tmp / "result.json", doc)
        rows = [[p, *v["xyz_m"], *v["xyz_std_m"], v["semi_axes_95_m"][2], v["status"], " ".join(v["roles"])]
                for p, v in doc["points"].items()]
        write_csv_atomic(tmp / "points.csv", ["point", "x_m", "y_m", "z_m", "x_std_m", "y_std_m", "z_std_m",
                                              "semi_axis_max_95_m", "status", "roles"], rows)


def print_summary(doc, adj, stats, out) -> None:
    from rich.table import Table

    from multilat.cli.app import console

    say = lambda s: console.print(s, markup=False)  # noqa: E731
    kinds = {}
    for o in doc["observations"]:
        kinds[o["kind"]] = kinds.get(o["kind"], 0) + 1
    say(f"adjusted {doc['n_points']} points from {doc['n_obs']} observation rows ("
        + ", ".join(f"{n} {k.replace('_', ' ')}" for k, n in kinds.items()) + f") of {doc['input']} (gama-local)")
    say(f"  datum: {doc['datum']}")
    gt, t = doc["global_test"], doc["tests"]
    if gt["statistic"] is None:
        say(f"  σ0 = {doc['sigma0']:.4g}, dof = {doc['dof']} (no global test without redundancy)")
    elif doc["variance_factor"] == "unknown":
        say(f"  σ0 = {doc['sigma0']:.4f} (estimated: variance factor unknown; covariances and MDBs scaled by σ0²), "
            f"dof = {doc['dof']}")
        say(f"  global χ² test (information only): {gt['statistic']:.2f} vs {gt['critical']:.2f} "
            f"(α = {gt['alpha']:.3g})")
        say(f"  Pope's τ-test: α0 = {t['alpha0']:g}, critical |τ| {t['critical']:.3f}")
    else:
        say(f"  σ0 = {doc['sigma0']:.4f} (ratio to the a-priori σ), dof = {doc['dof']}; global χ² test: "
            f"{gt['statistic']:.2f} {'<=' if gt['passed'] else '>'} {gt['critical']:.2f} (α = {gt['alpha']:.3g}, "
            f"{'B-method' if gt['method'] == 'b-method' else 'fixed α'}): {'passed' if gt['passed'] else 'FAILED'}")
        say(f"  w-test: α0 = {t['alpha0']:g}, critical |w| {t['critical']:.2f}, λ0 = {t['lambda0']:.2f}")
    red = stats.redundancy
    say(f"  redundancy {max(red.min(), 0.0):.3f}..{red.max():.3f}; {int((red <= 1e-9).sum())} uncontrolled row(s) "
        f"(r = 0); {t['n_failed']} test(s) above the critical value (listed in the JSON; no data snooping here)")
    for e in doc["excluded"]:
        say(f"  left out: point {e['id']} ({e['reason']}; {e['n_obs']} observation rows)")
    for note in doc["notes"]:
        say(f"  note: {note}")
    _worst(say, doc, stats)
    tb = Table(title="points", title_justify="left")
    for c in ("point", "status", "roles", "x (m)", "y (m)", "z (m)", "95 % max (mm)"):
        tb.add_column(c, justify="right")
    for p, v in doc["points"].items():
        x = v["xyz_m"]
        tb.add_row(p, v["status"], ",".join(v["roles"]), f"{x[0]:.5f}", f"{x[1]:.5f}", f"{x[2]:.5f}",
                   f"{v['semi_axes_95_m'][2] * 1e3:.2f}")
    console.print(tb)
    if out is not None:
        say(f"results written to {out}")


def _worst(say, doc, stats, n: int = 3) -> None:
    """The rows with the largest |test statistic|."""
    order = np.argsort(-np.abs(stats.statistic))[:n]
    obs = doc["observations"]
    parts = []
    for k in order:
        o = obs[int(k)]
        ends = "->".join(o[e] for e in ("from", "to", "point", "bs", "fs") if e in o)
        parts.append(f"{o['kind'].replace('_', ' ')} {ends} {doc['tests']['test']} = {o['statistic']:+.2f}")
    if parts:
        say("  largest tests: " + "; ".join(parts))
