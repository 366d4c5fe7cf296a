"""The per-observation rows of an adjustment (schema ``multilat.adjust/3``): one definition of the
columns, written whole to the ``observations`` table of ``adjust --out`` (Parquet or CSV) and, in the
``--json`` document, only for the observations that matter (:func:`flagged`), with their counts.

An observation *matters* when it was rejected by data snooping, fails its w-test at the end (a
member of :attr:`AdjustmentResult.w_failure_groups`), or is poorly controlled (redundancy below
``r_min`` or MDB above ``mdb_limit_sigma`` σ: :attr:`Reliability.poor_obs`). Observations of points
left out before solving are not rows of the adjusted network: :func:`excluded_rows` lists them from
the observations given. Each row carries ``index``, its row in the table, so the JSON rows join the
table's.
"""

from __future__ import annotations

import numpy as np

__all__ = ["FLAGS", "observation_columns", "observation_flags", "flagged", "observation_counts",
           "excluded_rows", "observation_extremes", "largest_w", "LARGEST_W_ROWS"]

#: the boolean columns that make a row matter, in the order the counts name them
FLAGS = ("rejected", "w_failed", "poorly_controlled")

#: rows of the ``largest_w`` summary
LARGEST_W_ROWS = 10


def observation_flags(res) -> dict[str, np.ndarray]:
    """``rejected``, ``w_failed``, ``poorly_controlled`` (bool, (m,)) of every observation."""
    m = res.obs.n_obs
    failed = np.zeros(m, bool)
    for g in res.w_failure_groups:
        failed[np.asarray(g, np.int64)] = True
    poor = np.zeros(m, bool)
    rel = res.reliability
    if rel is not None and len(rel.poor_obs):
        poor[np.asarray(rel.poor_obs, np.int64)] = True
    return {"rejected": ~np.asarray(res.used, bool), "w_failed": failed, "poorly_controlled": poor}


def observation_columns(res) -> dict:
    """The columns of the observations table, one row per observation of the adjusted network:
    ``index``, the observation (``station``, ``target``, ``distance_m``, ``sigma_m``), ``residual_m``,
    ``redundancy``, ``w``, ``mdb_m``, the flags (:data:`FLAGS`) and, with reliability, ``mdb_sigma``,
    ``bias_to_noise``, ``shift_max_m``, ``shift_point``. Label columns are ``(labels, index)``."""
    o = res.obs
    cols = {"index": np.arange(o.n_obs, dtype=np.int64),
            "station": (o.station_ids, o.station_index), "target": (o.target_ids, o.target_index),
            "distance_m": o.distance_m, "sigma_m": o.sigma_m, "residual_m": res.residuals_m,
            "redundancy": res.redundancy, "w": res.w, "mdb_m": res.mdb_m, **observation_flags(res)}
    rel = res.reliability
    if rel is not None:
        labels, index = np.unique(np.asarray(rel.shift_point, dtype=str), return_inverse=True)
        cols.update(mdb_sigma=rel.mdb_sigma, bias_to_noise=rel.bnr, shift_max_m=rel.shift_max_m,
                    shift_point=(tuple(str(x) for x in labels), index.ravel()))
    return cols


def take(cols: dict, rows: np.ndarray) -> dict:
    """``cols`` restricted to ``rows`` (label columns keep their labels)."""
    return {k: (v[0], np.asarray(v[1])[rows]) if isinstance(v, tuple) else np.asarray(v)[rows]
            for k, v in cols.items()}


def flagged(cols: dict) -> np.ndarray:
    """The rows that matter: any of :data:`FLAGS` set (sorted row numbers)."""
    any_ = np.zeros(len(cols["index"]), bool)
    for f in FLAGS:
        any_ |= cols[f]
    return np.flatnonzero(any_)


def observation_counts(cols: dict, listed: int, listing: str, n_excluded: int) -> dict:
    """The counts beside the listed rows: every observation, used, each flag, any flag, those of
    points left out before solving, and how many rows the document lists (``listing`` "flagged" or
    "all")."""
    n = len(cols["index"])
    out = {"n_obs": n, "n_used": int(n - np.count_nonzero(cols["rejected"]))}
    out.update({f"n_{f}": int(np.count_nonzero(cols[f])) for f in FLAGS})
    out["n_flagged"] = int(len(flagged(cols)))
    out["n_excluded"] = int(n_excluded)
    out["n_listed"] = int(listed)
    out["listing"] = listing
    return out


def excluded_rows(given, excluded) -> list[dict]:
    """The observations of ``given`` (the observations passed to the adjustment) at the points left out
    before solving (``excluded``: :class:`~multilat.network.adjust.distance.result.Excluded`), each with the point
    and why; empty when nothing was left out or ``given`` is None."""
    if given is None or not excluded:
        return []
    why = {(e.kind, e.id): f"{e.kind} {e.id} {e.reason}" for e in excluded}
    left_s = np.array([("station", i) in why for i in given.station_ids], bool)
    left_t = np.array([("target", i) in why for i in given.target_ids], bool)
    out = []
    for k in np.flatnonzero(left_s[given.station_index] | left_t[given.target_index]).tolist():
        sid, tid = given.station_ids[given.station_index[k]], given.target_ids[given.target_index[k]]
        out.append({"station": str(sid), "target": str(tid), "distance_m": float(given.distance_m[k]),
                    "sigma_m": float(given.sigma_m[k]),
                    "reason": why.get(("station", sid)) or why[("target", tid)]})
    return out


#: the quantities of :func:`observation_extremes` (over the observations kept)
EXTREME_KEYS = ("redundancy", "mdb_m", "mdb_sigma", "shift_max_m")


def _row(cols: dict, k: int) -> dict:
    out = {}
    for name, v in cols.items():
        if isinstance(v, tuple):
            out[name] = str(v[0][int(np.asarray(v[1])[k])])
        else:
            x = np.asarray(v)[k]
            out[name] = bool(x) if x.dtype == bool else (int(x) if x.dtype.kind in "iu" else float(x))
    return out


def observation_extremes(cols: dict) -> dict:
    """Per quantity of :data:`EXTREME_KEYS` present, over the observations kept (not rejected):
    ``smallest`` and ``largest``, each ``{"value", "index", "station", "target"}`` (non-finite values
    ignored; a quantity with no finite value is left out)."""
    kept = ~cols["rejected"]
    out = {}
    for key in EXTREME_KEYS:
        if key not in cols:
            continue
        v = np.where(kept, np.asarray(cols[key], float), np.nan)
        if not np.isfinite(v).any():
            continue
        ends = {}
        for name, k in (("smallest", int(np.nanargmin(v))), ("largest", int(np.nanargmax(v)))):
            r = _row(cols, k)
            ends[name] = {"value": float(v[k]), "index": k, "station": r["station"], "target": r["target"]}
        out[key] = ends
    return out


def largest_w(cols: dict, n: int = LARGEST_W_ROWS) -> list[dict]:
    """The ``n`` rows with the largest |w| (whole rows, largest first; ties in table order)."""
    key = -np.abs(np.nan_to_num(np.asarray(cols["w"], float), nan=-1.0))
    if 0 < n < key.size:                   # the rows up to the n-th value, ties included: no full sort
        rows = np.flatnonzero(key <= np.partition(key, n - 1)[n - 1])
    else:
        rows = np.arange(key.size)
    order = rows[np.argsort(key[rows], kind="stable")[:n]]
    return [_row(cols, int(k)) for k in order]
