"""Where the a-priori σ of the distances came from: one record for ``adjust``, ``propagate`` and
``simulate`` (their summaries and JSON ``sigma_source``).

Kinds: ``"file column"`` (the observations' ``sigma_m``), ``"--sigma-um"`` (one value for every
distance, from the option or the Python argument), ``"distance model"`` (the instrument's distance
model :func:`multilat.budget.distance_std_m`, per station with the head used; ``defaulted`` True when
no instrument was named and the ``seed2020`` preset stood in), ``"raw readings"`` (corrected
distances: the distance model and the air sensors).
"""

from __future__ import annotations

import os

__all__ = ["file_column", "option", "distance_model", "describe", "default_warning"]

DEFAULT_INSTRUMENT = "seed2020"
#: σ of one distance where neither the file, nor ``--sigma-um``, nor a distance model gives one: the
#: combined standard uncertainty of the default instrument's budget (seed2020, seed paper §3.4: 4.7 µm),
#: the gaussian σ of the paper's §4.4 simulations.
DEFAULT_SIGMA_M = 4.7e-6


def file_column(path) -> dict:
    return {"kind": "file column", "file": str(path), "column": "sigma_m"}


def option(sigma_m: float, what: str = "--sigma-um") -> dict:
    return {"kind": what, "sigma_m": float(sigma_m)}


def _instrument_name(instrument) -> tuple[str, bool]:
    if instrument is None:
        return DEFAULT_INSTRUMENT, True
    if isinstance(instrument, (str, os.PathLike)):
        return str(instrument), False
    return str(getattr(instrument, "name", "custom")), False


def distance_model(stations, instrument, *, heads: dict | None = None) -> dict:
    """The record of σ from ``instrument``'s distance model for the station ids ``stations``:
    the head used per station (``heads`` when the caller resolved them; else the station id when the
    instrument has such a head, otherwise head ``"A"`` — the rule of the readers)."""
    from multilat import instrument as _inst

    name, defaulted = _instrument_name(instrument)
    inst = instrument if not isinstance(instrument, (str, os.PathLike, type(None))) else _inst.load_instrument(name)
    if heads is None:
        trk = set(getattr(inst, "trackers", {}) or {})
        has = getattr(inst, "has_head", lambda n: n in (getattr(inst, "heads", {}) or {}))
        heads = {sid: (sid if (sid in trk or has(sid)) else "A") for sid in dict.fromkeys(stations)}
    trackers = getattr(inst, "trackers", {}) or {}
    out = {"kind": "distance model", "instrument": name, "defaulted": defaulted,
           "heads": {str(k): str(v) for k, v in heads.items() if v not in trackers}}
    used = {str(k): str(v) for k, v in heads.items() if v in trackers}
    if used:   # laser trackers: σ from the maker's MPE (a + b L) times std_per_mpe
        out["trackers"] = {k: {"tracker": v, "adm_a_um": trackers[v].adm_a_um,
                               "adm_b_um_per_m": trackers[v].adm_b_um_per_m,
                               "std_per_mpe": trackers[v].std_per_mpe} for k, v in used.items()}
    return out


def describe(src: dict) -> str:
    """One line for a summary."""
    if not src:
        return "σ: source not recorded (given by the caller)"
    k = src.get("kind")
    if k == "file column":
        return f"σ: from the file's sigma_m column ({src['file']})"
    if k == "distance model":
        hs = src.get("heads", {})
        pairs = sorted(set(hs.values()))
        how = ("the default instrument, no σ given (no sigma_m column, no --sigma-um)"
               if src.get("defaulted") else "--instrument")
        return (f"σ: distance model of instrument {src['instrument']!r} ({how}); heads used: "
                + ", ".join(f"{s}→{h}" for s, h in list(hs.items())[:8]) + ("…" if len(hs) > 8 else "")
                + ("" if len(pairs) > 1 or not hs else "")
                + "".join(f"; {st}: tracker {t['tracker']} MPE ({t['adm_a_um']:g} µm + {t['adm_b_um_per_m']:g} µm/m"
                          f" · L) × {t['std_per_mpe']:g}" for st, t in src.get("trackers", {}).items()))
    if k == "raw readings":
        return (f"σ: raw readings corrected with instrument {src['instrument']!r}'s distance model and the "
                "air sensors' uncertainties")
    if "sigma_m" in src:
        return f"σ: {src['sigma_m'] * 1e6:g} µm for every distance ({k})"
    return f"σ: {k}"


def default_warning(src: dict, path) -> str | None:
    """The warning when no σ source was given (no ``sigma_m`` column, no ``--sigma-um``, no
    ``--instrument``) and the default instrument's distance model weighted the distances (or, for raw
    readings, corrected and weighted them): a default that changes the numbers is never quiet. None
    when a source was given."""
    if not src.get("defaulted"):
        return None
    if src.get("kind") == "distance model":
        return (f"{path}: no σ given (no sigma_m column, no --sigma-um, no --instrument): the distances are "
                f"weighted by the distance model of the default instrument {src['instrument']!r}; give "
                "--sigma-um or --instrument to choose")
    if src.get("kind") == "raw readings":
        return (f"{path}: no --instrument: the raw readings are corrected and weighted by the distance model "
                f"of the default instrument {src['instrument']!r}; give --instrument to choose")
    return None
