"""The two experiments of seed 000 §4 as built-in network configurations with a known truth.

The text gives the head coordinates (§4.1-4.2), the reference lengths (§4.4) and a few facts about
the targets; the figures (11, 12) that showed the 14 target positions are lost. The targets here
are a *reconstruction* that satisfies every stated constraint; docs/network-simulation.md lists
each assumption. What is from the paper and what is ours:

Small volume (§4.1): heads A = [504, 938, 491], B = [0, 0, 0], C = [524, -7, 909], D = [1050, 0, 0]
mm (paper; a tetrahedron with edges 1091 mm ± 71 mm). Ours: three heads at y ~ 0 share the table
plane, so **y is vertical** here (A stands 0.94 m above the table); targets 1-2-3, 6-7-8 and
12-13-14 are the triplet breadboard at three placements (P1-P2 150.022 mm, P2-P3 174.615 mm,
P1-P3 324.636 mm, exact in the truth: P2 sits 0.40 mm off the P1-P3 line because the published
lengths add up to 324.637 mm), 4, 5, 9, 10, 11 isolated; the longest head-target distance is
1.470 m (paper: "maximal measured distance is 1.47 m"); the bounding box of heads and targets is
1.11 m x 0.945 m x 0.909 m = 0.95 m³ ("about one cubic metre").

Large volume (§4.2): heads A = [0, 0, 0], B = [2736, 56, 1406], C = [5289, 0, 0],
D = [2692, 6236, 793] mm (paper); z vertical. Ours: couples (1, 2), (5, 6), (10, 11) of the
breadboard at 324.071 mm; pillars 3, 7, 12 aligned (P1-P2 2232.037 mm, P2-P3 6700.471 mm exact;
P1-P3 = 8932.508 mm, 1 µm short of the published 8932.509 mm, which exceeds the sum of the other
two so no three points can match all three); 4, 8, 9, 13, 14 isolated; head-target distances
0.340 m to 11.540 m (paper: 0.34 m to 11.54 m); bounding box 5.60 m x 10.30 m x 2.60 m (paper:
5.6 m x 10.3 m x 2.6 m); the floor is assumed 1.10 m below head A, and 13 of the 14 targets are
less than 1.5 m above it ("most of the targets have a height less than 1.5 m"). The heads'
tetrahedron is flat (z 0-1.4 m), so 13 targets lie outside it; 8, 9, 12 and 14 lie 0.6-3.9 m beyond
head D in y ("largely outside the volume bounded by the measurement heads").

Instrument offsets (both): A +2.0 mm, B -1.5 mm, C +3.1 mm, D +0.7 mm (the paper gives none;
"a few mm", convention ``measured = |H - T| + offset``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.data import ReferenceLengths

__all__ = ["NetworkConfig", "small_volume", "large_volume", "BUILTIN", "get_config",
           "PAPER_OFFSETS_M", "triplet_points"]

#: the offsets assumed for both experiments (A, B, C, D), metres
PAPER_OFFSETS_M = (2.0e-3, -1.5e-3, 3.1e-3, 0.7e-3)


@dataclass(frozen=True, eq=False)
class NetworkConfig:
    """A network with a known truth.

    Attributes
    ----------
    name : str
    station_ids : tuple of str, length s
    station_xyz_m : ndarray, shape (s, 3), metres
    target_ids : tuple of str, length t
    target_xyz_m : ndarray, shape (t, 3), metres
    offset_m : ndarray, shape (s,), metres (``measured = |H - T| + offset``)
    reference_lengths : ReferenceLengths
        The published reference lengths (``u_m``: their stated standard uncertainty) between target
        pairs; the pairs the §4.4 study compares.
    vertical_axis : int
        0, 1 or 2: the axis that points up (1 in the small volume, 2 in the large one).
    description : str
    """

    name: str
    station_ids: tuple
    station_xyz_m: np.ndarray
    target_ids: tuple
    target_xyz_m: np.ndarray
    offset_m: np.ndarray
    reference_lengths: ReferenceLengths
    vertical_axis: int = 2
    description: str = ""

    def __post_init__(self):
        sx = np.array(self.station_xyz_m, dtype=float)
        tx = np.array(self.target_xyz_m, dtype=float)
        off = np.array(self.offset_m, dtype=float)
        sid = tuple(str(s) for s in self.station_ids)
        tid = tuple(str(t) for t in self.target_ids)
        if sx.shape != (len(sid), 3) or tx.shape != (len(tid), 3) or off.shape != (len(sid),):
            raise MultilatError(f"{self.name}: expected station_xyz_m ({len(sid)}, 3), target_xyz_m "
                                f"({len(tid)}, 3), offset_m ({len(sid)},); got {sx.shape}, {tx.shape}, "
                                f"{off.shape}")
        if len(sid) < 4:
            raise MultilatError(f"{self.name}: at least 4 stations are needed, got {len(sid)}")
        for name, a in (("station", sx), ("target", tx), ("offset", off)):
            if not np.all(np.isfinite(a)):
                raise MultilatError(f"{self.name}: {name} coordinates must be finite")
        if len(set(sid)) != len(sid) or len(set(tid)) != len(tid) or set(sid) & set(tid):
            raise MultilatError(f"{self.name}: station and target ids must be unique")
        self.reference_lengths.check_ids(tid, what=f"{self.name}: reference lengths")
        if self.vertical_axis not in (0, 1, 2):
            raise MultilatError(f"{self.name}: vertical_axis must be 0, 1 or 2")
        for k, v in (("station_ids", sid), ("target_ids", tid), ("station_xyz_m", sx),
                     ("target_xyz_m", tx), ("offset_m", off)):
            object.__setattr__(self, k, v)
        for a in (sx, tx, off):
            a.flags.writeable = False

    @property
    def n_stations(self) -> int:
        return len(self.station_ids)

    @property
    def n_targets(self) -> int:
        return len(self.target_ids)

    def geometric_distances_m(self) -> np.ndarray:
        """True head-target distances ``|H_i - T_j|``, shape (s, t), metres."""
        return np.linalg.norm(self.station_xyz_m[:, None, :] - self.target_xyz_m[None, :, :], axis=2)

    def reference_pairs(self) -> list[tuple[int, int]]:
        """The reference-length pairs as target indices."""
        ix = {t: j for j, t in enumerate(self.target_ids)}
        return [(ix[a], ix[b]) for a, b in zip(self.reference_lengths.target_a,
                                               self.reference_lengths.target_b)]

    def true_lengths_m(self) -> np.ndarray:
        """True distances of the reference pairs (equal to the published ones where consistent)."""
        tx = self.target_xyz_m
        return np.array([np.linalg.norm(tx[a] - tx[b]) for a, b in self.reference_pairs()])


def triplet_points(p1_m, direction, *, a_m, b_m, c_m, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Three points P1, P2, P3 with |P1P2| = a, |P2P3| = b, |P1P3| = c exactly.

    P3 = P1 + c u along the unit ``direction`` u; P2 is at distance a from P1 and b from P3, off the
    line (towards ``up`` projected perpendicular to u) by ``sqrt(a^2 - x^2)``, ``x = (a^2 - b^2 +
    c^2) / 2c`` (0 for a + b = c). Raises :class:`MultilatError` if a + b < c (no such triangle).

    Returns
    -------
    ndarray (3, 3), metres
    """
    u = np.asarray(direction, float)
    u = u / np.linalg.norm(u)
    x = (a_m ** 2 - b_m ** 2 + c_m ** 2) / (2 * c_m)
    h2 = a_m ** 2 - x ** 2
    if h2 < -1e-18:
        raise MultilatError(f"no triangle with sides {a_m}, {b_m}, {c_m} m")
    perp = np.asarray(up, float) - u * (np.asarray(up, float) @ u)
    if np.linalg.norm(perp) < 1e-9:
        perp = np.cross(u, [1.0, 0.0, 0.0])
    perp /= np.linalg.norm(perp)
    p1 = np.asarray(p1_m, float)
    return np.array([p1, p1 + x * u + np.sqrt(max(h2, 0.0)) * perp, p1 + c_m * u])


# ---------------------------------------------------------------------------- small volume
_TRIPLET_MM = (150.022, 174.615, 324.636)          # §4.4, P1-P2, P2-P3, P1-P3
_TRIPLET_U_M = (4e-6, 4e-6, 3e-6)


def small_volume() -> NetworkConfig:
    """Seed 000 §4.1: 4 heads on an optical table, 14 target positions in about 1 m³ (y vertical)."""
    a, b, c = (v * 1e-3 for v in _TRIPLET_MM)
    up = (0.0, 1.0, 0.0)
    t123 = triplet_points((0.220, 0.160, 0.230), (1.0, 0.0, 0.0), a_m=a, b_m=b, c_m=c, up=up)
    t678 = triplet_points((0.780, 0.260, 0.260), (0.0, 0.15, 1.0), a_m=a, b_m=b, c_m=c, up=up)
    t121314 = triplet_points((0.330, 0.420, 0.820), (-0.2, 0.0, -1.0), a_m=a, b_m=b, c_m=c, up=up)
    iso = {4: (0.880, 0.120, 0.760), 5: (0.150, 0.520, 0.640), 9: (0.560, 0.620, 0.120),
           10: (0.470, 0.090, 0.470), 11: (1.110, 0.350, 0.898)}
    pts = {1: t123[0], 2: t123[1], 3: t123[2], 6: t678[0], 7: t678[1], 8: t678[2],
           12: t121314[0], 13: t121314[1], 14: t121314[2]}
    pts.update({k: np.array(v) for k, v in iso.items()})
    tid = tuple(str(k) for k in range(1, 15))
    refs = []
    for p in ((1, 2, 3), (6, 7, 8), (12, 13, 14)):
        refs += [(str(p[0]), str(p[1]), a, _TRIPLET_U_M[0]), (str(p[1]), str(p[2]), b, _TRIPLET_U_M[1]),
                 (str(p[0]), str(p[2]), c, _TRIPLET_U_M[2])]
    return NetworkConfig(
        name="small-volume",
        station_ids=("A", "B", "C", "D"),
        station_xyz_m=np.array([[504, 938, 491], [0, 0, 0], [524, -7, 909], [1050, 0, 0]]) * 1e-3,
        target_ids=tid,
        target_xyz_m=np.array([pts[k] for k in range(1, 15)]),
        offset_m=np.array(PAPER_OFFSETS_M),
        reference_lengths=ReferenceLengths(tuple(r[0] for r in refs), tuple(r[1] for r in refs),
                                           np.array([r[2] for r in refs]), np.array([r[3] for r in refs])),
        vertical_axis=1,
        description="seed 000 §4.1 (heads from the paper; targets reconstructed)",
    )


# ---------------------------------------------------------------------------- large volume
_COUPLE_MM = 324.071
_PILLARS_MM = (2232.037, 6700.471, 8932.509)       # P1-P2, P2-P3, P1-P3 (published)
#: assumed height of head A above the floor (the paper gives none), metres
LARGE_FLOOR_Z_M = -1.10


def large_volume() -> NetworkConfig:
    """Seed 000 §4.2: 4 heads on pillars in a 5.6 m x 10.3 m x 2.6 m workshop (z vertical)."""
    L = _COUPLE_MM * 1e-3
    p12, p23, p13 = (v * 1e-3 for v in _PILLARS_MM)

    def couple(p, d):
        d = np.asarray(d, float)
        return [np.asarray(p, float), np.asarray(p, float) + L * d / np.linalg.norm(d)]

    c1 = couple((1.200, 1.500, -0.200), (1.0, 0.0, 0.0))
    c2 = couple((2.000, 4.800, 0.100), (0.6, 0.8, 0.0))
    c3 = couple((3.000, 2.600, -0.950), (-0.8, 0.6, 0.0))
    pil0 = np.array([4.400, 1.200, 0.250])
    pillars = [pil0, pil0 + [0.0, p12, 0.0], pil0 + [0.0, p12 + p23, 0.0]]   # aligned along +y
    pts = {1: c1[0], 2: c1[1], 3: pillars[0], 4: np.array([0.200, -0.168, -0.2177]),
           5: c2[0], 6: c2[1], 7: pillars[1], 8: np.array([1.000, 6.800, -0.600]),
           9: np.array([5.350, 8.600, 0.300]), 10: c3[0], 11: c3[1], 12: pillars[2],
           13: np.array([2.400, 3.600, 1.650]), 14: np.array([-0.250, 10.1195, -0.300])}
    tid = tuple(str(k) for k in range(1, 15))
    refs = [("1", "2", L), ("5", "6", L), ("10", "11", L),
            ("3", "7", p12), ("7", "12", p23), ("3", "12", p13)]
    return NetworkConfig(
        name="large-volume",
        station_ids=("A", "B", "C", "D"),
        station_xyz_m=np.array([[0, 0, 0], [2736, 56, 1406], [5289, 0, 0], [2692, 6236, 793]]) * 1e-3,
        target_ids=tid,
        target_xyz_m=np.array([pts[k] for k in range(1, 15)]),
        offset_m=np.array(PAPER_OFFSETS_M),
        reference_lengths=ReferenceLengths(tuple(r[0] for r in refs), tuple(r[1] for r in refs),
                                           np.array([r[2] for r in refs]), np.full(len(refs), 4e-6)),
        vertical_axis=2,
        description="seed 000 §4.2 (heads from the paper; targets reconstructed)",
    )


BUILTIN = {"small-volume": small_volume, "large-volume": large_volume}


def get_config(name: str) -> NetworkConfig:
    """A built-in configuration by name (``small-volume``, ``large-volume``)."""
    try:
        return BUILTIN[name]()
    except KeyError:
        raise MultilatError(f"unknown configuration {name!r} (built-in: {', '.join(BUILTIN)})") from None
