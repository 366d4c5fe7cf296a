"""The distance-only search of self-calibrating multilateration, for the part of a network that
nothing else places.

The slope distances measured from instrument points (an instrument's ``from`` point is a station,
its ``to`` point a target; a point on both sides takes the side it has more rows on, and scale bars
between targets drop out) become multilat's :class:`~multilat.network.model.data.Observations`, with the
instrument as the head (its additive constant is estimated by the search) or the station itself.
Targets seen by three or more stations keep their rows, and the distance path's own initial values
(:func:`multilat.network.adjust.approximate.starts.initial_for`: the mirror search and multilateration of the targets
seen by three) place them. Placed points of the network fix the frame: with three or more of them
among the searched points the search is fitted onto them rigidly (a mirror image allowed: distances
cannot tell one from the other), and its stations are placed: the chain places the targets from
them (multilateration, or trilateration where another observation picks the side) and only the
targets it still cannot place take the search's values, as the last resort (the search picks their
side from the whole network jointly). With no point placed anywhere its frame is the network's and
every point is placed (the distance path's guarantees); with one or two placed points among the
searched ones (:data:`FIT_POINTS`) its own frame is moved onto them (:func:`onto_given`: the translation,
and for two the direction of the line between them; the rotation about that line stays the search's)
and every point is placed too (issue 26: approximate coordinates for some points only). Placed
points outside the searched ones do not move it: where angles tie them to it, the adjustment starts
from that frame. Where the search left rows out between its points (mutual distances, scale
bars), each of up to :data:`SEARCHES` runs is refitted on every distance (:func:`_polish`) and the
first whose cost the noise explains is kept (else the lowest).

The distance path's minimum search is not part of the chain: :func:`multilat.network.adjust.general.run.adjust_network`
adjusts from the search's start first and, only when that adjustment fails the global test by far
(or does not converge) and the search ran in the network's own frame (:func:`searched_free`), runs
it from the search's own start (:func:`minimum_search`). Run always, it cost a full distance-path
adjustment per chain (about 1.3 s of 3.6 at 8 stations x 20 000 targets).
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.datum import apply_rigid, rigid_fit
from multilat.network.model.distance import line_of_sight

__all__ = ["distance_search", "onto_given", "searched_free", "minimum_search", "NOTE", "FREE_FRAME", "MINIMUM_NOTE"]

#: Levenberg-Marquardt iterations of the refit on every distance when the search left rows out
POLISH_ITERATIONS = 100
#: searches (from one random generator) when the search left rows out: the first whose refit cost
#: the noise explains (χ² below dof + 5 sqrt(2 dof)) is kept, else the lowest
SEARCHES = 8
#: the chain's note of a search (:func:`distance_search`), and the words that say it ran in the network's
#: own frame (no point placed: where the distance path's minimum search applies)
NOTE = "distance-only search"
FREE_FRAME = "in the network's own frame"
#: the note of :func:`minimum_search` once run (so that it runs once per network, not per snooping round)
MINIMUM_NOTE = "the distance path's minimum search"
#: placed points among the searched ones that fix the search's frame by a rigid fit; with fewer (one
#: or two, :func:`onto_given`) the search keeps its own frame, moved onto them, and places every point
FIT_POINTS = 3


def _tables(network):
    """(Observations of the instrument distances, their points, the (from, to) rows left out) or None."""
    from multilat.network.model.data import Observations, distinct_pair_codes

    ids = network.points.ids
    f, t, d, s, h, names = [], [], [], [], [], []
    for b in network.blocks:
        if b.kind != "slope_distance":
            continue
        m = len(b.value)
        inst = np.asarray(b.index.get("instrument", np.full(m, -1)), int)
        f.append(np.asarray(b.index["from"], int))
        t.append(np.asarray(b.index["to"], int))
        d.append(b.value)
        s.append(b.sigma)
        h.append(np.where(inst >= 0, inst + len(names), -1))
        names += list(b.names.get("instrument", ()))
    if not f:
        return None
    f, t, d, s, h = (np.concatenate(a) for a in (f, t, d, s, h))
    n = len(ids)
    n_from, n_to = np.bincount(f, minlength=n), np.bincount(t, minlength=n)
    keep = (n_from[f] >= n_to[f]) & (n_to[t] > n_from[t])
    seen = np.bincount(distinct_pair_codes(f[keep], t[keep], n) % n, minlength=n)
    keep &= seen[t] >= 3
    if not keep.any():
        return None
    dropped = np.c_[f[~keep], t[~keep]]
    f, t, d, s, h = (a[keep] for a in (f, t, d, s, h))
    st, si = np.unique(f, return_inverse=True)
    tg, ti = np.unique(t, return_inverse=True)
    first = np.zeros(len(st), int)
    first[si[::-1]] = np.arange(len(f))[::-1]             # a station's first row names its head
    heads = tuple(names[h[r]] if h[r] >= 0 else f"station {ids[st[k]]}" for k, r in enumerate(first))
    obs = Observations(tuple(ids[i] for i in st), tuple(ids[j] for j in tg), si, ti, d, s, station_heads=heads)
    return obs, np.concatenate([st, tg]), dropped


def distance_search(network, xyz, known, rng):
    """The distance-only search on the unplaced points of the distance sub-network: (points placed,
    (points, coordinates) offered as the last resort, note or None, {point: reason} of the targets
    it cannot place: :func:`_initial`). ``xyz``, ``known`` are updated in place for the points placed."""
    none = (np.zeros(0, int), (np.zeros(0, int), np.zeros((0, 3))), None, {})
    got = _tables(network)
    if got is None:
        return none
    obs, sub, dropped = got
    anchors = sub[known[sub]]
    unknown = ~known[sub]
    if not unknown.any():
        return none
    gen = np.random.default_rng(rng)
    first, how, weak = _search(obs, sub, anchors, xyz, gen, {})
    if first is None:
        return none[0], none[1], how, {}
    unknown &= np.all(np.isfinite(first), axis=1)           # the targets it cannot place stay unplaced
    new = unknown.copy()
    if len(anchors) >= FIT_POINTS:        # in a placed frame: its stations now, its targets last
        new[obs.n_stations:] = False
    placed = sub[new]
    left_out = bool(len(dropped)) and bool(np.isin(dropped, sub).all(1).any()) and bool(new.any())
    best = None
    for k in range(SEARCHES if left_out else 1):
        got, how = (first, how) if k == 0 else _search(obs, sub, anchors, xyz, gen, weak)[:2]
        if got is None:
            break
        trial = xyz.copy()
        trial[placed] = got[new]
        cost, dof = _polish(network, trial, known | np.isin(np.arange(len(known)), placed), placed,
                            defect=_DEFECT.get(len(anchors), 0)) if left_out else (0.0, 0)
        if best is None or cost < best[0]:
            best = (cost, trial[placed], got[unknown & ~new])
        if cost <= dof + 5 * np.sqrt(2 * max(dof, 1)):     # a χ² the noise explains: the minimum
            break
    xyz[placed], known[placed] = best[1], True
    note = f"{NOTE}{_frame_words(anchors, network.points.ids)}: {how}"
    return placed, (sub[unknown & ~new], best[2]), note, {int(sub[r]): why for r, why in weak.items()}


def _frame_words(anchors, ids) -> str:
    """The note's words on the search's frame (:data:`FREE_FRAME` only with no point placed: where
    :func:`searched_free` lets the minimum search replace the sub-network's coordinates)."""
    if not len(anchors):
        return f" ({FREE_FRAME})"
    if len(anchors) >= FIT_POINTS:
        return ""
    names = " and ".join(repr(ids[j]) for j in anchors)
    fixed = "translation" if len(anchors) == 1 else "translation and the direction of the line between them"
    return f" (its own frame moved onto the given {names}: {fixed}; the rest of its orientation is its own)"


def searched_free(notes) -> bool:
    """Whether the chain's ``notes`` (a network's notes) say the distance-only search placed points in
    the network's own frame: where the distance path's minimum search (``minimum=True``) applies."""
    return any(n.startswith(f"{NOTE} ({FREE_FRAME}") for n in notes)


def _search(obs, sub, anchors, xyz, gen, weak):
    """One run of the distance path's search: (coordinates of ``sub`` in the placed frame, NaN for
    the targets it cannot place, method, {row of ``sub``: reason} of those: :func:`_initial`; the
    rows of ``weak`` left out from the start), or (None, why not, {})."""
    try:
        start, how, weak, part = _initial(obs, gen, weak)
    except MultilatError as e:
        return None, f"the distance-only search failed: {e}", {}
    got = np.full((len(sub), 3), np.nan)
    got[_sub_rows(obs, part)] = np.vstack([start.station_xyz_m, start.target_xyz_m])
    if len(anchors):
        if not np.isfinite(got[_rows(sub, anchors)]).all():     # a placed point among those it cannot place
            left = ", ".join(repr(i) for i in _ids(obs, weak))
            return None, (f"the distance-only search failed: without {left} (lines of sight coplanar) it "
                          "cannot place a point placed already, to fit its frame"), {}
        try:
            R, t = onto_given(got[_rows(sub, anchors)], xyz[anchors])
        except MultilatError:
            return None, None, {}
        got = apply_rigid(R, t, got)
    return got, how.get("method", "?").removeprefix("distances: "), weak


def _initial(obs, gen, weak=None):
    """The distance path's initial values (:func:`multilat.network.adjust.approximate.starts.initial_for`)
    without the targets it finds undetermined (:class:`multilat.network.adjust.distance.exclusion.UndeterminedTargets`:
    lines of sight exactly coplanar or collinear; the reason words of
    :mod:`multilat.network.model.weak_points`), as the distance path leaves them out, at most
    ``MAX_UNDETERMINED_ROUNDS`` rounds: (start, how, {row of the sub-network (stations first): reason},
    the observations it was computed from). ``weak``: rows already known undetermined."""
    from multilat.network.adjust.approximate.starts import initial_for
    from multilat.network.adjust.distance.exclusion import MAX_UNDETERMINED_ROUNDS, UndeterminedTargets

    weak = dict(weak or {})
    for _ in range(MAX_UNDETERMINED_ROUNDS):
        out = np.isin(obs.target_index, [r - obs.n_stations for r in weak])
        part = obs.subset(~out) if out.any() else obs
        try:
            start, how = initial_for(part, None, None, gen)
        except UndeterminedTargets as e:
            new = {obs.n_stations + obs.target_ids.index(t): why for t, why in e.reasons.items()
                   if t in obs.target_ids}
            if not new or set(new) <= set(weak):
                raise
            weak.update(new)
            continue
        return start, how, weak, part
    raise MultilatError(f"targets still undetermined after {MAX_UNDETERMINED_ROUNDS} rounds of leaving them out")


def _ids(obs, rows):
    """The ids of the sub-network's ``rows`` (stations first)."""
    ids = tuple(obs.station_ids) + tuple(obs.target_ids)
    return [ids[r] for r in rows]


def _sub_rows(obs, part):
    """The rows of the sub-network of ``obs`` (stations first) holding the points of ``part`` (its subset)."""
    if part is obs:
        return np.arange(obs.n_stations + obs.n_targets)
    row = {p: r for r, p in enumerate(tuple(obs.station_ids) + tuple(obs.target_ids))}
    return np.array([row[p] for p in tuple(part.station_ids) + tuple(part.target_ids)], int)


def _rows(sub, anchors):
    """The rows of ``sub`` holding ``anchors``, in the order of ``anchors``."""
    return np.array([int(np.flatnonzero(sub == j)[0]) for j in anchors], int)


def onto_given(src, dst, about_z: bool = False):
    """(R, t) bringing the search's placed points ``src`` (p, 3) onto their given coordinates ``dst``:
    three or more, the rigid fit (a mirror image allowed: distances cannot tell one from the other);
    one, the translation; two, the translation of their mid-point and the smallest rotation turning
    the line between them onto the given line (its rotation about that line stays the search's:
    nothing given fixes it; with ``about_z``, a frame whose vertical is observed, the rotation about
    z that best turns it). The search's scale is kept (the given points may be rough)."""
    if len(src) >= FIT_POINTS:
        return rigid_fit(src, dst, allow_reflection=True)
    if about_z and len(src) == 2:
        return rigid_fit(src, dst, about_z=True)
    R = np.eye(3)
    if len(src) == 2:
        (na, nb), (ua, ub) = line_of_sight(np.stack([src[1] - src[0], dst[1] - dst[0]]), floor_m=1.0)
        if na > 0 and nb > 0:
            R = _turn(ua, ub)
    c = src.mean(axis=0)
    return R, dst.mean(axis=0) - R @ c


def _turn(a, b):
    """The smallest rotation taking the unit vector ``a`` onto the unit vector ``b`` (Rodrigues; half a
    turn about an axis normal to ``a`` when they are opposite)."""
    v, c = np.cross(a, b), float(np.dot(a, b))
    if c < -1.0 + 1e-12:
        n = np.cross(a, np.eye(3)[int(np.argmin(np.abs(a)))])
        n /= np.linalg.norm(n)
        return 2.0 * np.outer(n, n) - np.eye(3)
    k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


def minimum_search(network, rng=0):
    """The distance path's minimum search (:func:`_minimum`) on the distance sub-network of ``network``
    (:func:`_tables`), from the search's own start (:func:`multilat.network.adjust.approximate.starts.initial_for`,
    seeded by ``rng`` and its generator then driving the candidates: the chain's start and, for
    the default seed, what the search did when it ran inside the chain); (n, 3) coordinates with the
    sub-network's points at the solution and the others NaN (to be placed again by the chain), or
    None when it found nothing else."""
    got = _tables(network)
    if got is None:
        return None
    obs, sub, _ = got
    xyz = network.points.xyz_m
    gen = np.random.default_rng(rng)
    try:
        start, _, _, part = _initial(obs, gen)
    except MultilatError:
        return None
    sol = _minimum(part, start, gen)
    if sol is start:
        return None
    out = np.full_like(xyz, np.nan)
    out[sub[_sub_rows(obs, part)]] = np.vstack([sol.station_xyz_m, sol.target_xyz_m])
    return out


def _minimum(obs, start, gen):
    """The distance path's minimum search (:func:`multilat.network.adjust.approximate.search.find_minimum`) from
    ``start``: the distances adjusted from it and, when that minimum fails the global test by far,
    the search's solution (what :func:`multilat.network.adjust.distance.adjust.adjust` does after its first fit);
    ``start`` itself when it already leads to a minimum the noise explains, or when the distance
    path fails or leaves points out. Without it a flat ring whose initial values put targets on the
    wrong side converged at σ0 ~ 130 on the general layer (network 87 of
    ``benchmarks/study_general_acceptance.py``) where the distance path reaches σ0 1.05."""
    import warnings

    from multilat.network.adjust.distance.adjust import adjust
    from multilat.network.adjust.approximate.search import find_minimum, needs_search

    def solve(s):
        return adjust(obs, initial=s, snooping=False)

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            first = solve(start)
            if first.obs.n_stations != obs.n_stations or first.obs.n_targets != obs.n_targets:
                return start
            if not needs_search(first, obs):
                return first
            return find_minimum(obs, solve, first, rng=gen).solution
    except MultilatError:
        return start


#: the datum defect the placed points leave the searched ones (rigid motions not fixed), by their number
_DEFECT = {0: 6, 1: 3, 2: 1}


def _polish(network, xyz, known, placed, defect: int) -> tuple[float, int]:
    """Least squares of every slope distance between placed points over the coordinates of
    ``placed`` (the others held; instrument constants ignored), from the search's values
    (:func:`multilat.network.adjust.approximate.initial_refine.levenberg_marquardt`, Marquardt-damped: the datum
    defect of a free network is harmless); its cost (sum of squared weighted residuals) and degrees
    of freedom (rows - 3 x placed + ``defect``: the rigid motions the held points leave free, 6 with
    none). The search saw
    only station-to-target rows; the rows between two stations or two targets (mutual sights,
    scale bars) would otherwise first act in the adjustment, whose Gauss-Newton steps are
    undamped."""
    import scipy.sparse

    from multilat.network.adjust.approximate.initial_refine import levenberg_marquardt

    rows = [np.c_[b.index["from"], b.index["to"], b.value, b.sigma] for b in network.blocks
            if b.kind == "slope_distance"]
    r = np.vstack(rows)
    f, t = r[:, 0].astype(int), r[:, 1].astype(int)
    use = known[f] & known[t]
    f, t, d, w = f[use], t[use], r[use, 2], 1.0 / r[use, 3]
    col = np.full(len(known), -1)
    col[placed] = np.arange(len(placed))
    base = xyz.copy()

    def at(x):
        p = base.copy()
        p[placed] = x.reshape(-1, 3)
        return p

    def fun(x):
        p = at(x)
        return w * (d - np.linalg.norm(p[t] - p[f], axis=1))

    def jac(x):
        p = at(x)
        _, u = line_of_sight(p[t] - p[f])
        m = len(d)
        ri, ci, vi = [], [], []
        for end, sign in ((t, -1.0), (f, 1.0)):           # d r / d P = -w d|.|/dP
            ok = col[end] >= 0
            for a in range(3):
                ri.append(np.flatnonzero(ok))
                ci.append(3 * col[end[ok]] + a)
                vi.append(sign * w[ok] * u[ok, a])
        return scipy.sparse.csr_matrix((np.concatenate(vi), (np.concatenate(ri), np.concatenate(ci))),
                                       shape=(m, 3 * len(placed)))

    x, _ = levenberg_marquardt(fun, jac, xyz[placed].ravel(), max_iter=POLISH_ITERATIONS)
    xyz[placed] = x.reshape(-1, 3)
    return float(np.sum(fun(x) ** 2)), len(d) - 3 * len(placed) + defect
