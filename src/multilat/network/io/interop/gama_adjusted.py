"""GNU Gama: gama-local's adjusted XML output (``gama-local IN.xml --xml OUT.xml``), read into
multilat's terms (metres, radians, multilat's axes).

Adjusted output (``gama-local --xml``; schema ``xml/gama-local-adjustment.xsd``): adjusted and
fixed coordinates, degrees of freedom, a-priori and a-posteriori reference standard deviations and
per observation ``<slope-distance>`` with ``obs``, ``adj`` (m), ``stdev`` (mm, of the adjusted
observation), ``qrr`` (redundancy number) and ``std-residual``: :func:`read_gama_adjustment`.

Directions and zenith angles (``<direction>``, ``<zenith-angle>``: gon, σ in cc) and the
orientations of the direction sets (``<orientation-shifts>``) are read as :class:`GamaAngles` and
``GamaAdjustment.orientation_rad`` (docs/interop.md "Angles"), in the sign convention of
:func:`.gama.read_gama_local`: a direction is an azimuth (counter-clockwise seen from above) as it
stands under ``angles="right-handed"`` and negated under ``left-handed``; an orientation is
multilat's heading κ of the station (``azimuth = atan2(north, east) - κ``).

**The frames Gama writes in** (GNU Gama 2.24 sources, ``lib/gnu_gama/xml/localnetworkxml.cpp``,
``LocalNetworkXML::coordinates`` and ``orientation_shifts``; ``lib/gnu_gama/local/network.cpp``,
``consistent``, ``y_sign``, ``change_y_signs_for_inconsistent_system_``): when the handedness of
``axes-xy`` (``en``, ``nw``, ``se``, ``ws`` right-handed; ``ne``, ``sw``, ``es``, ``wn``
left-handed) differs from ``angles``, gama-local negates every y internally and adjusts in those
axes. It prints the coordinates with y multiplied back by ``y_sign`` (-1 then) and the orientations
multiplied by ``y_sign``, but ``<cov-mat>`` is ``m0² qxx`` of the internal unknowns as they stand:
its x-y and y-z cross-covariances carry the internal sign. :func:`_covariance` therefore reads the
matrix in the internal axes, then turns it to the printed ones and to multilat's.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.data import Points
from multilat.inputs import finite_number
from multilat.network.io.interop.common import parse_xml
from multilat.network.io.interop.gama import GON_PER_RAD, _axes, _to_enu

__all__ = ["read_gama_adjustment", "GamaAdjustment", "GamaAngles", "OUT_NAMESPACE"]

OUT_NAMESPACE = "http://www.gnu.org/software/gama/gama-local-adjustment"


@dataclass(frozen=True, eq=False)
class GamaAngles:
    """gama-local's adjusted directions and zenith angles, in multilat's terms (radians).

    kind : tuple of str  "azimuth" (a ``<direction>`` read as an azimuth: counter-clockwise seen from
        above, so negated under ``angles="left-handed"``, as :func:`.gama.read_gama_local` reads it) or
        "zenith" (a ``<zenith-angle>``)
    station, target : tuple of str
    observed_rad, adjusted_rad : ndarray  the observed and adjusted values (gon -> rad)
    adjusted_std_rad : ndarray  σ of the adjusted observation (cc -> rad)
    residual_cofactor_rad2 : ndarray  Gama's ``qrr`` (cc² -> rad²)
    control_percent, std_residual : ndarray  as for the distances
    sigma_ratio : float  Gama's ``sigma-apr`` over the reference deviation it used (``<used>``):
        σ_adj = sigma_ratio⁻¹ · sqrt(1 - r) · σ (see :meth:`GamaAdjustment.redundancy_from_sigma`)
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
    sigma_ratio: float = 1.0

    @property
    def residual_rad(self) -> np.ndarray:
        """Observed minus adjusted, wrapped to ``[-pi, pi)``."""
        return (self.observed_rad - self.adjusted_rad + np.pi) % (2 * np.pi) - np.pi

    def redundancy_from_sigma(self, sigma_rad) -> np.ndarray:
        """Redundancy numbers from each angle's a-priori σ (rad), as for the distances
        (:meth:`GamaAdjustment.redundancy_from_sigma`)."""
        return 1.0 - (self.sigma_ratio * self.adjusted_std_rad / np.asarray(sigma_rad, float)) ** 2


@dataclass(frozen=True, eq=False)
class GamaAdjustment:
    """What multilat reads from gama-local's XML output (SI units; coordinates in multilat's axes).

    ids, xyz_m : adjusted and fixed points ; fixed : ids of the fixed ones
    dof, defect : degrees of freedom and network defect ; sum_of_squares : vᵀPv (Gama's units)
    sigma_apriori, sigma_aposteriori : reference standard deviations (Gama's ``sigma-apr``, and σ0)
    sigma_used : which of them gama-local scaled its σ and covariances with (``sigma-act``)
    adjusted_ids : the adjusted points, in the order of the rows of ``covariance_m2``
    covariance_m2 : (3a, 3a) covariance of their x, y, z (multilat's axes), m², scaled by Gama's
        ``sigma_used`` reference deviation ("apriori" in multilat's export); None when Gama wrote
        only a band of it
    station, target : per slope distance ; observed_m, adjusted_m ; residual_m = observed - adjusted
    adjusted_std_m : standard deviation of the adjusted distance
    residual_cofactor_mm2 : Gama's ``qrr``, the weight coefficient of the residual (mm² with
        sigma-apr = 1; printed with 3 decimals, so 0.000 for µm-level σ: not the redundancy number)
    control_percent : Gama's ``f = 100 (1 - sqrt(1 - r))`` (Charamza; independent of ``sigma-act``),
        so the redundancy number is ``r = 1 - (1 - f/100)²`` (:attr:`redundancy`), or better from
        σ_adj and the inputs' σ (:meth:`redundancy_from_sigma`, which honours ``sigma-act`` and
        ``sigma-apr``)
    std_residual : Gama's studentised residual ``|v| / (m0 √qrr)`` (NaN where Gama prints none:
        f < 0.1 %)
    angles : :class:`GamaAngles` or None
    orientation_rad, orientation_std_rad : per station with directions, its heading κ
        (``azimuth = atan2(north, east) - κ``, wrapped to [-π, π)) from Gama's orientation, and its σ
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
        """Redundancy numbers from the a-priori σ of each distance (m).

        gama-local prints σ_adj = (m0/σ_apr)·sqrt(q)·σ with q = 1 - r the weighted hat diagonal,
        σ_apr its ``sigma-apr`` and m0 the reference deviation it used (``sigma-act``: σ_apr itself
        for ``apriori``, the a-posteriori σ0 for ``aposteriori``; Gama 2.24 ``network.cpp``, where
        ``sigma_L`` is computed), so ``r = 1 - (σ_apr σ_adj / (m0 σ))²``."""
        return 1.0 - (self.sigma_ratio * self.adjusted_std_m / np.asarray(sigma_m, float)) ** 2

    @property
    def sigma_ratio(self) -> float:
        """``sigma-apr`` over the reference deviation gama-local used (1 for ``apriori``)."""
        return _sigma_ratio(self.sigma_used, self.sigma_apriori, self.sigma_aposteriori)

    @property
    def residual_m(self) -> np.ndarray:
        return self.observed_m - self.adjusted_m

    def points(self) -> Points:
        return Points(self.ids, self.xyz_m)


def _float(path, node, what) -> float:
    """The text of ``node`` as a finite float (NaN and infinities refused, ``FILE:LINE``)."""
    return finite_number((node.text or "").strip(), f"{path}:{node.line}: {what}")


def _num(path, node, tag, *, integer=False):
    c = node.find(tag) if node is not None else None
    if c is None:
        where = node.line if node is not None else 1
        raise MultilatError(f"{path}:{where}: missing <{tag}> in gama-local's output")
    if not integer:
        return _float(path, c, f"<{tag}>")
    try:
        return int(c.text.strip())
    except ValueError:
        raise MultilatError(f"{path}:{c.line}: <{tag}> {c.text.strip()!r} is not a number") from None


def _sigma_ratio(used: str, apriori: float, aposteriori: float) -> float:
    if used == "aposteriori":
        return apriori / aposteriori if aposteriori > 0 else math.nan
    return 1.0


def _frame(path, gp, root):
    """The printed axes (``ex``, ``ey``: Gama's x and y in east/north), the sign of the directions
    as azimuths (+1 right-handed, -1 left-handed), the sign of the printed orientations as headings
    (+1 when the printed axes are right-handed) with the heading of Gama's x axis, and ``y_sign``
    (-1 when the axes and the angles differ in handedness: see the module docstring)."""
    ex, ey = _axes(path, gp or root, gp.attrib.get("axes-xy") if gp is not None else None)
    sense = (gp.attrib.get("angles", "left-handed") if gp is not None else "left-handed").strip()
    if sense not in ("left-handed", "right-handed"):
        raise MultilatError(f"{path}:{(gp or root).line}: angles={sense!r} must be left-handed or right-handed")
    right_axes = ex[0] * ey[1] - ex[1] * ey[0] > 0
    right_angles = sense == "right-handed"
    return (ex, ey, 1.0 if right_angles else -1.0, 1.0 if right_axes else -1.0,
            math.atan2(ex[1], ex[0]), 1.0 if right_axes == right_angles else -1.0)


def read_gama_adjustment(path) -> GamaAdjustment:
    """Read gama-local's adjusted XML output (``gama-local IN.xml --xml OUT.xml``).

    Slope distances, directions and zenith angles (:class:`GamaAngles`) are read, other observation
    kinds are refused with the kind named; a value that is not a finite number (NaN, inf) is refused
    with ``FILE:LINE``; an error document (``<error>``) is reported with Gama's message."""
    root = parse_xml(path)
    if root.tag != "gama-local-adjustment":
        raise MultilatError(f"{path}:{root.line}: expected a <gama-local-adjustment> document, found "
                            f"<{root.tag}>")
    err = root.find("error")
    if err is not None:
        msg = re.sub(r"\s+", " ", " ".join(d.text.strip() for d in err.findall("description")))
        where = err.child_text("lineNumber")
        raise MultilatError(f"{path}:{err.line}: gama-local reported an error: {msg}"
                            + (f" (line {where} of its input)" if where else ""))
    gp = root.find("network-general-parameters")
    ex, ey, az_sign, kappa_sign, kappa_x, y_sign = _frame(path, gp, root)
    summ = root.find("network-processing-summary")
    eq = summ.find("project-equations") if summ is not None else None
    sd = summ.find("standard-deviation") if summ is not None else None
    coords = root.find("coordinates")
    if coords is None:
        raise MultilatError(f"{path}:{root.line}: no <coordinates> in gama-local's output")
    ids, xyz, fixed = _points(path, coords, ex, ey)
    adjusted_ids = tuple(i for i in ids if i not in fixed)
    orient = {k: (kappa_x + kappa_sign * v + math.pi) % (2 * math.pi) - math.pi
              for k, v in _orientations(path, coords.find("orientation-shifts")).items()}
    cov, orient_var = _covariance(path, coords.find("cov-mat"), len(adjusted_ids), len(orient), ex, ey, y_sign)
    orient_std = {} if orient_var is None else {k: float(np.sqrt(v)) for k, v in zip(orient, orient_var)}
    sigma_apr, sigma_post = _num(path, sd, "apriori"), _num(path, sd, "aposteriori")
    used = sd.child_text("used", "") if sd is not None else ""
    obs_node = root.find("observations")
    rows, arows = [], []
    for o in (obs_node.children if obs_node is not None else []):
        w = _num(path, o, "std-residual") if o.find("std-residual") is not None else math.nan
        if o.tag in _ANGLE_KINDS:
            sign = az_sign if o.tag == "direction" else 1.0
            arows.append((_ANGLE_KINDS[o.tag], o.child_text("from"), o.child_text("to"),
                          sign * _num(path, o, "obs") / GON_PER_RAD, sign * _num(path, o, "adj") / GON_PER_RAD,
                          _num(path, o, "stdev") / (GON_PER_RAD * 1e4),
                          _num(path, o, "qrr") / (GON_PER_RAD * 1e4) ** 2, _num(path, o, "f"), w))
            continue
        if o.tag != "slope-distance":
            raise MultilatError(f"{path}:{o.line}: <{o.tag}> observations are not supported: "
                                "multilat reads slope distances, directions and zenith angles")
        rows.append((o.child_text("from"), o.child_text("to"), _num(path, o, "obs"),
                     _num(path, o, "adj"), _num(path, o, "stdev") * 1e-3, _num(path, o, "qrr"), _num(path, o, "f"), w))
    if not rows:
        raise MultilatError(f"{path}: no slope distances in gama-local's output")
    col = list(zip(*rows))
    return GamaAdjustment(tuple(ids), np.array(xyz).reshape(-1, 3), tuple(fixed),
                          _num(path, eq, "degrees-of-freedom", integer=True),
                          _num(path, eq, "defect", integer=True), _num(path, eq, "sum-of-squares"),
                          sigma_apr, sigma_post,
                          tuple(col[0]), tuple(col[1]), np.array(col[2]), np.array(col[3]),
                          np.array(col[4]), np.array(col[5]), np.array(col[6]), np.array(col[7]),
                          adjusted_ids, cov, used, _angles(arows, _sigma_ratio(used, sigma_apr, sigma_post)),
                          orient, orient_std)


def _points(path, coords, ex, ey):
    """Fixed and adjusted points (multilat's axes)."""
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
                vals.append(_float(path, v, f"<{v.tag}> of point {pid!r}"))
            ids.append(pid)
            xyz.append(_to_enu(vals, ex, ey))
            if part == "fixed":
                fixed.append(pid)
    return ids, xyz, fixed


_ANGLE_KINDS = {"direction": "azimuth", "zenith-angle": "zenith"}


def _angles(rows, ratio) -> GamaAngles | None:
    if not rows:
        return None
    c = list(zip(*rows))
    return GamaAngles(tuple(c[0]), tuple(c[1]), tuple(c[2]), *(np.array(v, float) for v in c[3:]), sigma_ratio=ratio)


def _orientations(path, node) -> dict:
    """``<orientation-shifts>``: each station's adjusted orientation as Gama prints it (gon -> rad).

    A station with several direction sets (several orientations) is refused by ``FILE:LINE``, as
    ``import gama`` refuses it: multilat has one orientation per station, and keying them by
    station would keep the last and misalign the covariance's orientation rows."""
    out, first = {}, {}
    for o in (node.findall("orientation") if node is not None else []):
        sid = o.child_text("id")
        if sid in out:
            raise MultilatError(f"{path}:{o.line}: station {sid!r} has a second orientation (the first at line "
                                f"{first[sid]}): several direction sets on one station; multilat has one per "
                                "station")
        out[sid], first[sid] = _num(path, o, "adj") / GON_PER_RAD, o.line
    return out


def _covariance(path, cm, n_points, n_orient, ex, ey, y_sign):
    """The full covariance of the adjusted x, y, z (m², multilat's axes) from ``<cov-mat>`` (mm²,
    upper band by rows, in gama-local's internal axes: y negated when ``y_sign`` is -1) and the
    variances of the orientations that follow them (cc² -> rad²); (None, None) when Gama wrote only
    a band."""
    if cm is None:
        return None, None
    dim, band = _num(path, cm, "dim", integer=True), _num(path, cm, "band", integer=True)
    if dim != 3 * n_points + n_orient or band < dim - 1:
        return None, None
    vals = [_float(path, f, "<flt>") for f in cm.findall("flt")]
    if len(vals) != dim * (dim + 1) // 2:
        raise MultilatError(f"{path}:{cm.line}: <cov-mat> holds {len(vals)} values, expected "
                            f"{dim * (dim + 1) // 2} for dim {dim}")
    C = np.zeros((dim, dim))
    C[np.triu_indices(dim)] = vals
    C = C + np.triu(C, 1).T
    # internal (x, y_sign·y, z) -> printed (x, y, z) -> multilat's (east, north, up)
    R = np.array([[ex[0], ey[0], 0.0], [ex[1], ey[1], 0.0], [0.0, 0.0, 1.0]]) @ np.diag([1.0, y_sign, 1.0])
    T = np.kron(np.eye(n_points), R)
    k = 3 * n_points
    return T @ C[:k, :k] @ T.T * 1e-6, np.diag(C)[k:] / (GON_PER_RAD * 1e4) ** 2
