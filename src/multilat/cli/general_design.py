"""``multilat design --evaluate NET.xml`` (or ``multilat design NET.xml``): the pre-analysis of a planned
general network (:mod:`multilat.network.design.general_preanalysis`) from the command line: parse, call, print.

The input is a gama-local file or a directory of multilat's network files (``docs/general-files.md``)
whose points carry the *planned* coordinates of every point and whose observations carry their σ; the
observed values in it are not used (the model at the planned coordinates replaces them). The datum is
the file's (``fix=``/``adj=``, upper-case ``adj`` = datum points). Printed: per point the standard
deviations and the 95 % ellipsoid, the weak rows (redundancy below R_MIN or MDB above MDB_LIMIT_SIGMA
σ) and the undetermined points, left out and named. ``--json``: the document
``multilat.design-general/1``. The options of the layout search (``--seed``, ``--simulate``,
``--noise``, ``--out``, ``--report``) do not apply and are refused in one line.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from multilat.errors import MultilatError

__all__ = ["wants_general", "run", "compute", "SCHEMA"]

#: the document's schema name: ``"schema": "multilat.design-general/1"``
SCHEMA = "design-general"
#: the design command's parameters that the general pre-analysis reads
_APPLIES = ("config", "evaluate", "as_json")
#: the row keys of the weak rows (the adjustment's observation records, without the residual tests)
_ROW_KEYS = ("kind", "from", "to", "bs", "fs", "point", "axis", "component", "set", "label", "unit", "sigma",
             "redundancy", "mdb", "mdb_sigma", "shift_max_m", "shift_point")


def wants_general(config, evaluate) -> bool:
    """True when the design command is given a planned general network (gama-local or multilat's
    network directory) as ``--evaluate`` or as its argument; a TOML config with a general network is
    refused in one line."""
    from multilat.cli.general_adjust import is_general_input

    ev = evaluate is not None and is_general_input(evaluate)
    cf = config is not None and is_general_input(config)
    if ev and config is not None:
        raise MultilatError(f"--evaluate {evaluate}: a planned network is evaluated on its own; leave out the "
                            f"design config {config}")
    if cf and evaluate is not None:
        raise MultilatError(f"--evaluate {evaluate} does not apply to a planned network ({config}): its points "
                            "carry the coordinates")
    return ev or cf


def run(**params) -> None:
    """The general pre-analysis of ``multilat design`` (``params``: the design command's parameters)."""
    from multilat.cli.general_adjust import given_options, option_name

    params.pop("general_design", None)                 # the hook's own import, passed with locals()
    for name in given_options(params):
        if name not in _APPLIES:
            raise MultilatError(f"{option_name(name)} does not apply to the pre-analysis of a planned network: "
                                "it belongs to the layout search of a design config")
    path = Path(params["evaluate"] if params["evaluate"] is not None else params["config"])
    doc, pred = compute(path)
    for e in pred.undetermined:
        warnings.warn(f"point {e['id']!r} left out: {e['reason']} ({e['n_obs']} observation row(s) removed)",
                      stacklevel=2)
    if params["as_json"]:
        from multilat.cli.app import emit_json

        emit_json(doc, SCHEMA)
        return
    print_summary(doc)


def compute(path: Path):
    """Read the planned network and predict it: (document, GeneralPrediction)."""
    from multilat.network.adjust.general import read_gama_input
    from multilat.network.io.general_files import is_network_dir, read_network_dir
    from multilat.network.design.general_preanalysis import predict

    net = read_network_dir(path) if is_network_dir(path) else read_gama_input(path)
    try:
        pred = predict(net)
    except MultilatError as e:
        raise MultilatError(f"{path}: {e}") from None
    return document(pred, str(path), "multilat-files" if is_network_dir(path) else "gama-local"), pred


def document(pred, source: str, fmt: str) -> dict:
    """The ``multilat.design-general/1`` document of a :class:`~multilat.network.design.general_preanalysis.GeneralPrediction`."""
    from multilat.network.adjust.general.report import datum_words, observation_rows, status_words

    res, st, sysm = pred.result, pred.stats, pred.system
    pts = sysm.network.points
    points = {}
    for i, p in enumerate(res.ids):
        cov = st.cov_m2[i]
        points[p] = {"xyz_m": res.xyz_m[i], "status": status_words(pts.status[i]),
                     "xyz_std_m": np.sqrt(np.clip(np.diag(cov), 0, None)), "cov_m2": cov,
                     "semi_axes_95_m": st.semi_axes_95_m[i]}
    std = np.sqrt(np.clip(res.cofactor_diagonal(), 0, None))
    params = {n: {"std": float(s), "unit": "rad" if n.split(":")[0] in ("orientation", "omega", "phi", "kappa")
                  else ("1" if n.startswith("scale:") else "m")}
              for n, s in zip(res.free_names, std) if n[:2] not in ("x:", "y:", "z:")}
    rows = observation_rows(sysm, st)
    weak = [{k: r[k] for k in _ROW_KEYS if k in r} for r, w in zip(rows, pred.weak) if w]
    return {"model": "general", "input": source, "format": fmt, "datum": datum_words(pts, res),
            "n_points": len(res.ids), "n_rows": sysm.n_rows, "n_free": sysm.n_free, "defect": res.defect,
            "dof": res.dof, "points": points, "parameters": params,
            "reliability": {"redundancy_min": float(st.redundancy.min()) if st.redundancy.size else None,
                            "mdb_sigma_max": _finite(np.max(st.mdb_sigma)) if st.mdb_sigma.size else None,
                            "r_min": pred.r_min, "mdb_limit_sigma": pred.mdb_limit_sigma, "n_weak": len(weak)},
            "weak_rows": weak,
            "undetermined": [{"id": e["id"], "reason": e["reason"], "n_obs": e["n_obs"]} for e in pred.undetermined]}


def _finite(v):
    v = float(v)
    return v if np.isfinite(v) else None


def print_summary(doc: dict) -> None:
    from rich.table import Table

    from multilat.cli.app import console

    say = lambda s: console.print(s, markup=False)  # noqa: E731
    say(f"pre-analysis of {doc['n_points']} planned points, {doc['n_rows']} observation rows, of {doc['input']} "
        f"({doc['format']}; general model, σ a priori, no measurements)")
    say(f"  datum: {doc['datum']}; dof = {doc['dof']}")
    t = Table("point", "status", "σx µm", "σy µm", "σz µm", "95 % semi-axes µm")
    for p, v in doc["points"].items():
        s = v["xyz_std_m"] * 1e6
        t.add_row(p, v["status"], *(f"{x:.2f}" for x in s), " ".join(f"{x * 1e6:.2f}" for x in v["semi_axes_95_m"]))
    console.print(t)
    rel = doc["reliability"]
    if rel["redundancy_min"] is not None:
        mdb = "∞" if rel["mdb_sigma_max"] is None else f"{rel['mdb_sigma_max']:.3g}"
        say(f"  redundancy min {rel['redundancy_min']:.3g}, largest MDB {mdb} σ")
    if doc["weak_rows"]:
        say(f"  {rel['n_weak']} weak row(s) (redundancy < {rel['r_min']:g} or MDB > {rel['mdb_limit_sigma']:g} σ: "
            "a blunder in it would not show):")
        for r in doc["weak_rows"][:12]:
            ends = "-".join(str(r[k]) for k in ("from", "to", "point") if k in r)
            mdb = "∞" if r["mdb_sigma"] is None else f"{r['mdb_sigma']:.3g} σ"
            say(f"    {r['kind']} {ends} {r.get('component', r.get('axis', ''))}: r = {r['redundancy']:.3g}, "
                f"MDB {mdb}")
        if len(doc["weak_rows"]) > 12:
            say(f"    ... and {len(doc['weak_rows']) - 12} more (--json lists them)")
    for e in doc["undetermined"]:
        say(f"  undetermined: {e['id']}: {e['reason']} ({e['n_obs']} observation row(s) left out)")
