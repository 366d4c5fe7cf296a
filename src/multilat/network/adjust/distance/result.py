"""The result of a network adjustment: coordinates, instrument parameters, their covariance in the
datum, and the statistics (σ0, global test, redundancy numbers, w-tests, MDBs, data snooping),
whichever solver back end produced them; and its JSON document (:func:`result_to_json`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from multilat.errors import MultilatError
from multilat.io import JsonKeyedRows, JsonRows
from multilat.network.adjust import statistics as st
from multilat.network.adjust.covariance import NetworkCovariance
from multilat.network.model.data import Observations, ReferenceLengths
from multilat.network.model.datum import Datum
from multilat.network.model.distance import Q

__all__ = ["Start", "Excluded", "Outlier", "InterpointDistance", "AdjustmentResult", "build_result", "result_to_json"]


@dataclass(frozen=True)
class Start:
    """Initial values (any object with these three attributes is accepted by :func:`adjust`)."""

    station_xyz_m: np.ndarray
    target_xyz_m: np.ndarray
    offset_m: np.ndarray


@dataclass(frozen=True)
class Excluded:
    """A station or target left out of the adjustment before solving: ``kind`` "station" or
    "target", ``reason`` one phrase, ``n_obs`` how many of its observations were set aside."""

    id: str
    kind: str
    reason: str
    n_obs: int


@dataclass(frozen=True)
class Outlier:
    """An observation rejected by data snooping: ``w`` its normalised residual when rejected,
    ``residual_m`` observed minus computed in the final adjustment (without it); ``statistic`` and
    ``critical`` the test that rejected it (``test`` "w", or "tau" with an unknown variance factor)."""

    station: str
    target: str
    w: float
    residual_m: float
    mdb_m: float
    statistic: float | None = None
    critical: float | None = None
    test: str = "w"
    index: int | None = None      # its row in the observations table (``observation_columns``)


@dataclass(frozen=True)
class InterpointDistance:
    """Distance between two points of the adjusted network and its standard uncertainty, compared to
    a reference length when given (``difference_m = length_m - reference_m``)."""

    target_a: str
    target_b: str
    length_m: float
    u_m: float
    reference_m: float | None = None
    reference_u_m: float | None = None
    difference_m: float | None = None


@dataclass(frozen=True, eq=False)
class AdjustmentResult:
    """Result of :func:`adjust`. Arrays are in the order of ``obs.station_ids`` / ``obs.target_ids``.

    Attributes
    ----------
    obs : Observations  all observations given (including rejected ones)
    used : ndarray of bool (m,)  False for observations rejected by data snooping
    datum : Datum
    cost : str  "distance" or "squared"
    station_xyz_m : (s, 3) ; target_xyz_m : (t, 3)   adjusted coordinates in the datum frame, m
    offset_m : (s,)  additive instrument offsets, m ; offset_estimated : (s,) bool
    scale : (s,)  scale per station (0 when not estimated) ; scale_estimated : (s,) bool
    station_cov_m2 : (s, 3, 3) ; target_cov_m2 : (t, 3, 3)   point covariances in the datum, m²
    global_cov : (5s, 5s)  covariance of [x, y, z, offset, scale] per station (datum)
    offset_std_m : (s,) ; scale_std : (s,)
    residuals_m : (m,)  observed minus computed (``"squared"``: still in metres, d_obs - d_model)
    redundancy : (m,)  redundancy numbers (0 for rejected observations)
    w : (m,)  Baarda's normalised residuals (0 for rejected or uncontrolled observations)
    mdb_m : (m,)  minimal detectable biases (alpha, power), m
    sigma0 : float  a-posteriori standard deviation of unit weight (distance cost: dimensionless)
    dof : int
    global_test : statistics.GlobalTest
    outliers : tuple of Outlier  rejected by data snooping, in order of rejection
    unlocated : tuple of Outlier  a w-test failure that was not rejected: either it cannot be
        located (these observations' w-tests are perfectly correlated, e.g. the 4 distances to a
        target seen by only 4 stations) or rejecting it would leave the network unsolvable or a
        point without redundancy; empty when snooping ended normally
    unlocated_reason : str  why ``unlocated`` was not rejected (one phrase; "" when empty)
    snooping : bool  whether data snooping was run (not for the ``"squared"`` cost, nor when off)
    alpha, power : float  w-test significance and power used for the MDBs
    iterations : int ; condition : float (unit-diagonal reduced normal matrix)
    convergence : solve.Convergence  how the last adjustment's solver ended
    solver : str  the back end that ran ("dense" or "sparse")
    excluded : tuple of Excluded  points left out before solving (too weakly observed, disconnected);
        ``obs`` holds the observations of the adjusted network only
    warnings : tuple of str  what a user must know (zero-redundancy targets and their mirror
        ambiguity, a result that still looks like a false minimum, ...)
    w_failure_groups : tuple of tuple of int  every failing w-test at the end, grouped: observations
        whose w-tests are perfectly correlated form one group (the data cannot tell them apart)
    initial : dict  how the initial values were found and what the minimum search tried
    scale_bars : tuple of dict  reference lengths used as observations: ``target_a``, ``target_b``,
        ``length_m``, ``u_m``, ``adjusted_m``, ``residual_m``, ``redundancy``
    weighted_control : tuple of dict  control points observed with uncertainties: ``point``,
        ``xyz_m``, ``std_m``, ``residual_m`` (3), ``redundancy`` (3)
    covariance : NetworkCovariance  any block of the full covariance in the datum (scaled by σ̂0²
        with an unknown variance factor)
    tests : dict  the test procedure: method (b-method/sidak/fixed, and the one requested), variance
        factor (known/unknown), alpha0 (the one used and the one given), alpha_family, n_tests, the
        detection test, the rule in one sentence, power, lambda0, critical values, the final
        alpha_global, and each round of detection/identification (``steps``: statistic, critical,
        alpha, dof, power, verdict, action)
    sigma0_check : dict or None  :func:`statistics.sigma0_check` of the final σ0 (verdict, tails,
        the warning's message when implausible)
    reliability : reliability.Reliability or None  internal and external reliability and the poorly
        controlled observations and targets (distance cost)
    sigma_source : dict  where the a-priori σ came from (file column, option, distance model)
    variance_factor : str  "known" or "unknown" (σ̂0 then scales the covariances)
    angles : tuple of dict  each angle observation used (station, target, kind, value, σ, residual,
        redundancy, w, MDB, verdict); orientations : dict  station -> (ω, φ, κ) and their σ
    angle_outliers : tuple of dict  angles rejected by data snooping, in order (station, target, kind,
        w when rejected, residual_rad against the final solution, test, statistic, critical, step)
    ambiguous : tuple of ambiguity.Ambiguous  points whose mirror image fits the distances equally
        (:mod:`multilat.network.adjust.distance.ambiguity`; named in ``warnings`` too)
    """

    obs: Observations
    used: np.ndarray
    datum: Datum
    cost: str
    station_xyz_m: np.ndarray
    target_xyz_m: np.ndarray
    offset_m: np.ndarray
    offset_estimated: np.ndarray
    scale: np.ndarray
    scale_estimated: np.ndarray
    station_cov_m2: np.ndarray
    target_cov_m2: np.ndarray
    global_cov: np.ndarray
    offset_std_m: np.ndarray
    scale_std: np.ndarray
    residuals_m: np.ndarray
    redundancy: np.ndarray
    w: np.ndarray
    mdb_m: np.ndarray
    sigma0: float
    dof: int
    global_test: st.GlobalTest
    outliers: tuple
    unlocated: tuple
    alpha: float
    power: float
    iterations: int
    condition: float
    covariance: NetworkCovariance = field(repr=False)
    unlocated_reason: str = ""
    snooping: bool = True
    convergence: object = None
    solver: str = "dense"
    excluded: tuple = ()
    warnings: tuple = ()
    w_failure_groups: tuple = ()
    initial: dict = field(default_factory=dict)
    scale_bars: tuple = ()
    weighted_control: tuple = ()
    angles: tuple = ()
    orientations: dict = field(default_factory=dict)
    angle_outliers: tuple = ()
    angle_design_w: object = field(default=None, repr=False)   # (a, 5s+3t+n_o) whitened angle rows, internal frame
    tests: dict = field(default_factory=dict)
    reliability: object = None
    sigma_source: dict = field(default_factory=dict)
    variance_factor: str = "known"
    ambiguous: tuple = ()     # ambiguity.Ambiguous: points the distances place only up to a mirror
    sigma0_check: dict | None = None

    @property
    def sigma0_unit(self) -> str:
        """Unit of ``sigma0``: ``"1"`` for the weighted distance cost (a ratio to the a-priori
        uncertainties), ``"m^2"`` for the unweighted squared-distance cost (eq. 6)."""
        return "1" if self.cost == "distance" else "m^2"

    # ------------------------------------------------------------ derived quantities
    @property
    def station_ids(self):
        return self.obs.station_ids

    @property
    def target_ids(self):
        return self.obs.target_ids

    def point_index(self, ident: str) -> tuple[str, int]:
        """``("station", i)`` or ``("target", j)`` of a point id."""
        if ident in self.obs.station_ids:
            return "station", self.obs.station_ids.index(ident)
        if ident in self.obs.target_ids:
            return "target", self.obs.target_ids.index(ident)
        raise MultilatError(f"unknown point id {ident!r}")

    def xyz(self, ident: str) -> np.ndarray:
        kind, i = self.point_index(ident)
        return (self.station_xyz_m if kind == "station" else self.target_xyz_m)[i]

    def _param_rows(self, ident: str) -> np.ndarray:
        kind, i = self.point_index(ident)
        if kind == "station":
            return Q * i + np.arange(3)
        return Q * self.obs.n_stations + 3 * i + np.arange(3)

    def points_covariance(self, ids) -> np.ndarray:
        """Joint covariance (3p, 3p) of the points ``ids`` (stations or targets), m²."""
        rows = np.concatenate([self._param_rows(i) for i in ids])
        return self.covariance.block(rows)

    def interpoint_distance(self, a: str, b: str) -> InterpointDistance:
        """Distance between points ``a`` and ``b`` with its standard uncertainty (datum-free)."""
        d = self.xyz(a) - self.xyz(b)
        L = float(np.linalg.norm(d))
        g = np.concatenate([d / L, -d / L])
        C = self.points_covariance([a, b])
        return InterpointDistance(a, b, L, float(np.sqrt(max(g @ C @ g, 0.0))))

    def compare_references(self, refs: ReferenceLengths) -> list[InterpointDistance]:
        """Interpoint distances beside the reference lengths (seed 000 Tables V-VI)."""
        known = self.obs.station_ids + self.obs.target_ids
        refs.check_ids(known)
        out = []
        for a, b, L, u in zip(refs.target_a, refs.target_b, refs.length_m, refs.u_m):
            ip = self.interpoint_distance(a, b)
            out.append(InterpointDistance(a, b, ip.length_m, ip.u_m, float(L),
                                          None if np.isnan(u) else float(u), ip.length_m - float(L)))
        return out

    def ellipsoids(self, *, level: float = 0.95):
        """Confidence ellipsoids of stations and targets: ``(semi_axes_m, axes)`` each a pair of
        arrays ((s, 3), (s, 3, 3)) and ((t, 3), (t, 3, 3)); see :func:`statistics.confidence_ellipsoid`.
        Computed once per level (the tables, the JSON and the figures of a million targets share
        them; the result is immutable)."""
        memo = self.__dict__.setdefault("_ellipsoids", {})
        if level not in memo:
            memo[level] = (st.confidence_ellipsoid(self.station_cov_m2, level=level),
                           st.confidence_ellipsoid(self.target_cov_m2, level=level))
        return memo[level]

    def offset_correlations(self) -> np.ndarray:
        """Correlation of each station's offset with its own x, y, z and offset (s, 4):
        ``corr[i] = (rho(o_i, x_i), rho(o_i, y_i), rho(o_i, z_i), 1)`` (NaN where not estimated)."""
        s = self.obs.n_stations
        C = self.global_cov
        out = np.full((s, 4), np.nan)
        for i in range(s):
            o = Q * i + 3
            if C[o, o] <= 0:
                continue
            for c in range(4):
                v = C[Q * i + c, Q * i + c]
                if v > 0:
                    out[i, c] = C[o, Q * i + c] / np.sqrt(C[o, o] * v)
        return out

    def heads(self) -> dict:
        """Per head (``obs.head_ids``; a head is its station when no heads were given): ``offset_m``,
        ``offset_std_m``, ``offset_estimated``, ``scale``, ``scale_std``, ``scale_estimated`` and the
        ``stations`` it occupied. Its stations carry the same values (the tie of problem.py)."""
        hos = self.obs.head_of_station
        out = {}
        for i, (sid, hid) in enumerate(zip(self.station_ids, hos)):
            if hid in out:
                out[hid]["stations"].append(sid)
                continue
            out[hid] = {"offset_m": float(self.offset_m[i]), "offset_std_m": float(self.offset_std_m[i]),
                        "offset_estimated": bool(self.offset_estimated[i]), "scale": float(self.scale[i]),
                        "scale_std": float(self.scale_std[i]), "scale_estimated": bool(self.scale_estimated[i]),
                        "stations": [sid]}
        return out

    def target_n_obs(self) -> np.ndarray:
        """Observations used per target (t,)."""
        return np.bincount(self.obs.target_index[self.used], minlength=self.obs.n_targets)

    def target_redundancy(self) -> np.ndarray:
        """Sum of the redundancy numbers of each target's observations (t,): 0 means the target is
        determined without any check."""
        return np.bincount(self.obs.target_index, weights=self.redundancy, minlength=self.obs.n_targets)

    def correlation_matrix(self) -> np.ndarray:
        """Correlations among all station parameters (5s, 5s) (NaN rows for fixed parameters)."""
        d = np.sqrt(np.clip(np.diag(self.global_cov), 0, None))
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.global_cov / np.outer(d, d)


#: observations per slice of the final residuals (bounded temporaries)
RESIDUAL_SLICE = 1 << 16


def build_result(obs, used, rejected, unlocated, core, datum, cost, alpha, power, alpha_global, *,
                  reason="", snooped=True, sigma_scale=1.0, mdb_limit_sigma=10.0, r_min=0.1):
    s, t, m = obs.n_stations, obs.n_targets, obs.n_obs
    smap, tmap = core.smap, core.tmap
    sx = np.full((s, 3), np.nan)
    tx = np.full((t, 3), np.nan)
    off = np.full(s, np.nan)
    sc = np.zeros(s)
    sx[smap], tx[tmap], off[smap], sc[smap] = core.sx, core.tx, core.off, core.sc
    if len(smap) != s or len(tmap) != t:
        lost = [obs.station_ids[i] for i in range(s) if i not in smap] + \
               [obs.target_ids[j] for j in range(t) if j not in tmap]
        raise MultilatError(f"data snooping removed every observation of {', '.join(lost)}")
    cov = core.cov
    gcov = cov.global_block()
    scov = np.stack([gcov[Q * i:Q * i + 3, Q * i:Q * i + 3] for i in range(s)])
    tcov = cov.target_blocks(core.chunk_targets)
    off_est = np.zeros(s, bool)
    sc_est = np.zeros(s, bool)
    off_est[smap], sc_est[smap] = core.off_free, core.sc_free
    # residuals of all observations (rejected ones against the final solution), in slices: the same
    # numbers without (m, 3) temporaries of the whole network (115 MB at 1.6 M distances)
    r_all = np.empty(m)
    for lo in range(0, m, RESIDUAL_SLICE):
        hi = lo + RESIDUAL_SLICE
        si_, ti_ = obs.station_index[lo:hi], obs.target_index[lo:hi]
        r_all[lo:hi] = obs.distance_m[lo:hi] - ((1 + sc[si_]) * np.linalg.norm(sx[si_] - tx[ti_], axis=1)
                                                + off[si_])
    red = np.zeros(m)
    red[used] = core.redundancy
    if cost == "distance":
        w = st.w_statistics(r_all, obs.sigma_m, red)
        w[~used] = 0.0
        from multilat.network.adjust.distance.reliability import reliability as _reliability

        rel = _reliability(obs, used, red, obs.sigma_m, core.cov, obs.station_ids, obs.target_ids,
                           alpha=alpha, power=power, r_min=r_min, mdb_limit_sigma=mdb_limit_sigma,
                           sigma_scale=sigma_scale)
        mdb = st.minimal_detectable_bias_m(obs.sigma_m * sigma_scale, red, alpha=alpha, power=power)
        gt = st.global_test(core.vtpv, core.dof, alpha=alpha_global,
                            lambda0=st.noncentrality(alpha, power))
    else:
        w = np.zeros(m)
        mdb = np.full(m, np.nan)
        gt = st.GlobalTest(None, None, None, None, alpha_global, core.dof)
        rel = None
    outliers = tuple(Outlier(obs.station_ids[obs.station_index[k]], obs.target_ids[obs.target_index[k]],
                             wk, float(r_all[k]), float(mdb[k]) if np.isfinite(mdb[k]) else float("nan"),
                             *rest, index=int(k))
                     for k, wk, *rest in rejected)
    unloc = tuple(Outlier(obs.station_ids[obs.station_index[k]], obs.target_ids[obs.target_index[k]],
                          float(w[k]), float(r_all[k]), float(mdb[k]) if np.isfinite(mdb[k]) else float("nan"),
                          index=int(k))
                  for k in unlocated)
    cov = core.cov
    gd = np.diag(gcov).reshape(s, Q)
    return AdjustmentResult(
        obs=obs, used=used, datum=datum, cost=cost, station_xyz_m=sx, target_xyz_m=tx, offset_m=off,
        offset_estimated=off_est, scale=sc, scale_estimated=sc_est, station_cov_m2=scov,
        target_cov_m2=tcov, global_cov=gcov, offset_std_m=np.sqrt(np.clip(gd[:, 3], 0, None)),
        scale_std=np.sqrt(np.clip(gd[:, 4], 0, None)), residuals_m=r_all, redundancy=red, w=w,
        mdb_m=mdb, sigma0=core.sigma0, dof=core.dof, global_test=gt, outliers=outliers,
        unlocated=unloc, unlocated_reason=reason if unloc else "", snooping=bool(snooped),
        alpha=alpha, power=power, iterations=core.iterations, condition=core.cond, covariance=cov,
        convergence=core.convergence, solver=core.solver, reliability=rel,
        variance_factor="unknown" if sigma_scale != 1.0 else "known")


def _obs_label(obs: Observations, k: int) -> dict:
    return {"station": obs.station_ids[obs.station_index[k]], "target": obs.target_ids[obs.target_index[k]]}


def _stations_json(res) -> dict:
    """One object per station: coordinates, offset (and scale, orientation where estimated), their
    covariance and the offset's correlations with the coordinates."""
    stations = {}
    corr = res.offset_correlations()
    o_heads = res.obs.head_of_station
    for i, sid in enumerate(res.station_ids):
        stations[sid] = {"xyz_m": res.station_xyz_m[i], "offset_m": res.offset_m[i],
                         "offset_std_m": res.offset_std_m[i], "offset_estimated": bool(res.offset_estimated[i]),
                         "cov_m2": res.station_cov_m2[i], "offset_corr_xyz": corr[i, :3],
                         "head": o_heads[i]}
        if res.scale_estimated[i]:
            stations[sid]["scale"] = res.scale[i]
            stations[sid]["scale_std"] = res.scale_std[i]
        if sid in res.orientations:
            stations[sid].update(res.orientations[sid])
    return stations


def _observations_json(res, listing: str, given) -> dict:
    """The document's observation keys (schema ``multilat.adjust/3``): ``observations`` (the rows that
    matter, or every row with ``listing="all"``), ``observation_counts``, ``excluded_observations``,
    ``observation_extremes`` and ``largest_w`` (:mod:`multilat.network.io.result_rows`)."""
    from multilat.network.io import result_rows as rr

    if listing not in ("flagged", "all"):
        raise MultilatError(f"observations listing must be 'flagged' or 'all', got {listing!r}")
    cols = rr.observation_columns(res)
    rows = np.arange(res.obs.n_obs) if listing == "all" else rr.flagged(cols)
    excl = rr.excluded_rows(given, res.excluded)
    n_excl = len(excl) if given is not None else sum(e.n_obs for e in res.excluded)
    return {"observation_counts": rr.observation_counts(cols, len(rows), listing, n_excl),
            "observations": JsonRows(rr.take(cols, rows)),
            "excluded_observations": excl,
            "observation_extremes": rr.observation_extremes(cols) if res.cost == "distance" else {},
            "largest_w": rr.largest_w(cols) if res.cost == "distance" else []}


def result_to_json(res: AdjustmentResult, refs: ReferenceLengths | None = None, *,
                   observations: str = "flagged", given: Observations | None = None) -> dict:
    """The ``--json`` document of an adjustment (schema ``multilat.adjust/3``), the same keys whichever
    back end ran. ``observations``: "flagged" lists only the rows that matter (rejected, failing
    w-tests, poorly controlled; every row is in the ``--out`` table), "all" every row. ``given``: the
    observations passed to the adjustment, to list those of points left out before solving."""
    from multilat.network.model.frame_words import result_frame_words

    stations = _stations_json(res)
    # one object per target, written from the columns (no Python object per target)
    targets = JsonKeyedRows(res.target_ids, {"xyz_m": res.target_xyz_m, "cov_m2": res.target_cov_m2,
                                             "n_obs": np.asarray(res.target_n_obs(), np.int64),
                                             "redundancy": np.asarray(res.target_redundancy(), float)})
    gt = res.global_test
    o, rel = res.obs, res.reliability
    obs_keys = _observations_json(res, observations, given)
    doc = {
        "datum": res.datum.describe(),
        "frame": result_frame_words(res),
        "cost": res.cost,
        "solver": res.solver,
        "convergence": res.convergence.to_json() if res.convergence is not None else None,
        "n_obs": res.obs.n_obs,
        "n_used": int(res.used.sum()),
        "excluded": [{"id": e.id, "kind": e.kind, "reason": e.reason, "n_obs": e.n_obs} for e in res.excluded],
        "warnings": list(res.warnings),
        "ambiguous": [a.to_json() for a in res.ambiguous],
        "stations": stations,
        "heads": res.heads(),
        "scale_bars": list(res.scale_bars),
        "weighted_control": list(res.weighted_control),
        "angles": list(res.angles),
        "angle_outliers": list(res.angle_outliers),
        "targets": targets,
        "sigma0": res.sigma0,
        "sigma0_unit": res.sigma0_unit,
        "dof": res.dof,
        "global_test": {"statistic": gt.statistic, "critical": gt.critical, "passed": gt.passed,
                        "alpha": gt.alpha, "dof": gt.dof, "power": gt.power, "lambda0": gt.lambda0,
                        "critical_low": gt.critical_low, "alpha_low": gt.alpha_low, "failed_tail": gt.side,
                        "decides": res.variance_factor == "known"},
        "sigma0_check": dict(res.sigma0_check or st.sigma0_check(float("nan"), res.dof)),
        "alpha": res.alpha,
        "snooping": res.snooping,
        "tests": dict(res.tests),
        "sigma_source": dict(res.sigma_source),
        "variance_factor": res.variance_factor,
        "outliers": [{"index": x.index, "station": x.station, "target": x.target, "w": x.w, "residual_m": x.residual_m,
                      "test": x.test, "statistic": x.statistic, "critical": x.critical, "order": n + 1}
                     for n, x in enumerate(res.outliers)],
        "unlocated": [{"index": x.index, "station": x.station, "target": x.target, "w": x.w, "residual_m": x.residual_m}
                      for x in res.unlocated],
        "unlocated_reason": res.unlocated_reason,
        "w_failures": [{"observations": [_obs_label(o, k) for k in g], "w": float(res.w[g[0]]),
                        "located": len(g) == 1} for g in res.w_failure_groups],
        **obs_keys,
        "initial": dict(res.initial),
        "reliability": None if rel is None else {
            "r_min": rel.r_min, "mdb_limit_sigma": rel.mdb_limit_sigma, "shifts_computed": rel.shifts_computed,
            "poor_observations": [dict(_obs_label(o, k), redundancy=float(rel.redundancy[k]),
                                       mdb_m=float(rel.mdb_m[k]), mdb_sigma=float(rel.mdb_sigma[k]),
                                       shift_max_m=float(rel.shift_max_m[k]), shift_point=rel.shift_point[k])
                                  for k in rel.poor_obs],
            "poor_targets": [dict(t) for t in rel.poor_targets]},
        "reference_lengths": [],
        "iterations": res.iterations,
        "condition": res.condition,
    }
    if refs is not None:
        doc["reference_lengths"] = [
            {"target_a": c.target_a, "target_b": c.target_b, "length_m": c.length_m, "length_std_m": c.u_m,
             "reference_m": c.reference_m, "reference_std_m": c.reference_u_m,
             "difference_m": c.difference_m} for c in res.compare_references(refs)]
    return doc
