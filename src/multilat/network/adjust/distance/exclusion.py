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
the adjustment :mod:`multilat.network.adjust.distance.ambiguity` lists it among the mirror-ambiguous points, with the
stations that see only coplanar targets and the targets seen by coplanar stations).
A target whose lines of sight are coplanar within their uncertainty is not determined either,
whatever the size of the network (:func:`undetermined_targets`, the rule of
:mod:`multilat.network.model.weak_points`, shared with the general layer): it is left out the same way, named
with its reason. Its coordinates are needed to see it, so it is found on the initial values or the
first adjustment (a 3x3 target block numerically singular: :class:`UndeterminedTargets`) and the
adjustment runs again without it (:func:`leaving_out_undetermined`, a bounded number of rounds).
With ``strict=True`` the first point that would be left out is an error instead.
"""

from __future__ import annotations

import warnings

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.data import Observations, distinct_pair_codes
from multilat.network.adjust.distance.result import Excluded
from multilat.network.adjust.distance.fit_state import Fit
from multilat.network.model.weak_points import COPLANAR_REASON, weak_points

__all__ = ["COPLANAR_REASON", "UndeterminedTargets", "exclude_weak_points", "leaving_out_undetermined", "raise_undetermined",
           "undetermined_targets",
           "zero_redundancy_warnings"]

#: at most this many rounds of "adjust, find undetermined targets, leave them out" (each round leaves
#: out every target found in it; a target left out can weaken another only through its stations)
MAX_UNDETERMINED_ROUNDS = 5


class UndeterminedTargets(MultilatError):
    """Targets the observations cannot place, found with coordinates at hand (initial values, the
    solve's 3x3 blocks): ``reasons`` maps each target id to its reason. The adjustment leaves them
    out and runs again (:func:`leaving_out_undetermined`)."""

    def __init__(self, reasons: dict):
        self.reasons = dict(reasons)
        tid, why = next(iter(self.reasons.items()))
        more = f" (and {len(self.reasons) - 1} more)" if len(self.reasons) > 1 else ""
        super().__init__(f"target {tid!r} {why}{more}")


def _distinct_counts(obs: Observations, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct stations per target (t,) and distinct targets per station (s,) over the kept
    observations: repeated readings of one pair add no geometry."""
    s, t = obs.n_stations, obs.n_targets
    pair = distinct_pair_codes(obs.station_index[keep], obs.target_index[keep], t)
    return np.bincount(pair % t, minlength=t), np.bincount(pair // t, minlength=s)


def _largest_component(obs: Observations, keep: np.ndarray) -> np.ndarray:
    """Mask (m,) of the kept observations that belong to the component with the most observations."""
    from multilat.network.adjust.distance.solvability import graph_components

    s, t = obs.n_stations, obs.n_targets
    k = np.flatnonzero(keep)
    n, lab = graph_components(s + t, obs.station_index[k], s + obs.target_index[k])
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
                        fixed_targets=(), strict: bool = False, undetermined=None):
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
    undetermined : dict, optional
        Target id -> reason for targets found undetermined on coordinates (coplanar lines of sight,
        :func:`undetermined_targets`): left out first.

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

    index = {tid: j for j, tid in enumerate(obs.target_ids)}
    for tid, why in (undetermined or {}).items():
        if tid in index and not gone_t[index[tid]]:
            drop("target", index[tid], why)
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


def undetermined_targets(obs: Observations, station_xyz_m, target_xyz_m, skip=()) -> dict:
    """Targets whose lines of sight are coplanar within their uncertainty: id -> reason.

    The rule of :func:`multilat.network.model.weak_points.weak_points` (shared with the general
    layer) on each free target's distances ``k`` to stations ``H_k`` (σ_k), at position ``T``: the
    3x3 normal block ``N = sum u_k u_k^T / σ_k^2``, its weakest direction ``v`` with ``σ_v = λ^-1/2``,
    the RMS spread ``h = rms((T - H_k).v)`` of the sights along it (for stations in one plane: the
    target's height above it; ``σ_v ≈ σ L / (h sqrt(k))``). The target is undetermined when
    ``h < K_PLANE σ_v`` (``h`` below about ``sqrt(K_PLANE σ L)``, where distances fix the height only
    to second order) or when ``N`` is singular. A target seen by 3 stations well off their plane is
    determined (mirror-ambiguous only) and stays. Targets in ``skip`` (control, angles, scale-bar
    ends: placed otherwise) and targets without finite coordinates are not tested.
    """
    H = np.asarray(station_xyz_m, float)
    T = np.asarray(target_xyz_m, float)
    skip = set(skip)
    test = np.all(np.isfinite(T), axis=1) & np.array([tid not in skip for tid in obs.target_ids], bool)
    found = weak_points(obs.target_index, T[obs.target_index] - H[obs.station_index], obs.sigma_m,
                        obs.n_targets, tested=test)
    return {obs.target_ids[j]: why for j, why in found.items()}


def raise_undetermined(obs: Observations, core: Fit, skip=()) -> None:
    """Raise :class:`UndeterminedTargets` for the targets of an adjustment (``core``: its points
    ``sx``, ``tx`` and their indices ``smap``, ``tmap`` in ``obs``) that :func:`undetermined_targets`
    finds, if any. When it finds every target tested, the network is flat, not one target weak: left
    to the flat-network test (:func:`multilat.network.adjust.distance.ambiguity.flat_network`), which names it."""
    H = np.full((obs.n_stations, 3), np.nan)
    T = np.full((obs.n_targets, 3), np.nan)
    H[core.smap], T[core.tmap] = core.sx, core.tx
    found = undetermined_targets(obs, H, T, skip)
    tested = {obs.target_ids[j] for j in np.asarray(core.tmap)} - set(skip)
    if found and not tested <= set(found):
        raise UndeterminedTargets(found)


def leaving_out_undetermined(run, *, strict: bool = False):
    """``run(undetermined)`` (an adjustment leaving out the targets in the dict ``undetermined``) until
    it no longer raises :class:`UndeterminedTargets`: each round adds the targets found and runs
    again, at most :data:`MAX_UNDETERMINED_ROUNDS` rounds. The warnings of a round that found
    undetermined targets are dropped (the next round gives its own, with the targets named as left
    out). With ``strict`` the first undetermined target is refused (the error alone)."""
    def replay(caught):     # at the caller of adjust(): replay < here < adjust < caller
        for w in caught:
            warnings.warn(w.message, w.category, stacklevel=4)

    found: dict = {}
    for _ in range(MAX_UNDETERMINED_ROUNDS):
        error = None
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                res = run(dict(found))
            except BaseException as e:      # noqa: BLE001 - re-raised below, after the warnings
                error = e
        if not isinstance(error, UndeterminedTargets):
            replay(caught)
        if error is None:
            return res
        if not isinstance(error, UndeterminedTargets):
            raise error
        new = {k: v for k, v in error.reasons.items() if k not in found}
        if strict or not new:       # one line: the refusal (the round's warnings were about it)
            tid, why = next(iter(error.reasons.items()))
            tail = " (--strict: refused; without it, it would be left out)" if strict else ""
            raise MultilatError(f"target {tid!r} {why}{tail}") from None
        found.update(new)
    raise MultilatError(f"undetermined targets still found after {MAX_UNDETERMINED_ROUNDS} rounds of "
                        f"leaving them out ({', '.join(list(found)[:8])}...)")


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
