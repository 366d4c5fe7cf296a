"""Generate the gama-local 2.24 input networks of this directory from known truth (issue 26).

Each network is simulated from truth coordinates (``NAME_truth.csv``, in the file's own x, y, z)
and random orientations of its direction sets: true observation + gaussian noise of the σ written
in the file, one numpy Generator per network (seed ``SEED + index``). Gama's models (2.24 sources,
``lib/gnu_gama/local/local_linearization.cpp``, ``test_linearization_visitor.cpp``):

- bearing ``atan2(dy, dx)`` in the file's x, y (axes and angle sense are always consistent here:
  ``ne`` + ``left-handed``, Gama's default, or ``en`` + ``right-handed``);
  ``<direction>`` = bearing − orientation of its ``<obs>`` set; ``<angle>`` = bearing(fs) − bearing(bs);
- ``<s-distance>``, ``<z-angle>`` between (from, z + from_dh) and (to, z + to_dh); other kinds take
  no heights; ``<distance>`` horizontal; ``<dh>`` = z_to − z_from; ``<vec>`` = to − from;
- σ in mm (linear) and cc (angles); ``<cov-mat>`` in mm², upper band by rows.

Run from the repository root: ``python tests/data/gama3d/generate.py`` (writes NAME.xml and
NAME_truth.csv); then gama-local on each file, and for ``heights`` the manual iteration
``generate.py --approx-from heights`` (README.md).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

HERE = Path(__file__).resolve().parent
SEED = 20261126
GON = 200.0 / math.pi          # gon per radian
CC = GON * 1e4                 # cc per radian


def bearing(a, b):
    return math.atan2(b[1] - a[1], b[0] - a[0]) % (2 * math.pi)


class Net:
    """A network under construction: truth, point attributes and observations, written as XML."""

    def __init__(self, name, rng, description, axes="ne", angles="left-handed"):
        self.name, self.rng, self.description = name, rng, description
        self.axes, self.angles = axes, angles
        self.truth, self.attrs, self.approx = {}, {}, {}
        self.sets, self.blocks = [], []

    def point(self, pid, xyz, attr, approx_sigma_m=None):
        """``attr`` e.g. 'fix="xyz"'; approx_sigma_m None: approximate = truth (fixed coordinates),
        a number: truth + noise, 'none': no coordinates in the file (Gama computes them)."""
        self.truth[pid] = np.asarray(xyz, float)
        self.attrs[pid] = attr
        self.approx[pid] = approx_sigma_m

    # ---------------------------------------------------------------- observations
    def _noisy(self, value, sigma):
        return value + sigma * self.rng.standard_normal()

    def obs_set(self, station, from_dh=None):
        """Open a new ``<obs from=station>`` set with its own random orientation."""
        s = dict(station=station, from_dh=from_dh, ori=self.rng.uniform(0, 2 * math.pi), rows=[])
        self.sets.append(s)
        return s

    def _heights(self, s, own_from_dh, to_dh):
        hf = own_from_dh if own_from_dh is not None else (s["from_dh"] or 0.0)
        return hf, (to_dh or 0.0)

    def _attrs_dh(self, own_from_dh, to_dh):
        a = ""
        if own_from_dh is not None:
            a += f' from_dh="{own_from_dh:.3f}"'
        if to_dh is not None:
            a += f' to_dh="{to_dh:.3f}"'
        return a

    def direction(self, s, to, sigma_cc):
        a, b = self.truth[s["station"]], self.truth[to]
        v = (self._noisy(bearing(a, b) - s["ori"], sigma_cc / CC)) % (2 * math.pi)
        s["rows"].append(f'<direction to="{to}" val="{v * GON:.7f}" stdev="{sigma_cc:.1f}" />')

    def angle(self, s, bs, fs, sigma_cc):
        a = self.truth[s["station"]]
        v = self._noisy(bearing(a, self.truth[fs]) - bearing(a, self.truth[bs]), sigma_cc / CC) % (2 * math.pi)
        s["rows"].append(f'<angle bs="{bs}" fs="{fs}" val="{v * GON:.7f}" stdev="{sigma_cc:.1f}" />')

    def sdist(self, s, to, a_mm, b_ppm, from_dh=None, to_dh=None):
        hf, ht = self._heights(s, from_dh, to_dh)
        d = self.truth[to] + [0, 0, ht] - self.truth[s["station"]] - [0, 0, hf]
        true = float(np.linalg.norm(d))
        sigma = round(a_mm + b_ppm * true * 1e-3, 4)
        v = self._noisy(true, sigma * 1e-3)
        s["rows"].append(f'<s-distance to="{to}" val="{v:.6f}" stdev="{sigma:.4f}"'
                         f'{self._attrs_dh(from_dh, to_dh)} />')

    def hdist(self, s, to, a_mm, b_ppm):
        d = self.truth[to][:2] - self.truth[s["station"]][:2]
        true = float(np.linalg.norm(d))
        sigma = round(a_mm + b_ppm * true * 1e-3, 4)
        v = self._noisy(true, sigma * 1e-3)
        s["rows"].append(f'<distance to="{to}" val="{v:.6f}" stdev="{sigma:.4f}" />')

    def zangle(self, s, to, sigma_cc, from_dh=None, to_dh=None):
        hf, ht = self._heights(s, from_dh, to_dh)
        d = self.truth[to] + [0, 0, ht] - self.truth[s["station"]] - [0, 0, hf]
        true = math.atan2(math.hypot(d[0], d[1]), d[2])
        v = self._noisy(true, sigma_cc / CC)
        s["rows"].append(f'<z-angle to="{to}" val="{v * GON:.7f}" stdev="{sigma_cc:.1f}"'
                         f'{self._attrs_dh(from_dh, to_dh)} />')

    def polar(self, s, to, dist=(1.0, 1.5), dir_cc=5.0, z_cc=5.0, to_dh=None):
        """Direction, slope distance and zenith angle to one target."""
        self.direction(s, to, dir_cc)
        self.sdist(s, to, *dist, to_dh=to_dh)
        self.zangle(s, to, z_cc, to_dh=to_dh)

    # ---------------------------------------------------------------- clusters
    def height_differences(self, pairs, sigmas_mm=None, dists_km=None, cov_mm2=None):
        """``<height-differences>``: per dh a ``stdev`` (mm), or a ``dist`` (km: σ = sqrt(D) mm with
        sigma-apr 1), or one ``cov_mm2`` for the block."""
        n = len(pairs)
        true = np.array([self.truth[b][2] - self.truth[a][2] for a, b in pairs])
        if cov_mm2 is None:
            sig = np.array([s if s is not None else math.sqrt(d) for s, d in
                            zip(sigmas_mm or [None] * n, dists_km or [None] * n)])
            cov_mm2 = np.diag(sig ** 2)
        vals = true + np.linalg.cholesky(cov_mm2) @ self.rng.standard_normal(n) * 1e-3
        rows = []
        for i, ((a, b), v) in enumerate(zip(pairs, vals)):
            extra = ""
            if sigmas_mm is not None and sigmas_mm[i] is not None:
                extra = f' stdev="{sigmas_mm[i]:.2f}"'
            elif dists_km is not None and dists_km[i] is not None:
                extra = f' dist="{dists_km[i]:.3f}"'
            rows.append(f'<dh from="{a}" to="{b}" val="{v:.6f}"{extra} />')
        if sigmas_mm is None and dists_km is None:
            rows.append(_cov_xml(cov_mm2, n - 1))
        self.blocks.append(("height-differences", rows))

    def vectors(self, pairs, cov_blocks_mm2):
        """``<vectors>``: one 3x3 covariance (mm²) per vector, written as band 2."""
        n = 3 * len(pairs)
        C = np.zeros((n, n))
        rows = []
        for k, ((a, b), Ck) in enumerate(zip(pairs, cov_blocks_mm2)):
            C[3 * k:3 * k + 3, 3 * k:3 * k + 3] = Ck
            v = self.truth[b] - self.truth[a] + np.linalg.cholesky(Ck) @ self.rng.standard_normal(3) * 1e-3
            rows.append(f'<vec from="{a}" to="{b}" dx="{v[0]:.6f}" dy="{v[1]:.6f}" dz="{v[2]:.6f}" />')
        rows.append(_cov_xml(C, 2))
        self.blocks.append(("vectors", rows))

    def coordinates(self, spec):
        """``<coordinates>``: observed coordinates, spec = [(id, 'xyz' | 'xy' | 'z', σ mm)], diagonal."""
        rows, var = [], []
        for pid, which, sig in spec:
            t = self.truth[pid]
            v = {c: t[i] + sig * 1e-3 * self.rng.standard_normal() for i, c in enumerate("xyz") if c in which}
            rows.append(f'<point id="{pid}" ' + " ".join(f'{c}="{v[c]:.6f}"' for c in "xyz" if c in v) + " />")
            var += [sig ** 2] * len(v)
        rows.append(_cov_xml(np.diag(var), 0))
        self.blocks.append(("coordinates", rows))

    # ---------------------------------------------------------------- output
    def write(self):
        L = ['<?xml version="1.0" ?>',
             '<gama-local xmlns="http://www.gnu.org/software/gama/gama-local">',
             f'<network axes-xy="{self.axes}" angles="{self.angles}">',
             f"<description>\n{escape(self.description)}\n"
             f"Simulated by tests/data/gama3d/generate.py (truth: {self.name}_truth.csv).\n</description>",
             '<parameters sigma-apr="1" conf-pr="0.95" tol-abs="1000" sigma-act="apriori" '
             'algorithm="svd" cov-band="-1" />',
             "<points-observations>"]
        for pid, t in self.truth.items():
            a = self.approx[pid]
            if a == "none":
                xyz = ""
            else:
                p = t if a is None else t + a * self.rng.standard_normal(3) * _free_mask(self.attrs[pid])
                xyz = f' x="{p[0]:.6f}" y="{p[1]:.6f}" z="{p[2]:.6f}"'
            L.append(f'<point id="{pid}"{xyz} {self.attrs[pid]} />')
        for s in self.sets:
            dh = f' from_dh="{s["from_dh"]:.3f}"' if s["from_dh"] is not None else ""
            L.append(f'<obs from="{s["station"]}"{dh}>')
            L += ["  " + r for r in s["rows"]]
            L.append("</obs>")
        for tag, rows in self.blocks:
            L.append(f"<{tag}>")
            L += ["  " + r for r in rows]
            L.append(f"</{tag}>")
        L += ["</points-observations>", "</network>", "</gama-local>", ""]
        (HERE / f"{self.name}.xml").write_text("\n".join(L))
        with open(HERE / f"{self.name}_truth.csv", "w") as f:
            f.write("id,x_m,y_m,z_m\n")
            for pid, t in self.truth.items():
                f.write(f"{pid},{t[0]:.6f},{t[1]:.6f},{t[2]:.6f}\n")


def _free_mask(attr):
    """1 for the coordinates that are not fixed (they get perturbed approximate values)."""
    fix = re.search(r'fix="([^"]*)"', attr)
    fix = fix.group(1).lower() if fix else ""
    return np.array([0.0 if "x" in fix else 1.0, 0.0 if "y" in fix else 1.0, 0.0 if "z" in fix else 1.0])


def _cov_xml(C, band):
    """``<cov-mat>`` of C (mm²): upper band by rows, as Gama's parser reads it (``finish_cov``)."""
    n = len(C)
    vals = [C[i, j] for i in range(n) for j in range(i, min(i + band, n - 1) + 1)]
    return (f'<cov-mat dim="{n}" band="{band}">\n    '
            + " ".join(f"{v:.6g}" for v in vals) + "\n  </cov-mat>")


def _box(rng, n, lo, hi):
    return rng.uniform(lo, hi, size=(n, 3))


# ==================================================================== the networks
def two_trackers(rng):
    """1. Two levelled trackers (directions, zenith angles, slope distances) and 15 common
    targets; no control: free network, every point constrained (datum defect 4)."""
    n = Net("two_trackers", rng, "Two levelled laser trackers, 15 common targets, free network "
            "(all points adj=XYZ).", axes="en", angles="right-handed")
    n.point("T1", [0.0, 0.0, 0.0], 'adj="XYZ"', 0.003)
    n.point("T2", [6.2, 0.4, 0.15], 'adj="XYZ"', 0.003)
    for i, p in enumerate(_box(rng, 15, [-2.0, 3.0, -1.2], [8.0, 9.0, 2.5])):
        n.point(f"P{i + 1:02d}", p, 'adj="XYZ"', 0.003)
    for st in ("T1", "T2"):
        s = n.obs_set(st)
        for i in range(15):
            n.polar(s, f"P{i + 1:02d}", dist=(0.1, 1.0), dir_cc=3.0, z_cc=3.0)
    return n


def station_control(rng):
    """2. One total station, 5 fixed control points and 10 free targets (polar points, zero
    redundancy); neither the station nor the targets have approximate coordinates."""
    n = Net("station_control", rng, "One station on 5 fixed control points, 10 polar points; "
            "station and targets without approximate coordinates (Gama computes them).")
    S = np.array([1000.0, 2000.0, 300.0])
    n.point("S", S, 'adj="xyz"', "none")
    for k in range(5):
        az, r = 2 * math.pi * k / 5 + rng.uniform(-0.3, 0.3), rng.uniform(50, 150)
        n.point(f"K{k + 1}", S + [r * math.cos(az), r * math.sin(az), rng.uniform(-10, 10)], 'fix="xyz"')
    for k in range(10):
        az, r = rng.uniform(0, 2 * math.pi), rng.uniform(20, 120)
        n.point(f"Q{k + 1:02d}", S + [r * math.cos(az), r * math.sin(az), rng.uniform(-8, 8)], 'adj="xyz"', "none")
    s = n.obs_set("S")
    for pid in list(n.truth)[1:]:
        n.polar(s, pid, dist=(1.0, 1.5), dir_cc=5.0, z_cc=8.0)
    return n


def partly_fixed(rng):
    """3. Fixed (xyz), partly fixed (fix=xy with z adjusted; fix=z with xy adjusted) and weighted
    points (<coordinates>: observed xyz, observed z only) in a 4-station network."""
    n = Net("partly_fixed", rng, "Fixed, partly fixed (fix=xy adj=z, fix=z adj=xy) and weighted "
            "points (observed coordinates with covariance).")
    pts = {"A": ([0, 0, 100.0], 'fix="xyz"', None), "B": ([180, 40, 104.0], 'fix="xyz"', None),
           "C": ([60, 150, 98.5], 'fix="xy" adj="z"', None), "D": ([200, 190, 101.2], 'fix="z" adj="xy"', 0.02),
           "E": ([100, 80, 103.3], 'adj="xyz"', 0.02), "F": ([-40, 120, 99.1], 'adj="xyz"', 0.02),
           "G": ([120, -60, 102.4], 'adj="xyz"', 0.02), "H": ([250, 90, 105.0], 'adj="xyz"', 0.02),
           "J": ([30, 250, 97.0], 'adj="xyz"', 0.02)}
    for pid, (xyz, attr, ap) in pts.items():
        n.point(pid, xyz, attr, ap)
    plan = {"A": "BCEFGJ", "C": "AEFJD", "D": "BCEH", "G": "ABEH"}
    for st, targets in plan.items():
        s = n.obs_set(st)
        for t in targets:
            n.polar(s, t, dist=(1.0, 2.0), dir_cc=5.0, z_cc=10.0)
    n.coordinates([("E", "xyz", 5.0), ("F", "z", 3.0)])
    return n


def heights(rng):
    """4. Instrument and target heights: two stations on ground marks (the set-wide from_dh of
    <obs>, and from_dh per observation), targets with reflector heights (to_dh)."""
    n = Net("heights", rng, "Instrument heights (obs from_dh, and per observation) and reflector "
            "heights (to_dh) on slope distances and zenith angles.")
    n.point("K1", [0, 0, 250.0], 'fix="xyz"')
    n.point("K2", [220, 30, 256.0], 'fix="xyz"')
    n.point("K3", [90, 210, 247.5], 'fix="xyz"')
    # approximate coordinates = truth: gama-local 2.24 does not converge with from_dh/to_dh when
    # it has to iterate; then replaced by its adjusted ones until they stop changing (README.md)
    n.point("S1", [60, 70, 251.2], 'adj="xyz"', 0.0)
    n.point("S2", [160, 130, 253.9], 'adj="xyz"', 0.0)
    targets = [f"P{k}" for k in range(1, 7)]
    for t, p in zip(targets, _box(rng, 6, [20, 20, 246], [200, 200, 258])):
        n.point(t, p, 'adj="xyz"', 0.0)
    th = {t: round(rng.uniform(1.3, 2.0), 3) for t in ["K1", "K2", "K3", *targets]}
    s1 = n.obs_set("S1", from_dh=1.532)
    for t in ["K1", "K2", "K3", *targets]:
        n.polar(s1, t, dist=(1.0, 1.5), dir_cc=5.0, z_cc=8.0, to_dh=th[t])
    n.polar(s1, "S2", dist=(1.0, 1.5), dir_cc=5.0, z_cc=8.0, to_dh=1.611)
    s2 = n.obs_set("S2")
    for t in ["K1", "K2", "K3", *targets, "S1"]:
        ht = 1.498 if t == "S1" else th[t]
        n.direction(s2, t, 5.0)
        n.sdist(s2, t, 1.0, 1.5, from_dh=1.611, to_dh=ht)
        n.zangle(s2, t, 8.0, from_dh=1.611, to_dh=ht)
    return n


def traverse(rng):
    """5. A traverse between fixed points: each station observes the previous and the next one
    (mutual directions, zenith angles and slope distances), orientations to fixed points."""
    n = Net("traverse", rng, "Traverse A-T1..T5-C between fixed points, orientations to B and D; "
            "mutual observations.")
    n.point("B", [-150, 250, 310.0], 'fix="xyz"')
    n.point("A", [0, 0, 300.0], 'fix="xyz"')
    chain, p = [], np.array([0.0, 0.0, 300.0])
    for k in range(1, 6):
        az = math.radians(20 + 15 * rng.standard_normal())
        r = rng.uniform(150, 250)
        p = p + [r * math.cos(az), r * math.sin(az), rng.uniform(-6, 6)]
        n.point(f"T{k}", p.copy(), 'adj="xyz"', 0.05)
        chain.append(f"T{k}")
    az, r = math.radians(25), 200.0
    C = p + [r * math.cos(az), r * math.sin(az), 3.0]
    n.point("C", C, 'fix="xyz"')
    n.point("D", C + [100, -220, -4.0], 'fix="xyz"')
    line = ["A", *chain, "C"]
    for i, st in enumerate(line):
        s = n.obs_set(st)
        if st == "A":
            n.direction(s, "B", 5.0)
        if i > 0:
            n.polar(s, line[i - 1], dist=(2.0, 2.0), dir_cc=5.0, z_cc=10.0)
        if i < len(line) - 1:
            n.polar(s, line[i + 1], dist=(2.0, 2.0), dir_cc=5.0, z_cc=10.0)
        if st == "C":
            n.direction(s, "D", 5.0)
    return n


def direction_sets(rng):
    """6. Several direction sets on one station (three <obs from="S1">, each with its own
    orientation), a second station with one set."""
    n = Net("direction_sets", rng, "Three direction sets on station S1 (one orientation each), one on S2.")
    n.point("S1", [0, 0, 50.0], 'fix="xyz"')
    n.point("S2", [140, 20, 52.0], 'fix="xyz"')
    R = [f"R{k}" for k in range(1, 7)]
    for t, p in zip(R, _box(rng, 6, [-60, 60, 45], [200, 180, 58])):
        n.point(t, p, 'adj="xyz"', 0.02)
    s = n.obs_set("S1")
    n.direction(s, "S2", 4.0)
    for t in R:
        n.polar(s, t, dist=(1.0, 1.0), dir_cc=4.0, z_cc=8.0)
    s = n.obs_set("S1")
    for t in ["S2", *R[:4]]:
        n.direction(s, t, 4.0)
    s = n.obs_set("S1")
    for t in R[2:]:
        n.direction(s, t, 4.0)
    s = n.obs_set("S2")
    n.direction(s, "S1", 4.0)
    for t in R:
        n.polar(s, t, dist=(1.0, 1.0), dir_cc=4.0, z_cc=8.0)
    return n


def angles_hdist(rng):
    """7. Horizontal angles (<angle bs fs>) and horizontal distances (<distance>), zenith angles
    for the heights; no directions (no orientation unknowns)."""
    n = Net("angles_hdist", rng, "Horizontal angles, horizontal distances and zenith angles.")
    n.point("A", [0, 0, 20.0], 'fix="xyz"')
    n.point("B", [300, 0, 24.0], 'fix="xyz"')
    n.point("N1", [80, 120, 21.5], 'adj="xyz"', 0.03)
    n.point("N2", [220, 140, 23.0], 'adj="xyz"', 0.03)
    Q = [f"Q{k}" for k in range(1, 5)]
    for t, p in zip(Q, [[40, 260, 19.0], [170, 280, 22.0], [320, 220, 25.5], [150, 60, 21.0]]):
        n.point(t, p, 'adj="xyz"', 0.03)
    plan = {"A": ["B", "Q4", "N2", "N1", "Q1"], "B": ["N2", "Q3", "Q4", "A"],
            "N1": ["A", "Q4", "N2", "Q2", "Q1"], "N2": ["B", "Q3", "Q2", "N1", "Q4"]}
    for st, targets in plan.items():
        s = n.obs_set(st)
        for bs, fs in zip(targets[:-1], targets[1:]):
            n.angle(s, bs, fs, 5.0)
        for t in targets:
            if {st, t} != {"A", "B"}:
                n.hdist(s, t, 1.0, 1.5)
                n.zangle(s, t, 10.0)
    return n


def height_differences(rng):
    """8. Directions and slope distances for the position, levelled height differences for the
    heights: a line with stdev / dist per dh and a block with a full covariance."""
    n = Net("height_differences", rng, "Directions, slope distances and levelling (<dh>: stdev, "
            "dist, and a block with a covariance matrix).")
    n.point("A", [0, 0, 120.0], 'fix="xyz"')
    n.point("B", [400, 50, 131.0], 'fix="xyz"')
    n.point("C", [150, 300, 118.0], 'fix="xyz"')
    P = [f"L{k}" for k in range(1, 7)]
    for t, p in zip(P, [[60, 40, 121.3], [130, 80, 124.9], [200, 110, 123.1], [260, 170, 126.4],
                        [330, 120, 129.8], [250, 30, 127.2]]):
        n.point(t, p, 'adj="xyz"', 0.03)
    for st, targets in {"A": ["B", "C", "L1", "L2", "L3", "L6"], "L4": ["C", "B", "L3", "L5", "L6", "L2"]}.items():
        s = n.obs_set(st)
        for t in targets:
            n.direction(s, t, 5.0)
            n.sdist(s, t, 1.0, 1.5)
    line = ["A", *P[:5], "B"]
    pairs = list(zip(line[:-1], line[1:]))
    n.height_differences(pairs, sigmas_mm=[0.8, None, 0.7, None, 0.9, None],
                         dists_km=[None, 0.12, None, 0.2, None, 0.16])
    cov = np.array([[0.49, 0.12, 0.05], [0.12, 0.64, 0.10], [0.05, 0.10, 0.36]])
    n.height_differences([("C", "L4"), ("L4", "L6"), ("L6", "L2")], cov_mm2=cov)
    return n


def vectors(rng):
    """9. GNSS-like coordinate-difference vectors with a 3x3 covariance each (<vectors>, band 2)."""
    n = Net("vectors", rng, "Coordinate-difference vectors with their covariance, two fixed points.")
    G = [f"G{k}" for k in range(1, 9)]
    for k, (t, p) in enumerate(zip(G, _box(rng, 8, [0, 0, 200], [2000, 2000, 260]))):
        n.point(t, p, 'fix="xyz"' if k < 2 else 'adj="xyz"', None if k < 2 else 0.05)
    pairs = [("G1", "G3"), ("G1", "G4"), ("G2", "G3"), ("G2", "G5"), ("G3", "G4"), ("G3", "G6"),
             ("G4", "G7"), ("G5", "G6"), ("G5", "G8"), ("G6", "G7"), ("G6", "G8"), ("G7", "G8"),
             ("G1", "G7"), ("G2", "G8")]
    blocks = []
    for _ in pairs:
        sh, sv = rng.uniform(2.0, 3.0), rng.uniform(4.0, 6.0)
        corr = np.array([[1, 0.2, 0.3], [0.2, 1, -0.25], [0.3, -0.25, 1]])
        sd = np.array([sh, sh, sv])
        blocks.append(np.round(corr * np.outer(sd, sd), 4))
    n.vectors(pairs, blocks)
    return n


def trilateration_fixed(rng):
    """10a. Distances only: 4 fixed points (not coplanar) and 10 unknown points."""
    n = Net("trilateration_fixed", rng, "Slope distances only, 4 fixed points, 10 unknown points.",
            axes="en", angles="right-handed")
    F = {"F1": [0, 0, 0], "F2": [12, 0, 0.5], "F3": [0, 9, 1.0], "F4": [11, 10, 4.0]}
    for pid, p in F.items():
        n.point(pid, p, 'fix="xyz"')
    U = [f"U{k:02d}" for k in range(1, 11)]
    for t, p in zip(U, _box(rng, 10, [1, 1, -1], [11, 9, 3.5])):
        n.point(t, p, 'adj="xyz"', 0.005)
    for f in F:
        s = n.obs_set(f)
        for t in U:
            n.sdist(s, t, 0.1, 1.0)
    s = None
    for i, a in enumerate(U):
        s = n.obs_set(a)
        for b in U[i + 1:i + 3]:
            n.sdist(s, b, 0.1, 1.0)
    n.sets = [x for x in n.sets if x["rows"]]
    return n


def trilateration_free(rng):
    """10b. Distances only, free network: every point constrained (adj=XYZ, datum defect 6)."""
    n = Net("trilateration_free", rng, "Slope distances only, free network (all points adj=XYZ).",
            axes="en", angles="right-handed")
    V = [f"V{k:02d}" for k in range(1, 13)]
    for t, p in zip(V, _box(rng, 12, [0, 0, 0], [15, 10, 4])):
        n.point(t, p, 'adj="XYZ"', 0.005)
    pairs = [(a, b) for i, a in enumerate(V) for b in V[i + 1:]]
    keep = rng.permutation(len(pairs))[:48]
    by = {}
    for k in sorted(keep):
        a, b = pairs[k]
        by.setdefault(a, []).append(b)
    for a, bs in by.items():
        s = n.obs_set(a)
        for b in bs:
            n.sdist(s, b, 0.1, 1.0)
    return n


NETWORKS = [two_trackers, station_control, partly_fixed, heights, traverse, direction_sets,
            angles_hdist, height_differences, vectors, trilateration_fixed, trilateration_free]


def approx_from(name):
    """Replace the approximate coordinates of NAME.xml's adjusted points by the adjusted ones of
    NAME_out.xml (10 decimals): a step of the manual iteration of README.md "heights"."""
    import xml.etree.ElementTree as ET
    out = ET.parse(HERE / f"{name}_out.xml").getroot()
    ns = "{http://www.gnu.org/software/gama/gama-local-adjustment}"
    adj = {}
    for p in out.find(f"{ns}coordinates/{ns}adjusted"):
        adj[p.find(f"{ns}id").text.strip()] = {c.tag[len(ns):].lower(): float(c.text) for c in p
                                                if c.tag[len(ns):].lower() in ("x", "y", "z")}
    text = (HERE / f"{name}.xml").read_text()

    def repl(m):
        pid, c = m.group(1), adj.get(m.group(1), {})
        if set(c) != {"x", "y", "z"}:
            return m.group(0)
        return f'<point id="{pid}" x="{c["x"]:.10f}" y="{c["y"]:.10f}" z="{c["z"]:.10f}" '
    (HERE / f"{name}.xml").write_text(
        re.sub(r'<point id="([^"]+)" x="[^"]*" y="[^"]*" z="[^"]*" ', repl, text))


def main(argv):
    if argv[:1] == ["--approx-from"]:
        approx_from(argv[1])
        return
    for k, make in enumerate(NETWORKS):
        make(np.random.default_rng(SEED + k)).write()


if __name__ == "__main__":
    import sys
    main(sys.argv[1:])
