"""The minimum search: escape a wrong local minimum of a network adjusted from distances alone.

From distances alone the adjustment is a local method started from computed initial values
(:mod:`multilat.network.adjust.approximate.initial`). When those put a target on the wrong side of its stations (a
mirror image through their nearly common plane: flat station rings) or a station on the wrong side
of its targets, Gauss-Newton converges to a *wrong* local minimum: one point far off, every other
point pulled by tens of mm, and a global test that fails *by far* (issue 10: σ0 4.6-7.9 where the
least-squares minimum has σ0 1.0-1.1).

Trigger
-------
:func:`needs_search`: the χ² upper-tail probability of the weighted sum of squares ``vᵀPv`` with
``dof`` degrees of freedom is below ``p_min = 1e-9``. With the stated a-priori σ and a correct model
this happens once in 10^9 adjustments; a wrong minimum reaches it at once (its ``vᵀPv`` grows
with the square of a displacement of centimetres against σ of micrometres). It also fires on gross
errors and on a-priori σ that are too small: the search then only costs time; the lowest cost wins
whatever the cause, and the result is the same as without it when no candidate is lower.

Candidates (from the current best solution, lowest cost wins)
-------------------------------------------------------------
1. each of the ``n_targets`` targets with the largest RMS normalised residual, moved to its mirror
   image through the best-fitting plane of its stations, then through the planes of up to
   ``n_triples`` of its station triples (the largest triangles first);
2. those targets mirrored together;
3. each of the ``n_stations`` stations with the largest RMS normalised residual, mirrored through
   the best-fitting plane of its targets;
4. a restart from the best partial solution: the worst targets (1, 2, 3 of them) left out, the rest
   re-fitted, the left-out targets placed again from the fitted stations on whichever side of
   their stations fits their distances better;
5. other anchor sets: initial values computed without the worst targets (other station blocks),
   the left-out targets placed as in 4.

Each candidate start is solved by the caller's ``solve``; a candidate is accepted when its cost is
lower than the best so far; rounds repeat from the new best while the test still fails by far (at
most ``max_rounds``) and stop as soon as it no longer does.

Bounds
------
The search is bounded by work, ``max_rounds`` rounds and at most ``max_solves`` candidate starts
(:data:`~multilat.network.adjust.approximate.bounds.SEARCH_SOLVES`), and by wall time, ``max_seconds``
(:data:`~multilat.network.adjust.approximate.bounds.SEARCH_SECONDS`, which also bounds the initial values computed for
candidate 5). A search stopped by a bound keeps its best solution; the record's ``bounded`` says
which bound stopped it, and a wall-time stop is a warning (the result then depends on the machine's
speed). On a terminal the CLI shows the candidate being tried (:func:`multilat.network.adjust.approximate.bounds.report`).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust.approximate.bounds import SEARCH_SECONDS, SEARCH_SOLVES, Bound, report
from multilat.network.adjust.approximate.initial import distance_matrix, initial_values
from multilat.network.adjust.approximate.initial_refine import choose_frame, point_fit, refine_unmirrored, to_frame

__all__ = ["Candidate", "MinimumSearch", "false_minimum_text", "find_minimum", "needs_search", "P_MIN"]

#: χ² upper-tail probability below which a converged solution is "failing by far"
P_MIN = 1e-9


def false_minimum_text(sigma0: float, p: float, *, searched: bool = True, n_tried: int | None = None) -> str:
    """The "possible false minimum" warning, one wording on every path (the search's, the distance
    adjustment's after snooping, the general layer's): σ0, the χ² tail probability ``p``, and whether
    the minimum search ran (``searched``) and how many starts it tried."""
    after = " after the minimum search" if searched else ""
    starts = f", {n_tried} starts tried" if n_tried is not None else ""
    return (f"possible false minimum: the global test fails by far{after} (sigma0 {sigma0:.3g}, chi-square p "
            f"{p:.1e}{starts}): check for gross errors, a-priori sigma too small, or give approximate coordinates")


@dataclass(frozen=True)
class Candidate:
    """One start tried: ``label`` says what it was, ``cost`` its converged ``vᵀPv`` (None when
    the solve failed, then ``note`` gives the error), ``sigma0``, and whether it became the best."""

    label: str
    cost: float | None
    sigma0: float | None
    accepted: bool
    note: str = ""


@dataclass(frozen=True, eq=False)
class MinimumSearch:
    """Result of :func:`find_minimum`.

    Attributes
    ----------
    solution : the lowest-cost solution found (``first`` when nothing was lower)
    triggered : bool  whether ``first`` failed the global test by far (else nothing was tried)
    first_cost, cost : float  ``vᵀPv`` of ``first`` and of ``solution``
    dof : int
    p_value : float  χ² upper-tail probability of ``cost``
    candidates : tuple of Candidate  every start tried, in order
    warning : str or None  set when ``solution`` still fails the global test by far
    bounded : str or None  set when a bound stopped the search (which one)
    """

    solution: object
    triggered: bool
    first_cost: float
    cost: float
    dof: int
    p_value: float
    candidates: tuple
    warning: str | None
    bounded: str | None = None

    def as_dict(self) -> dict:
        """The JSON ``initial`` block's search part (plain types)."""
        return {"search_triggered": self.triggered, **({"bounded": self.bounded} if self.bounded else {}),
                "first_cost": self.first_cost,
                "cost": self.cost, "dof": self.dof, "p_value": self.p_value,
                "tried": [{"label": c.label, "cost": c.cost, "sigma0": c.sigma0,
                           "accepted": c.accepted, **({"note": c.note} if c.note else {})}
                          for c in self.candidates],
                "warning": self.warning}


def _dof(obs, sol) -> int:
    d = getattr(sol, "dof", None)
    return int(d) if d is not None else obs.n_obs - (4 * obs.n_stations + 3 * obs.n_targets - 6)


def _cost(sol) -> float:
    v = getattr(sol, "vtpv", None)
    if v is not None:
        return float(v)
    return float(sol.sigma0) ** 2 * int(sol.dof)


def p_value(cost: float, dof: int) -> float:
    """χ² upper-tail probability of ``cost`` with ``dof`` degrees of freedom (1 when dof <= 0)."""
    from multilat.network.adjust.statistics import chi2_sf

    return chi2_sf(cost, dof) if dof > 0 else 1.0


def needs_search(sol, obs, *, p_min: float = P_MIN) -> bool:
    """Whether a converged solution fails the global test by far (χ² tail probability < p_min)."""
    return p_value(_cost(sol), _dof(obs, sol)) < p_min


def _residuals(obs, H, T, o):
    """Normalised residuals (d - |H - T| - o) / sigma, shape (m,)."""
    rho = np.linalg.norm(H[obs.station_index] - T[obs.target_index], axis=1)
    return (obs.distance_m - rho - o[obs.station_index]) / obs.sigma_m


def _mirror(p, pts):
    """``p`` mirrored through the best-fitting plane of ``pts`` (n >= 3, 3)."""
    c = pts.mean(0)
    n = np.linalg.svd(pts - c)[2][2]
    return p - 2.0 * ((p - c) @ n) * n


def _start(H, T, o):
    return SimpleNamespace(station_xyz_m=H, target_xyz_m=T, offset_m=o)


def _place(obs, H, T, o, j):
    """Target ``j`` re-fitted from the stations on whichever side of their plane fits better."""
    k = np.flatnonzero(obs.target_index == j)
    st = obs.station_index[k]
    A, d, w = H[st], obs.distance_m[k] - o[st], 1.0 / obs.sigma_m[k] ** 2
    if len(st) < 3:
        return T[j]
    best = None
    for p0 in (T[j], _mirror(T[j], A)):
        p, c = point_fit(A, d, w, p0.copy())
        if np.all(np.isfinite(p)) and (best is None or c < best[1]):
            best = (p, c)
    return best[0] if best is not None else T[j]


def _without(obs, drop):
    """Observations without the targets ``drop`` and the index maps (stations, targets) into obs,
    or None when a station would lose too much."""
    keep = ~np.isin(obs.target_index, drop)
    sub = obs.subset(keep)
    if sub.n_stations != obs.n_stations:
        return None
    tmap = np.array([obs.target_ids.index(t) for t in sub.target_ids])
    return sub, tmap


def _partial_restart(obs, H, T, o, drop):
    """Re-fit the network without targets ``drop`` from (H, T, o), then place them again."""
    got = _without(obs, drop)
    if got is None:
        return None
    sub, tmap = got
    D, W = distance_matrix(sub)
    frame = choose_frame(H)
    Hf, Tf = to_frame(H, T, frame)
    Hs, Ts, os_, _, _, _ = refine_unmirrored(D, W, Hf, Tf[tmap], o.copy(), frame, robust=False)
    T2 = Tf.copy()
    T2[tmap] = Ts
    for j in drop:
        T2[j] = _place(obs, Hs, T2, os_, j)
    return _start(Hs, T2, os_)


def _other_anchors(obs, T, drop, rng, deadline=None):
    """Initial values computed without targets ``drop`` (other blocks), the dropped placed again."""
    got = _without(obs, drop)
    if got is None:
        return None
    sub, tmap = got
    iv = initial_values(sub, rng=rng, deadline=deadline)
    H, o = iv.station_xyz_m, iv.offset_m
    T2 = np.zeros_like(T)
    T2[tmap] = iv.target_xyz_m
    for j in drop:   # start from the centroid of its stations, lifted off their plane both ways
        st = obs.station_index[obs.target_index == j]
        A = H[st]
        n = np.linalg.svd(A - A.mean(0))[2][2]
        T2[j] = A.mean(0) + n * float(np.median(obs.distance_m[obs.target_index == j])) * 0.5
        T2[j] = _place(obs, H, T2, o, j)
    return _start(H, T2, o)


def _candidates(obs, sol, *, n_targets, n_stations, n_triples, rng, deadline=None):
    """(label, start or callable returning a start) pairs from solution ``sol``."""
    H = np.asarray(sol.station_xyz_m, float)
    T = np.asarray(sol.target_xyz_m, float)
    o = np.asarray(sol.offset_m, float)
    v2 = _residuals(obs, H, T, o) ** 2
    t_score = np.bincount(obs.target_index, v2, obs.n_targets) / np.maximum(
        np.bincount(obs.target_index, minlength=obs.n_targets), 1)
    s_score = np.bincount(obs.station_index, v2, obs.n_stations) / np.maximum(
        np.bincount(obs.station_index, minlength=obs.n_stations), 1)
    worst_t = [int(j) for j in np.argsort(-t_score, kind="stable")[:n_targets]]
    worst_s = [int(i) for i in np.argsort(-s_score, kind="stable")[:n_stations]]
    out = []
    for j in worst_t:
        A = H[obs.station_index[obs.target_index == j]]
        T2 = T.copy()
        T2[j] = _mirror(T[j], A)
        out.append((f"target {obs.target_ids[j]} mirrored (plane of its stations)", _start(H, T2, o)))
    for j in worst_t:
        A = H[obs.station_index[obs.target_index == j]]
        tri = sorted(itertools.combinations(range(len(A)), 3),
                     key=lambda c: -np.linalg.norm(np.cross(A[c[1]] - A[c[0]], A[c[2]] - A[c[0]])))
        if len(A) == 3:
            continue                          # the triple is the best-fitting plane: tried above
        for c in tri[:n_triples]:
            T2 = T.copy()
            T2[j] = _mirror(T[j], A[list(c)])
            names = ",".join(obs.station_ids[i] for i in obs.station_index[obs.target_index == j][list(c)])
            out.append((f"target {obs.target_ids[j]} mirrored (plane of {names})", _start(H, T2, o)))
    if len(worst_t) > 1:
        T2 = T.copy()
        for j in worst_t:
            T2[j] = _mirror(T[j], H[obs.station_index[obs.target_index == j]])
        out.append((f"targets {', '.join(obs.target_ids[j] for j in worst_t)} mirrored together",
                    _start(H, T2, o)))
    for i in worst_s:
        H2 = H.copy()
        H2[i] = _mirror(H[i], T[obs.target_index[obs.station_index == i]])
        out.append((f"station {obs.station_ids[i]} mirrored (plane of its targets)", _start(H2, T, o)))
    for k in (1, 2, 3):
        drop = worst_t[:k]
        names = ", ".join(obs.target_ids[j] for j in drop)
        out.append((f"partial solution without {names}, then placed again",
                    lambda drop=drop: _partial_restart(obs, H, T, o, drop)))
        out.append((f"initial values without {names} (other anchor sets)",
                    lambda drop=drop: _other_anchors(obs, T, drop, rng, deadline)))
    return out


def find_minimum(obs, solve, first, *, rng=None, p_min: float = P_MIN, n_targets: int = 4,
                 n_stations: int = 2, n_triples: int = 3, max_rounds: int = 3,
                 max_solves: int = SEARCH_SOLVES, max_seconds: float = SEARCH_SECONDS) -> MinimumSearch:
    """Search for a lower minimum when a converged solution fails the global test by far.

    Parameters
    ----------
    obs : Observations  the distances (``sigma_m`` their a-priori standard deviations)
    solve : callable ``solve(start) -> solution``; ``start`` has ``station_xyz_m`` (s, 3),
        ``target_xyz_m`` (t, 3), ``offset_m`` (s,) in ``obs`` order; the solution has the same
        three attributes and ``vtpv`` or (``sigma0``, ``dof``); raises MultilatError when it fails
        (e.g. ``lambda start: adjust(obs, initial=start, snooping=False)``)
    first : the converged solution to check
    rng : numpy Generator, int or None  for the initial values of candidate 5
    p_min : float  trigger and warning threshold on the χ² tail probability (module docstring)
    n_targets, n_stations, n_triples : int  how many worst targets / stations / triples to try
    max_rounds : int  rounds of candidates from the best solution so far
    max_solves, max_seconds : int, float  the work and wall-time bounds (module docstring)

    Returns
    -------
    MinimumSearch
    """
    gen = np.random.default_rng(rng)
    dof = _dof(obs, first)
    best, best_cost = first, _cost(first)
    first_cost = best_cost
    tried: list[Candidate] = []
    triggered = p_value(best_cost, dof) < p_min
    rounds = max_rounds if triggered else 0
    bound = Bound("minimum search", max_work=max_solves, max_seconds=max_seconds)
    for _ in range(rounds):
        improved = False
        for label, start in _candidates(obs, best, n_targets=n_targets, n_stations=n_stations,
                                        n_triples=n_triples, rng=gen, deadline=bound.deadline):
            if bound.exhausted():
                break
            bound.spend()
            report(f"minimum search: start {bound.work} ({label})")
            try:
                if callable(start):
                    start = start()
                    if start is None:
                        continue
                sol = solve(start)
            except (MultilatError, np.linalg.LinAlgError) as exc:
                tried.append(Candidate(label, None, None, False, str(exc).splitlines()[0][:200]))
                continue
            c = _cost(sol)
            ok = bool(np.isfinite(c) and c < best_cost * (1.0 - 1e-9))
            tried.append(Candidate(label, c, float(np.sqrt(c / dof)) if dof > 0 else None, ok))
            if ok:
                best, best_cost, improved = sol, c, True
                if p_value(best_cost, dof) >= p_min:
                    break
        if not improved or p_value(best_cost, dof) >= p_min or bound.stopped_by:
            break
    bound.warn_if_timed_out()
    p = p_value(best_cost, dof)
    warning = false_minimum_text(np.sqrt(best_cost / dof), p, n_tried=len(tried)) if p < p_min else None
    return MinimumSearch(best, triggered, first_cost, best_cost, dof, p, tuple(tried), warning, bound.note())
