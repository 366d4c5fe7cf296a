"""The data of a self-calibrating multilateration network: distance observations, reference
lengths and point coordinates, validated once at construction (the solver trusts them).

Conventions
-----------
* One observation is one distance measured by station (measurement head) ``i`` to target position
  ``j``, in metres, *as reported by the instrument*: it includes the station's additive instrument
  offset, ``distance_m = |H_i - T_j| + offset_i`` (seed 000 §4.3).
* Ids are strings; ``station_ids``/``target_ids`` keep first-appearance order, and
  ``station_index[k]``/``target_index[k]`` point into them.
* A (station, target) pair may appear several times: repeated readings are separate observations
  (or averaged first, :func:`multilat.network.model.repeats.average_repeats`); geometric counts (targets
  per station, stations per target) count distinct pairs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError

__all__ = ["Observations", "ReferenceLengths", "Points", "distinct_pair_codes"]


def _ids(name: str, values) -> tuple[str, ...]:
    out = tuple(str(v) for v in values)
    for v in out:
        if v.strip() == "" or v != v.strip():
            raise MultilatError(f"{name}: ids must be non-empty without surrounding blanks, got {v!r}")
    return out


def _index_of(ids: Sequence[str]) -> dict[str, int]:
    return {s: i for i, s in enumerate(ids)}


def distinct_pair_codes(station_index, target_index, n_targets: int) -> np.ndarray:
    """The distinct (station, target) pairs as sorted codes ``station * n_targets + target`` (int64):
    repeated readings of a pair appear once. Sort-based (numpy 2's hashing ``np.unique`` is ~10x slower
    on millions of codes)."""
    code = np.asarray(station_index, np.int64) * int(n_targets) + np.asarray(target_index, np.int64)
    code.sort(kind="stable")          # radix/timsort: ~2x numpy's default on files in target or station order
    if code.size < 2:
        return code
    keep = np.empty(code.size, bool)
    keep[0] = True
    np.not_equal(code[1:], code[:-1], out=keep[1:])
    return code[keep]


@dataclass(frozen=True, eq=False)
class Observations:
    """Distances measured by stations to targets.

    Attributes
    ----------
    station_ids, target_ids : tuple of str
        Unique ids, in order of first appearance (``s`` stations, ``t`` targets).
    station_index, target_index : ndarray of int, shape (m,)
        Station and target of each observation.
    distance_m : ndarray, shape (m,)
        Measured distances (including the station offset), metres, > 0.
    sigma_m : ndarray, shape (m,)
        A-priori standard uncertainty of each distance, metres, > 0.
    azimuth_rad, elevation_rad : ndarray, shape (m,), or None
        Pointing angles of the head for each observation when known (NaN where unknown).
    station_heads : tuple of str, length s, or None
        The measurement head that occupied each station (None: every station is its own head, head
        id = station id). Offsets and scales belong to heads: a head that occupies several stations
        (sequential multilateration) has one offset and one scale for all of them.
    sigma_azimuth_rad, sigma_elevation_rad : ndarray, shape (m,), or None
        A-priori standard uncertainty of the row's azimuth / elevation when that angle is an
        **observation** of the adjustment (NaN: the angle, if given, serves only for initial values).
        A station with angle observations gets an orientation (:mod:`multilat.network.model.angle_rows`).
    levelled : tuple of str
        Stations whose vertical axis is the world's +z (a tracker on its level): one orientation angle
        (κ) instead of three.

    Build with :meth:`from_labels` (ids per row); the constructor checks shapes, finiteness,
    positivity and index ranges; repeated (station, target) pairs are allowed (repeated readings).
    """

    station_ids: tuple[str, ...]
    target_ids: tuple[str, ...]
    station_index: np.ndarray
    target_index: np.ndarray
    distance_m: np.ndarray
    sigma_m: np.ndarray
    azimuth_rad: np.ndarray | None = None
    elevation_rad: np.ndarray | None = None
    station_heads: tuple[str, ...] | None = None
    sigma_azimuth_rad: np.ndarray | None = None
    sigma_elevation_rad: np.ndarray | None = None
    levelled: tuple = ()

    def __post_init__(self):
        set_ = object.__setattr__
        set_(self, "station_ids", _ids("station_ids", self.station_ids))
        if self.station_heads is not None:
            hs = _ids("station_heads", self.station_heads)
            if len(hs) != len(self.station_ids):
                raise MultilatError(f"station_heads: expected {len(self.station_ids)} head ids (one per "
                                    f"station), got {len(hs)}")
            set_(self, "station_heads", None if hs == self.station_ids else hs)
        set_(self, "target_ids", _ids("target_ids", self.target_ids))
        if len(set(self.station_ids)) != len(self.station_ids):
            raise MultilatError("station_ids: duplicate station id")
        if len(set(self.target_ids)) != len(self.target_ids):
            raise MultilatError("target_ids: duplicate target id")
        if set(self.station_ids) & set(self.target_ids):
            both = sorted(set(self.station_ids) & set(self.target_ids))[0]
            raise MultilatError(f"id {both!r} is used both as a station and as a target")
        si = np.asarray(self.station_index)
        ti = np.asarray(self.target_index)
        if si.ndim != 1 or ti.shape != si.shape or not (np.issubdtype(si.dtype, np.integer)
                                                        and np.issubdtype(ti.dtype, np.integer)):
            raise MultilatError("station_index/target_index: expected integer arrays of equal shape (m,)")
        m = si.shape[0]
        if m == 0:
            raise MultilatError("no observations")
        if si.min() < 0 or si.max() >= len(self.station_ids):
            raise MultilatError("station_index out of range")
        if ti.min() < 0 or ti.max() >= len(self.target_ids):
            raise MultilatError("target_index out of range")
        set_(self, "station_index", si.astype(np.intp, copy=True))
        set_(self, "target_index", ti.astype(np.intp, copy=True))
        for name in ("distance_m", "sigma_m"):
            a = np.array(getattr(self, name), dtype=float)
            if a.shape != (m,):
                raise MultilatError(f"{name}: expected shape ({m},), got {a.shape}")
            bad = np.flatnonzero(~(np.isfinite(a) & (a > 0)))
            if bad.size:
                k = int(bad[0])
                raise MultilatError(f"{name} of observation {self.label(k)} must be finite and > 0, "
                                    f"got {a[k]!r}")
            set_(self, name, a)
        for name in ("azimuth_rad", "elevation_rad"):
            v = getattr(self, name)
            if v is not None:
                a = np.array(v, dtype=float)
                if a.shape != (m,):
                    raise MultilatError(f"{name}: expected shape ({m},), got {a.shape}")
                if np.any(np.isinf(a)):
                    raise MultilatError(f"{name}: infinite angle")
                set_(self, name, a)
        for name, value in (("sigma_azimuth_rad", "azimuth_rad"), ("sigma_elevation_rad", "elevation_rad")):
            v = getattr(self, name)
            if v is None:
                continue
            a = np.array(v, dtype=float)
            if a.shape != (m,):
                raise MultilatError(f"{name}: expected shape ({m},), got {a.shape}")
            bad = np.flatnonzero(~np.isnan(a) & ~(np.isfinite(a) & (a > 0)))
            if bad.size:
                k = int(bad[0])
                raise MultilatError(f"{name} of observation {self.label(k)} must be > 0 (or empty: not an "
                                    f"observation), got {a[k]!r}")
            ang = getattr(self, value)
            used = np.isfinite(a)
            if used.any() and (ang is None or np.any(~np.isfinite(ang[used]))):
                k = int(np.flatnonzero(used if ang is None else used & ~np.isfinite(ang))[0])
                raise MultilatError(f"observation {self.label(k)}: {name} given without its {value}")
            set_(self, name, a if used.any() else None)
        lev = tuple(str(x) for x in (self.levelled or ()))
        for x in lev:
            if x not in self.station_ids:
                raise MultilatError(f"levelled: {x!r} is not a station")
        set_(self, "levelled", lev)
        for a in (self.station_index, self.target_index, self.distance_m, self.sigma_m):
            a.flags.writeable = False

    # ---------------------------------------------------------------- construction
    @classmethod
    def from_labels(cls, station: Sequence[str], target: Sequence[str], distance_m, sigma_m, *,
                    azimuth_rad=None, elevation_rad=None, head: Sequence[str] | None = None,
                    sigma_azimuth_rad=None, sigma_elevation_rad=None, levelled=()) -> "Observations":
        """Build from one station id and one target id per observation.

        Parameters
        ----------
        station, target : sequence of str, length m
        distance_m : array_like, shape (m,), metres
        sigma_m : float or array_like, shape (m,), metres
        azimuth_rad, elevation_rad : array_like, shape (m,), optional
        head : sequence of str, length m, optional
            The head that measured each distance (default: the station id). All observations of a
            station must name the same head.
        """
        station = _ids("station", station)
        target = _ids("target", target)
        if len(station) != len(target):
            raise MultilatError("station and target lists differ in length")
        sids = tuple(dict.fromkeys(station))
        heads = None
        if head is not None:
            head = _ids("head", head)
            if len(head) != len(station):
                raise MultilatError("head and station lists differ in length")
            hs: dict[str, str] = {}
            for k, (s_, h_) in enumerate(zip(station, head)):
                if hs.setdefault(s_, h_) != h_:
                    raise MultilatError(f"row {k + 1}: station {s_!r} has two heads, {hs[s_]!r} and {h_!r}")
            heads = tuple(hs[s_] for s_ in sids)
        tids = tuple(dict.fromkeys(target))
        sx, tx = _index_of(sids), _index_of(tids)
        m = len(station)
        sig = np.broadcast_to(np.asarray(sigma_m, dtype=float), (m,)).copy() if m else np.zeros(0)
        return cls(sids, tids, np.array([sx[s] for s in station], dtype=np.intp),
                   np.array([tx[t] for t in target], dtype=np.intp), np.asarray(distance_m, float),
                   sig, azimuth_rad=azimuth_rad, elevation_rad=elevation_rad, station_heads=heads,
                   sigma_azimuth_rad=sigma_azimuth_rad, sigma_elevation_rad=sigma_elevation_rad,
                   levelled=tuple(x for x in dict.fromkeys(levelled) if x in sids))

    # ---------------------------------------------------------------- views
    @property
    def head_of_station(self) -> tuple[str, ...]:
        """The head id of each station (s,) (the station id when no heads were given)."""
        return self.station_ids if self.station_heads is None else self.station_heads

    @property
    def head_ids(self) -> tuple[str, ...]:
        """Unique head ids in order of first appearance among the stations."""
        return tuple(dict.fromkeys(self.head_of_station))

    @property
    def head_index(self) -> np.ndarray:
        """Index into :attr:`head_ids` of each station (s,)."""
        pos = {h: k for k, h in enumerate(self.head_ids)}
        return np.array([pos[h] for h in self.head_of_station], dtype=np.intp)

    @property
    def shares_heads(self) -> bool:
        """Whether some head occupies more than one station."""
        return len(self.head_ids) < self.n_stations

    @property
    def n_obs(self) -> int:
        return int(self.distance_m.shape[0])

    @property
    def n_stations(self) -> int:
        return len(self.station_ids)

    @property
    def n_targets(self) -> int:
        return len(self.target_ids)

    def label(self, k: int) -> str:
        """``'station->target'`` of observation ``k`` (for messages)."""
        return f"{self.station_ids[self.station_index[k]]}->{self.target_ids[self.target_index[k]]}"

    def distinct_pairs(self) -> np.ndarray:
        """:func:`distinct_pair_codes` of these observations, computed once per object (the structure
        checks, the exclusions and the snooping rounds all read it)."""
        got = self.__dict__.get("_distinct_pairs")
        if got is None:
            got = distinct_pair_codes(self.station_index, self.target_index, self.n_targets)
            got.setflags(write=False)
            object.__setattr__(self, "_distinct_pairs", got)
        return got

    def subset(self, keep) -> "Observations":
        """The observations selected by the boolean mask or index array ``keep``; ids keep their
        order, ids that lose all their observations are dropped."""
        keep = np.asarray(keep)
        if keep.dtype == bool:
            keep = np.flatnonzero(keep)
        si, ti = self.station_index[keep], self.target_index[keep]
        s_present = np.flatnonzero(np.bincount(si, minlength=self.n_stations) > 0)
        t_present = np.flatnonzero(np.bincount(ti, minlength=self.n_targets) > 0)
        s_new = np.full(self.n_stations, -1, dtype=np.intp)
        t_new = np.full(self.n_targets, -1, dtype=np.intp)
        s_new[s_present] = np.arange(s_present.size)
        t_new[t_present] = np.arange(t_present.size)
        az = None if self.azimuth_rad is None else self.azimuth_rad[keep]
        el = None if self.elevation_rad is None else self.elevation_rad[keep]
        hs = None if self.station_heads is None else tuple(self.station_heads[i] for i in s_present)
        saz = None if self.sigma_azimuth_rad is None else self.sigma_azimuth_rad[keep]
        sel = None if self.sigma_elevation_rad is None else self.sigma_elevation_rad[keep]
        return Observations(tuple(self.station_ids[i] for i in s_present),
                            tuple(self.target_ids[j] for j in t_present), s_new[si], t_new[ti],
                            self.distance_m[keep], self.sigma_m[keep], az, el, hs, saz, sel,
                            tuple(x for x in self.levelled if x in {self.station_ids[i] for i in s_present}))

    def with_sigma(self, sigma_m) -> "Observations":
        """A copy with other a-priori uncertainties (scalar or shape (m,))."""
        sig = np.broadcast_to(np.asarray(sigma_m, dtype=float), (self.n_obs,)).copy()
        return Observations(self.station_ids, self.target_ids, self.station_index, self.target_index,
                            self.distance_m, sig, self.azimuth_rad, self.elevation_rad, self.station_heads,
                            self.sigma_azimuth_rad, self.sigma_elevation_rad, self.levelled)

    def with_distances(self, distance_m) -> "Observations":
        """A copy with other distances (same pattern), e.g. a simulated draw."""
        return Observations(self.station_ids, self.target_ids, self.station_index, self.target_index,
                            distance_m, self.sigma_m, self.azimuth_rad, self.elevation_rad, self.station_heads,
                            self.sigma_azimuth_rad, self.sigma_elevation_rad, self.levelled)

    def with_angle_sigma(self, sigma_azimuth_rad, sigma_elevation_rad) -> "Observations":
        """A copy with other a-priori uncertainties of the angle observations (NaN: not an observation)."""
        return Observations(self.station_ids, self.target_ids, self.station_index, self.target_index,
                            self.distance_m, self.sigma_m, self.azimuth_rad, self.elevation_rad, self.station_heads,
                            sigma_azimuth_rad, sigma_elevation_rad, self.levelled)

    @property
    def has_angle_observations(self) -> bool:
        """Whether any azimuth or elevation is an observation (has its σ)."""
        return self.sigma_azimuth_rad is not None or self.sigma_elevation_rad is not None


@dataclass(frozen=True, eq=False)
class ReferenceLengths:
    """Independently measured distances between two target positions (Tables V-VI of seed 000).

    Attributes
    ----------
    target_a, target_b : tuple of str, length r
    length_m : ndarray, shape (r,), metres, > 0
    u_m : ndarray, shape (r,), standard uncertainty, metres (NaN when not given)
    path : str, optional  the file they were read from (for ``FILE:LINE:`` errors)
    line_numbers : tuple of int, length r, optional  the file line of each row
    """

    target_a: tuple[str, ...]
    target_b: tuple[str, ...]
    length_m: np.ndarray
    u_m: np.ndarray
    path: str | None = None
    line_numbers: tuple[int, ...] | None = None

    def __post_init__(self):
        a, b = _ids("target_a", self.target_a), _ids("target_b", self.target_b)
        r = len(a)
        if len(b) != r:
            raise MultilatError("target_a and target_b differ in length")
        L = np.array(self.length_m, dtype=float)
        u = np.broadcast_to(np.asarray(self.u_m, dtype=float), (r,)).copy()
        if L.shape != (r,):
            raise MultilatError(f"length_m: expected shape ({r},), got {L.shape}")
        if not np.all(np.isfinite(L) & (L > 0)):
            raise MultilatError("length_m must be finite and > 0")
        if np.any(u[~np.isnan(u)] < 0) or np.any(np.isinf(u)):
            raise MultilatError("u_m must be finite and >= 0")
        for x, y in zip(a, b):
            if x == y:
                raise MultilatError(f"reference length from {x!r} to itself")
        object.__setattr__(self, "target_a", a)
        object.__setattr__(self, "target_b", b)
        object.__setattr__(self, "length_m", L)
        object.__setattr__(self, "u_m", u)
        if self.line_numbers is not None:
            ln = tuple(int(v) for v in self.line_numbers)
            if len(ln) != r:
                raise MultilatError(f"line_numbers: expected {r} entries, got {len(ln)}")
            object.__setattr__(self, "line_numbers", ln)

    def __len__(self) -> int:
        return len(self.target_a)

    def check_ids(self, known: Sequence[str], *, what: str = "reference lengths") -> None:
        """Raise :class:`MultilatError` naming the first id not in ``known``: ``FILE:LINE:`` when
        read from a file (``path``, ``line_numbers``), else ``what: row K:`` (1-based)."""
        ks = set(known)
        for k, (x, y) in enumerate(zip(self.target_a, self.target_b)):
            for v in (x, y):
                if v not in ks:
                    if self.path is not None and self.line_numbers is not None:
                        raise MultilatError(f"{self.path}:{self.line_numbers[k]}: unknown point id {v!r}")
                    raise MultilatError(f"{what}: row {k + 1}: unknown point id {v!r}")


@dataclass(frozen=True, eq=False)
class Points:
    """Coordinates of named points (stations or targets): approximate values or control.

    Attributes
    ----------
    ids : tuple of str, length p (unique)
    xyz_m : ndarray, shape (p, 3), metres
    std_m : ndarray, shape (p, 3), or None
        Standard uncertainties of the coordinates, metres: a row with all three given (> 0) is a
        **weighted** control point (its coordinates are observations), a row of NaN a hard one (held
        fixed under ``datum="control"``). None: every point hard.
    """

    ids: tuple[str, ...]
    xyz_m: np.ndarray
    std_m: np.ndarray | None = None

    def __post_init__(self):
        ids = _ids("point", self.ids)
        if len(set(ids)) != len(ids):
            raise MultilatError("points: duplicate point id")
        x = np.array(self.xyz_m, dtype=float).reshape(len(ids), 3)
        if not np.all(np.isfinite(x)):
            raise MultilatError("points: coordinates must be finite")
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "xyz_m", x)
        object.__setattr__(self, "_row", _index_of(ids))
        if self.std_m is not None:
            sd = np.array(self.std_m, dtype=float).reshape(len(ids), 3)
            given = ~np.isnan(sd)
            for k in range(len(ids)):
                if given[k].any() and not given[k].all():
                    raise MultilatError(f"points: {ids[k]!r}: give all three standard uncertainties or none")
                if given[k].all() and not np.all(np.isfinite(sd[k]) & (sd[k] > 0)):
                    raise MultilatError(f"points: {ids[k]!r}: standard uncertainties must be finite and > 0, "
                                        f"got {sd[k].tolist()}")
            object.__setattr__(self, "std_m", sd if given.any() else None)

    def std(self, ident: str) -> np.ndarray | None:
        """Standard uncertainties (3,) of a weighted control point, None for a hard one or an unknown id."""
        k = self._row.get(ident)
        if k is None or self.std_m is None or np.isnan(self.std_m[k, 0]):
            return None
        return self.std_m[k]

    def get(self, ident: str) -> np.ndarray | None:
        """Coordinates (3,) of ``ident``, or None when not given (a dict look-up)."""
        k = self._row.get(ident)
        return None if k is None else self.xyz_m[k]

    def as_dict(self) -> dict[str, np.ndarray]:
        return {i: self.xyz_m[k] for k, i in enumerate(self.ids)}
