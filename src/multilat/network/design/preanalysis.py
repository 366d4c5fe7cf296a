"""Pre-analysis of a multilateration layout: the covariance, redundancy numbers and minimal
detectable biases that :func:`multilat.network.adjust.distance.adjust.adjust` would report for error-free distances,
computed from the geometry alone (no measurements).

For exact distances the residuals are zero, so the adjustment's covariance is the (datum-transformed)
inverse of the normal matrix at the true geometry. Here the normal matrix is built densely from the
model's Jacobian (:func:`multilat.network.model.distance.residuals_and_jacobian`, parameter layout of
:mod:`multilat.network.model.distance`: ``[x, y, z, offset, scale]`` per station then ``x, y, z`` per target;
scales are never estimated, offsets optionally) and inverted in the inner-constraint datum by

    N^+ = (N + c U U^T)^-1 - U U^T / c,

``U`` an orthonormal basis of the 6 rigid motions (:func:`multilat.network.model.datum.helmert_basis`),
``c = trace(N) / n`` for conditioning. Other datums follow by the S-transform
``S N^+ S^T``, ``S = I - G (E^T G)^-1 E^T``. Dense algebra: fast for a few hundred targets (a 4 x 14
layout is a 58 x 58 matrix); see docs/design.md for the sizes.

Units: metres, m²; ``sigma`` is the standard uncertainty of one distance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust import statistics as st
from multilat.network.model.data import Observations
from multilat.network.model.datum import Datum, helmert_basis, parse_datum, s_transform
from multilat.network.model.distance import Q, line_of_sight, range_m, residuals_and_jacobian

__all__ = ["Layout", "SigmaModel", "design_head_names", "PreAnalysis", "preanalyse", "covariance", "CRITERIA",
           "criterion_value", "target_criterion", "layout_observations", "probe_cov_m2", "DENSE_MAX_PARAMS"]

#: optimisation criteria (docs/design.md): name -> description
CRITERIA = {
    "max_u95": "largest 95 % ellipsoid semi-axis over the targets (m)",
    "rms_u": "RMS over targets of the 3-D standard uncertainty sqrt(trace C_j) (m)",
    "length_u": "largest standard uncertainty of the chosen interpoint lengths (m)",
    "max_mdb": "largest minimal detectable bias over the distances (m)",
}


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
def _datum_E(datum: Datum, layout: Layout, G, rows):
    """The datum's constraint matrix E (n, 6) in the model layout (None for inner constraints over
    all points, where the pseudo-inverse is already the answer)."""
    if datum.kind == "free" and datum.points is None:
        return None
    ids = layout.station_ids + layout.target_ids
    pos = {p: k for k, p in enumerate(ids)}
    for p in datum.points:
        if p not in pos:
            raise MultilatError(f"datum point {p!r} is neither a station nor a target")
    E = np.zeros_like(G)
    if datum.kind == "321":
        a, b, c = datum.points
        for col, (p, comp) in enumerate([(a, 0), (a, 1), (a, 2), (b, 1), (b, 2), (c, 2)]):
            E[rows[3 * pos[p] + comp], col] = 1.0
    elif datum.kind == "free":
        for p in datum.points:
            r = rows[3 * pos[p]: 3 * pos[p] + 3]
            E[r] = G[r]
    else:
        raise MultilatError("design supports the free and 321 datums (not control)")
    return E


def covariance(layout: Layout, sigma_m, *, offsets: bool = True, datum="free"):
    """Predicted covariance of all parameters for exact distances.

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
        In the model layout (:mod:`multilat.network.model.distance`), m² (rows of fixed parameters zero).
    A_w : ndarray (m, n_free)  whitened Jacobian of the free parameters
    free : ndarray of bool (5s + 3t,)
    Qplus : ndarray (n_free, n_free)  inner-constraint (pseudo-inverse) covariance of the free ones

    Raises
    ------
    MultilatError
        A singular layout (a target seen by too few heads, coplanar heads, ...).
    """
    s, t = layout.n_stations, layout.n_targets
    si, ti = layout.pairs()
    sx, tx = layout.station_xyz_m, layout.target_xyz_m
    zero = np.zeros(s)
    d = range_m(sx[si] - tx[ti])
    _, Js, Jt = residuals_and_jacobian(d, sx, tx, zero, zero, si, ti)
    m = si.size
    n = Q * s + 3 * t
    w = 1.0 / np.asarray(sigma_m, float)
    A = np.zeros((m, n))
    rows = np.arange(m)
    for c in range(Q):
        A[rows, Q * si + c] = Js[:, c] * w
    for c in range(3):
        A[rows, Q * s + 3 * ti + c] = Jt[:, c] * w
    free = np.ones(n, bool)
    free[Q * np.arange(s) + 4] = False                 # scales: never estimated here
    if not offsets:
        free[Q * np.arange(s) + 3] = False
    A_w = A[:, free]
    N = A_w.T @ A_w
    point_rows = np.concatenate([(Q * np.arange(s)[:, None] + np.arange(3)).ravel(), Q * s + np.arange(3 * t)])
    G = np.zeros((n, 6))
    G[point_rows] = helmert_basis(np.vstack([sx, tx]))
    U, _ = np.linalg.qr(G[free])
    nf = int(free.sum())
    c = np.trace(N) / nf
    try:
        L = np.linalg.cholesky(N + c * (U @ U.T))
    except np.linalg.LinAlgError:
        raise MultilatError("layout is singular (a target seen by too few heads, or flat geometry)") from None
    Linv = np.linalg.inv(L)
    Qplus = Linv.T @ Linv - (U @ U.T) / c
    # singular but numerically positive: the smallest non-null eigenvalue relative to the largest
    if not np.all(np.isfinite(Qplus)) or np.max(np.abs(Qplus)) * c > 1e12:
        raise MultilatError("layout is (nearly) singular: condition above 1e12")
    cov = np.zeros((n, n))
    cov[np.ix_(free, free)] = Qplus
    E = _datum_E(parse_datum(datum), layout, G, point_rows)
    if E is not None:
        S = s_transform(G, E)
        cov = S @ cov @ S.T
    return cov, A_w, free, Qplus


def _point_blocks(cov, s, t):
    st_ = np.stack([cov[Q * i:Q * i + 3, Q * i:Q * i + 3] for i in range(s)])
    o = Q * s
    idx = o + 3 * np.arange(t)[:, None] + np.arange(3)
    tt = cov[idx[:, :, None], idx[:, None, :]]
    return st_, tt


def _u95_max(cov3):
    return np.sqrt(st.CHI2_3_95 * np.clip(np.linalg.eigvalsh(cov3)[..., -1], 0.0, None))


def target_criterion(name: str, target_cov_m2) -> float:
    """``max_u95`` or ``rms_u`` (:data:`CRITERIA`, m) from the targets' covariances (t, 3, 3): the one
    evaluation of both behind every method (dense, blocked, fast) and :meth:`PreAnalysis.criterion`."""
    if name == "max_u95":
        return float(_u95_max(target_cov_m2).max())
    if name == "rms_u":
        return float(np.sqrt(np.trace(target_cov_m2, axis1=1, axis2=2).mean()))
    raise MultilatError(f"target_criterion: {name!r} is not a criterion of the targets' covariances alone")


def _length_u(layout: Layout, cov, pairs):
    """``(length_m, standard uncertainty_m)`` of the distances between point pairs (ids); ``cov`` the
    full covariance matrix, or an object whose ``block(rows)`` gives the block of those rows (the
    blocked pre-analysis' covariance)."""
    s = layout.n_stations
    ids = layout.station_ids + layout.target_ids
    pos = {p: k for k, p in enumerate(ids)}
    xyz = np.vstack([layout.station_xyz_m, layout.target_xyz_m])
    out = []
    for a, b in pairs:
        ra, rb = (Q * pos[p] + np.arange(3) if pos[p] < s else Q * s + 3 * (pos[p] - s) + np.arange(3)
                  for p in (a, b))
        L, u = line_of_sight(xyz[pos[a]] - xyz[pos[b]])
        g = np.concatenate([u, -u])
        r = np.concatenate([ra, rb])
        C = cov.block(r) if hasattr(cov, "block") else cov[np.ix_(r, r)]
        out.append((float(L), float(np.sqrt(max(g @ C @ g, 0.0)))))
    return out


def _redundancy(A_w, Qplus):
    h = np.einsum("ij,jk,ik->i", A_w, Qplus, A_w)
    return np.clip(1.0 - h, 0.0, 1.0)


#: above this many free parameters the pre-analysis works on the adjustment's reduced system
#: (:mod:`.blocked`, O(t s^2)) instead of the dense normal matrix (O(t^3))
DENSE_MAX_PARAMS = 120


def _method(method: str, layout: Layout, name: str | None = None) -> str:
    """The evaluation to use: ``fast`` (:mod:`.fast`, a criterion other than length_u), else dense
    up to :data:`DENSE_MAX_PARAMS` parameters and blocked above."""
    if method not in ("auto", "dense", "blocked", "fast"):
        raise MultilatError(f"method must be auto, dense, blocked or fast, got {method!r}")
    if method == "fast" and name in (None, "length_u"):
        method = "auto"
    if method == "auto":
        if name is not None and name != "length_u":
            return "fast"
        n = 4 * layout.n_stations + 3 * layout.n_targets
        return "dense" if n <= DENSE_MAX_PARAMS else "blocked"
    return method


def criterion_value(name: str, layout: Layout, sigma: SigmaModel, *, offsets=True, datum="free",
                    lengths=(), alpha=0.001, power=0.80, method: str = "auto") -> float:
    """The design criterion ``name`` (:data:`CRITERIA`) of a layout, metres; ``inf`` when singular.

    ``method``: ``"dense"`` (the whole normal matrix), ``"blocked"`` (the adjustment's Schur-reduced
    system, :mod:`.blocked`), ``"fast"`` (the search's evaluator, :mod:`.fast`; not length_u) or
    ``"auto"`` (fast, and for length_u dense up to :data:`DENSE_MAX_PARAMS` parameters, else
    blocked). All four agree to 1e-9 (tested)."""
    if name not in CRITERIA:
        raise MultilatError(f"criterion must be one of {', '.join(CRITERIA)}, got {name!r}")
    si, ti = layout.pairs()
    d = range_m(layout.station_xyz_m[si] - layout.target_xyz_m[ti])
    sig = sigma(d, si, layout.station_ids)
    how = _method(method, layout, name)
    if how == "fast":
        from multilat.network.design.fast import fast_criterion

        sig_mat = np.ones(layout.visible.shape)
        sig_mat[si, ti] = sig
        return fast_criterion(name, layout, sig_mat, offsets=offsets, datum=datum, alpha=alpha, power=power)
    if how == "blocked":
        from multilat.network.design.blocked import blocked_criterion

        return blocked_criterion(name, layout, sig, offsets=offsets, datum=datum, lengths=lengths,
                                 alpha=alpha, power=power)
    try:
        cov, A_w, _, Qplus = covariance(layout, sig, offsets=offsets, datum=datum)
    except MultilatError:
        return float("inf")
    if name in ("max_u95", "rms_u"):
        return target_criterion(name, _point_blocks(cov, layout.n_stations, layout.n_targets)[1])
    if name == "length_u":
        return float(max(u for _, u in _length_u(layout, cov, lengths)))
    if name == "max_mdb":
        return float(st.minimal_detectable_bias_m(sig, _redundancy(A_w, Qplus), alpha=alpha,
                                                  power=power).max())
    raise MultilatError(f"criterion must be one of {', '.join(CRITERIA)}, got {name!r}")


# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class PreAnalysis:
    """Result of :func:`preanalyse`: what ``adjust`` would report for error-free distances.

    Attributes
    ----------
    layout : Layout
    station_index, target_index : ndarray of int (m,)  the observations (visible pairs)
    distance_m, sigma_m : ndarray (m,)  geometric distances and their standard uncertainties
    cov : ndarray (5s + 3t, 5s + 3t) or None  full covariance, model layout, in the datum, m²
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
        """The value of criterion ``name`` for this layout (metres)."""
        if name in ("max_u95", "rms_u"):
            return target_criterion(name, self.target_cov_m2)
        if name == "length_u":
            if not self.lengths:
                raise MultilatError("criterion length_u needs lengths (pairs of point ids)")
            return float(max(x[3] for x in self.lengths))
        if name == "max_mdb":
            return float(self.mdb_m.max())
        raise MultilatError(f"criterion must be one of {', '.join(CRITERIA)}, got {name!r}")


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
    si, ti = layout.pairs()
    s, t = layout.n_stations, layout.n_targets
    d = range_m(layout.station_xyz_m[si] - layout.target_xyz_m[ti])
    if isinstance(sigma, SigmaModel):
        sig = sigma(d, si, layout.station_ids)
    else:
        sig = np.broadcast_to(np.asarray(sigma, float), d.shape).copy()
    if not np.all(np.isfinite(sig) & (sig > 0)):
        raise MultilatError("sigma must be finite and > 0")
    ids = set(layout.station_ids + layout.target_ids)
    for a, b in lengths:
        for p in (a, b):
            if p not in ids:
                raise MultilatError(f"lengths: unknown point id {p!r}")
    dat = parse_datum(datum)
    if _method(method, layout) == "blocked":
        return _preanalyse_blocked(layout, sig, d, si, ti, offsets=offsets, datum=dat, lengths=lengths,
                                   alpha=alpha, power=power)
    cov, A_w, free, Qplus = covariance(layout, sig, offsets=offsets, datum=dat)
    scov, tcov = _point_blocks(cov, s, t)
    red = _redundancy(A_w, Qplus)
    mdb = st.minimal_detectable_bias_m(sig, red, alpha=alpha, power=power)
    # external reliability: parameter shift of a bias of one MDB in observation k (inner datum)
    with np.errstate(invalid="ignore"):
        shift = (Qplus @ A_w.T) * np.where(np.isfinite(mdb), mdb, 0.0) / sig      # (n_free, m)
    full = np.zeros((free.size, si.size))
    full[free] = shift
    tshift = full[Q * s:].reshape(t, 3, -1)
    ext = np.sqrt((tshift ** 2).sum(axis=1)).max(axis=0)
    ext[~np.isfinite(mdb)] = np.inf
    lens = tuple((a, b, L, u) for (a, b), (L, u) in zip(lengths, _length_u(layout, cov, lengths)))
    return PreAnalysis(layout=layout, station_index=si, target_index=ti, distance_m=d, sigma_m=sig,
                       cov=cov, global_cov=cov[:Q * s, :Q * s], station_cov_m2=scov, target_cov_m2=tcov,
                       offset_std_m=np.sqrt(np.clip(np.diag(cov)[Q * np.arange(s) + 3], 0, None)),
                       u95_max_m=_u95_max(tcov), redundancy=red, mdb_m=mdb, external_m=ext,
                       dof=int(si.size - free.sum() + 6), lengths=lens, datum=dat, offsets=offsets,
                       alpha=alpha, power=power)


def _preanalyse_blocked(layout, sig, d, si, ti, *, offsets, datum, lengths, alpha, power):
    """:func:`preanalyse` on the reduced system (:mod:`.blocked`): the same numbers, no full matrix."""
    from multilat.network.design.blocked import blocked_covariance, external_reliability_m

    s, t = layout.n_stations, layout.n_targets
    bc = blocked_covariance(layout, sig, offsets=offsets, datum=datum)
    gcov = bc.cov.global_block()
    tcov = bc.target_cov_m2()
    red = bc.redundancy()
    mdb = st.minimal_detectable_bias_m(sig, red, alpha=alpha, power=power)
    ext = external_reliability_m(bc, layout, mdb, offsets=offsets)
    scov = np.stack([gcov[Q * i:Q * i + 3, Q * i:Q * i + 3] for i in range(s)])
    lens = tuple((a, b, L, u) for (a, b), (L, u) in zip(lengths, _length_u(layout, bc.cov, lengths)))
    nfree = (4 if offsets else 3) * s + 3 * t
    return PreAnalysis(layout=layout, station_index=si, target_index=ti, distance_m=d, sigma_m=sig,
                       cov=None, global_cov=gcov, station_cov_m2=scov, target_cov_m2=tcov,
                       offset_std_m=np.sqrt(np.clip(np.diag(gcov)[Q * np.arange(s) + 3], 0, None)),
                       u95_max_m=_u95_max(tcov), redundancy=red, mdb_m=mdb, external_m=ext,
                       dof=int(si.size - nfree + 6), lengths=lens, datum=datum, offsets=offsets,
                       alpha=alpha, power=power)


def _xyz(layout, pid):
    ids = layout.station_ids + layout.target_ids
    k = ids.index(pid)
    s = layout.n_stations
    return layout.station_xyz_m[k] if k < s else layout.target_xyz_m[k - s]


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
    Jg = np.zeros((p.shape[0], s, Q * s))                             # d dist / d [x,y,z,o,k]
    for i in range(s):
        Jg[:, i, Q * i:Q * i + 3] = u[:, i]
        Jg[:, i, Q * i + 3] = 1.0 if offsets else 0.0
    M = np.einsum("psa,ps,psb->pab", Jp, w, Jp)
    ok = seen.sum(axis=1) >= 3
    Minv = np.full_like(M, np.nan)
    Minv[ok] = np.linalg.inv(M[ok])
    B = np.einsum("pab,psb,ps,psg->pag", Minv, Jp, w, Jg)             # (p, 3, 5s)
    return Minv + np.einsum("pag,gh,pbh->pab", B, global_cov, B)
