"""Where to put the heads: a global search over head positions for a design criterion.

The criterion (:data:`multilat.network.design.preanalysis.CRITERIA`) of a layout is evaluated by the
pre-analysis (no measurements); heads move in a box (a floor area with a height range is a box) or
are chosen among candidate positions. A head sees the targets within its range limits
(``min_range_m <= |H - T| <= max_range_m``) and not hidden from it; a layout the model cannot solve
scores :data:`PENALTY_M`.

Two global methods, both seeded (``rng``):

``"multistart"`` (default)  Powell's bounded derivative-free local search (the criteria are maxima,
    not smooth) from the start layout and from ``starts - 1`` random layouts in the box.
``"differential_evolution"``  :func:`scipy.optimize.differential_evolution` (Latin hypercube
    population including the start layout), then a Powell polish of its best member.

Candidate positions: every combination when there are at most ``max_evaluations``, else random
combinations and a swap search from the best.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.design.preanalysis import CRITERIA, Layout, SigmaModel, criterion_value

__all__ = ["DesignResult", "SearchStart", "optimise_heads", "choose_candidates", "head_ids",
           "visibility", "segment_hits_box", "corner_start", "PENALTY_M", "min_heads"]

#: criterion value of a layout the model cannot solve (metres)
PENALTY_M = 1.0e3

#: unit-cube corners in the order used for start layouts (4 first: a tetrahedron)
_CORNERS = np.array([[0, 0, 0], [1, 1, 0], [1, 0, 1], [0, 1, 1], [1, 0, 0], [0, 1, 0], [0, 0, 1],
                     [1, 1, 1]], float)


def min_heads(offsets: bool) -> int:
    """Fewest heads self-calibration can work with (4, with or without offsets)."""
    return 4


def head_ids(count: int, names=()) -> tuple[str, ...]:
    """The design's head ids: ``names`` (the instrument's head names, :func:`design_head_names`)
    first, then ``A, B, C, ...``, ``H27, H28, ...`` not already taken."""
    out = list(names)[:count]
    k = 0
    while len(out) < count:
        g = chr(65 + k) if k < 26 else f"H{k + 1}"
        k += 1
        if g not in out:
            out.append(g)
    return tuple(out)


def visibility(station_xyz_m, target_xyz_m, *, min_range_m=0.0, max_range_m=math.inf, hidden=None,
               occluders=()):
    """Which head sees which target (s, t): within the range limits, not ``hidden`` (s, t), and no
    ``occluders`` box (``(box_min_m, box_max_m)`` pairs) cutting the line of sight (a target inside
    a box is hidden)."""
    h = np.asarray(station_xyz_m, float).reshape(-1, 3)
    t = np.asarray(target_xyz_m, float).reshape(-1, 3)
    d = np.linalg.norm(h[:, None, :] - t[None], axis=2)
    vis = (d >= max(min_range_m, 1e-6)) & (d <= max_range_m)
    if hidden is not None:
        vis &= ~np.asarray(hidden, bool)
    for lo, hi in occluders:
        vis &= ~segment_hits_box(h, t, lo, hi)
    return vis


def segment_hits_box(a_xyz_m, b_xyz_m, box_min_m, box_max_m) -> np.ndarray:
    """Whether the segment from each point of ``a`` (s, 3) to each of ``b`` (t, 3) meets the closed
    axis-aligned box (slab method) -> bool (s, t)."""
    a = np.asarray(a_xyz_m, float)[:, None, :]
    dv = np.asarray(b_xyz_m, float)[None] - a                       # (s, t, 3)
    lo, hi = np.asarray(box_min_m, float), np.asarray(box_max_m, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - a) / dv, (hi - a) / dv
    par = np.abs(dv) < 1e-15                                        # parallel to a slab
    inside = (a >= lo) & (a <= hi)
    t1 = np.where(par, np.where(inside, -np.inf, np.inf), t1)      # outside a slab it is parallel
    t2 = np.where(par, np.inf, t2)                                  # to: never enters (tmin = inf)
    tmin = np.minimum(t1, t2).max(axis=2)
    tmax = np.maximum(t1, t2).min(axis=2)
    return (tmin <= tmax) & (tmax >= 0.0) & (tmin <= 1.0)


def corner_start(count: int, box_min_m, box_max_m, rng) -> np.ndarray:
    """A start layout: box corners (a tetrahedron of alternate corners for 4 heads), random points
    for heads beyond 8. Shape (count, 3)."""
    lo, hi = np.asarray(box_min_m, float), np.asarray(box_max_m, float)
    k = min(count, 8)
    pts = lo + _CORNERS[:k] * (hi - lo)
    if count > 8:
        pts = np.vstack([pts, rng.uniform(lo, hi, size=(count - 8, 3))])
    return pts


@dataclass(frozen=True)
class SearchStart:
    """One local search: its start and end criterion (m; None where that layout is unsolvable: a
    target seen by fewer than 3 heads or a singular geometry, which the search scores
    :data:`PENALTY_M`) and the evaluations used."""

    start_criterion_m: float | None
    end_criterion_m: float | None
    evaluations: int

    @classmethod
    def of(cls, start: float, end: float, evaluations: int) -> "SearchStart":
        """From the objective's values: a penalised (unsolvable) value becomes None."""
        def real(v):
            return None if v >= PENALTY_M else float(v)

        return cls(real(start), real(end), int(evaluations))

    @property
    def start_unsolvable(self) -> bool:
        return self.start_criterion_m is None


@dataclass(frozen=True, eq=False)
class DesignResult:
    """Result of :func:`optimise_heads` / :func:`choose_candidates`.

    Attributes
    ----------
    criterion : str
    layout : Layout  the best layout found (visibility from the range limits)
    criterion_m : float  its criterion value
    start_layout : Layout ; start_criterion_m : float  the start layout and its value
    method : str
    evaluations : int  criterion evaluations in all
    starts : tuple of SearchStart  the local searches, in order
    history_m : ndarray  best criterion value after each start (multistart) or generation
    """

    criterion: str
    layout: Layout
    criterion_m: float
    start_layout: Layout
    start_criterion_m: float
    method: str
    evaluations: int
    starts: tuple
    history_m: np.ndarray

    @property
    def gain(self) -> float:
        """Start criterion over best criterion (> 1: the search improved the layout)."""
        return self.start_criterion_m / self.criterion_m


class _Objective:
    """Counts evaluations and keeps the best layout seen."""

    def __init__(self, target_ids, target_xyz_m, ids, sigma, criterion, kw, ranges, hidden, occluders=()):
        self.tid, self.tx, self.ids = target_ids, target_xyz_m, ids
        self.sigma, self.criterion, self.kw = sigma, criterion, kw
        self.ranges, self.hidden, self.occluders = ranges, hidden, tuple(occluders)
        self.n = 0
        self.best = (math.inf, None)

    def layout(self, heads_xyz_m) -> Layout:
        h = np.asarray(heads_xyz_m, float).reshape(-1, 3)
        vis = visibility(h, self.tx, min_range_m=self.ranges[0], max_range_m=self.ranges[1],
                         hidden=self.hidden, occluders=self.occluders)
        return Layout(self.ids, h, self.tid, self.tx, vis)

    def __call__(self, x) -> float:
        self.n += 1
        lay = self.layout(x)
        if not lay.visible.any() or lay.visible.sum(axis=0).min() < 3:
            v = PENALTY_M
        else:
            v = criterion_value(self.criterion, lay, self.sigma, **self.kw)
            v = v if np.isfinite(v) else PENALTY_M
        if v < self.best[0]:
            self.best = (v, np.array(x, float).copy())
        return v


def _check(criterion, count, offsets, lengths):
    if criterion not in CRITERIA:
        raise MultilatError(f"criterion must be one of {', '.join(CRITERIA)}, got {criterion!r}")
    if count < min_heads(offsets):
        raise MultilatError(f"count: self-calibration needs at least {min_heads(offsets)} heads, got {count}")
    if criterion == "length_u" and not lengths:
        raise MultilatError("criterion length_u needs lengths (pairs of point ids)")


def _sigma(sigma):
    return sigma if isinstance(sigma, SigmaModel) else SigmaModel(float(sigma))


def optimise_heads(target_xyz_m, *, count: int, box_min_m, box_max_m, sigma, target_ids=None,
                   criterion: str = "max_u95", start=None, offsets: bool = True, datum="free",
                   lengths=(), min_range_m: float = 0.0, max_range_m: float = math.inf, hidden=None,
                   occluders=(), method: str = "multistart", starts: int = 8, max_evaluations: int = 20_000,
                   rng=None, evaluation: str = "auto", head_names=()) -> DesignResult:
    """Head positions in a box that minimise a design criterion for the given targets.

    Parameters
    ----------
    target_xyz_m : ndarray (t, 3)
    count : int  number of heads (>= 4)
    box_min_m, box_max_m : (3,)  where heads may stand
    sigma : SigmaModel or float (m)
    target_ids : sequence of str, optional (default ``"1", "2", ...``)
    criterion : one of :data:`CRITERIA`
    start : ndarray (count, 3), optional  start layout (default :func:`corner_start`)
    offsets, datum, lengths : as :func:`multilat.network.design.preanalysis.preanalyse`
    min_range_m, max_range_m : range limits of a head; hidden : bool (count, t), optional
    occluders : sequence of (box_min_m, box_max_m)  boxes that block the line of sight
    method : "multistart" or "differential_evolution"
    starts : int  local searches (multistart) ; max_evaluations : int  total criterion evaluations
    rng : Generator, int or None
    evaluation : "auto", "dense" or "blocked"  how the criterion is computed
        (:func:`~multilat.network.design.preanalysis.criterion_value`'s ``method``)
    head_names : sequence of str  the heads' ids (default ``A, B, ...``; :func:`head_ids`)

    Returns
    -------
    DesignResult
    """
    from scipy import optimize

    _check(criterion, count, offsets, lengths)
    rng = np.random.default_rng(rng)
    tx = np.asarray(target_xyz_m, float).reshape(-1, 3)
    tid = tuple(str(i + 1) for i in range(len(tx))) if target_ids is None else tuple(target_ids)
    lo, hi = np.asarray(box_min_m, float), np.asarray(box_max_m, float)
    if not np.all(hi > lo):
        raise MultilatError("heads box: box_max_m must exceed box_min_m in every axis")
    x0 = corner_start(count, lo, hi, rng) if start is None else np.asarray(start, float).reshape(count, 3)
    obj = _Objective(tid, tx, head_ids(count, head_names), _sigma(sigma), criterion,
                     dict(offsets=offsets, datum=datum, lengths=tuple(lengths), method=evaluation),
                     (min_range_m, max_range_m), hidden, occluders)
    bounds = list(zip(np.tile(lo, count), np.tile(hi, count)))
    f0 = obj(x0.ravel())
    runs, hist = [], []
    if method == "multistart":
        per = max(50, max_evaluations // max(starts, 1))
        for k in range(max(starts, 1)):
            xs = x0.ravel() if k == 0 else rng.uniform(np.tile(lo, count), np.tile(hi, count))
            n_before = obj.n
            fs = f0 if k == 0 else obj(xs)
            res = optimize.minimize(obj, np.clip(xs, np.tile(lo, count), np.tile(hi, count)),
                                    method="Powell", bounds=bounds,
                                    options=dict(maxfev=per, xtol=1e-4, ftol=1e-7))
            runs.append(SearchStart.of(fs, res.fun, obj.n - n_before))
            hist.append(obj.best[0])
            if obj.n >= max_evaluations:
                break
    elif method == "differential_evolution":
        popsize = 10
        maxiter = max(1, max_evaluations // (popsize * 3 * count) - 1)
        res = optimize.differential_evolution(obj, bounds, seed=rng, popsize=popsize, maxiter=maxiter,
                                              x0=x0.ravel(), init="latinhypercube", polish=False,
                                              tol=1e-6, callback=lambda *a, **k: hist.append(obj.best[0]))
        n_before = obj.n
        pol = optimize.minimize(obj, obj.best[1], method="Powell", bounds=bounds,
                                options=dict(maxfev=max(200, max_evaluations // 10), xtol=1e-4, ftol=1e-7))
        runs.append(SearchStart.of(res.fun, pol.fun, obj.n - n_before))
        hist.append(obj.best[0])
    else:
        raise MultilatError(f"method must be multistart or differential_evolution, got {method!r}")
    best_v, best_x = obj.best
    return DesignResult(criterion, obj.layout(best_x), float(best_v), obj.layout(x0), float(f0),
                        method, obj.n, tuple(runs), np.array(hist))


def choose_candidates(target_xyz_m, candidates_xyz_m, *, count: int, sigma, target_ids=None,
                      candidate_ids=None, criterion: str = "max_u95", offsets: bool = True,
                      datum="free", lengths=(), min_range_m: float = 0.0,
                      max_range_m: float = math.inf, max_evaluations: int = 20_000,
                      rng=None, evaluation: str = "auto", hidden=None, occluders=(),
                      head_names=()) -> DesignResult:
    """The ``count`` candidate positions (c, 3) that minimise the criterion (exhaustive when the
    combinations fit in ``max_evaluations``, else random combinations then single swaps). The
    returned layout's station ids are the chosen candidates' ids (the i-th chosen is head
    ``head_ids(count, head_names)[i]`` of the instrument). ``hidden`` (c, t): targets each
    candidate cannot see; ``occluders`` as :func:`optimise_heads`."""
    _check(criterion, count, offsets, lengths)
    rng = np.random.default_rng(rng)
    cx = np.asarray(candidates_xyz_m, float).reshape(-1, 3)
    c = len(cx)
    cid = tuple(f"C{i + 1}" for i in range(c)) if candidate_ids is None else tuple(candidate_ids)
    if count > c:
        raise MultilatError(f"count: {count} heads but only {c} candidate positions")
    tx = np.asarray(target_xyz_m, float).reshape(-1, 3)
    tid = tuple(str(i + 1) for i in range(len(tx))) if target_ids is None else tuple(target_ids)
    obj = _Objective(tid, tx, head_ids(count, head_names), _sigma(sigma), criterion,
                     dict(offsets=offsets, datum=datum, lengths=tuple(lengths), method=evaluation),
                     (min_range_m, max_range_m), None, occluders)
    hid = None if hidden is None else np.asarray(hidden, bool).reshape(c, len(tx))
    cache: dict[tuple, float] = {}

    def score(sub):
        key = tuple(sorted(sub))
        if key not in cache:
            obj.hidden = None if hid is None else hid[list(key)]
            cache[key] = obj(cx[list(key)].ravel())
        return cache[key]

    first = tuple(range(count))
    f0 = score(first)
    hist = []
    if math.comb(c, count) <= max_evaluations:
        for sub in itertools.combinations(range(c), count):
            score(sub)
        method = "exhaustive"
    else:
        method = "random+swap"
        for _ in range(max_evaluations // 2):
            score(tuple(rng.choice(c, count, replace=False)))
        hist.append(min(cache.values()))
        improved = True
        while improved and obj.n < max_evaluations:
            improved = False
            cur = min(cache, key=cache.get)
            for i, j in itertools.product(range(count), range(c)):
                if j in cur:
                    continue
                cand = tuple(sorted(cur[:i] + (j,) + cur[i + 1:]))
                if score(cand) < cache[cur]:
                    improved = True
                    break
            hist.append(min(cache.values()))
    best = min(cache, key=cache.get)
    hist.append(cache[best])

    def lay(sub):
        obj.hidden = None if hid is None else hid[list(sub)]
        base = obj.layout(cx[list(sub)].ravel())
        return Layout(tuple(cid[i] for i in sub), base.station_xyz_m, tid, tx, base.visible)

    return DesignResult(criterion, lay(best), float(cache[best]), lay(first), float(f0), method, obj.n,
                        (SearchStart.of(f0, cache[best], obj.n),), np.array(hist))
