"""Pre-analysis of a multilateration layout: the covariance, redundancy numbers and minimal
detectable biases that :func:`multilat.network.adjust.distance.adjust.adjust` would report for error-free distances,
computed from the geometry alone (no measurements).

For exact distances the residuals are zero, so the adjustment's covariance is the (datum-transformed)
inverse of its normal matrix at the true geometry. The pre-analysis asks the adjustment's own layer
for it (:func:`multilat.network.design.blocked.blocked_covariance`: the model's Jacobian, the solve's
reduced normal equations, :class:`~multilat.network.adjust.covariance.NetworkCovariance` in the datum of
:mod:`multilat.network.model.datum`), in the adjustment's parameter layout
(:meth:`~multilat.network.model.parameter_layout.ParameterLayout.adjustment`: ``[x, y, z, offset,
scale]`` per station then ``x, y, z`` per target; scales are never estimated, offsets optionally),
through one of the back ends of :mod:`.backends`: ``dense`` (the whole matrix, up to
:data:`~.backends.DENSE_MAX_PARAMS` parameters) or ``blocked`` (the Schur form, larger layouts); the
criteria of a search through :func:`criterion_value` (the ``fast`` back end by default).

Units: metres, m²; ``sigma`` is the standard uncertainty of one distance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust import statistics as st
from multilat.network.design.backends import (CRITERIA, DENSE_MAX_PARAMS, DesignBackend, choose_backend, criterion,
                                              make_backend, target_criterion, u95_max_m)
from multilat.network.design.blocked import external_reliability_m
from multilat.network.model.data import Observations
from multilat.network.model.datum import Datum, parse_datum
from multilat.network.model.distance import line_of_sight, range_m
from multilat.network.model.parameter_layout import XYZ, ParameterLayout

__all__ = ["Layout", "SigmaModel", "design_head_names", "PreAnalysis", "preanalyse", "covariance", "CRITERIA",
           "criterion_value", "target_criterion", "layout_observations", "probe_cov_m2", "DENSE_MAX_PARAMS"]


# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Layout:
    """Stations (heads), targets and which head sees which target.

    Attributes
    ----------
    station_ids : tuple of str, length s
    station_xyz_m : ndarray (s, 3)
    target_ids : tuple of str, length t
    target_xyz_m : ndarray (t, 3)
    visible : ndarray of bool (s, t), optional
        True where the head measures the target (default: every pair).
    """

    station_ids: tuple
    station_xyz_m: np.ndarray
    target_ids: tuple
    target_xyz_m: np.ndarray
    visible: np.ndarray | None = None

    def __post_init__(self):
        sid = tuple(str(x) for x in self.station_ids)
        tid = tuple(str(x) for x in self.target_ids)
        sx = np.array(self.station_xyz_m, float).reshape(-1, 3)
        tx = np.array(self.target_xyz_m, float).reshape(-1, 3)
        if sx.shape[0] != len(sid) or tx.shape[0] != len(tid):
            raise MultilatError("layout: ids and coordinates differ in number")
        if not (np.all(np.isfinite(sx)) and np.all(np.isfinite(tx))):
            raise MultilatError("layout: coordinates must be finite")
        if len(set(sid + tid)) != len(sid) + len(tid):
            raise MultilatError("layout: station and target ids must be unique")
        vis = np.ones((len(sid), len(tid)), bool) if self.visible is None else \
            np.array(self.visible, bool)
        if vis.shape != (len(sid), len(tid)):
            raise MultilatError(f"layout: visible must have shape ({len(sid)}, {len(tid)})")
        for k, v in (("station_ids", sid), ("target_ids", tid), ("station_xyz_m", sx),
                     ("target_xyz_m", tx), ("visible", vis)):
            object.__setattr__(self, k, v)

    @property
    def n_stations(self) -> int:
        return len(self.station_ids)

    @property
    def n_targets(self) -> int:
        return len(self.target_ids)

    def with_stations(self, station_xyz_m) -> "Layout":
        return Layout(self.station_ids, station_xyz_m, self.target_ids, self.target_xyz_m, self.visible)

    def pairs(self):
        """Station and target index of every observation (station-major), ``(si, ti)``."""
        si, ti = np.nonzero(self.visible)
        return si.astype(np.intp), ti.astype(np.intp)


class SigmaModel:
    """Standard uncertainty of a distance: a constant ``sigma_m``, or the instrument's distance model
    (:func:`multilat.budget.distance_std_m`, tabulated once per head on a log grid of distances from
    0.01 m to ``max_distance_m`` and interpolated: relative error below 1e-6 of the model, whose own
    Monte Carlo precision is ~0.3 %).

    The instrument head of a station (:meth:`head_of`): ``station_heads[id]`` when given (a chosen
    candidate position: the design head it holds), else the station id when the instrument has a
    head of that name, else head ``"A"`` (or ``[heads.default]``); an instrument with neither
    refuses the station by name.
    """

    def __init__(self, sigma_m: float | None = None, *, instrument=None, max_distance_m: float = 100.0,
                 station_heads: dict | None = None):
        if (sigma_m is None) == (instrument is None):
            raise MultilatError("give either sigma_m or an instrument")
        self.sigma_m = None if sigma_m is None else float(sigma_m)
        if self.sigma_m is not None and not (np.isfinite(self.sigma_m) and self.sigma_m > 0):
            raise MultilatError(f"sigma must be > 0, got {sigma_m!r}")
        self.instrument = instrument
        self._grid = np.geomspace(0.01, max(max_distance_m, 1.0), 400)
        self._tables: dict[str, np.ndarray] = {}
        self.station_heads = dict(station_heads or {})

    def with_station_heads(self, station_heads: dict) -> "SigmaModel":
        """This model with ``station_heads`` (station id -> instrument head) added; tables shared."""
        out = SigmaModel.__new__(SigmaModel)
        out.__dict__.update(self.__dict__)
        out.station_heads = {**self.station_heads, **station_heads}
        return out

    def describe(self) -> str:
        if self.sigma_m is not None:
            return f"σ {self.sigma_m * 1e6:.3g} µm"
        return f"instrument {getattr(self.instrument, 'name', 'model')}"

    def head_of(self, station_id: str) -> str:
        """The instrument head measuring from ``station_id`` (see the class)."""
        inst = self.instrument
        if station_id in self.station_heads:
            return self.station_heads[station_id]
        if inst is None or inst.has_head(station_id):
            return station_id
        if inst.has_head("A"):
            return "A"
        raise MultilatError(f"station {station_id!r} is not a head of instrument {inst.name!r} (heads: "
                            f"{', '.join(design_head_names(inst))}): name the station after a head, or "
                            "add a [heads.default] block")

    def __call__(self, distance_m, station_index, station_ids) -> np.ndarray:
        d = np.asarray(distance_m, float)
        if self.sigma_m is not None:
            return np.full(d.shape, self.sigma_m)
        from multilat import budget

        out = np.empty(d.shape)
        for i, sid in enumerate(station_ids):
            h = self.head_of(sid)
            if h not in self._tables:
                self._tables[h] = budget.distance_std_m(self.instrument, self._grid, head=h)
            sel = station_index == i
            out[sel] = np.interp(np.log(d[sel]), np.log(self._grid), self._tables[h])
        return out


def design_head_names(instrument) -> tuple[str, ...]:
    """The heads an instrument names, in its file's order (``[heads.X]`` blocks but ``default``, then
    the ``[head_map]`` entries); () with no instrument."""
    if instrument is None:
        return ()
    return tuple(h for h in instrument.heads if h != "default") + tuple(instrument.head_map)


# ---------------------------------------------------------------------------------------------
def _sigma_per_pair(layout: Layout, sigma) -> tuple:
    """``(distance_m, sigma_m)`` (m,) of the layout's observations (:meth:`Layout.pairs` order) from a
    :class:`SigmaModel`, a float or an (m,) array."""
    si, ti = layout.pairs()
    d = range_m(layout.station_xyz_m[si] - layout.target_xyz_m[ti])
    if isinstance(sigma, SigmaModel):
        return d, sigma(d, si, layout.station_ids)
    return d, np.broadcast_to(np.asarray(sigma, float), d.shape).copy()


def covariance(layout: Layout, sigma_m, *, offsets: bool = True, datum="free") -> np.ndarray:
    """Predicted covariance of all parameters for exact distances: the adjustment's own (the
    ``dense`` back end of :mod:`.backends`).

    Parameters
    ----------
    layout : Layout
    sigma_m : ndarray (m,)
        Standard uncertainty of each observation, in :meth:`Layout.pairs` order, metres.
    offsets : bool
        Estimate one additive offset per station (else they are known).
    datum : Datum or str
        ``free`` (inner constraints over all points, default), ``free:P,..`` or ``321:A,B,C``.

    Returns
    -------
    cov : ndarray (5s + 3t, 5s + 3t)
        In the adjustment's layout (:meth:`ParameterLayout.adjustment`), m² (rows of fixed parameters zero).

    Raises
    ------
    MultilatError
        A singular layout (a target seen by too few heads, coplanar heads, ...).
    """
    return make_backend("dense", layout, sigma_m, offsets=offsets, datum=datum).full


def criterion_value(name: str, layout: Layout, sigma: SigmaModel, *, offsets=True, datum="free",
                    lengths=(), alpha=0.001, power=0.80, method: str = "auto") -> float:
    """The design criterion ``name`` (:data:`CRITERIA`) of a layout, metres; ``inf`` when singular.

    ``method``: a back end of :mod:`.backends`, ``"dense"`` (the adjustment's covariance as the whole
    matrix), ``"blocked"`` (the same in its Schur form), ``"fast"`` (the search's evaluator; not
    length_u) or ``"auto"`` (fast, and blocked for length_u: :func:`~.backends.choose_backend`).
    All agree to 1e-9 (tested)."""
    if name not in CRITERIA:
        raise MultilatError(f"criterion must be one of {', '.join(CRITERIA)}, got {name!r}")
    _, sig = _sigma_per_pair(layout, sigma)
    how = choose_backend(method, layout, name)
    try:
        be = make_backend(how, layout, sig, offsets=offsets, datum=datum)
    except MultilatError:
        return float("inf")
    return criterion(name, be, lengths=lengths, alpha=alpha, power=power)


# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class PreAnalysis:
    """Result of :func:`preanalyse`: what ``adjust`` would report for error-free distances.

    Attributes
    ----------
    layout : Layout
    station_index, target_index : ndarray of int (m,)  the observations (visible pairs)
    distance_m, sigma_m : ndarray (m,)  geometric distances and their standard uncertainties
    cov : ndarray (5s + 3t, 5s + 3t) or None  full covariance, the adjustment's layout, in the datum, m²
        (None from the blocked method: large layouts keep only the blocks below)
    global_cov : ndarray (5s, 5s)  covariance of the station parameters (x, y, z, offset, scale)
    station_cov_m2 : (s, 3, 3) ; target_cov_m2 : (t, 3, 3)
    offset_std_m : (s,)  (0 when offsets are known)
    u95_max_m : (t,)  largest 95 % ellipsoid semi-axis of each target
    redundancy : (m,)  redundancy numbers (datum-free), ``sum = dof``
    mdb_m : (m,)  minimal detectable biases (alpha, power)
    external_m : (m,)  external reliability: largest shift of any target caused by a bias of one MDB
    dof : int
    lengths : tuple of (a, b, length_m, u_m)  the chosen interpoint lengths
    datum : Datum ; offsets : bool ; alpha, power : float
    """

    layout: Layout
    station_index: np.ndarray
    target_index: np.ndarray
    distance_m: np.ndarray
    sigma_m: np.ndarray
    cov: np.ndarray | None
    global_cov: np.ndarray
    station_cov_m2: np.ndarray
    target_cov_m2: np.ndarray
    offset_std_m: np.ndarray
    u95_max_m: np.ndarray
    redundancy: np.ndarray
    mdb_m: np.ndarray
    external_m: np.ndarray
    dof: int
    lengths: tuple
    datum: Datum
    offsets: bool
    alpha: float
    power: float

    # the attributes the network figures read (multilat.report.network_figures)
    @property
    def station_ids(self):
        return self.layout.station_ids

    @property
    def target_ids(self):
        return self.layout.target_ids

    @property
    def station_xyz_m(self):
        return self.layout.station_xyz_m

    @property
    def target_xyz_m(self):
        return self.layout.target_xyz_m

    def ellipsoids(self, *, level: float = 0.95):
        """95 % ellipsoids of stations and targets, as :meth:`AdjustmentResult.ellipsoids`."""
        return (st.confidence_ellipsoid(self.station_cov_m2, level=level),
                st.confidence_ellipsoid(self.target_cov_m2, level=level))

    def probe_cov_m2(self, points_xyz_m, *, min_range_m: float = 0.0, max_range_m: float = np.inf,
                     visible=None):
        """Predicted covariance (p, 3, 3) of new points measured by the calibrated heads (the heads
        within range of each point, or ``visible`` (p, s)), for a map of the work volume:
        :func:`probe_cov_m2` with this layout's station covariance and mean ``sigma_m``."""
        return probe_cov_m2(self.layout.station_xyz_m, self.global_cov, float(np.mean(self.sigma_m)),
                            points_xyz_m, offsets=self.offsets, min_range_m=min_range_m,
                            max_range_m=max_range_m, visible=visible)

    def criterion(self, name: str) -> float:
        """The value of criterion ``name`` for this layout (metres): :func:`~.backends.criterion` on
        this result's numbers."""
        if name == "length_u" and not self.lengths:
            raise MultilatError("criterion length_u needs lengths (pairs of point ids)")
        return criterion(name, _Predicted(self), lengths=[x[:2] for x in self.lengths], alpha=self.alpha,
                         power=self.power)


class _Predicted(DesignBackend):
    """A :class:`PreAnalysis`'s numbers as a back end (for :meth:`PreAnalysis.criterion`)."""

    name = "pre-analysis"

    def __init__(self, pa: PreAnalysis):
        super().__init__(pa.layout, pa.sigma_m)
        self.pa = pa

    def target_cov_m2(self):
        return self.pa.target_cov_m2

    def redundancy(self):
        return self.pa.redundancy

    def length_u(self, pairs):
        return [x[2:] for x in self.pa.lengths]


def layout_observations(layout: Layout, sigma_m, offset_m=None) -> Observations:
    """The exact observations of a layout (distance = |H - T| + offset), for ``adjust``/``propagate``."""
    si, ti = layout.pairs()
    off = np.zeros(layout.n_stations) if offset_m is None else np.asarray(offset_m, float)
    d = range_m(layout.station_xyz_m[si] - layout.target_xyz_m[ti]) + off[si]
    return Observations(layout.station_ids, layout.target_ids, si, ti, d,
                        np.broadcast_to(np.asarray(sigma_m, float), d.shape).copy())


def preanalyse(layout: Layout, sigma, *, offsets: bool = True, datum="free", lengths=(),
               alpha: float = 0.001, power: float = 0.80, method: str = "auto") -> PreAnalysis:
    """Predicted covariance and reliability of a layout for error-free distances.

    Parameters
    ----------
    layout : Layout
    sigma : SigmaModel, float (metres) or ndarray (m,) in :meth:`Layout.pairs` order
    offsets : bool   estimate one additive offset per station (as ``adjust`` does by default)
    datum : Datum or str   ``free`` (default, inner constraints over all points), ``free:P,..``,
        ``321:A,B,C``
    lengths : sequence of (id, id)   interpoint lengths whose uncertainty to report
    alpha, power : float   w-test significance and power for the MDBs (``adjust``'s defaults)
    method : "auto", "dense" or "blocked"  as :func:`criterion_value` (blocked: ``cov`` is None)

    Returns
    -------
    PreAnalysis
    """
    d, sig = _sigma_per_pair(layout, sigma)
    if not np.all(np.isfinite(sig) & (sig > 0)):
        raise MultilatError("sigma must be finite and > 0")
    ids = set(layout.station_ids + layout.target_ids)
    for a, b in lengths:
        for p in (a, b):
            if p not in ids:
                raise MultilatError(f"lengths: unknown point id {p!r}")
    dat = parse_datum(datum)
    how = choose_backend(method, layout)
    be = make_backend(how, layout, sig, offsets=offsets, datum=dat)
    s, t = layout.n_stations, layout.n_targets
    cols = ParameterLayout.adjustment(s)
    gcov = be.station_cov()
    sb = cols.station_block(XYZ)
    tcov = be.target_cov_m2()
    red = be.redundancy()
    mdb = st.minimal_detectable_bias_m(sig, red, alpha=alpha, power=power)
    off = cols.station_columns("offset")
    lens = tuple((a, b, L, u) for (a, b), (L, u) in zip(lengths, be.length_u(lengths)))
    return PreAnalysis(layout=layout, station_index=be.station_index, target_index=be.target_index,
                       distance_m=d, sigma_m=sig, cov=be.full if how == "dense" else None, global_cov=gcov,
                       station_cov_m2=gcov[sb[:, :, None], sb[:, None, :]], target_cov_m2=tcov,
                       offset_std_m=np.sqrt(np.clip(gcov[off, off], 0, None)), u95_max_m=u95_max_m(tcov),
                       redundancy=red, mdb_m=mdb, external_m=external_reliability_m(be, layout, mdb, offsets=offsets),
                       dof=int(d.size - ParameterLayout.station_system(s, t, offsets=offsets).n + 6),
                       lengths=lens, datum=dat, offsets=offsets, alpha=alpha, power=power)


def probe_cov_m2(station_xyz_m, global_cov, sigma_m: float, points_xyz_m, *, offsets: bool = True,
                 min_range_m: float = 0.0, max_range_m: float = np.inf, visible=None):
    """Covariance (p, 3, 3) of points measured by heads whose parameters have covariance
    ``global_cov`` (5s, 5s; x, y, z, offset, scale per station): the trilateration covariance
    ``M^-1`` with ``M = J_p^T W J_p`` plus the heads' and offsets' covariance carried through,
    ``M^-1 J_p^T W J_g C_gg J_g^T W J_p M^-1`` (the Schur complement of one more target). Each
    distance has standard uncertainty ``sigma_m``. NaN where fewer than 3 heads see a point.

    For a target of the network and a datum on the stations only, this is the adjustment's own
    target block (tested)."""
    p = np.asarray(points_xyz_m, float).reshape(-1, 3)
    sx = np.asarray(station_xyz_m, float)
    s = sx.shape[0]
    d, u = line_of_sight(sx[None] - p[:, None])                       # (p, s), (p, s, 3)
    seen = (d >= max(min_range_m, 1e-9)) & (d <= max_range_m)
    if visible is not None:
        seen &= np.asarray(visible, bool)
    w = seen / float(sigma_m) ** 2                                    # (p, s)
    Jp = -u                                                           # d dist / d point
    cols = ParameterLayout.adjustment(s)                              # global_cov's columns
    Jg = np.zeros((p.shape[0], s, cols.n))                            # d dist / d [x,y,z,o,k]
    own = np.arange(s)
    Jg[:, own[:, None], cols.station_block(XYZ)] = u
    Jg[:, own, cols.station_columns("offset")] = 1.0 if offsets else 0.0
    M = np.einsum("psa,ps,psb->pab", Jp, w, Jp)
    ok = seen.sum(axis=1) >= 3
    Minv = np.full_like(M, np.nan)
    Minv[ok] = np.linalg.inv(M[ok])
    B = np.einsum("pab,psb,ps,psg->pag", Minv, Jp, w, Jg)             # (p, 3, 5s)
    return Minv + np.einsum("pag,gh,pbh->pab", B, global_cov, B)
