"""Approximate coordinates of a general network from whatever was observed, chained pass by pass as
gama-local does (``docs/general-network.md``, "Approximate coordinates").

Given coordinates are kept. Each pass, in this order, until a pass places nothing new:

1. **vectors** (:mod:`.place`): observed coordinates, coordinate differences off placed points;
2. **frames** (:mod:`.frames`): set-ups on placed points oriented on placed targets (κ, or ω φ κ for
   an unlevelled tracker); set-ups on unplaced points placed by **resection** (2D from directions
   and distances, two placed targets; an unlevelled tracker fitted rigidly to three);
3. **polar points** from oriented set-ups on placed points (also a horizontal reading and a slope
   distance on a point whose height is given or levelled from a placed point);
4. **intersection** of the sights from two or more oriented set-ups (near-parallel rays flagged);
5. **multilateration** from four or more placed ends, **trilateration** from three where another
   observation picks the side (:mod:`.ranging`).

When a pass places nothing: with no point placed at all, the first set-up with a reading vector is
the origin with the world's axes; otherwise the distance-only search of self-calibrating
multilateration places the distance sub-network (:mod:`.search`, once; inside a placed frame its
stations, its targets only as the last resort, when the passes place nothing more; with one or two
placed points of its own, every point, its frame moved onto them). A target it finds undetermined
(lines of sight exactly coplanar) does not sink it: it is left out of the search, as the distance
path leaves it out, and stays unplaced unless other observations place it (a tracker's angles: a
polar point), named with the distance path's reason. When the chain still stops with
only one or two points given in the whole network (a given station that reads no other placed
point orients nothing), it is run again as with none given and moved onto them
(:func:`.search.onto_given`; two points of a levelled network turn it about the vertical only),
if that places more. A point still not placed is named in one line saying what would reach it.

The kinds' model is not needed: this is a separate step (JAG3D's ``approximation/`` package), and
:func:`..adjust.adjust` iterates from its result.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.datum import apply_rigid
from multilat.network.adjust.approximate.general import frames as _frames
from multilat.network.adjust.approximate.general import place, ranging
from multilat.network.adjust.approximate.general.search import (FIT_POINTS, FREE_FRAME, NOTE,
                                                                   distance_search, onto_given)
from multilat.network.adjust.approximate.general.sights import Sights, gather
from multilat.network.model.observations import Network

__all__ = ["approximate", "unreachable", "reasons", "chain", "Chain"]

#: the first words of the note of :func:`_seed`
ORIGIN_NOTE = "no point has coordinates"


@dataclass
class Chain:
    """The chain's state: xyz (n, 3), known (n,), frames {set-up index: R}, notes, and per point the
    sights ``reads`` [(set-up, reading)], its own set-ups ``own``, its distance rows (``drows``: CSR
    order and pointers), ``rises``;
    ``method`` {point index: how it was placed}; ``undetermined`` {point index: reason} of the targets
    the distance-only search cannot place (lines of sight exactly coplanar: the distance path's words,
    :mod:`multilat.network.model.weak_points`), named so if nothing else places them."""

    ids: tuple
    sights: Sights
    xyz: np.ndarray
    known: np.ndarray
    frames: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    reads: dict = field(default_factory=dict)
    own: dict = field(default_factory=dict)
    drows: tuple = ()
    rises: dict = field(default_factory=dict)
    method: dict = field(default_factory=dict)
    undetermined: dict = field(default_factory=dict)


def chain(network: Network, *, extra=(), rng=0) -> Chain:
    """Runs the chain (module docstring). ``extra``: blocks that serve the approximations only
    (angles read without σ); ``rng``: seed of the distance-only search."""
    sights = gather(tuple(network.blocks) + tuple(extra))
    st = _run(network, sights, network.points.xyz_m.copy(), rng)
    given = np.flatnonzero(np.all(np.isfinite(network.points.xyz_m), axis=1))
    if st.known.all() or not 0 < len(given) < FIT_POINTS:
        return st
    free = _run(network, sights, np.full_like(st.xyz, np.nan), rng)
    if free.known.sum() <= st.known.sum() or not free.known[given].all():
        return st
    return _moved(free, given, network.points.xyz_m[given])


def _moved(free: Chain, given, given_xyz) -> Chain:
    """The chain run as with no point given (``free``) moved onto the one or two ``given`` points
    (:func:`.search.onto_given`; for two, about the vertical only where a levelled set-up observes it);
    their given coordinates kept."""
    levelled = any(su.levelled for su in free.sights.setups)
    R, t = onto_given(free.xyz[given], given_xyz, about_z=levelled)
    free.xyz[free.known] = apply_rigid(R, t, free.xyz[free.known])
    free.xyz[given] = given_xyz
    free.frames = {s: R @ F for s, F in free.frames.items()}
    for j in given:
        free.method.pop(int(j), None)
    free.notes = [n.replace(f"{NOTE} ({FREE_FRAME}", f"{NOTE} (its own frame, moved onto the given point(s)")
                  for n in free.notes if not n.startswith(ORIGIN_NOTE)]
    names = " and ".join(repr(free.ids[j]) for j in given)
    fixed = "translation" if len(given) == 1 else ("translation and the bearing of the line between them" if levelled
                                                    else "translation and the direction of the line between them")
    free.notes.append(f"the given point(s) {names} place nothing more on their own: the chain run as with no "
                      f"point given, moved onto {'it' if len(given) == 1 else 'them'} ({fixed})")
    return free


def _run(network: Network, sights: Sights, xyz, rng) -> Chain:
    """The chain from the coordinates ``xyz`` (NaN rows: not placed)."""
    st = Chain(network.points.ids, sights, xyz, np.all(np.isfinite(xyz), axis=1))
    if st.known.all():
        return st
    pts = network.points
    _index(st, pts.n)
    seeded = searched = False
    last = None                                           # the search's targets, offered last
    while not st.known.all():
        if _pass(st):
            continue
        if not st.known.any() and not seeded:
            seeded = True
            if _seed(st):
                continue
        if not searched:
            searched = True
            placed, last, note, st.undetermined = distance_search(network, st.xyz, st.known, rng)
            st.notes += [note] if note else []
            st.method.update({int(j): "distance-only search" for j in placed})
            if len(placed):
                continue
        if last is not None and (~st.known[last[0]]).any():
            for j, p in zip(*last):
                if not st.known[j]:
                    st.xyz[j], st.known[j] = p, True
                    st.method[int(j)] = "distance-only search"
            last = None
            continue
        break
    return st


def _seed(st: Chain) -> bool:
    """No point placed: the first set-up with a reading vector is the origin, its axes the world's."""
    first = next((s for s, su in enumerate(st.sights.setups) if np.isfinite(su.v).all(1).any()), None)
    if first is None:
        return False
    su = st.sights.setups[first]
    st.xyz[su.station], st.known[su.station] = 0.0, True
    st.method[int(su.station)] = "origin"
    st.frames[first] = np.eye(3)
    st.notes.append(f"{ORIGIN_NOTE}: the {su.key} on {st.ids[su.station]!r} is the origin, its axes "
                    "the world's")
    return True


def _index(st: Chain, n: int) -> None:
    st.reads, st.own, st.rises = {}, {}, {}               # point -> list (absent: empty)
    for s, su in enumerate(st.sights.setups):
        st.own.setdefault(su.station, []).append(s)
        for k, j in enumerate(su.to):
            st.reads.setdefault(int(j), []).append((s, k))
    ends = st.sights.dist[:, :2].astype(int).T.ravel()    # rows of each point, grouped (CSR)
    order = np.argsort(ends, kind="stable")
    st.drows = (order % len(st.sights.dist), np.searchsorted(ends[order], np.arange(n + 1)))
    for (i, j), dh in st.sights.rise.items():
        st.rises.setdefault(j, []).append((i, dh))


def _rows_of(st: Chain, j):
    order, ptr = st.drows
    return order[ptr[j]:ptr[j + 1]]


def _tried(st: Chain) -> np.ndarray:
    """The unplaced points some method might place now: sighted, or with 3+ distances to placed points."""
    known, d = st.known, st.sights.dist
    f, t = d[:, 0].astype(int), d[:, 1].astype(int)
    ranged = np.bincount(np.r_[t[known[f]], f[known[t]]], minlength=len(known)) >= 3
    sighted = np.zeros(len(known), bool)
    sighted[list(st.reads)] = True
    return np.flatnonzero(~known & (ranged | sighted))


def _pass(st: Chain) -> int:
    """One pass of the chain; the number of points placed (each one's method in ``st.method``)."""
    xyz, known, setups = st.xyz, st.known, st.sights.setups
    before = known.copy()
    place.by_vector(st.sights.vec, st.sights.coord, xyz, known)
    _record(st, before, "vector")
    for s, su in enumerate(setups):
        if s in st.frames:
            continue
        if known[su.station]:
            R = _frames.orient(su, xyz, known)
        else:
            got = _frames.resect(su, xyz, known) or _frames.resect_directions(su, xyz, known)
            if got is None:
                continue
            xyz[su.station], R = got
            known[su.station] = True
        if R is not None:
            st.frames[s] = R
    _record(st, before, "resection")
    for s, R in st.frames.items():
        if known[setups[s].station]:
            place.polar(setups[s], R, xyz, known)
    _record(st, before, "polar")
    for j in _tried(st):
        reads, rises = st.reads.get(j, ()), st.rises.get(j, ())
        got = place.intersect(setups, st.frames, reads, rises, xyz, known) if reads else None
        if got is not None:
            how = "intersection"
            if got[1] < place.WEAK_RAD:
                st.notes.append(f"point {st.ids[j]!r}: intersected by rays {np.degrees(got[1]):.2g} degrees from "
                                "parallel (weak)")
        else:
            p = place.polar_on_height(setups, st.frames, reads, rises, xyz, known, j)
            got, how = ((p, None), "polar") if p is not None else _ranged(st, j)
        if got is not None:
            xyz[j], known[j] = got[0], True
            st.method[j] = how
    return int((known & ~before).sum())


def _record(st: Chain, before, how: str) -> None:
    for j in np.flatnonzero(st.known & ~before):
        st.method.setdefault(int(j), how)


def _ranged(st: Chain, j):
    rows = _rows_of(st, j)
    if len(rows) < 3:
        return None, None
    anchors, d, n_ends = ranging.ends(st.sights.dist, rows, j, st.xyz, st.known)
    cand = ranging.candidates(anchors, d, n_ends)
    if len(cand) == 1:
        return (cand[0], None), "multilateration"
    if len(cand) == 2:
        m = [ranging.side_misfit(p, st.sights, st.frames, st.reads.get(j, ()), st.own.get(j, ()),
                                 st.rises.get(j, ()), st.xyz, st.known) for p in cand]
        if m[0][1] and m[0][0] != m[1][0]:
            return (cand[int(m[1][0] < m[0][0])], None), "trilateration"
    return None, None


def reasons(network: Network, *, extra=(), rng=0) -> dict:
    """{id: why no approximate coordinates can be computed} for the points the chain does not reach,
    in point order (one line each, saying what would reach the point)."""
    st = chain(network, extra=extra, rng=rng)
    return {st.ids[j]: _why(st, j) for j in np.flatnonzero(~st.known)}


def unreachable(network: Network, *, extra=(), rng=0) -> tuple:
    """The ids of the points whose approximate coordinates cannot be computed from the observations
    (what :func:`approximate` would name), in point order."""
    return tuple(reasons(network, extra=extra, rng=rng))


def approximate(network: Network, *, extra=(), rng=0, partial: bool = False) -> Network:
    """The network with every missing approximate coordinate computed (given coordinates are kept).
    A point the chain does not reach is refused in one line, or with ``partial`` left NaN."""
    pts = network.points
    if np.all(np.isfinite(pts.xyz_m)):
        return network
    st = chain(network, extra=extra, rng=rng)
    missing = np.flatnonzero(~st.known)
    if missing.size and not partial:
        more = f" (and {missing.size - 1} more)" if missing.size > 1 else ""
        sep = " " if int(missing[0]) in st.undetermined else ": "     # "point 'P' is undetermined: ..."
        raise MultilatError(f"point {st.ids[missing[0]]!r}{more}{sep}{_why(st, missing[0])}")
    given = np.all(np.isfinite(pts.xyz_m), 1)
    placed = int((st.known & ~given).sum())
    xyz = np.where(np.isfinite(pts.xyz_m), pts.xyz_m, st.xyz)
    count = {}
    for how in st.method.values():
        count[how] = count.get(how, 0) + 1
    by = ", ".join(f"{n} {how}" for how, n in count.items())
    notes = tuple(st.notes) + ((f"approximate coordinates computed for {placed} point(s) ({by})",) if placed else ())
    return Network(pts.with_xyz(xyz), network.blocks, network.notes + notes)


def _why(st: Chain, j) -> str:
    """What the observations give point ``j`` and what would place it, one line; for a target the
    distance-only search found undetermined, its reason in the distance path's words."""
    if int(j) in st.undetermined:
        return st.undetermined[int(j)]
    known, setups = st.known, st.sights.setups
    have = []
    if len(_rows_of(st, j)):
        _, _, n_ends = ranging.ends(st.sights.dist, _rows_of(st, j), j, st.xyz, known)
        have.append(f"distances to {n_ends} placed point(s) (multilateration needs 4 not in one plane, "
                    "trilateration 3 and another observation to pick the side)")
    if st.reads.get(j, ()):
        oriented = {setups[s].station for s, _ in st.reads.get(j, ()) if s in st.frames and known[setups[s].station]}
        have.append(f"sighted from {len(oriented)} oriented set-up(s) on placed points without a distance to it "
                    "(a polar point needs the distance with the zenith angle or elevation, intersection 2 set-ups)")
    for s in st.own.get(j, ()):
        su = setups[s]
        n = int(len(set(su.to[known[su.to] & np.all(np.isfinite(su.v), 1)].tolist())))
        have.append(f"its {su.key} reads {n} placed point(s) with distance and height (resection needs "
                    f"{2 if su.levelled else 3})")
    if not have:
        have.append("no observation links it to a placed point")
    return "no approximate coordinates can be computed from the observations: " + "; ".join(have) + \
        "; give them in the file"
