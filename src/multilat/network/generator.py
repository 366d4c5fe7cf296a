"""Random self-calibrating multilateration networks of the kinds users meet, with their truth.

The population of the minimum-search acceptance study (issue 10, item 4): networks nobody here
designed, drawn from explicit distributions so that a failure rate measured on them means
something. One call draws one network::

    net = random_network(np.random.default_rng(7))
    adjust(net.obs)                     # from distances alone
    adjust(net.obs, initial=net)        # the truth has station_xyz_m, target_xyz_m, offset_m

Distributions (each network; ``U(a, b)`` uniform, ``U{a..b}`` uniform integer, ``L`` the extent)
------------------------------------------------------------------------------------------------
* stations ``s ~ U{n_stations}`` (default 4..10), targets ``t ~ U{n_targets}`` (default 12..60);
* extent ``L`` log-uniform in ``extent_m`` (default 2-20 m): the horizontal size of the volume;
* station layout, one of (equal probability unless ``station_layout`` is given):

  - ``"volume"``: stations uniform in ``[-L/2, L/2]^2 x [0, L/2]`` (heads at all heights);
  - ``"ring"``: a flat ring, the typical tracker set-up: azimuths evenly spaced with a jitter
    ``U(-0.3, 0.3)`` of the spacing, radius ``U(0.35, 0.5) L``, heights ``1.5 m + U(-h, h)``
    with ``h ~ U(0.05, 0.3)`` m (tripod heads all near one height; never exactly coplanar);
  - ``"two-level"``: a ring as above whose stations alternate between a low level
    (``U(0.3, 0.8)`` m) and a high level (``U(0.25, 0.5) L + 1 m``);

* target layout, one of (equal probability unless ``target_layout`` is given):

  - ``"volume"``: uniform in ``[-0.4 L, 0.4 L]^2 x [0, 0.4 L]``;
  - ``"clustered"``: ``U{2..4}`` clusters with centres uniform in that box, targets assigned to
    clusters at random, gaussian about their centre with per-cluster ``sd ~ U(0.03, 0.12) L``
    (height clipped at 0);
  - ``"floor"``: a target field near the floor: ``x, y`` uniform in ``[-0.4 L, 0.4 L]``,
    height ``U(0, 0.1 L)``;

  targets closer than ``max(0.2 m, 0.05 L)`` to a station are drawn again;
* offsets ``U(-offset_max_m, offset_max_m)`` per station (default 5 mm);
* noise gaussian with standard deviation ``sigma_m`` (default 5 µm), the observations' sigma;
* unobserved pairs: a gap fraction ``g ~ U(gap_fraction)`` (default 0-0.3); each station-target
  pair is missing with probability ``g``, independently; the mask is drawn again (at most 1000
  times; then the pattern is repaired by restoring random missing pairs) until every target is seen
  by at least ``min_stations_per_target`` stations (default 4) and every station sees at least
  5 targets (its 4 unknowns + 1).

Nothing else is conditioned on: no flatness or redundancy screening, so near-degenerate draws
(flat rings, tight clusters) stay in the population.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.data import Observations

__all__ = ["GeneratedNetwork", "random_network", "sequential_network", "STATION_LAYOUTS", "TARGET_LAYOUTS"]

STATION_LAYOUTS = ("volume", "ring", "two-level")
TARGET_LAYOUTS = ("volume", "clustered", "floor")


@dataclass(frozen=True, eq=False)
class GeneratedNetwork:
    """A random network: its truth, its observations and how it was drawn.

    Attributes
    ----------
    station_xyz_m : ndarray, shape (s, 3), metres, true station coordinates (``obs.station_ids`` order)
    target_xyz_m : ndarray, shape (t, 3), metres, true target coordinates (``obs.target_ids`` order)
    offset_m : ndarray, shape (s,), metres, true offsets (``distance = |H - T| + offset + noise``)
    obs : Observations  the noisy distances, ``sigma_m`` their standard deviation
    extent_m : float  ``L``
    station_layout, target_layout : str  one of :data:`STATION_LAYOUTS` / :data:`TARGET_LAYOUTS`
    gap_fraction : float  the drawn probability ``g`` of a pair being unobserved
    """

    station_xyz_m: np.ndarray
    target_xyz_m: np.ndarray
    offset_m: np.ndarray
    obs: Observations
    extent_m: float
    station_layout: str
    target_layout: str
    gap_fraction: float


def _range(name, v, lo_min):
    a, b = (v, v) if np.isscalar(v) else v
    if not (lo_min <= a <= b):
        raise MultilatError(f"random_network: {name} must be a range (low, high) with "
                            f"{lo_min} <= low <= high, got {v!r}")
    return a, b


def _ring(g, s, L):
    phase = g.uniform(0, 2 * np.pi)
    az = phase + 2 * np.pi * (np.arange(s) + g.uniform(-0.3, 0.3, s)) / s
    r = g.uniform(0.35, 0.5, s) * L
    h = g.uniform(0.05, 0.3)
    return np.column_stack([r * np.cos(az), r * np.sin(az), 1.5 + g.uniform(-h, h, s)])


def _stations(g, layout, s, L):
    if layout == "volume":
        return np.column_stack([g.uniform(-L / 2, L / 2, (s, 2)), g.uniform(0, L / 2, s)])
    H = _ring(g, s, L)
    if layout == "two-level":
        low = np.arange(s) % 2 == 0
        H[low, 2] = g.uniform(0.3, 0.8, low.sum())
        H[~low, 2] = g.uniform(0.25, 0.5, (~low).sum()) * L + 1.0
    return H


def _targets(g, layout, t, L):
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


def random_network(rng=None, *, n_stations=(4, 10), n_targets=(12, 60), extent_m=(2.0, 20.0),
                   gap_fraction=(0.0, 0.3), offset_max_m: float = 5e-3, sigma_m: float = 5e-6,
                   station_layout: str | None = None, target_layout: str | None = None,
                   min_stations_per_target: int = 4) -> GeneratedNetwork:
    """Draw one random network (the distributions are in the module docstring).

    Parameters
    ----------
    rng : numpy Generator, int or None
    n_stations, n_targets : int or (low, high), inclusive
    extent_m : float or (low, high), metres, drawn log-uniformly
    gap_fraction : float or (low, high), probability of an unobserved pair, drawn uniformly
    offset_max_m, sigma_m : float, metres
    station_layout, target_layout : str or None (None: drawn with equal probability)
    min_stations_per_target : int, 3 or more (4 for networks solvable from distances alone)

    Returns
    -------
    GeneratedNetwork
    """
    g = np.random.default_rng(rng)
    s_lo, s_hi = _range("n_stations", n_stations, 4)
    t_lo, t_hi = _range("n_targets", n_targets, 5)
    l_lo, l_hi = _range("extent_m", extent_m, 1e-3)
    g_lo, g_hi = _range("gap_fraction", gap_fraction, 0.0)
    if g_hi >= 1.0:
        raise MultilatError(f"random_network: gap_fraction must be below 1, got {gap_fraction!r}")
    for name, lay, known in (("station_layout", station_layout, STATION_LAYOUTS),
                             ("target_layout", target_layout, TARGET_LAYOUTS)):
        if lay is not None and lay not in known:
            raise MultilatError(f"random_network: {name} must be one of {', '.join(known)}, got {lay!r}")
    need = int(min_stations_per_target)
    if need < 3:
        raise MultilatError("random_network: min_stations_per_target must be >= 3")
    s = int(g.integers(s_lo, s_hi + 1))
    t = int(g.integers(t_lo, t_hi + 1))
    if need > s:
        raise MultilatError(f"random_network: {s} stations cannot give {need} stations per target")
    L = float(np.exp(g.uniform(np.log(l_lo), np.log(l_hi))))
    slay = station_layout or STATION_LAYOUTS[int(g.integers(len(STATION_LAYOUTS)))]
    tlay = target_layout or TARGET_LAYOUTS[int(g.integers(len(TARGET_LAYOUTS)))]
    gap = float(g.uniform(g_lo, g_hi))
    H = _stations(g, slay, s, L)
    clearance = max(0.2, 0.05 * L)
    T = _targets(g, tlay, t, L)
    for _ in range(1000):
        close = np.linalg.norm(T[:, None] - H[None], axis=2).min(1) < clearance
        if not close.any():
            break
        T[close] = _targets(g, tlay, int(close.sum()), L)
    else:
        raise MultilatError("random_network: targets keep falling next to a station")
    seen = _mask(g, s, t, gap, need)
    o = g.uniform(-offset_max_m, offset_max_m, s)
    si, ti = np.nonzero(seen)
    d = np.linalg.norm(H[si] - T[ti], axis=1) + o[si] + g.normal(0.0, sigma_m, si.size)
    obs = Observations(tuple(f"S{i + 1}" for i in range(s)), tuple(f"T{j + 1}" for j in range(t)),
                       si, ti, d, np.full(si.size, float(sigma_m)))
    return GeneratedNetwork(H, T, o, obs, L, slay, tlay, gap)


def sequential_network(rng=None, *, heads=("T1", "T2"), n_stations: int = 8, n_targets: int = 16,
                       part_m=(1.6, 1.0, 0.6), radius_m: float = 2.8, offset_max_m: float = 2e-3,
                       sigma_m: float = 5e-6, gap: float = 0.15) -> GeneratedNetwork:
    """Sequential multilateration: ``len(heads)`` heads moved over ``n_stations`` stations around a part.

    Targets uniform in the part's box ``part_m`` (centred on the origin in x, y; z from 0); stations
    on a ring of radius ``radius_m`` (azimuths evenly spaced, jitter ``U(-0.2, 0.2)`` of the spacing),
    heights alternating low ``U(0.4, 0.8)`` m and high ``U(1.4, 1.9)`` m (tripods at two heights: the
    stations are off one plane); station ``i`` is occupied by head ``heads[i % len(heads)]``. One
    offset per head ``U(-offset_max_m, offset_max_m)``; each station-target pair unseen with
    probability ``gap`` (every target seen by >= 5 stations); gaussian noise ``sigma_m``.

    Returns a :class:`GeneratedNetwork` whose ``offset_m`` is per station (the head's offset) and
    whose ``obs.station_heads`` names the heads.
    """
    g = np.random.default_rng(rng)
    s, t, nh = int(n_stations), int(n_targets), len(heads)
    if nh < 1 or s < 4 or t < 5:
        raise MultilatError("sequential_network: needs >= 1 head, >= 4 stations and >= 5 targets")
    az = 2 * np.pi * (np.arange(s) + g.uniform(-0.2, 0.2, s)) / s
    z = np.where(np.arange(s) % 2 == 0, g.uniform(0.4, 0.8, s), g.uniform(1.4, 1.9, s))
    H = np.column_stack([radius_m * np.cos(az), radius_m * np.sin(az), z])
    half = np.array(part_m, float) / 2
    T = g.uniform([-half[0], -half[1], 0.0], [half[0], half[1], 2 * half[2]], (t, 3))
    seen = _mask(g, s, t, gap, min(5, s))
    head_off = g.uniform(-offset_max_m, offset_max_m, nh)
    hi = np.arange(s) % nh
    o = head_off[hi]
    si, ti = np.nonzero(seen)
    d = np.linalg.norm(H[si] - T[ti], axis=1) + o[si] + g.normal(0.0, sigma_m, si.size)
    obs = Observations(tuple(f"S{i + 1}" for i in range(s)), tuple(f"P{j + 1}" for j in range(t)),
                       si, ti, d, np.full(si.size, float(sigma_m)),
                       station_heads=tuple(heads[k] for k in hi))
    return GeneratedNetwork(H, T, o, obs, float(2 * radius_m), "sequential ring", "part", gap)


def mixed_network(rng=None, *, heads=("H1", "H2", "H3", "H4"), trackers=None, n_targets: int = 14,
                  room_m=(4.0, 3.0, 1.2), head_sigma_m: float = 5e-6, offset_max_m: float = 2e-3,
                  levelled: bool = False):
    """A mixed campaign: multilateration heads (distances) and laser trackers (distance and two angles
    to every target), all seeing every target.

    Heads on the corners of the ``room_m`` floor plan at alternating heights (0.5 / 1.6 m), trackers
    ``trackers`` (default: AT1 and AT2 of ``examples/instruments/heads_and_trackers.toml``'s
    specification, :class:`multilat.tracker.TrackerSpec`) near the middle of two opposite walls at
    1.2 m, each with a small random tilt (``U(±0.02)`` rad) and a random heading; targets uniform in the
    inner box of the room. Heads: one offset each ``U(±offset_max_m)``, gaussian noise ``head_sigma_m``;
    trackers: offset 0, distance noise and angle noise of their specification's σ at each range.

    ``levelled``: the trackers stand on their level (no tilt; ``obs.levelled`` names them); the random
    draws are the same as without it.

    Returns ``(GeneratedNetwork, orientation_rad (s, 3))`` — the orientations of the heads are zero
    (they read no angles).
    """
    from multilat.network.angles import predicted_angles
    from multilat.tracker import TrackerSpec

    g = np.random.default_rng(rng)
    if trackers is None:
        spec = TrackerSpec(10.0, 0.3, 15.0, 6.0)
        trackers = {"AT1": spec, "AT2": spec}
    L, W, Z = (float(v) for v in room_m)
    Hh = np.array([[0.0, 0.0, 0.5], [L, 0.0, 1.6], [L, W, 0.5], [0.0, W, 1.6]])[:len(heads)]
    Ht = np.array([[L / 2, -0.3, 1.2], [L / 2, W + 0.3, 1.2]])[:len(trackers)]
    H = np.vstack([Hh, Ht]) + g.uniform(-0.1, 0.1, (len(heads) + len(trackers), 3))
    T = g.uniform([0.4, 0.4, 0.2], [L - 0.4, W - 0.4, 0.2 + Z], (int(n_targets), 3))
    s, t = H.shape[0], T.shape[0]
    ori = np.zeros((s, 3))
    nh = len(heads)
    ori[nh:, :2] = g.uniform(-0.02, 0.02, (s - nh, 2))
    ori[nh:, 2] = g.uniform(-np.pi, np.pi, s - nh)
    if levelled:
        ori[nh:, :2] = 0.0
    off = np.concatenate([g.uniform(-offset_max_m, offset_max_m, nh), np.zeros(s - nh)])
    si, ti = np.meshgrid(np.arange(s), np.arange(t), indexing="ij")
    si, ti = si.ravel(), ti.ravel()
    rho = np.linalg.norm(H[si] - T[ti], axis=1)
    specs = list(trackers.values())
    sig = np.where(si < nh, head_sigma_m, 0.0)
    sig_a = np.full(si.size, np.nan)
    for q, sp in enumerate(specs):
        k = si == nh + q
        sig[k] = sp.distance_sigma_m(rho[k])
        sig_a[k] = sp.angle_sigma_rad(rho[k])
    d = rho + off[si] + g.normal(0.0, 1.0, si.size) * sig
    az, el = predicted_angles(H, ori, T, si, ti)
    tr = si >= nh
    az = np.where(tr, az + g.normal(0.0, 1.0, si.size) * np.where(tr, sig_a, 0.0), np.nan)
    el = np.where(tr, el + g.normal(0.0, 1.0, si.size) * np.where(tr, sig_a, 0.0), np.nan)
    obs = Observations(tuple(heads) + tuple(trackers), tuple(f"P{j + 1}" for j in range(t)), si, ti, d, sig,
                       az, el, None, sig_a, sig_a, tuple(trackers) if levelled else ())
    return GeneratedNetwork(H, T, off, obs, float(np.hypot(L, W)), "room corners and walls", "room", 0.0), ori
