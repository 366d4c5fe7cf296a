"""Weak points do not sink a network: which stations and targets to leave out before solving.

Rules, applied repeatedly until nothing changes (leaving one point out can weaken another):

* a free target needs 3 observations (its 3 coordinates); with fewer it is left out. A target held
  fixed (control point) needs none;
* a station needs more observations than its own unknowns (3 coordinates + offset + scale when
  estimated): with fewer it is left out;
* the network must be connected: points outside the component with the most observations are left
  out (they would float against the rest); two parts of 3 or more stations each are refused (each
  is a network of its own, to be adjusted separately or linked by common targets).

A target with exactly 3 observations stays: it is determined, without redundancy, and from distances
alone its mirror image through the plane of its 3 stations fits them equally (named in a warning; after
the adjustment :mod:`multilat.network.ambiguity` lists it among the mirror-ambiguous points, with the
stations that see only coplanar targets and the targets seen by coplanar stations).
With ``strict=True`` the first point that would be left out is an error instead.
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.data import Observations, distinct_pair_codes
from multilat.network.result import Excluded

__all__ = ["exclude_weak_points", "zero_redundancy_warnings"]


def _distinct_counts(obs: Observations, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct stations per target (t,) and distinct targets per station (s,) over the kept
    observations: repeated readings of one pair add no geometry."""
    s, t = obs.n_stations, obs.n_targets
    pair = distinct_pair_codes(obs.station_index[keep], obs.target_index[keep], t)
    return np.bincount(pair % t, minlength=t), np.bincount(pair // t, minlength=s)


def _largest_component(obs: Observations, keep: np.ndarray) -> np.ndarray:
    """Mask (m,) of the kept observations that belong to the component with the most observations."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    s, t = obs.n_stations, obs.n_targets
    k = np.flatnonzero(keep)
    g = coo_matrix((np.ones(k.size), (obs.station_index[k], s + obs.target_index[k])), shape=(s + t, s + t))
    n, lab = connected_components(g, directed=False)
    if n <= 1:
        return keep
    comp = lab[obs.station_index]
    sizes = np.bincount(comp[keep], minlength=n)
    n_st = np.array([np.unique(obs.station_index[keep & (comp == c)]).size for c in range(n)])
    if np.sum(n_st >= 3) > 1:
        parts = []
        for c in np.flatnonzero(n_st >= 3)[:2]:
            ids = [obs.station_ids[i] for i in np.unique(obs.station_index[keep & (comp == c)])]
            parts.append(",".join(ids[:4]) + ("..." if len(ids) > 4 else ""))
        raise MultilatError(f"the network is disconnected into {int(np.sum(n_st >= 3))} parts of 3 or more "
                            f"stations ({' | '.join(parts)}); each part must be adjusted separately or "
                            "linked by common targets")
    return keep & (comp == int(np.argmax(sizes)))


def exclude_weak_points(obs: Observations, *, offset_free: np.ndarray, scale_free: np.ndarray,
                        fixed_targets=(), strict: bool = False):
    """Leave out what cannot be determined.

    Parameters
    ----------
    obs : Observations
    offset_free, scale_free : ndarray of bool (s,)
        Which station offsets / scales are estimated.
    fixed_targets : collection of str
        Ids of targets held fixed (control): they need no observation of their own.
    strict : bool
        Raise :class:`MultilatError` instead of leaving a point out.

    Returns
    -------
    keep : ndarray of bool (m,)
        The observations of the points kept.
    excluded : tuple of Excluded
        What was left out and why, in the order it was decided.
    """
    s, t = obs.n_stations, obs.n_targets
    fixed = np.array([tid in set(fixed_targets) for tid in obs.target_ids], bool)
    hi = obs.head_index          # a shared head's offset/scale are not one station's own unknowns
    alone = (np.bincount(hi)[hi] == 1).astype(int)
    need_s = 3 + alone * (np.asarray(offset_free, int) + np.asarray(scale_free, int))
    keep = np.ones(obs.n_obs, bool)
    out: list[Excluded] = []
    gone_s = np.zeros(s, bool)
    gone_t = np.zeros(t, bool)

    def drop(kind, idx, reason):
        ident = obs.station_ids[idx] if kind == "station" else obs.target_ids[idx]
        rows = (obs.station_index if kind == "station" else obs.target_index) == idx
        n = int(np.sum(rows & keep))
        if strict:
            raise MultilatError(f"{kind} {ident!r} {reason} (--strict: refused; without it, it would be "
                                "left out)")
        out.append(Excluded(ident, kind, reason, n))
        keep[rows] = False
        (gone_s if kind == "station" else gone_t)[idx] = True

    while True:
        changed = False
        per_t, per_s = _distinct_counts(obs, keep)
        for j in np.flatnonzero((per_t < 3) & ~fixed & ~gone_t):
            drop("target", int(j), f"has {int(per_t[j])} observation(s); 3 are needed to place it")
            changed = True
        for i in np.flatnonzero((per_s < need_s + 1) & ~gone_s):
            drop("station", int(i), f"has {int(per_s[i])} usable observation(s); its {int(need_s[i])} "
                                    f"unknowns need at least {int(need_s[i]) + 1}")
            changed = True
        if not keep.any():
            break
        main = _largest_component(obs, keep)
        if not np.array_equal(main, keep):
            lost = keep & ~main
            for i in np.unique(obs.station_index[lost]):
                if not np.any(obs.station_index[main] == i):
                    drop("station", int(i), "is not connected to the main network")
            for j in np.unique(obs.target_index[lost]):
                if not np.any(obs.target_index[main] == j):
                    drop("target", int(j), "is not connected to the main network")
            keep &= main
            changed = True
        if not changed:
            break
    return keep, tuple(out)


def zero_redundancy_warnings(obs: Observations, fixed_targets=()) -> list[str]:
    """One warning per free target with exactly 3 observations, naming its mirror ambiguity."""
    per_t, _ = _distinct_counts(obs, np.ones(obs.n_obs, bool))
    msgs = []
    fixed = set(fixed_targets)
    for j in np.flatnonzero(per_t == 3):
        tid = obs.target_ids[j]
        if tid in fixed:
            continue
        st = [obs.station_ids[i] for i in dict.fromkeys(obs.station_index[obs.target_index == j])]
        msgs.append(f"target {tid!r} has 3 observations: determined without redundancy (its distances "
                    f"are unchecked); from distances alone its mirror image through the plane of "
                    f"{', '.join(st)} fits them equally")
    return msgs
