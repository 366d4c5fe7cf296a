"""One vocabulary for every output key and column: ``quantity[_statistic][_qualifier]_unit``.

The convention (``docs/conventions.md``, "Output keys") in code, so that the tests can hold every
command's JSON to it:

* **quantity** first, in words (``offset``, ``xyz``, ``interpoint``, ``error``, ``length``); then the
  **statistic** (:data:`STATISTICS`: ``std`` = standard uncertainty / standard deviation, k = 1; ``u95``
  expanded uncertainty at 95 %; ``cov``; ``mean``; ``rms``; ``se`` the Monte Carlo standard error of the
  statistic before it; ``min``/``max`` over a set; ``95`` a 95 % region or interval); then the
  **method** qualifier (``lin`` first-order / linear, ``mc`` Monte Carlo) when both exist; then the
  **unit** (:data:`UNITS`; none for a dimensionless number or a text). Examples: ``offset_m``,
  ``offset_std_m``, ``xyz_m``, ``cov_m2``, ``std_mc_m``, ``std_lin_m``, ``std_mc_se_m``,
  ``semi_axes_95_m``, ``u95_max_m``, ``error_rms_m``.
* Counts are ``n_<things>``; the seed of a run is ``seed`` (the root entropy, an integer).
* A JSON object keyed by ids (stations, targets, heads, pairs) is an *id map*: its keys are ids, not
  names (:data:`ID_MAPS` lists the keys that hold one).
* Every JSON document starts with ``"schema": "multilat.<command>/<version>"`` (:func:`stamp`,
  :func:`schema_id`); the JSON Schema of each command is shipped in ``multilat/schemas/<command>.json``,
  generated from its typed model (:mod:`multilat.schemas.models`).

:data:`RENAMED` lists the names this convention replaced (removed, not aliased); :func:`key_problems`
refuses them and anything else outside the convention.
"""

from __future__ import annotations

import re

__all__ = ["SCHEMA_VERSION", "SCHEMA_VERSIONS", "schema_id", "schema_version", "STATISTICS", "QUALIFIERS", "UNITS", "RENAMED", "ID_MAPS", "stamp",
           "key_problems", "document_problems"]

#: Version of the output schemas (bumped when a key changes meaning or name).
SCHEMA_VERSION = 1
#: A command's schema version where it is not :data:`SCHEMA_VERSION`: bumped, with the ``schema`` literal of
#: its model (:mod:`multilat.schemas.models`), when the shape of its document changes.
SCHEMA_VERSIONS: dict[str, int] = {
    "adjust": 3,                # /2: JSON for summaries, tables for rows (issue 29); /3: outliers' index
    "propagate": 2,             # /2: points an id map, as adjust's targets and propagate-general's
    "adjust-general": 3,        # /2: the same rule for the general path (observation_counts, tables); /3: index
    "propagate-general": 2,     # /2: n_full_gauss_newton -> n_retried (one Monte Carlo record)
}


def schema_version(command: str) -> int:
    """The schema version of ``command``'s document."""
    return SCHEMA_VERSIONS.get(command, SCHEMA_VERSION)

STATISTICS = ("std", "var", "cov", "mean", "rms", "u95", "se", "min", "max", "median", "95")
QUALIFIERS = ("lin", "mc")
UNITS = ("m", "m2", "rad", "s", "c", "pa", "hpa", "pct", "ppm", "nm", "um", "hz", "um_per_m", "c_per_m",
         "per_c")

#: Old output names and what replaced them (removed, not aliased).
RENAMED = {
    "offset_u_m": "offset_std_m", "u_offset_m": "offset_std_m", "scale_u": "scale_std",
    "lin_std_m": "std_lin_m", "mc_std_m": "std_mc_m", "mc_mean_m": "mean_mc_m",
    "mc_std_se_m": "std_mc_se_m", "seed_entropy": "seed",
    "combined_std_m": "error_rms_m", "combined_sd_m": "error_std_m", "combined_mean_m": "error_mean_m",
    "means_m": "component_error_mean_m", "stds_m": "component_error_std_m",
    "ell95_a_m": "semi_axis_1_95_m", "ell95_b_m": "semi_axis_2_95_m", "ell95_c_m": "semi_axis_3_95_m",
    "a1_95_m": "semi_axis_1_95_m", "a2_95_m": "semi_axis_2_95_m", "a3_95_m": "semi_axis_3_95_m",
    "u_x_m": "x_std_m", "u_y_m": "y_std_m", "u_z_m": "z_std_m",
    "coverage_mc_ellipsoid": "ellipsoid_coverage_mc", "coverage_lin_ellipsoid": "ellipsoid_coverage_lin",
    "u_m": "length_std_m", "reference_u_m": "reference_std_m", "rms_residual_m": "residual_rms_m",
    "interpoint_std_sem_m": "interpoint_std_se_m", "predicted_rms_std_m": "interpoint_std_lin_rms_m",
    "pair_rms_error_m": "pair_error_rms_m", "offset_rms_error_m": "offset_error_rms_m",
    "max_std_m": "std_max_m", "max_mean_error_m": "error_mean_max_m", "mean_error_m": "error_mean_m",
    "l0_mean_error_m": "l0_error_mean_m", "sim_std_m": "std_mc_m", "sim_mean_error_m": "error_mean_mc_m",
    "std_predicted_m": "std_lin_m", "std_ratio_max": "ratio_max", "std_ratio_min": "ratio_min",
    "max_target_std_m": "target_std_max_m", "max_target_std_diagonal_m": "target_std_diagonal_max_m",
    "u95_max_predicted_m": "u95_max_lin_m", "max_abs_z": "z_abs_max", "mean_z": "z_mean",
    "std_ratio_mean": "ratio_mean", "max_abs_z_vs_linear_with_drawn_std": "z_drawn_abs_max",
}

#: Keys whose object is keyed by ids (stations, targets, heads, pairs, components), not by names.
ID_MAPS = frozenset({"stations", "targets", "heads", "interpoint_std_m", "paper_m", "pair_error_rms_m",
                     "offset_error_rms_m", "components", "component_error_mean_m", "component_error_std_m",
                     "sensitivity_um_per_m", "inputs", "offsets_m", "start_stations",
                     "points", "parameters"})     # adjust-general: {point id: ...}, {"offset:H1": ...}

_SNAKE = re.compile(r"^[a-z][a-z0-9]*(_[a-z0-9]+)*$")
_FORBIDDEN_TOKENS = frozenset({"u", "sd", "sem", "entropy", "ell95", "sim"})
_LEADING = frozenset(STATISTICS) | frozenset(QUALIFIERS) | {"sim"}
_UNIT_TOKENS = frozenset(t for u in UNITS for t in u.split("_"))


def schema_id(command: str) -> str:
    """``"multilat.<command>/<version>"``: the ``schema`` of ``command``'s documents."""
    return f"multilat.{command}/{schema_version(command)}"


def stamp(doc: dict, command: str) -> dict:
    """``doc`` with ``"schema": "multilat.<command>/<version>"`` first (a new dict)."""
    return {"schema": schema_id(command), **{k: v for k, v in doc.items() if k != "schema"}}


def key_problems(key: str) -> list[str]:
    """Why ``key`` breaks the convention (empty when it follows it)."""
    out = []
    if key in RENAMED:
        return [f"{key!r} was renamed {RENAMED[key]!r}"]
    if not _SNAKE.match(key):
        return [f"{key!r} is not snake_case"]
    tok = key.split("_")
    bad = _FORBIDDEN_TOKENS.intersection(tok)
    if bad:
        out.append(f"{key!r} uses {sorted(bad)[0]!r} (say std, se or what the statistic is)")
    if tok[0] in _LEADING and not all(t in _LEADING or t in _UNIT_TOKENS for t in tok):
        out.append(f"{key!r} puts the statistic {tok[0]!r} before the quantity")
    return out


def document_problems(doc, path: str = "$") -> list[str]:
    """Every key of a JSON document (recursively) that breaks the convention, with its path; the keys
    of id maps (:data:`ID_MAPS`) are ids and only their values are checked."""
    out = []
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += [f"{path}.{k}: {p}" for p in key_problems(str(k))]
            if k in ID_MAPS and isinstance(v, dict):
                for ident, sub in v.items():
                    out += document_problems(sub, f"{path}.{k}[{ident}]")
            else:
                out += document_problems(v, f"{path}.{k}")
    elif isinstance(doc, list):
        for i, v in enumerate(doc[:50]):
            out += document_problems(v, f"{path}[{i}]")
    return out
