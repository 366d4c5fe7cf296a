"""Synthetic networks with their truth: the package's one generator (issue 27, item 4).

One call draws one network from an explicit numpy ``Generator`` (or a seed / ``SeedSequence``)::

    net = synthetic_network(np.random.default_rng(7))                        # a "field" network
    net = synthetic_network(3, population="rings", n_stations=20, n_targets=200_000, per_target=8)
    adjust(net.obs)                     # from distances alone
    adjust(net.obs, initial=net)        # the truth: station_xyz_m, target_xyz_m, offset_m

``population`` chooses how stations, targets and coverage are drawn; the other options are those of
that population (an option the population does not use is refused, never ignored). The defaults
are in :data:`POPULATIONS`. Distributions (``U(a, b)`` uniform, ``U{a..b}`` uniform integer):

``"field"`` — networks of the kinds users meet (the minimum-search population, issue 10 item 4)
    stations ``s ~ U{n_stations}``, targets ``t ~ U{n_targets}``, extent ``L`` log-uniform in
    ``extent_m`` (the horizontal size of the volume); station layout (equal probability unless
    ``station_layout`` is given, :data:`STATION_LAYOUTS`): ``"volume"`` uniform in
    ``[-L/2, L/2]^2 x [0, L/2]``; ``"ring"`` a flat ring (azimuths evenly spaced with a jitter
    ``U(-0.3, 0.3)`` of the spacing, radius ``U(0.35, 0.5) L``, heights ``1.5 m + U(-h, h)``, ``h ~
    U(0.05, 0.3)`` m); ``"two-level"`` that ring with stations alternating between ``U(0.3, 0.8)`` m and
    ``U(0.25, 0.5) L + 1 m``. Target layout (:data:`TARGET_LAYOUTS`): ``"volume"`` uniform in
    ``[-0.4 L, 0.4 L]^2 x [0, 0.4 L]``; ``"clustered"`` ``U{2..4}`` gaussian clusters in that box
    (per-cluster sd ``U(0.03, 0.12) L``, height clipped at 0); ``"floor"`` height ``U(0, 0.1 L)``.
    Targets closer than ``max(0.2 m, 0.05 L)`` to a station are drawn again. Each pair unobserved
    with probability ``g ~ U(gap_fraction)``; the mask is drawn again (at most 1000 times, then
    repaired by restoring random missing pairs) until every target is seen by
    ``min_stations_per_target`` stations and every station sees 5 targets. No flatness screening:
    flat rings and tight clusters stay in the population.
``"well-conditioned"`` — the convergence tests' population
    stations uniform in a cube of half-side ``size_m``, targets in one of half-side
    ``1.5 size_m``; with more than 4 stations each pair missing with probability ``gap_fraction``;
    the whole draw repeated until :data:`WELL_CONDITIONED` holds (stations and targets off a plane:
    smallest / largest singular value of the centred coordinates >= 0.25; every target seen by 4
    stations, every station sees 5 targets; redundancy ``m - (4 s + 3 t - 6) >= 4``; no target closer
    than ``0.1 size_m`` to a station).
``"rings"`` — large-volume networks (benchmarks, the large-network path)
    ``n_stations`` on a ring of radius ``0.6 size_m`` at alternating heights 0 and
    ``0.3 size_m``; targets uniform in ``size_m x size_m x 0.25 size_m``; each target seen by
    exactly ``per_target`` distinct stations chosen at random, half on each height (a target seen
    only by the low ring at floor height would have coplanar lines of sight; ``per_target`` 3-4 gives
    weak targets). Observations listed target by target; ``obs`` is built on first use.
``"shell"`` — stations around the volume, targets inside (the network-adjustment tests' population)
    station directions gaussian, the vertical folded up (``0.6 |z| + U(0, 0.2)``) and normalised; with
    4 or more stations the first points down, at ``(0.1, 0.1, -0.9)``; each at ``U(0.8, 1.2) size_m``
    along its direction; targets uniform in the cube of side ``size_m`` centred on the origin;
    offsets ``N(0, offset_sd_m)``. Each pair unseen with probability ``gap_fraction`` (with more than
    4 stations; a target left with fewer than 4 keeps 4 stations drawn at random). Observations listed
    target by target. No screening: every draw is returned.
``"sequential"`` — ``len(heads)`` heads moved over ``n_stations`` stations around a part
    stations on a ring of radius ``radius_m`` (jitter ``U(-0.2, 0.2)`` of the spacing), heights
    alternating ``U(0.4, 0.8)`` and ``U(1.4, 1.9)`` m; station ``i`` occupied by ``heads[i % len(heads)]``
    with one offset per head; targets uniform in the part's box ``part_m``; each pair unseen with
    probability ``gap_fraction`` (every target seen by 5 stations).
``"mixed"`` — multilateration heads and laser trackers (distance and two angles to every target)
    heads on the corners of the ``room_m`` floor plan at 0.5 / 1.6 m, ``trackers`` (default two of
    :class:`multilat.tracker.TrackerSpec` ``(10, 0.3, 15, 6)``) near two opposite walls at 1.2 m with a
    random tilt ``U(+-0.02)`` rad (none if ``levelled``; same draws) and heading; ``orientation_rad``
    holds the true orientations. Trackers: offset 0, their specification's σ at each range.

Common to all: offsets ``U(-offset_max_m, offset_max_m)`` (per station, per head for "sequential";
gaussian for "shell"),
gaussian noise of ``sigma_m`` (the observations' σ). ``blunders`` observations (distinct rows, drawn
after everything else, so the rest of the network is the same as without them) get
``+-blunder_m``; ``blunder_index`` names them. Same seed and options -> the same network, bit for
bit; the draws do not depend on anything but the seed and the options.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.data import Observations

__all__ = ["SyntheticNetwork", "synthetic_network", "POPULATIONS", "STATION_LAYOUTS", "TARGET_LAYOUTS",
           "WELL_CONDITIONED"]

STATION_LAYOUTS = ("volume", "ring", "two-level")
TARGET_LAYOUTS = ("volume", "clustered", "floor")

#: thresholds of a "well-conditioned" network (population ``"well-conditioned"``)
WELL_CONDITIONED = {"station_flatness": 0.25, "target_flatness": 0.25, "min_stations_per_target": 4,
                    "min_targets_per_station": 5, "min_redundancy": 4, "min_clearance": 0.1}

_COMMON = {"offset_max_m": 5e-3, "sigma_m": 5e-6}
#: each population's options and their defaults (a range is ``(low, high)``, inclusive)
POPULATIONS = {
    "field": {"n_stations": (4, 10), "n_targets": (12, 60), "extent_m": (2.0, 20.0), "gap_fraction": (0.0, 0.3),
              "station_layout": None, "target_layout": None, "min_stations_per_target": 4, **_COMMON},
    "well-conditioned": {"n_stations": (4, 8), "n_targets": (10, 30), "size_m": 1.0, "gap_fraction": 0.15,
                         **_COMMON},
    "rings": {"n_stations": 20, "n_targets": 200_000, "per_target": 8, "size_m": 20.0, **_COMMON},
    "shell": {"n_stations": 4, "n_targets": 20, "size_m": 2.0, "gap_fraction": 0.0, "offset_sd_m": 3e-3,
              "sigma_m": 5e-6},
    "sequential": {"heads": ("T1", "T2"), "n_stations": 8, "n_targets": 16, "part_m": (1.6, 1.0, 0.6),
                   "radius_m": 2.8, "gap_fraction": 0.15, "offset_max_m": 2e-3, "sigma_m": 5e-6},
    "mixed": {"heads": ("H1", "H2", "H3", "H4"), "trackers": None, "n_targets": 14, "room_m": (4.0, 3.0, 1.2),
              "levelled": False, "offset_max_m": 2e-3, "sigma_m": 5e-6},
}


@dataclass(frozen=True, eq=False)
class SyntheticNetwork:
    """A generated network: its truth, its observations and how it was drawn.

    station_xyz_m (s, 3), target_xyz_m (t, 3), offset_m (s,): the truth, metres (``distance = |H - T| +
    offset + noise``; ``offset_m`` per station, the head's offset where heads move).
    station_index, target_index, distance_m, sigma_m (m,): the observations as arrays; ``obs`` the same
    as :class:`Observations` (ids ``S1..``, ``T1..``; ``P1..`` for "sequential" and "mixed").
    population, station_layout, target_layout: how it was drawn; extent_m: its size ``L``, metres;
    gap_fraction: the drawn probability of an unobserved pair; orientation_rad (s, 3): true
    orientations ("mixed"), else None; blunder_index: the rows given a blunder of ``blunder_m``.
    """

    station_xyz_m: np.ndarray
    target_xyz_m: np.ndarray
    offset_m: np.ndarray
    station_index: np.ndarray
    target_index: np.ndarray
    distance_m: np.ndarray
    sigma_m: np.ndarray
    population: str
    extent_m: float
    station_layout: str
    target_layout: str
    gap_fraction: float
    orientation_rad: np.ndarray | None = None
    blunder_index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    blunder_m: float = 0.0
    _obs: Observations | None = field(default=None, repr=False)

    @cached_property
    def obs(self) -> Observations:
        if self._obs is not None:
            return self._obs
        s, t = len(self.station_xyz_m), len(self.target_xyz_m)
        return Observations(tuple(f"S{i + 1}" for i in range(s)), tuple(f"T{j + 1}" for j in range(t)),
                            self.station_index, self.target_index, self.distance_m, self.sigma_m)


def _range(name, v, lo_min):
    a, b = (v, v) if np.isscalar(v) else v
    if not (lo_min <= a <= b):
        raise MultilatError(f"synthetic_network: {name} must be a range (low, high) with "
                            f"{lo_min} <= low <= high, got {v!r}")
    return a, b


def _mask(g, s, t, gap, need):
    for _ in range(1000):
        seen = g.random((s, t)) >= gap
        if seen.sum(0).min() >= need and seen.sum(1).min() >= 5:
            return seen
    while seen.sum(0).min() < need or seen.sum(1).min() < 5:   # repair: restore a missing pair
        i, j = np.nonzero(~seen)
        k = int(g.integers(len(i)))
        seen[i[k], j[k]] = True
    return seen


def _observe(g, H, T, o, seen, sigma_m):
    """Rows of the seen pairs (station-major) with ``|H - T| + o + noise``."""
    si, ti = np.nonzero(seen)
    d = np.linalg.norm(H[si] - T[ti], axis=1) + o[si] + g.normal(0.0, sigma_m, si.size)
    return si, ti, d, np.full(si.size, float(sigma_m))


# --------------------------------------------------------------------------------------------- field
def _ring(g, s, L):
    phase = g.uniform(0, 2 * np.pi)
    az = phase + 2 * np.pi * (np.arange(s) + g.uniform(-0.3, 0.3, s)) / s
    r = g.uniform(0.35, 0.5, s) * L
    h = g.uniform(0.05, 0.3)
    return np.column_stack([r * np.cos(az), r * np.sin(az), 1.5 + g.uniform(-h, h, s)])


def _field_stations(g, layout, s, L):
    if layout == "volume":
        return np.column_stack([g.uniform(-L / 2, L / 2, (s, 2)), g.uniform(0, L / 2, s)])
    H = _ring(g, s, L)
    if layout == "two-level":
        low = np.arange(s) % 2 == 0
        H[low, 2] = g.uniform(0.3, 0.8, low.sum())
        H[~low, 2] = g.uniform(0.25, 0.5, (~low).sum()) * L + 1.0
    return H


def _field_targets(g, layout, t, L):
    box_lo, box_hi = np.array([-0.4 * L, -0.4 * L, 0.0]), np.array([0.4 * L, 0.4 * L, 0.4 * L])
    if layout == "volume":
        return g.uniform(box_lo, box_hi, (t, 3))
    if layout == "floor":
        return np.column_stack([g.uniform(-0.4 * L, 0.4 * L, (t, 2)), g.uniform(0, 0.1 * L, t)])
    k = int(g.integers(2, 5))
    centres = g.uniform(box_lo, box_hi, (k, 3))
    sd = g.uniform(0.03, 0.12, k) * L
    which = g.integers(0, k, t)
    T = centres[which] + g.normal(size=(t, 3)) * sd[which, None]
    T[:, 2] = np.maximum(T[:, 2], 0.0)
    return T


def _field(g, o):
    s_lo, s_hi = _range("n_stations", o["n_stations"], 4)
    t_lo, t_hi = _range("n_targets", o["n_targets"], 5)
    l_lo, l_hi = _range("extent_m", o["extent_m"], 1e-3)
    g_lo, g_hi = _range("gap_fraction", o["gap_fraction"], 0.0)
    if g_hi >= 1.0:
        raise MultilatError(f"synthetic_network: gap_fraction must be below 1, got {o['gap_fraction']!r}")
    for name, known in (("station_layout", STATION_LAYOUTS), ("target_layout", TARGET_LAYOUTS)):
        if o[name] is not None and o[name] not in known:
            raise MultilatError(f"synthetic_network: {name} must be one of {', '.join(known)}, got {o[name]!r}")
    need = int(o["min_stations_per_target"])
    if need < 3:
        raise MultilatError("synthetic_network: min_stations_per_target must be >= 3")
    s = int(g.integers(s_lo, s_hi + 1))
    t = int(g.integers(t_lo, t_hi + 1))
    if need > s:
        raise MultilatError(f"synthetic_network: {s} stations cannot give {need} stations per target")
    L = float(np.exp(g.uniform(np.log(l_lo), np.log(l_hi))))
    slay = o["station_layout"] or STATION_LAYOUTS[int(g.integers(len(STATION_LAYOUTS)))]
    tlay = o["target_layout"] or TARGET_LAYOUTS[int(g.integers(len(TARGET_LAYOUTS)))]
    gap = float(g.uniform(g_lo, g_hi))
    H = _field_stations(g, slay, s, L)
    clearance = max(0.2, 0.05 * L)
    T = _field_targets(g, tlay, t, L)
    for _ in range(1000):
        close = np.linalg.norm(T[:, None] - H[None], axis=2).min(1) < clearance
        if not close.any():
            break
        T[close] = _field_targets(g, tlay, int(close.sum()), L)
    else:
        raise MultilatError("synthetic_network: targets keep falling next to a station")
    seen = _mask(g, s, t, gap, need)
    off = g.uniform(-o["offset_max_m"], o["offset_max_m"], s)
    rows = _observe(g, H, T, off, seen, o["sigma_m"])
    return SyntheticNetwork(H, T, off, *rows, "field", L, slay, tlay, gap)


# ---------------------------------------------------------------------------------- well-conditioned
def _flatness(x):
    sv = np.linalg.svd(x - x.mean(0), compute_uv=False)
    return float(sv[2] / sv[0])


def _well_conditioned(g, o):
    c, size = WELL_CONDITIONED, float(o["size_m"])
    s_lo, s_hi = _range("n_stations", o["n_stations"], 4)
    t_lo, t_hi = _range("n_targets", o["n_targets"], 5)
    for _ in range(10_000):
        s = int(g.integers(s_lo, s_hi + 1))
        t = int(g.integers(t_lo, t_hi + 1))
        H = g.uniform(-size, size, (s, 3))
        T = g.uniform(-1.5 * size, 1.5 * size, (t, 3))
        if _flatness(H) < c["station_flatness"] or _flatness(T) < c["target_flatness"]:
            continue
        if np.linalg.norm(H[:, None] - T[None], axis=2).min() < c["min_clearance"] * size:
            continue
        seen = np.ones((s, t), bool) if s == 4 else g.random((s, t)) >= o["gap_fraction"]
        if seen.sum(0).min() < c["min_stations_per_target"] or seen.sum(1).min() < c["min_targets_per_station"]:
            continue
        if seen.sum() - (4 * s + 3 * t - 6) < c["min_redundancy"]:
            continue
        off = g.uniform(-o["offset_max_m"], o["offset_max_m"], s)
        rows = _observe(g, H, T, off, seen, o["sigma_m"])
        return SyntheticNetwork(H, T, off, *rows, "well-conditioned", 2 * size, "cube", "cube",
                                float(o["gap_fraction"]))
    raise MultilatError("synthetic_network: no well-conditioned network drawn (loosen the ranges)")


# ------------------------------------------------------------------------------------------------ rings
def _rings(g, o):
    s, t, k, size = int(o["n_stations"]), int(o["n_targets"]), int(o["per_target"]), float(o["size_m"])
    if k < 3 or k > s:
        raise MultilatError(f"synthetic_network: per_target must be in 3..n_stations, got {k}")
    ang = 2 * np.pi * np.arange(s) / s
    hz = np.where(np.arange(s) % 2 == 0, 0.0, 0.3 * size)
    H = np.column_stack([0.6 * size * np.cos(ang), 0.6 * size * np.sin(ang), hz])
    off = g.uniform(-o["offset_max_m"], o["offset_max_m"], s)
    T = g.uniform([-size / 2, -size / 2, 0.0], [size / 2, size / 2, 0.25 * size], (t, 3))
    low, high = np.arange(0, s, 2), np.arange(1, s, 2)
    n_low = min(len(low), k // 2)
    n_high = min(k - n_low, len(high))
    n_low = k - n_high
    pick_l = np.argpartition(g.random((t, len(low))), n_low - 1, axis=1)[:, :n_low]
    pick_h = np.argpartition(g.random((t, len(high))), n_high - 1, axis=1)[:, :n_high]
    st = np.concatenate([low[pick_l], high[pick_h]], axis=1)
    st.sort(axis=1)
    si = st.ravel().astype(np.int64)
    ti = np.repeat(np.arange(t, dtype=np.int64), k)
    diff = H[si] - T[ti]
    d = np.sqrt(np.einsum("mi,mi->m", diff, diff)) + off[si]
    d = d + g.normal(0.0, o["sigma_m"], len(si))
    return SyntheticNetwork(H, T, off, si, ti, d, np.full(len(si), float(o["sigma_m"])), "rings", size,
                            "two-height ring", "box", 1.0 - k / s)


# ------------------------------------------------------------------------------------------------ shell
def _shell(g, o):
    s, t, size, gap = int(o["n_stations"]), int(o["n_targets"]), float(o["size_m"]), float(o["gap_fraction"])
    if s < 4 or t < 1 or not 0.0 <= gap < 1.0:
        raise MultilatError("synthetic_network: shell needs >= 4 stations, >= 1 target and 0 <= gap_fraction < 1")
    d = g.normal(size=(s, 3))
    d[:, 2] = np.abs(d[:, 2]) * 0.6 + 0.2 * g.uniform(size=s)
    d /= np.linalg.norm(d, axis=1)[:, None]
    d[0] = [0.1, 0.1, -0.9]                       # one station well below the others
    H = d * size * g.uniform(0.8, 1.2, size=(s, 1))
    T = g.uniform(-0.5, 0.5, size=(t, 3)) * size
    off = g.normal(0.0, o["offset_sd_m"], size=s)
    seen = np.ones((t, s), bool)                  # target-major: rows listed target by target
    if gap > 0 and s > 4:
        for j in range(t):
            drop = g.uniform(size=s) < gap
            if s - drop.sum() < 4:
                keep = g.choice(s, size=4, replace=False)
                drop[:] = True
                drop[keep] = False
            seen[j] = ~drop
    ti, si = np.nonzero(seen)
    d_m = np.linalg.norm(H[si] - T[ti], axis=1) + off[si] + g.normal(0.0, o["sigma_m"], size=si.size)
    return SyntheticNetwork(H, T, off, si, ti, d_m, np.full(si.size, float(o["sigma_m"])), "shell", 2 * size,
                            "shell", "cube", gap)


# ------------------------------------------------------------------------------------------- sequential
def _sequential(g, o):
    heads = tuple(o["heads"])
    s, t, nh, radius = int(o["n_stations"]), int(o["n_targets"]), len(heads), float(o["radius_m"])
    if nh < 1 or s < 4 or t < 5:
        raise MultilatError("synthetic_network: sequential needs >= 1 head, >= 4 stations and >= 5 targets")
    az = 2 * np.pi * (np.arange(s) + g.uniform(-0.2, 0.2, s)) / s
    z = np.where(np.arange(s) % 2 == 0, g.uniform(0.4, 0.8, s), g.uniform(1.4, 1.9, s))
    H = np.column_stack([radius * np.cos(az), radius * np.sin(az), z])
    half = np.array(o["part_m"], float) / 2
    T = g.uniform([-half[0], -half[1], 0.0], [half[0], half[1], 2 * half[2]], (t, 3))
    seen = _mask(g, s, t, o["gap_fraction"], min(5, s))
    head_off = g.uniform(-o["offset_max_m"], o["offset_max_m"], nh)
    hi = np.arange(s) % nh
    off = head_off[hi]
    rows = _observe(g, H, T, off, seen, o["sigma_m"])
    obs = Observations(tuple(f"S{i + 1}" for i in range(s)), tuple(f"P{j + 1}" for j in range(t)), *rows,
                       station_heads=tuple(heads[k] for k in hi))
    return SyntheticNetwork(H, T, off, *rows, "sequential", 2 * radius, "sequential ring", "part",
                            float(o["gap_fraction"]), _obs=obs)


# ------------------------------------------------------------------------------------------------ mixed
def _mixed(g, o):
    from multilat.network.model.angles import predicted_angles
    from multilat.tracker import TrackerSpec

    heads, trackers = tuple(o["heads"]), o["trackers"]
    if trackers is None:
        spec = TrackerSpec(10.0, 0.3, 15.0, 6.0)
        trackers = {"AT1": spec, "AT2": spec}
    L, W, Z = (float(v) for v in o["room_m"])
    Hh = np.array([[0.0, 0.0, 0.5], [L, 0.0, 1.6], [L, W, 0.5], [0.0, W, 1.6]])[:len(heads)]
    Ht = np.array([[L / 2, -0.3, 1.2], [L / 2, W + 0.3, 1.2]])[:len(trackers)]
    H = np.vstack([Hh, Ht]) + g.uniform(-0.1, 0.1, (len(heads) + len(trackers), 3))
    T = g.uniform([0.4, 0.4, 0.2], [L - 0.4, W - 0.4, 0.2 + Z], (int(o["n_targets"]), 3))
    s, t, nh = H.shape[0], T.shape[0], len(heads)
    ori = np.zeros((s, 3))
    ori[nh:, :2] = g.uniform(-0.02, 0.02, (s - nh, 2))
    ori[nh:, 2] = g.uniform(-np.pi, np.pi, s - nh)
    if o["levelled"]:
        ori[nh:, :2] = 0.0
    off = np.concatenate([g.uniform(-o["offset_max_m"], o["offset_max_m"], nh), np.zeros(s - nh)])
    si, ti = np.meshgrid(np.arange(s), np.arange(t), indexing="ij")
    si, ti = si.ravel(), ti.ravel()
    rho = np.linalg.norm(H[si] - T[ti], axis=1)
    sig = np.where(si < nh, o["sigma_m"], 0.0)
    sig_a = np.full(si.size, np.nan)
    for q, sp in enumerate(trackers.values()):
        k = si == nh + q
        sig[k] = sp.distance_sigma_m(rho[k])
        sig_a[k] = sp.angle_sigma_rad(rho[k])
    d = rho + off[si] + g.normal(0.0, 1.0, si.size) * sig
    az, el = predicted_angles(H, ori, T, si, ti)
    tr = si >= nh
    az = np.where(tr, az + g.normal(0.0, 1.0, si.size) * np.where(tr, sig_a, 0.0), np.nan)
    el = np.where(tr, el + g.normal(0.0, 1.0, si.size) * np.where(tr, sig_a, 0.0), np.nan)
    obs = Observations(heads + tuple(trackers), tuple(f"P{j + 1}" for j in range(t)), si, ti, d, sig,
                       az, el, None, sig_a, sig_a, tuple(trackers) if o["levelled"] else ())
    return SyntheticNetwork(H, T, off, si, ti, d, sig, "mixed", float(np.hypot(L, W)), "room corners and walls",
                            "room", 0.0, orientation_rad=ori, _obs=obs)


_DRAW = {"field": _field, "well-conditioned": _well_conditioned, "rings": _rings, "shell": _shell,
         "sequential": _sequential, "mixed": _mixed}


def _with_blunders(g, net, n, size_m):
    """``net`` with ``n`` distinct rows (drawn uniformly) shifted by ``+-size_m`` (random signs)."""
    m = net.distance_m.size
    if not 0 <= n <= m:
        raise MultilatError(f"synthetic_network: blunders must be in 0..{m} (the observations), got {n}")
    if not size_m > 0:
        raise MultilatError(f"synthetic_network: blunder_m must be > 0, got {size_m!r}")
    rows = np.sort(g.choice(m, n, replace=False)).astype(np.int64)
    d = net.distance_m.copy()
    d[rows] += size_m * np.where(g.random(n) < 0.5, -1.0, 1.0)
    obs = None if net._obs is None else replace(net._obs, distance_m=d)
    return SyntheticNetwork(net.station_xyz_m, net.target_xyz_m, net.offset_m, net.station_index,
                            net.target_index, d, net.sigma_m, net.population, net.extent_m, net.station_layout,
                            net.target_layout, net.gap_fraction, net.orientation_rad, rows, float(size_m), obs)


def synthetic_network(rng=None, *, population: str = "field", blunders: int = 0, blunder_m: float = 1e-3,
                      **options) -> SyntheticNetwork:
    """Draw one network of ``population`` (distributions in the module docstring).

    Parameters
    ----------
    rng : numpy Generator, SeedSequence, int or None
    population : one of :data:`POPULATIONS`
    blunders : int, number of observations given a blunder of ``+-blunder_m`` metres
    **options : the population's options (:data:`POPULATIONS` lists them with their defaults); an
        option the population does not take is refused

    Returns
    -------
    SyntheticNetwork
    """
    if population not in POPULATIONS:
        raise MultilatError(f"synthetic_network: population must be one of {', '.join(POPULATIONS)}, "
                            f"got {population!r}")
    unknown = sorted(set(options) - set(POPULATIONS[population]))
    if unknown:
        raise MultilatError(f"synthetic_network: population {population!r} takes no option {unknown[0]!r} "
                            f"(its options: {', '.join(POPULATIONS[population])})")
    g = np.random.default_rng(rng)
    net = _DRAW[population](g, {**POPULATIONS[population], **options})
    return _with_blunders(g, net, int(blunders), blunder_m) if blunders else net
