"""The distance-only search of self-calibrating multilateration, for the part of a network that
nothing else places.

The slope distances measured from instrument points (an instrument's ``from`` point is a station,
its ``to`` point a target; a point on both sides takes the side it has more rows on, and scale bars
between targets drop out) become multilat's :class:`~multilat.network.data.Observations`, with the
instrument as the head (its additive constant is estimated by the search) or the station itself.
Targets seen by three or more stations keep their rows, and the distance path's own initial values
(:func:`multilat.network.starts.initial_for`: the mirror search and multilateration of the targets
seen by three) place them. Placed points of the network fix the frame: with three or more of them
among the searched points the search is fitted onto them rigidly (a mirror image allowed: distances
cannot tell one from the other); with none placed anywhere its frame is the network's; otherwise
the search is not used (its frame would be arbitrary).
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.datum import apply_rigid, rigid_fit

__all__ = ["distance_search"]


def _tables(network):
    """(Observations of the instrument distances, their point indices) or (None, None)."""
    from multilat.network.data import Observations

    f, t, d, s, h = [], [], [], [], []
    ids = network.points.ids
    for b in network.blocks:
        if b.kind != "slope_distance":
            continue
        inst = b.index.get("instrument")
        names = b.names.get("instrument", ())
        for k, (i, j) in enumerate(zip(b.index["from"], b.index["to"])):
            hi = -1 if inst is None else int(inst[k])
            f.append(int(i))
            t.append(int(j))
            d.append(b.value[k])
            s.append(b.sigma[k])
            h.append(names[hi] if hi >= 0 else "station " + ids[int(i)])
    if not f:
        return None, None
    f, t = np.array(f), np.array(t)
    n_from = np.bincount(f, minlength=len(ids))
    n_to = np.bincount(t, minlength=len(ids))
    keep = (n_from[f] >= n_to[f]) & (n_to[t] > n_from[t])
    pairs = {(a, c) for a, c in zip(f[keep], t[keep])}
    seen = np.bincount([c for _, c in pairs], minlength=len(ids))
    keep &= seen[t] >= 3
    if not keep.any():
        return None, None
    k = np.flatnonzero(keep)
    obs = Observations.from_labels([ids[i] for i in f[k]], [ids[j] for j in t[k]], np.array(d)[k], np.array(s)[k],
                                   head=[h[q] for q in k])
    return obs, ids


def distance_search(network, xyz, known, rng):
    """Places the points of the distance sub-network: (number placed, note or None). ``xyz``,
    ``known`` are updated in place."""
    from multilat.network.starts import initial_for

    obs, ids = _tables(network)
    if obs is None:
        return 0, None
    ix = {p: k for k, p in enumerate(ids)}
    sub = np.array([ix[p] for p in obs.station_ids + obs.target_ids])
    if known[sub].all():
        return 0, None
    anchors = sub[known[sub]]
    if known.any() and len(anchors) < 3:
        return 0, None
    try:
        start, how = initial_for(obs, None, None, rng)
    except MultilatError as e:
        return 0, f"the distance-only search failed: {e}"
    got = np.vstack([start.station_xyz_m, start.target_xyz_m])
    if len(anchors):
        try:
            R, t = rigid_fit(got[known[sub]], xyz[anchors], allow_reflection=True)
        except MultilatError:
            return 0, None
        got = apply_rigid(R, t, got)
    new = ~known[sub]
    xyz[sub[new]] = got[new]
    known[sub[new]] = True
    return int(new.sum()), (f"approximate coordinates of {int(new.sum())} point(s) from the distance-only search "
                            f"({how.get('method', '?')})")
