"""What the approximate-coordinate methods need from a network's blocks, gathered once: the
instrument set-ups with their readings as vectors in the instrument's frame, the distances between
points, and the vectors and coordinates observed directly.

A **set-up** is one frame of readings on one point: a direction set (one orientation unknown), a
laser tracker's set-up (levelled: κ; unlevelled: ω φ κ) or one horizontal angle (a set of two
readings, the backsight at 0). Each reading to point ``j`` carries its horizontal reading ``t`` in the
set-up's frame and, where the network gives it, the elevation ``el`` and the vector ``v`` from the
instrument to the target in that frame (metres)::

    P_j = P_i + (from_dh - to_dh) e_z + R v          (R: the set-up's frame in the world)

``v`` comes from a slope distance with a zenith angle (or a tracker's elevation), or from a
horizontal distance with a height difference (or with a zenith angle), or from a slope distance
with a height difference; the zenith angle of the opposite sight serves where the direct one is
missing. Heights ``from_dh``, ``to_dh`` are those of the reading's own row (zenith angle or tracker
angles), as in the kinds (:mod:`..kinds.geometry`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.network.model.angles import polar_to_xyz

__all__ = ["Setup", "Sights", "gather"]


@dataclass
class Setup:
    """One frame of readings. key : for messages; station : point index; levelled : the frame is a
    rotation about z; to, t, el (k,), v (k, 3), dz (k,) = from_dh - to_dh: per reading (NaN unknown);
    s (k,), sdz (k,): the slope distance of the sight and its from_dh - to_dh (NaN: none)."""

    key: str
    station: int
    levelled: bool
    to: np.ndarray
    t: np.ndarray
    el: np.ndarray
    v: np.ndarray
    dz: np.ndarray
    s: np.ndarray = None
    sdz: np.ndarray = None

    def __post_init__(self):
        n = np.linalg.norm(self.v, axis=1)
        u = self.v / np.where(n > 0, n, np.nan)[:, None]
        ang = polar_to_xyz(np.zeros(3), np.zeros(3), 1.0, self.t, self.el).reshape(-1, 3)
        #: (k, 3) unit vectors of the sights in the set-up's frame; NaN where the elevation is unknown
        self.u = np.where(np.isfinite(u), u, ang)
        if self.s is None:
            self.s, self.sdz = np.full(len(self.to), np.nan), np.zeros(len(self.to))


@dataclass
class Sights:
    """setups : list of :class:`Setup`; dist : (m, 5) rows (from, to, s_m, from_dh, to_dh) of every
    slope distance (instrument constants ignored); rise : {(i, j): z_j - z_i} from height
    differences; vec : {(i, j): P_j - P_i} of complete coordinate-difference vectors; coord : {i: P_i}
    of completely observed coordinates."""

    setups: list
    dist: np.ndarray
    rise: dict
    vec: dict
    coord: dict


def _rows(b, *keys):
    return [np.asarray(b.index[k], int) for k in keys]


def _heights(b, m):
    return tuple(np.asarray(b.data.get(h, np.zeros(m)), float) for h in ("from_dh", "to_dh"))


def gather(blocks) -> Sights:
    """The sights of ``blocks`` (a network's, and any blocks given for approximations only)."""
    by = {}
    for b in blocks:
        by.setdefault(b.kind, []).append(b)
    zen, slope, hdist, rise = {}, {}, {}, {}
    for b in by.get("zenith_angle", ()):
        (f, t), (fh, th) = _rows(b, "from", "to"), _heights(b, len(b.value))
        for k in range(len(f)):
            zen.setdefault((f[k], t[k]), (b.value[k], fh[k], th[k]))
    dist = [np.column_stack([*_rows(b, "from", "to"), b.value, *_heights(b, len(b.value))])
            for b in by.get("slope_distance", ())]
    dist = np.vstack(dist) if dist else np.zeros((0, 5))
    if any(k in by for k in ("direction", "horizontal_angle", "tracker_angles")):     # readings need them
        for r in dist[::-1]:                                                              # the first wins
            slope[(int(r[0]), int(r[1]))] = (r[2], r[3], r[4])
    for b in by.get("horizontal_distance", ()):
        for i, j, h in zip(*_rows(b, "from", "to"), b.value):
            hdist.setdefault((i, j), h)
            hdist.setdefault((j, i), h)
    for b in by.get("height_difference", ()):
        for i, j, h in zip(*_rows(b, "from", "to"), b.value):
            rise.setdefault((i, j), h)
            rise.setdefault((j, i), -h)
    look = (zen, slope, hdist, rise)
    setups = _direction_sets(by, look) + _angle_sets(by, look) + _tracker_setups(by, slope)
    return Sights(setups, dist, rise, *_vectors(by))


def _reading(i, j, t, look):
    """(el, v (3,), dz) of a horizontal reading ``t`` from ``i`` to ``j`` (NaN where not derivable)."""
    zen, slope, hdist, rise = look
    z = zen.get((i, j))
    if z is None and (j, i) in zen:                       # the opposite sight, its heights swapped
        zr = zen[(j, i)]
        z = (np.pi - zr[0], zr[2], zr[1])
    s = slope.get((i, j)) or ((slope[(j, i)][0], slope[(j, i)][2], slope[(j, i)][1]) if (j, i) in slope else None)
    h, dh = hdist.get((i, j)), rise.get((i, j))
    nan3 = np.full(3, np.nan)
    if z is not None:
        dz = z[1] - z[2]
        el = np.pi / 2 - z[0]
        if s is not None:
            return el, polar_to_xyz(np.zeros(3), np.zeros(3), s[0], t, el), dz
        if h is not None:
            return el, np.array([h * np.cos(t), h * np.sin(t), h * np.tan(el)]), dz
        return el, nan3, dz
    if h is not None and dh is not None:
        return np.arctan2(dh, h), np.array([h * np.cos(t), h * np.sin(t), dh]), 0.0
    if s is not None and dh is not None:
        up = dh - s[1] + s[2]                             # instrument to reflector
        if s[0] > abs(up):
            hz = np.sqrt(s[0] ** 2 - up ** 2)
            return np.arctan2(up, hz), np.array([hz * np.cos(t), hz * np.sin(t), up]), s[1] - s[2]
    return np.nan, nan3, 0.0


def _slope(i, j, slope):
    """(s, from_dh - to_dh) of the slope distance between i and j (either way), NaN if none."""
    s = slope.get((i, j))
    if s is not None:
        return s[0], s[1] - s[2]
    s = slope.get((j, i))
    return (s[0], s[2] - s[1]) if s is not None else (np.nan, 0.0)


def _setup(key, station, levelled, readings, look) -> Setup:
    to = np.array([j for j, _ in readings], int)
    t = np.array([a for _, a in readings], float)
    got = [_reading(station, j, a, look) for j, a in readings]
    sl = np.array([_slope(station, j, look[1]) for j in to], float).reshape(-1, 2)
    return Setup(key, station, levelled, to, t, np.array([g[0] for g in got], float),
                 np.array([g[1] for g in got], float).reshape(-1, 3), np.array([g[2] for g in got], float),
                 sl[:, 0], sl[:, 1])


def _direction_sets(by, look) -> list:
    sets = {}
    for b in by.get("direction", ()):
        f, t, s = _rows(b, "from", "to", "set")
        for k in range(len(f)):
            sets.setdefault(("direction set", b.names["set"][s[k]]), (f[k], []))[1].append((t[k], b.value[k]))
    return [_setup(f"{kind} {name}", st, True, rd, look) for (kind, name), (st, rd) in sets.items()]


def _angle_sets(by, look) -> list:
    out = []
    for b in by.get("horizontal_angle", ()):
        for k, (i, bs, fs) in enumerate(zip(*_rows(b, "from", "bs", "fs"))):
            label = b.labels[k] if len(b.labels) == len(b.value) else f"{k + 1}"
            out.append(_setup(f"horizontal angle {label}", i, True, [(bs, 0.0), (fs, b.value[k])], look))
    return out


def _tracker_setups(by, slope) -> list:
    out = {}
    for b in by.get("tracker_angles", ()):
        f, t, u, c = _rows(b, "from", "to", "setup", "component")
        fh, th = _heights(b, len(b.value))
        for k in range(len(f)):
            key = ("set-up", b.names["setup"][u[k]])
            st = out.setdefault(key, (f[k], bool(b.options.get("levelled", True)), {}))
            rd = st[2].setdefault(t[k], [np.nan, np.nan, fh[k] - th[k]])
            if np.isnan(rd[c[k]]):
                rd[c[k]] = b.value[k]
    setups = []
    for (kind, name), (station, levelled, rd) in out.items():
        rows = [(j, a) for j, a in rd.items() if np.isfinite(a[0])]
        to = np.array([j for j, _ in rows], int)
        az = np.array([a[0] for _, a in rows], float)
        el = np.array([a[1] for _, a in rows], float)
        s = np.array([slope.get((station, j), (np.nan,))[0] for j in to], float)
        v = polar_to_xyz(np.zeros(3), np.zeros(3), s, az, el).reshape(-1, 3)
        setups.append(Setup(f"{kind} {name}", station, levelled, to, az, el, v,
                            np.array([a[2] for _, a in rows], float)))
    return setups


def _vectors(by):
    parts, coords = {}, {}
    for b in by.get("coordinate_difference", ()):
        for i, j, a, val in zip(*_rows(b, "from", "to", "axis"), b.value):
            parts.setdefault((i, j), {}).setdefault(a, val)
    vec = {}
    for (i, j), d in parts.items():
        if len(d) == 3:
            v = np.array([d[0], d[1], d[2]])
            vec.setdefault((i, j), v)
            vec.setdefault((j, i), -v)
    for b in by.get("observed_coordinates", ()):
        for p, a, val in zip(*_rows(b, "point", "axis"), b.value):
            coords.setdefault(p, {}).setdefault(a, val)
    return vec, {p: np.array([d[0], d[1], d[2]]) for p, d in coords.items() if len(d) == 3}
