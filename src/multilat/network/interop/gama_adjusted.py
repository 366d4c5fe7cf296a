"""GNU Gama: gama-local's adjusted XML output (``gama-local IN.xml --xml OUT.xml``), read into
multilat's terms (metres, radians, multilat's axes).

Adjusted output (``gama-local --xml``; schema ``xml/gama-local-adjustment.xsd``): adjusted and
fixed coordinates, degrees of freedom, a-priori and a-posteriori reference standard deviations and
per observation ``<slope-distance>`` with ``obs``, ``adj`` (m), ``stdev`` (mm, of the adjusted
observation), ``qrr`` (redundancy number) and ``std-residual``: :func:`read_gama_adjustment`.

Directions and zenith angles (``<direction>``, ``<zenith-angle>``: gon, σ in cc) and the
orientations of the direction sets (``<orientation-shifts>``) are read as :class:`GamaAngles` and
``GamaAdjustment.orientation_rad`` (docs/interop.md "Angles").
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from multilat.errors import MultilatError
from multilat.network.data import Points
from multilat.network.interop.common import parse_xml
from multilat.network.interop.gama import GON_PER_RAD, _axes, _to_enu

__all__ = ["read_gama_adjustment", "GamaAdjustment", "GamaAngles", "OUT_NAMESPACE"]

OUT_NAMESPACE = "http://www.gnu.org/software/gama/gama-local-adjustment"


@dataclass(frozen=True, eq=False)
class GamaAngles:
    """gama-local's adjusted directions and zenith angles, in multilat's terms (radians).

    kind : tuple of str  "azimuth" (a ``<direction>``, counter-clockwise under ``angles="right-handed"``)
        or "zenith" (a ``<zenith-angle>``)
    station, target : tuple of str
    observed_rad, adjusted_rad : ndarray  the observed and adjusted values (gon -> rad)
    adjusted_std_rad : ndarray  σ of the adjusted observation (cc -> rad)
    residual_cofactor_rad2 : ndarray  Gama's ``qrr`` (cc² -> rad²)
    control_percent, std_residual : ndarray  as for the distances
    """

    kind: tuple
    station: tuple
    target: tuple
    observed_rad: np.ndarray
    adjusted_rad: np.ndarray
    adjusted_std_rad: np.ndarray
    residual_cofactor_rad2: np.ndarray
    control_percent: np.ndarray
    std_residual: np.ndarray

    @property
    def residual_rad(self) -> np.ndarray:
        """Observed minus adjusted, wrapped to ``[-pi, pi)``."""
        return (self.observed_rad - self.adjusted_rad + np.pi) % (2 * np.pi) - np.pi

    def redundancy_from_sigma(self, sigma_rad) -> np.ndarray:
        """Redundancy numbers ``1 - (σ_adj/σ)²`` from each angle's a-priori σ (rad)."""
        return 1.0 - (self.adjusted_std_rad / np.asarray(sigma_rad, float)) ** 2


@dataclass(frozen=True, eq=False)
class GamaAdjustment:
    """What multilat reads from gama-local's XML output (SI units; coordinates in multilat's axes).

    ids, xyz_m : adjusted and fixed points ; fixed : ids of the fixed ones
    dof, defect : degrees of freedom and network defect ; sum_of_squares : vᵀPv (Gama's units)
    sigma_apriori, sigma_aposteriori : reference standard deviations (Gama's units, sigma-apr = 1)
    adjusted_ids : the adjusted points, in the order of the rows of ``covariance_m2``
    covariance_m2 : (3a, 3a) covariance of their x, y, z (multilat's axes), m², scaled by Gama's
        ``sigma_used`` reference deviation ("apriori" in multilat's export); None when Gama wrote
        only a band of it
    station, target : per slope distance ; observed_m, adjusted_m ; residual_m = observed - adjusted
    adjusted_std_m : standard deviation of the adjusted distance
    residual_cofactor_mm2 : Gama's ``qrr``, the weight coefficient of the residual (mm² with
        sigma-apr = 1; printed with 3 decimals, so 0.000 for µm-level σ: not the redundancy number)
    control_percent : Gama's ``f = 100 (σ - σ_adj) / σ`` (Charamza), so the redundancy number is
        ``r = 1 - (1 - f/100)²`` (:attr:`redundancy`), or better ``1 - (σ_adj/σ)²`` from the inputs'
        σ (:meth:`redundancy_from_sigma`)
    std_residual : Gama's studentised residual ``|v| / (m0 √qrr)`` (NaN where Gama prints none:
        f < 0.1 %)
    """

    ids: tuple
    xyz_m: np.ndarray
    fixed: tuple
    dof: int
    defect: int
    sum_of_squares: float
    sigma_apriori: float
    sigma_aposteriori: float
    station: tuple
    target: tuple
    observed_m: np.ndarray
    adjusted_m: np.ndarray
    adjusted_std_m: np.ndarray
    residual_cofactor_mm2: np.ndarray
    control_percent: np.ndarray
    std_residual: np.ndarray
    adjusted_ids: tuple = ()
    covariance_m2: np.ndarray | None = None
    sigma_used: str = ""
    angles: "GamaAngles | None" = None
    orientation_rad: dict = field(default_factory=dict)
    orientation_std_rad: dict = field(default_factory=dict)

    def interpoint_distance_std_m(self, a: str, b: str) -> float:
        """Standard deviation of the distance between adjusted points ``a`` and ``b`` from Gama's
        covariance of the adjusted coordinates (needs its full band: ``cov-band="-1"``)."""
        if self.covariance_m2 is None:
            raise MultilatError("gama-local's output has no full covariance (run it with "
                                "--cov-band -1 or cov-band=\"-1\" in <parameters>)")
        rows = []
        for p in (a, b):
            if p not in self.adjusted_ids:
                raise MultilatError(f"point {p!r} is not an adjusted point of gama-local's output")
            i = self.adjusted_ids.index(p)
            rows += [3 * i, 3 * i + 1, 3 * i + 2]
        P = dict(zip(self.ids, self.xyz_m))
        d = P[a] - P[b]
        g = np.concatenate([d, -d]) / np.linalg.norm(d)
        return float(np.sqrt(max(g @ self.covariance_m2[np.ix_(rows, rows)] @ g, 0.0)))

    @property
    def redundancy(self) -> np.ndarray:
        """Redundancy numbers from Gama's ``f`` (3 decimals of a percent: ±2e-5)."""
        return 1.0 - (1.0 - self.control_percent / 100.0) ** 2

    def redundancy_from_sigma(self, sigma_m) -> np.ndarray:
        """Redundancy numbers ``1 - (σ_adj/σ)²`` from the a-priori σ of each distance (m)."""
        return 1.0 - (self.adjusted_std_m / np.asarray(sigma_m, float)) ** 2

    @property
    def residual_m(self) -> np.ndarray:
        return self.observed_m - self.adjusted_m

    def points(self) -> Points:
        return Points(self.ids, self.xyz_m)


def _num(path, node, tag, *, integer=False):
    c = node.find(tag) if node is not None else None
    if c is None:
        where = node.line if node is not None else 1
        raise MultilatError(f"{path}:{where}: missing <{tag}> in gama-local's output")
    try:
        v = int(c.text.strip()) if integer else float(c.text.strip())
    except ValueError:
        raise MultilatError(f"{path}:{c.line}: <{tag}> {c.text.strip()!r} is not a number") from None
    if not integer and not math.isfinite(v):
        raise MultilatError(f"{path}:{c.line}: <{tag}> is not finite")
    return v


def read_gama_adjustment(path) -> GamaAdjustment:
    """Read gama-local's adjusted XML output (``gama-local IN.xml --xml OUT.xml``).

    Slope distances, directions and zenith angles (:class:`GamaAngles`) are read, other observation
    kinds are refused with the kind named; an error
    document (``<error>``) is reported with Gama's message."""
    root = parse_xml(path)
    if root.tag != "gama-local-adjustment":
        raise MultilatError(f"{path}:{root.line}: expected a <gama-local-adjustment> document, found "
                            f"<{root.tag}>")
    err = root.find("error")
    if err is not None:
        msg = re.sub(r"\s+", " ", err.child_text("description", "") or "")
        raise MultilatError(f"{path}:{err.line}: gama-local reported an error: {msg}")
    gp = root.find("network-general-parameters")
    ex, ey = _axes(path, gp or root, gp.attrib.get("axes-xy") if gp is not None else None)
    summ = root.find("network-processing-summary")
    eq = summ.find("project-equations") if summ is not None else None
    sd = summ.find("standard-deviation") if summ is not None else None
    coords = root.find("coordinates")
    if coords is None:
        raise MultilatError(f"{path}:{root.line}: no <coordinates> in gama-local's output")
    ids, xyz, fixed = [], [], []
    for part in ("fixed", "adjusted"):
        sec = coords.find(part)
        for p in (sec.findall("point") if sec is not None else []):
            pid = p.child_text("id")
            vals = []
            for c in ("x", "y", "z"):
                v = p.find(c) or p.find(c.upper())
                if v is None:
                    raise MultilatError(f"{path}:{p.line}: point {pid!r} has no {c} (a 3D network "
                                        "is expected)")
                try:
                    vals.append(float(v.text))
                except ValueError:
                    raise MultilatError(f"{path}:{v.line}: {c} of {pid!r} is not a number") from None
            ids.append(pid)
            xyz.append(_to_enu(vals, ex, ey))
            if part == "fixed":
                fixed.append(pid)
    adjusted_ids = tuple(i for i in ids if i not in fixed)
    orient, orient_std = _orientations(path, coords.find("orientation-shifts"))
    cov, orient_var = _covariance(path, coords.find("cov-mat"), len(adjusted_ids), len(orient), ex, ey)
    if orient_var is not None:
        orient_std = {k: float(np.sqrt(v)) for k, v in zip(orient, orient_var)}
    obs_node = root.find("observations")
    rows, arows = [], []
    for o in (obs_node.children if obs_node is not None else []):
        if o.tag in _ANGLE_KINDS:
            arows.append((_ANGLE_KINDS[o.tag], o.child_text("from"), o.child_text("to"),
                          _num(path, o, "obs") / GON_PER_RAD, _num(path, o, "adj") / GON_PER_RAD,
                          _num(path, o, "stdev") / (GON_PER_RAD * 1e4),
                          _num(path, o, "qrr") / (GON_PER_RAD * 1e4) ** 2, _num(path, o, "f"),
                          _num(path, o, "std-residual") if o.find("std-residual") else math.nan))
            continue
        if o.tag != "slope-distance":
            raise MultilatError(f"{path}:{o.line}: <{o.tag}> observations are not supported: "
                                "multilat reads slope distances, directions and zenith angles")
        rows.append((o.child_text("from"), o.child_text("to"), _num(path, o, "obs"),
                     _num(path, o, "adj"), _num(path, o, "stdev") * 1e-3, _num(path, o, "qrr"), _num(path, o, "f"),
                     _num(path, o, "std-residual") if o.find("std-residual") else math.nan))
    if not rows:
        raise MultilatError(f"{path}: no slope distances in gama-local's output")
    col = list(zip(*rows))
    return GamaAdjustment(tuple(ids), np.array(xyz).reshape(-1, 3), tuple(fixed),
                          _num(path, eq, "degrees-of-freedom", integer=True),
                          _num(path, eq, "defect", integer=True), _num(path, eq, "sum-of-squares"),
                          _num(path, sd, "apriori"), _num(path, sd, "aposteriori"),
                          tuple(col[0]), tuple(col[1]), np.array(col[2]), np.array(col[3]),
                          np.array(col[4]), np.array(col[5]), np.array(col[6]), np.array(col[7]),
                          adjusted_ids, cov, (sd.child_text("used", "") if sd is not None else ""),
                          _angles(arows), orient, orient_std)


_ANGLE_KINDS = {"direction": "azimuth", "zenith-angle": "zenith"}


def _angles(rows) -> GamaAngles | None:
    if not rows:
        return None
    c = list(zip(*rows))
    return GamaAngles(tuple(c[0]), tuple(c[1]), tuple(c[2]), *(np.array(v, float) for v in c[3:]))


def _orientations(path, node) -> tuple[dict, dict]:
    """``<orientation-shifts>``: each station's adjusted orientation of its directions (gon -> rad);
    its σ comes from the covariance (empty here)."""
    out = {}
    for o in (node.findall("orientation") if node is not None else []):
        out[o.child_text("id")] = _num(path, o, "adj") / GON_PER_RAD
    return out, {}


def _covariance(path, cm, n_points, n_orient, ex, ey):
    """The full covariance of the adjusted x, y, z (m², multilat's axes) from ``<cov-mat>`` (mm²,
    upper band by rows) and the variances of the orientations that follow them (cc² -> rad²);
    (None, None) when Gama wrote only a band."""
    if cm is None:
        return None, None
    dim, band = _num(path, cm, "dim", integer=True), _num(path, cm, "band", integer=True)
    if dim != 3 * n_points + n_orient or band < dim - 1:
        return None, None
    vals = []
    for f in cm.findall("flt"):
        try:
            vals.append(float(f.text))
        except ValueError:
            raise MultilatError(f"{path}:{f.line}: <flt> {f.text.strip()!r} is not a number") from None
    if len(vals) != dim * (dim + 1) // 2:
        raise MultilatError(f"{path}:{cm.line}: <cov-mat> holds {len(vals)} values, expected "
                            f"{dim * (dim + 1) // 2} for dim {dim}")
    C = np.zeros((dim, dim))
    C[np.triu_indices(dim)] = vals
    C = C + np.triu(C, 1).T
    R = np.array([[ex[0], ey[0], 0.0], [ex[1], ey[1], 0.0], [0.0, 0.0, 1.0]])
    T = np.kron(np.eye(n_points), R)
    k = 3 * n_points
    return T @ C[:k, :k] @ T.T * 1e-6, np.diag(C)[k:] / (GON_PER_RAD * 1e4) ** 2
