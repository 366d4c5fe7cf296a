"""The general network adjusted the way a metrologist expects: approximate coordinates, the
adjustment, and the points the observations cannot determine left out and named, never the network
refused.

:func:`adjust_network` chains :func:`.approximate.approximate` and :func:`.adjust.adjust`. A point
that is not determined (a target seen along coplanar lines of sight, one with two distances, a
point no observation reaches with approximate coordinates) is removed with every observation that
references it and the rest is adjusted again, for at most ``max_rounds`` rounds; each one is
recorded in :attr:`NetworkAdjustment.excluded` with its reason and the number of observation rows it
took with it. ``strict=True`` refuses instead (the one-line error of :func:`.adjust.adjust`).
A point the rank test finds determined but whose lines of sight are coplanar within their
uncertainty, its other observations not fixing it, is weak (the distance path's rule, one function:
:mod:`multilat.network.model.weak_points`, fed by :mod:`.weak`): left out after the adjustment the
same way, in the distance path's words.

What cannot be left out is still refused in one line: a defect no point carries (an instrument
scale with no scale in the network), or a network whose every free point is undetermined (a free
network without datum points).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust.general.adjust import (AdjustOptions, GeneralResult, System, UndeterminedError, adjust,
                                             backend_for, check_size)
from multilat.network.adjust.approximate.general import approximate, reasons
from multilat.network.model.observations import Network, without_points
from multilat.network.model.points import FREE

__all__ = ["NetworkAdjustment", "adjust_network", "check_sizes", "leave_out", "undetermined_reason", "MAX_ROUNDS",
           "sense_hint", "false_minimum_warning"]

#: rounds of leaving out undetermined points before giving up (each round removes at least one point)
MAX_ROUNDS = 10


@dataclass(frozen=True, eq=False)
class NetworkAdjustment:
    """network : the adjusted network (without the left-out points); system : its least-squares system
    result : the :class:`~.adjust.GeneralResult`; given : the network as read (every point)
    excluded : tuple of dicts {id, kind: "point", reason, n_obs, round} in the order they were left out
    """

    network: Network
    system: System
    result: GeneralResult
    given: Network
    excluded: tuple


def undetermined_reason(coords: str) -> str:
    """The reason recorded for a point whose coordinates ``coords`` (e.g. ``"z"``, ``"xyz"``) the
    observations do not determine."""
    if coords == "xyz":
        return "its coordinates are not determined by the observations"
    what = f"its {', '.join(coords)} {'is' if len(coords) == 1 else 'are'}"
    return f"{what} not determined by the observations"


def adjust_network(network: Network, *, options: AdjustOptions | None = None, strict: bool = False,
                   max_rounds: int = MAX_ROUNDS) -> NetworkAdjustment:
    """Approximate coordinates, adjustment, undetermined points left out and named (module docstring)."""
    given, net, excluded = network, network, []
    check_sizes(network, options)                   # the chosen back end's limit, before the approximations
    for rnd in range(1, max_rounds + 1):
        missing = reasons(net)                      # {id: what would reach it}
        if missing and strict:                      # the distance path's words (exclusion.raise_undetermined)
            pid, why = next(iter(missing.items()))
            sep = " " if why.startswith("is ") else ": "     # "point 'P' is undetermined: ..."
            raise MultilatError(f"point {pid!r}{sep}{why} (--strict: refused; without it, it would be left out)")
        if missing:
            net = leave_out(net, missing, rnd, excluded)
        try:
            ready, res = _adjusted(net, options)
        except UndeterminedError as e:
            if strict or not e.points:              # a defect no point carries: refused
                raise
            net = leave_out(net, {p: undetermined_reason(c) for p, c in e.points.items()}, rnd, excluded, error=e)
            continue
        system = System(ready)
        weak = _weak(system, res, strict)
        if weak:
            net = leave_out(net, weak, rnd, excluded)
            continue
        return NetworkAdjustment(ready, system, res, given, tuple(excluded))
    raise MultilatError(f"still undetermined points after {max_rounds} rounds of leaving them out "
                        f"({len(excluded)} left out: {', '.join(e['id'] for e in excluded[:5])}"
                        f"{', ...' if len(excluded) > 5 else ''}); use --strict to see the first")


def _weak(system: System, res: GeneralResult, strict: bool) -> dict:
    """The weak points of the adjusted network (:func:`.weak.weak_points_of`, the distance path's rule):
    {id: reason}, empty when none or when every point tested is weak (a flat network: not one point
    weak, as :func:`multilat.network.adjust.distance.exclusion.raise_undetermined`). ``strict``: the
    first is refused in the distance path's words."""
    from multilat.network.adjust.general.weak import weak_points_of

    weak, n_tested = weak_points_of(system, res.parameters)
    if not weak or len(weak) >= n_tested:
        return {}
    if strict:
        pid, why = next(iter(weak.items()))
        raise MultilatError(f"point {pid!r} {why} (--strict: refused; without it, it would be left out)")
    return weak


def check_sizes(network: Network, options: AdjustOptions | None = None) -> None:
    """The chosen back end's size limit, from the design alone (before the approximate coordinates,
    which may cost more than the refusal): the dense one's unknowns (:func:`.adjust.check_size`), the
    sparse one's reduced system (:func:`.sparse.check_reduced_size`, a lower bound of its size)."""
    system = System(network)
    check_size(system, options)
    if backend_for(system, options) == "sparse":
        from multilat.network.adjust.general.sparse import check_reduced_size

        check_reduced_size(system)


def _failing_by_far(res: GeneralResult) -> bool:
    """The distance path's trigger of its minimum search (:func:`multilat.network.adjust.approximate.search.needs_search`):
    the χ² tail probability of vᵀPv below ``P_MIN``."""
    from multilat.network.adjust.approximate.search import P_MIN, p_value

    return p_value(float(res.sigma0) ** 2 * res.dof, res.dof) < P_MIN


def _adjusted(net: Network, options) -> tuple[Network, GeneralResult]:
    """Approximate coordinates and the adjustment from them. Where the distance-only search placed
    points in the network's own frame and the adjustment fails the global test by far (or does not
    converge), the distance path's minimum search is run from the search's own start
    (:func:`.approximate.search.minimum_search`, once per network: its note), the chain places the
    other points again, and the lower minimum is kept: a flat ring started with targets on the
    mirrored side otherwise converges at σ0 ~ 130 (network 87 of
    ``benchmarks/study_general_acceptance.py``). Run always, it made the general layer ~4x the
    distance path's time at 8 x 20 000."""
    from multilat.network.adjust.approximate.general.search import MINIMUM_NOTE, minimum_search, searched_free

    ready = approximate(net)
    searched = searched_free(ready.notes) and not any(n.startswith(MINIMUM_NOTE) for n in ready.notes)
    try:
        res, failed = adjust(ready, options=options), None
    except UndeterminedError:
        raise
    except MultilatError as e:                              # diverged from the search's start
        if not searched:
            raise
        res, failed = None, e
    if not searched or res is not None and not _failing_by_far(res):
        return ready, res
    xyz = minimum_search(ready)
    try:
        if xyz is None:
            raise MultilatError("the minimum search found nothing lower")
        again = approximate(Network(ready.points.with_xyz(xyz), ready.blocks, ready.notes))
        res2 = adjust(again, options=options)
    except UndeterminedError:
        raise
    except MultilatError:
        if failed is not None:
            raise failed from None
        res2 = None
    before = "not converged" if res is None else f"sigma0 {res.sigma0:.4g}"
    if res2 is not None and (res is None or res2.sigma0 ** 2 * res2.dof < res.sigma0 ** 2 * res.dof):
        note = f"{MINIMUM_NOTE}: {before} from the search's start, {res2.sigma0:.4g} after it"
        return Network(again.points, again.blocks, again.notes + (note,)), res2
    note = f"{MINIMUM_NOTE}: {before} from the search's start, nothing lower found"
    return Network(ready.points, ready.blocks, ready.notes + (note,)), res


def false_minimum_warning(adj: NetworkAdjustment) -> str | None:
    """The distance path's "possible false minimum" warning (its words), for an adjustment whose
    approximations came from the distance-only search in the network's own frame and which still
    fails the global test by far (:func:`_failing_by_far`; the minimum search has run, see
    :func:`_adjusted`): None otherwise. Judged on the final adjustment (after data snooping, as the
    distance path)."""
    from multilat.network.adjust.approximate.general.search import searched_free
    from multilat.network.adjust.approximate.search import false_minimum_text, p_value

    res = adj.result
    if not searched_free(adj.network.notes) or not _failing_by_far(res):
        return None
    return false_minimum_text(res.sigma0, p_value(float(res.sigma0) ** 2 * res.dof, res.dof))


def leave_out(net: Network, reasons: dict, rnd: int, excluded: list, error: MultilatError | None = None) -> Network:
    """``net`` without the points of ``reasons`` ({id: why}) and every observation referencing them,
    each recorded in ``excluded`` ({id, kind, reason, n_obs, round ``rnd``}); refused in one line
    (``error`` if given) when no free point would be left, or no observation."""
    pts = net.points
    free_left = [i for i, p in enumerate(pts.ids) if p not in reasons and np.any(pts.status[i] == FREE)]
    if not free_left:
        raise error or MultilatError(f"no point of the network can be determined: {', '.join(list(reasons)[:5])}"
                                     f"{', ...' if len(reasons) > 5 else ''} ({next(iter(reasons.values()))})")
    out = net
    for p, why in reasons.items():
        out, n = without_points(out, [p])
        excluded.append({"id": p, "kind": "point", "reason": why, "n_obs": n, "round": rnd})
    if not out.blocks:
        raise MultilatError("no observation is left once the undetermined points are left out: "
                            + ", ".join(list(reasons)[:5]))
    return out


def sense_hint(flipped: Network, sigma0: float | None, *, options: AdjustOptions | None = None,
               strict: bool = False, **tests) -> str | None:
    """When an adjustment with azimuths is implausible (refused: ``sigma0`` None; its data snooping
    refused, or its global test failed: ``sigma0`` that adjustment's), whether the same network with
    its azimuths negated (``flipped``, built by the caller from the file) fits clearly better: one
    adjustment without data snooping, the rule and words of
    :func:`multilat.network.adjust.distance.azimuth_sense.hint_text` (σ0 ten times smaller, global test passed).
    ``tests``: the test options of :func:`.quality.statistics`. The text naming ``--azimuth-sense cw``,
    or None."""
    from multilat.network.adjust.distance.azimuth_sense import hint_text
    from multilat.network.adjust.general.quality import statistics

    try:
        adj = adjust_network(flipped, options=options, strict=strict)
    except MultilatError:
        return None
    stats = statistics(adj.system, adj.result, external=False, **tests)
    return hint_text(sigma0, float(adj.result.sigma0), bool(stats.global_test.passed))
