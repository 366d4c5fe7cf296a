"""Approximate coordinates of the general network from whatever was observed, chained as gama-local
does: each pass orients the direction sets of known stations, places polar points from oriented
set-ups (direction + slope distance + zenith angle, or horizontal distance + height difference),
and places free stations by resection (a 2D rotation-and-shift fit of the polar readings to two or
more known points, its height from their zenith angles). Passes repeat until nothing new is placed;
a point still without coordinates is named in one line.

A separate step with its own tests (JAG3D's ``approximation/`` package): :func:`.adjust.adjust`
needs every free point's approximate coordinates and only iterates from them.
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.general.observations import Network

__all__ = ["approximate", "unreachable"]


def _sights(network: Network):
    """Per ordered pair (from, to): horizontal distance and mark-to-mark rise where derivable, and
    the direction readings per set."""
    hd, rise, dirs, zen = {}, {}, {}, {}
    for za in (b for b in network.blocks if b.kind == "zenith_angle"):
        m = len(za.index["from"])
        fdh, tdh = (np.asarray(za.data.get(h, np.zeros(m)), float) for h in ("from_dh", "to_dh"))
        for k, (i, j) in enumerate(zip(za.index["from"], za.index["to"])):
            zen[(int(i), int(j))] = (za.value[k], fdh[k], tdh[k])
    for sd in (b for b in network.blocks if b.kind == "slope_distance"):
        for k, (i, j) in enumerate(zip(sd.index["from"], sd.index["to"])):
            key = (int(i), int(j))
            if key in zen:
                z, fdh, tdh = zen[key]
                hd[key] = sd.value[k] * np.sin(z)
                rise[key] = fdh + sd.value[k] * np.cos(z) - tdh
    for b in network.blocks:
        if b.kind == "horizontal_distance":
            for k, (i, j) in enumerate(zip(b.index["from"], b.index["to"])):
                hd.setdefault((int(i), int(j)), b.value[k])
        if b.kind == "height_difference" and b.value.ndim == 1:
            for k, (i, j) in enumerate(zip(b.index["from"], b.index["to"])):
                rise.setdefault((int(i), int(j)), b.value[k])
        if b.kind == "direction":
            for k, (i, j, s) in enumerate(zip(b.index["from"], b.index["to"], b.index["set"])):
                dirs.setdefault(b.names["set"][int(s)], (int(i), []))[1].append((int(j), b.value[k]))
    for (i, j), v in list(hd.items()):
        hd.setdefault((j, i), v)
    for (i, j), v in list(rise.items()):
        rise.setdefault((j, i), -v)
    return hd, rise, list(dirs.values())


def _orient(xyz, known, station, readings):
    """Circular mean of (bearing - reading) over the known targets of one set, or None."""
    az = [np.arctan2(*(xyz[j, 1::-1] - xyz[station, 1::-1])) - t for j, t in readings if known[j]]
    return float(np.angle(np.mean(np.exp(1j * np.array(az))))) if az else None


def _resect(xyz, known, station, readings, hd, rise):
    """Position of an unknown station from >= 2 known targets of one set (or None)."""
    use = [(j, t) for j, t in readings if known[j] and (station, j) in hd]
    if len(use) < 2:
        return None
    local = np.array([[hd[(station, j)] * np.cos(t), hd[(station, j)] * np.sin(t)] for j, t in use])
    world = np.array([xyz[j, :2] for j, _ in use])
    lc, wc = local - local.mean(0), world - world.mean(0)
    h = lc.T @ wc
    theta = np.arctan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1])
    rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    xy = world.mean(0) - rot @ local.mean(0)
    zs = [xyz[j, 2] - rise[(station, j)] for j, _ in use if (station, j) in rise]
    return None if not zs else np.array([xy[0], xy[1], np.mean(zs)])


def unreachable(network: Network) -> tuple:
    """The ids of the points whose approximate coordinates cannot be computed from the observations
    (what :func:`approximate` would name), in point order."""
    xyz, known = _chain(network)
    return tuple(network.points.ids[i] for i in np.flatnonzero(~known))


def approximate(network: Network) -> Network:
    """The network with every missing approximate coordinate computed (points whose three
    coordinates are all given are left as they are)."""
    pts = network.points
    if np.all(np.isfinite(pts.xyz_m)):
        return network
    xyz, known = _chain(network)
    if not known.all():
        missing = [pts.ids[i] for i in np.flatnonzero(~known)]
        raise MultilatError(f"point {missing[0]!r}{f' (and {len(missing) - 1} more)' if len(missing) > 1 else ''}: "
                            "no approximate coordinates can be computed from the observations (no polar reading "
                            "from an oriented set-up, no resection on two known points); give them in the file")
    return Network(pts.with_xyz(np.where(np.isfinite(pts.xyz_m), pts.xyz_m, xyz)), network.blocks,
                   network.notes + (f"approximate coordinates computed for {int((~np.all(np.isfinite(pts.xyz_m), 1)).sum())} "
                                    "point(s)",))


def _chain(network: Network):
    """Approximate coordinates chained pass by pass: (xyz (n, 3), known (n,) bool)."""
    pts = network.points
    xyz = pts.xyz_m.copy()
    known = np.all(np.isfinite(xyz), axis=1)
    if known.all():
        return xyz, known
    hd, rise, sets = _sights(network)
    changed = True
    while changed and not known.all():
        changed = False
        for station, readings in sets:
            if not known[station]:
                p = _resect(xyz, known, station, readings, hd, rise)
                if p is None:
                    continue
                xyz[station], known[station], changed = p, True, True
            ori = _orient(xyz, known, station, readings)
            for j, t in readings:
                if not known[j] and (station, j) in hd and (station, j) in rise:
                    a = t + ori
                    xyz[j] = xyz[station] + [hd[(station, j)] * np.cos(a), hd[(station, j)] * np.sin(a),
                                             rise[(station, j)]]
                    known[j], changed = True, True
    return xyz, known
