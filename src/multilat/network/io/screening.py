"""Screening of observations for gross errors before the adjustment.

A distance of ``1e300``, a σ of ``1e-300`` or one distance written in millimetres among metres make
the normal equations overflow or lose all their digits; the adjustment then fails with a message
about the geometry ("near-degenerate", "singular"), which points the user at the wrong culprit.
:func:`screen_observations` names those rows first, from the values alone:

- **absolute bounds**: a distance above :data:`MAX_DISTANCE_M` (no large-volume instrument measures
  1000 km), a σ below :data:`MIN_SIGMA_M` (its weight ``1/σ²`` overflows the model's precision) or
  above :data:`MAX_SIGMA_M`;
- **against the other distances of the same target**: by the triangle inequality two distances
  to one target differ by at most the distance between their stations, which is itself at most
  the size of the network. A distance farther from the median of its target's distances than
  :data:`SPREAD_FACTOR` times the network's size (the median over targets of the median of each
  target's distances) is a gross error (a value in mm among metres, a digit slipped), so is a
  distance beyond ``1 + SPREAD_FACTOR`` sizes when its target has too few distances for a median
  of its own, and so are all the distances of a target whose median exceeds
  :data:`TARGET_FACTOR` sizes (a whole target in mm).

Pure numpy; the distances in an ordinary 1 m blunder are left to the adjustment's data snooping.
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError

__all__ = ["screen_observations", "suspect_rows", "MAX_DISTANCE_M", "MIN_SIGMA_M", "MAX_SIGMA_M",
           "SPREAD_FACTOR"]

#: Longest distance accepted, metres.
MAX_DISTANCE_M = 1e6
#: Smallest σ accepted, metres (a picometre: weights up to 1e24 m⁻²).
MIN_SIGMA_M = 1e-12
#: Largest σ accepted, metres.
MAX_SIGMA_M = 1e3
#: A distance farther than this many network sizes from its target's median is a gross error.
SPREAD_FACTOR = 3.0
#: A target whose distances' median exceeds this many network sizes is measured in a wrong unit.
TARGET_FACTOR = 50.0
#: At most this many rows are named in the message (the count says how many more).
NAMED = 3


def suspect_rows(obs) -> list[tuple[int, str]]:
    """Rows (0-based indices into ``obs``) that cannot be adjusted as given, each with the reason.

    Parameters
    ----------
    obs : Observations (or anything with ``station_index``, ``target_index`` (m,), ``distance_m``,
        ``sigma_m`` (m,) metres, ``station_ids``, ``target_ids``)

    Returns
    -------
    list of (row, reason), in row order, each row once
    """
    d = np.asarray(obs.distance_m, dtype=float)
    s = np.asarray(obs.sigma_m, dtype=float)
    ti = np.asarray(obs.target_index, dtype=np.int64)
    found: dict[int, str] = {}

    def add(rows, why):
        for k in np.flatnonzero(rows):
            found.setdefault(int(k), why(int(k)))

    add(~np.isfinite(d) | (d <= 0), lambda k: f"distance {d[k]:g} m is not a positive number")
    add(np.isfinite(d) & (d > MAX_DISTANCE_M), lambda k: f"distance {d[k]:.6g} m is absurd (> {MAX_DISTANCE_M:g} m)")
    add(~np.isfinite(s) | (s < MIN_SIGMA_M), lambda k: f"sigma {s[k]:.3g} m is below {MIN_SIGMA_M:g} m "
                                                        "(its weight overflows the model)")
    add(np.isfinite(s) & (s > MAX_SIGMA_M), lambda k: f"sigma {s[k]:.3g} m is absurd (> {MAX_SIGMA_M:g} m)")
    ok = np.isfinite(d) & (d > 0) & (d <= MAX_DISTANCE_M)
    if ok.sum() >= 3 and ti.size:
        n_t = int(ti.max()) + 1
        counts = np.bincount(ti[ok], minlength=n_t)
        med_all = _group_medians(d[ok], ti[ok], n_t)
        med = np.where(counts >= 3, med_all, np.nan)  # a median that one bad value cannot move far
        if np.any(np.isfinite(med)):
            size = float(np.nanmedian(med))           # the network's size (a target's typical range)
            whole = ok & (med_all[ti] > TARGET_FACTOR * size)
            add(whole, lambda k: f"target {obs.target_ids[ti[k]]}'s distances (median {med_all[ti[k]]:.6g} m) "
                                 f"against {size:.6g} m for the network's targets (a wrong unit?)")
            ref = med[ti]
            far = ok & np.isfinite(ref) & (np.abs(d - ref) > SPREAD_FACTOR * size)
            add(far, lambda k: f"distance {d[k]:.6g} m against a median of {med[ti[k]]:.6g} m for target "
                               f"{obs.target_ids[ti[k]]} (a wrong unit or a slipped digit?)")
            lone = ok & ~np.isfinite(ref) & (d > (1 + SPREAD_FACTOR) * size)
            add(lone, lambda k: f"distance {d[k]:.6g} m beyond the network's size ({size:.6g} m; a wrong unit?)")
    return sorted(found.items())


def _group_medians(values, groups, n_groups):
    """Median of ``values`` per group id in ``[0, n_groups)`` (NaN for empty groups), vectorised."""
    # by group, then value, from two sorts (numpy's lexsort is ~2x slower on millions of rows); the
    # first need not be stable: equal values are interchangeable in a median (1.5-2x faster)
    order = np.argsort(values)
    order = order[np.argsort(groups[order], kind="stable")]
    v, g = values[order], groups[order]
    counts = np.bincount(g, minlength=n_groups)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    med = np.full(n_groups, np.nan)
    has = counts > 0
    lo = start[has] + (counts[has] - 1) // 2
    hi = start[has] + counts[has] // 2
    med[has] = 0.5 * (v[lo] + v[hi])
    return med


def screen_observations(obs, *, source: str = "", line_numbers=None) -> None:
    """Raise :class:`MultilatError` naming the suspect rows (see the module docstring), else None.

    The message names up to :data:`NAMED` rows as ``STATION->TARGET (row N)`` with the reason, and
    how many more there are; ``source`` (a file name) prefixes it. With ``line_numbers`` (the file
    line of each row) and ``source``, rows are named ``FILE:LINE``.
    """
    rows = suspect_rows(obs)
    if not rows:
        return
    si = np.asarray(obs.station_index)
    ti = np.asarray(obs.target_index)
    def where(k):
        if line_numbers is not None and source:
            return f"{source}:{line_numbers[k]}"
        return f"row {k + 1}"

    named = "; ".join(f"{where(k)} {obs.station_ids[si[k]]}->{obs.target_ids[ti[k]]}: {why}"
                      for k, why in rows[:NAMED])
    more = f" (+{len(rows) - NAMED} more)" if len(rows) > NAMED else ""
    prefix = f"{source}: " if source and line_numbers is None else ""
    raise MultilatError(f"{prefix}suspect observation(s), gross errors before the adjustment: {named}{more}")
