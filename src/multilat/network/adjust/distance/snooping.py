"""Data snooping: one round of Baarda's procedure (:func:`snooping_round`: detection by the global
test or Pope's τ, identification by the largest |w| of distances and angles, adaptation by rejecting
it unless it cannot be located or its rejection would leave the network unsolvable), and the rounds
between two adjustments as rank-one downdates of the last one (:class:`LinearRounds`, large
networks). :func:`multilat.network.adjust.distance.adjust.adjust` runs the rounds.

Data snooping rejects one observation per round and, in :func:`multilat.network.adjust.distance.adjust.adjust`,
adjusts the network again each time. On a network of 10⁵ distances the B-method's global test fails
most of the time even without a blunder (``alpha_global`` near 0.8 at that redundancy), and the
w-tests' own false alarms were then rejected one by one: dozens of rounds, each a full adjustment
(the default procedure now tests large networks at Šidák's family-wise level,
:func:`multilat.network.adjust.statistics.test_levels`; the rounds serve blunders and ``--test-method
b-method``).

Between two adjustments the rounds here use the Sherman-Morrison downdate of the linearised model
(whitened design ``A``, hat matrix ``H = A Q Aᵀ``, residuals ``v``, redundancy numbers ``r = 1 -
diag H``). Leaving out observation ``k``, with ``c = H e_k`` (one row of the hat matrix)::

    v'   = v + c v_k / r_k            (the solution moves by -Q a_k v_k / r_k)
    r'   = r - c² / r_k
    vᵀPv' = vᵀPv - v_k² / r_k,   dof' = dof - 1
    H'   = H + c cᵀ / r_k             (the next round's hat row)

A downdate's ``c`` is kept as its generator ``g`` (``c = A C g``; ``g`` a combination of the rejected
observations' design rows: the stations' part and the few targets touched), so a round costs two
passes over the observations (``C g``, then ``A (C g)``) and no memory of the network's size.

exact for the linearised model (Cook & Weisberg 1982, *Residuals and Influence in Regression*, §2.2;
the w-test's correlation ``rho_kl = -H_kl / sqrt(r_k r_l)`` as in Baarda's procedure). The network's
curvature changes the downdated vᵀPv by about 1e-8 relative after a marginal rejection (a move of
about one σ; ``tests/test_snooping_rounds.py``). The adjustment
is re-run after :data:`MAX_DOWNDATES` downdates (the linearisation's drift), after the
rejection of a gross error (|w| > :data:`LINEAR_W_MAX`: its removal moves the solution far enough
for the curvature to show, 1e-6 relative in vᵀPv at 50σ) and whenever the procedure would stop, so the decision to stop and every reported number come from a
full adjustment; only the statistics recorded for the intermediate rounds are the downdated ones.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust import statistics as st
from multilat.network.model.angle_rows import KIND_NAMES, angle_rows, angle_w
from multilat.network.adjust.distance.fit import check_network, control_ids, station_map
from multilat.network.adjust.distance.fit_state import Fit

__all__ = ["Procedure", "Rounds",
           "LinearRounds", "LINEAR_MIN_OBS", "LINEAR_W_MAX", "snooping_round", "detection_step", "angle_outliers",
           "n_tested"]

#: networks with at least this many distances use the downdated rounds (smaller ones are re-adjusted
#: after every rejection: fast anyway, and the exact path)
LINEAR_MIN_OBS = 20_000
#: a rejection with a larger |w| (a gross error, whose removal moves the solution by many σ) is
#: followed by a new adjustment; the downdate serves the marginal rejections (|w| a little above the
#: critical value: the w-tests' false alarms on large networks), where the model is linear to ~1e-8
LINEAR_W_MAX = 10.0
#: downdates before the next adjustment (each marginal rejection moves the linearisation by ~1e-8
#: relative in vᵀPv; nothing of the network's size is kept per downdate)
MAX_DOWNDATES = 64


@dataclass(frozen=True)
class RoundStats:
    """What the detection step reads of a round downdated from the last fit (a :class:`Fit` has the
    same fields)."""

    residual_w: np.ndarray
    redundancy: np.ndarray
    vtpv: float
    dof: int
    sigma0: float


class LinearRounds:
    """The state of the rounds since the last adjustment ``core`` (a :class:`Fit` of
    :func:`multilat.network.adjust.distance.fit.fit_once`) of the observations ``global_index`` (their rows in the
    caller's observations). Indices ``k`` below are positions in that adjustment's observations."""

    def __init__(self, core: Fit, global_index: np.ndarray, station_index, target_index,
                 n_stations: int, n_targets: int):
        self.cov = core.cov
        self.v = np.array(core.residual_w, float, copy=True)
        self.red = np.array(core.redundancy, float, copy=True)
        self.vtpv = float(core.vtpv)
        self.dof = int(core.dof)
        self.gidx = np.asarray(global_index)
        self.si = np.asarray(station_index)
        self.ti = np.asarray(target_index)
        m = self.v.size
        self.alive = np.ones(m, bool)
        # each downdate's hat row c_r = A C g_r kept as its generator g_r, a combination of design rows:
        # (station part (Q s,), targets touched (p,), their parts (p, 3), r_k)
        self.gens: list[tuple[np.ndarray, np.ndarray, np.ndarray, float]] = []
        self._last: tuple | None = None
        self.cap = MAX_DOWNDATES
        inc = np.zeros((n_stations, n_targets), bool)
        inc[self.si, self.ti] = True
        self.incidence = inc

    @staticmethod
    def applies(core: Fit, sub, datum) -> bool:
        """Distances only (no angles, bars or weighted control), one reading per pair, a free or 3-2-1
        datum, and a network large enough to need it."""
        if sub.n_obs < LINEAR_MIN_OBS or core.angles is not None or core.coupled is not None:
            return False
        if datum.kind == "control":
            return False
        return sub.distinct_pairs().size == sub.n_obs

    @property
    def pending(self) -> int:
        """Rejections since the last adjustment."""
        return len(self.gens)

    @property
    def full(self) -> bool:
        return len(self.gens) >= self.cap

    def stats(self) -> "RoundStats":
        """What the detection step reads: residual_w, redundancy (0 for the left-out), vtpv, dof, sigma0."""
        sigma0 = float(np.sqrt(self.vtpv / self.dof)) if self.dof > 0 else float("nan")
        return RoundStats(self.v, self.red, self.vtpv, self.dof, sigma0)

    def w(self) -> np.ndarray:
        return st.w_statistics(self.v, None, self.red)

    def hat_row(self, k: int) -> np.ndarray:
        """Row ``k`` of the current hat matrix (the last adjustment's plus the downdates)::

            H' e_k = H e_k + sum_r c_r c_r[k] / r_r = A C g,   g = a_k + sum_r g_r (g_r . C a_k) / r_r

        (``c_r = A C g_r``, ``C`` symmetric): two passes over the observations whatever the number of
        downdates, and nothing of length ``m`` kept between rounds."""
        cov = self.cov
        k = int(k)
        ns = cov.n_station_params                      # station parameters, then 3 per target
        g = cov.design_row(k)
        gt = g[ns:].reshape(cov.t, 3)
        tj = np.array([int(self.ti[k])])
        if not self.gens:
            c = np.array(cov.hat_row(k), float, copy=True)
        else:
            y = cov.internal_times(g)
            yg, yt = y[:ns], y[ns:].reshape(cov.t, 3)
            betas = [(float(rg @ yg) + float(np.sum(rv * yt[rj]))) / rho for rg, rj, rv, rho in self.gens]
            for beta, (rg, rj, rv, _) in zip(betas, self.gens):
                g[:ns] += beta * rg
                np.add.at(gt, rj, beta * rv)
            tj = np.unique(np.concatenate([tj] + [rj for _, rj, _, _ in self.gens]))
            c = cov.design_times(cov.internal_times(g))
        c[~self.alive] = 0.0
        self._last = (k, g[:ns].copy(), tj, gt[tj].copy())
        return c

    def twins(self, k: int, c: np.ndarray, tol: float = 1e-6) -> np.ndarray:
        """Observations other than ``k`` whose w-test is perfectly correlated with ``k``'s (as
        :meth:`multilat.network.adjust.covariance.NetworkCovariance.perfectly_correlated`)."""
        out = st.correlated_with(np.abs(c), self.red, k, tol)     # c itself is kept for the downdate
        out = out[self.alive[out]]
        return out[out != k]

    def keeps_structure(self, k: int, need_per_station: int = 7) -> bool:
        """Whether leaving out ``k`` surely keeps the network solvable: its station keeps at least
        ``need_per_station`` distances (more than any station's unknowns + 1), the redundancy stays
        positive, and the distance lies on a 4-cycle (station–target–station–target), so the network
        stays connected. False means "not sure": the caller checks the whole structure."""
        i, j = int(self.si[k]), int(self.ti[k])
        inc = self.incidence
        if int(inc[i].sum()) - 1 < need_per_station or self.dof - 1 < 1:
            return False
        others = np.flatnonzero(inc[:, j])
        others = others[others != i]
        if others.size == 0:
            return False
        common = inc[others] & inc[i]
        common[:, j] = False
        return bool(common.any())

    def reject(self, k: int, c: np.ndarray) -> None:
        """Leave out observation ``k`` (``c`` its current hat row)."""
        rho = float(self.red[k])
        vk = float(self.v[k])
        self.v += c * (vk / rho)
        self.red -= c * c / rho
        np.clip(self.red, 0.0, 1.0, out=self.red)
        self.vtpv -= vk * vk / rho
        self.dof -= 1
        self.alive[k] = False
        self.v[k] = 0.0
        self.red[k] = 0.0
        self.incidence[self.si[k], self.ti[k]] = False
        if self._last is None or self._last[0] != k:
            self.hat_row(k)                       # the generator of c (normally made just before)
        _, gs, tj, tv = self._last
        self.gens.append((gs, tj, tv, rho))
        self._last = None


# ---------------------------------------------------------------- one round of the procedure
def n_tested(obs) -> int:
    """How many observations data snooping tests: the distances and the angles (the n of the
    family-wise rule, :func:`multilat.network.adjust.statistics.test_levels`)."""
    return obs.n_obs + sum(int(np.count_nonzero(np.isfinite(a))) for a in (obs.sigma_azimuth_rad,
                                                                         obs.sigma_elevation_rad) if a is not None)


@dataclass(frozen=True)
class Procedure:
    """The test procedure of the snooping rounds: whether to snoop, at most ``limit`` rejections, the
    variance factor unknown (τ-test), the w-tests' ``alpha``, the levels ``alpha_g``
    (:class:`multilat.network.adjust.statistics.TestLevels`), Baarda's ``lam0`` and the critical value ``crit``."""

    do_snoop: bool
    limit: int
    unknown: bool
    alpha: float
    alpha_g: object
    lam0: float
    crit: float


@dataclass
class Rounds:
    """What the rounds have done: one record per round (``steps``), the rejected distances
    ``(k, w, statistic, critical, test)`` and the rejected angles (dicts), in order."""

    steps: list = field(default_factory=list)
    rejected: list = field(default_factory=list)
    ang_rejected: list = field(default_factory=list)


def snooping_round(obs, obs_w, used, core: Fit, lin, rounds: Rounds, proc: Procedure, model):
    """One round of detection, identification and adaptation on the last adjustment ``core`` (or its
    downdate ``lin``) of the network ``model`` (:class:`multilat.network.adjust.distance.adjust.Model`: datum, points,
    held offsets and scales, couplings). Appends the round to ``rounds.steps`` and a rejection to
    ``rounds.rejected`` / ``rounds.ang_rejected``. Returns ``("stop", (unlocated, reason))``,
    ``("distance", new used mask)`` or ``("angle", observations without the rejected angle)``."""
    steps, rejected, ang_rejected = rounds.steps, rounds.rejected, rounds.ang_rejected
    unknown, alpha, alpha_g, lam0, crit = proc.unknown, proc.alpha, proc.alpha_g, proc.lam0, proc.crit
    datum, points = model.datum, model.points
    if not proc.do_snoop or len(rejected) + len(ang_rejected) >= proc.limit:
        return "stop", ((), "")
    state = core if lin is None else lin.stats()
    to_global = np.flatnonzero(used) if lin is None else lin.gidx
    w_sub = st.w_statistics(state.residual_w, None, state.redundancy)
    k_sub = int(np.argmax(np.abs(w_sub)))
    w_ang = angle_w(core, lam0) if core.angles is not None else np.zeros(0)
    angle_first = w_ang.size > 0 and np.max(np.abs(w_ang)) > abs(w_sub[k_sub])
    w_top = w_ang[int(np.argmax(np.abs(w_ang)))] if angle_first else w_sub[k_sub]
    step = detection_step(state, w_top, unknown, alpha, alpha_g, lam0, crit)
    steps.append(step)
    # detection first: data snooping only while the global test fails (Baarda's DIA procedure;
    # with it passing, the w-tests' own false alarms at alpha over thousands of observations
    # would reject good distances). Variance factor unknown: Pope's τ-test of the largest |τ|.
    if step["detection_passed"] is not False or not step["identified"]:
        return "stop", ((), "")
    if angle_first:
        # the largest |w| is an angle's: reject that angle (the row's distance and other angle stay)
        k, kind, w_a, why = _angle_to_reject(core, w_ang, obs_w, used)
        step["index"], step["kind"] = k, kind            # the row of the observations table, its angle
        if why:
            return "stop", ((), why)
        step["action"] = "rejected"
        ang_rejected.append({"row": k, "kind": kind, "w": w_a, "test": step["test_k"],
                             "statistic": step["statistic_k"], "critical": step["critical_k"],
                             "step": len(steps)})
        return "angle", _without_angle(obs_w, k, kind)
    k = int(to_global[k_sub])
    step["index"], step["kind"] = k, "distance"       # adjust/3: one way to name a row (was "observation")
    # is the fault locatable? another observation whose w-test is perfectly (|rho| > 1 - 1e-6)
    # correlated with this one would show the same |w|: the data cannot tell which is wrong
    if lin is None:
        twins = core.cov.perfectly_correlated(k_sub, core.redundancy)
        twins = twins[twins != k_sub]
    else:
        c = lin.hat_row(k_sub)
        twins = lin.twins(k_sub, c)
    if twins.size:
        return "stop", (tuple(int(to_global[q]) for q in np.concatenate([[k_sub], twins])),
                        "perfectly correlated w-tests: the data cannot tell which observation is wrong")
    trial = used.copy()
    trial[k] = False
    why = _last_redundancy(obs, used, trial, k, datum, points)
    if why:
        return "stop", ((k,), why)
    if lin is None or not lin.keeps_structure(k_sub):
        try:
            check_network(obs.subset(trial), datum, points, model.off_free[station_map(obs, trial)],
                          model.sc_free[station_map(obs, trial)], warn=False, couplings=model.couplings)
        except MultilatError as exc:
            # rejecting it would make the network unsolvable: keep it, report it as not rejected
            return "stop", ((k,), f"rejecting it would leave the network unsolvable ({exc})")
    step["action"] = "rejected"
    rejected.append((k, float(w_sub[k_sub]), step["statistic_k"], step["critical_k"], step["test_k"]))
    if lin is not None:
        lin.reject(k_sub, c)
    return "distance", trial


def _angle_to_reject(core, w, obs_w, used) -> tuple[int, str, float, str]:
    """The angle with the largest |w| (``w`` per angle row of ``core``): its row in the observations,
    its kind, its w, and why it must not be rejected ("" when it may): its station would keep too few
    angles for its orientation."""
    rows = core.angles["rows"]
    q = int(np.argmax(np.abs(w)))
    k = int(np.flatnonzero(used)[rows.obs_index[q]])
    kind = KIND_NAMES[rows.kind[q]]
    try:
        angle_rows(_without_angle(obs_w, k, kind).subset(used))
    except MultilatError as exc:
        return k, kind, float(w[q]), f"rejecting it would leave its station's orientation unsolvable ({exc})"
    return k, kind, float(w[q]), ""


def _without_angle(obs, k: int, kind: str):
    """``obs`` with the ``kind`` ("azimuth"/"elevation") angle of row ``k`` no longer an observation."""
    sa = np.array(obs.sigma_azimuth_rad, float, copy=True) if obs.sigma_azimuth_rad is not None else None
    se = np.array(obs.sigma_elevation_rad, float, copy=True) if obs.sigma_elevation_rad is not None else None
    (sa if kind == "azimuth" else se)[k] = np.nan
    return obs.with_angle_sigma(sa, se)


def angle_outliers(obs, rejected: list[dict], res) -> tuple:
    """The rejected angles (JSON-ready, in order) with their residuals against the final solution."""
    from multilat.network.model.angles import predicted_angles, wrap_angle

    out = []
    for n, r in enumerate(rejected):
        k = r["row"]
        sid, tid = obs.station_ids[obs.station_index[k]], obs.target_ids[obs.target_index[k]]
        resid = float("nan")
        if sid in res.orientations and sid in res.station_ids and tid in res.target_ids:
            i, j = res.station_ids.index(sid), res.target_ids.index(tid)
            az, el = predicted_angles(res.station_xyz_m[[i]], [res.orientations[sid]["orientation_rad"]],
                                      res.target_xyz_m[[j]], [0], [0])
            resid = float(wrap_angle(obs.azimuth_rad[k] - az[0]) if r["kind"] == "azimuth"
                          else obs.elevation_rad[k] - el[0])
        out.append({"index": k, "station": sid, "target": tid, "kind": r["kind"], "w": r["w"], "residual_rad": resid,
                    "test": r["test"], "statistic": r["statistic"], "critical": r["critical"],
                    "step": r["step"], "order": n + 1})
    return tuple(out)


def detection_step(core, w_max, unknown, alpha, alpha_g, lam0, crit) -> dict:
    """One round of detection and identification: the global test (variance factor known; the largest
    |w| when ``alpha_g`` is a :class:`~.statistics.TestLevels` detecting by ``"max |w|"``) or Pope's
    τ-test of the largest |τ| (unknown), and whether the largest |w| (|τ|) exceeds its critical value.
    ``core``: a :class:`Fit` or :class:`RoundStats`, or a mapping with ``dof``, ``sigma0``, ``vtpv``
    (the general layer's rounds, :mod:`multilat.network.adjust.general.snooping`)."""
    if isinstance(core, dict):
        from types import SimpleNamespace

        core = SimpleNamespace(**core)
    dof = core.dof
    if unknown:
        tau = float(w_max / core.sigma0) if core.sigma0 > 0 else 0.0
        tc = st.tau_critical(alpha, dof)
        failed = bool(abs(tau) > tc) if np.isfinite(tc) else None
        return {"dof": dof, "test": "tau-max", "statistic": abs(tau), "critical": tc, "alpha": alpha,
                "sigma0": core.sigma0, "detection_passed": None if failed is None else not failed,
                "identified": bool(failed), "statistic_k": tau, "critical_k": tc, "test_k": "tau",
                "action": "none"}
    if getattr(alpha_g, "detection", "global chi2") == "max |w|":
        # Šidák (large networks): the largest |w| against the critical value of the family-wise alpha
        # is the detection test (power: each w-test's against λ0); the χ² test (of the variance factor,
        # in the result) starts nothing
        failed = bool(abs(w_max) > crit)
        return {"dof": dof, "test": "max |w|", "statistic": abs(float(w_max)), "critical": crit,
                "alpha": alpha_g.alpha_family, "power": alpha_g.power, "sigma0": core.sigma0,
                "detection_passed": not failed, "identified": failed, "statistic_k": float(w_max),
                "critical_k": crit, "test_k": "w", "action": "none"}
    gt = st.global_test(core.vtpv, dof, alpha=alpha_g(dof), lambda0=lam0)
    return {"dof": dof, "test": "global chi2", "statistic": gt.statistic, "critical": gt.critical,
            "alpha": gt.alpha, "power": gt.power, "sigma0": core.sigma0,
            "detection_passed": gt.passed, "identified": bool(abs(w_max) > crit),
            "statistic_k": float(w_max), "critical_k": crit, "test_k": "w", "action": "none"}


def _last_redundancy(obs, used, trial, k, datum, points) -> str:
    """Why rejecting observation ``k`` must not happen (it takes a point's last redundancy), or ""."""
    j = int(obs.target_index[k])
    tid = obs.target_ids[j]
    of_j = obs.target_index == j
    before = int(np.count_nonzero(of_j & used))
    after = int(np.count_nonzero(of_j & trial))
    fixed = datum.kind == "control" and tid in control_ids(obs.subset(used), datum, points)
    need = 1 if fixed else 4          # a control target: any distance checks it; a free one: 3 + 1
    if before >= need > after:
        what = "control point" if fixed else "target"
        return (f"rejecting it would leave {what} {tid!r} with {after} observation(s), without "
                "redundancy")
    return ""
