"""The steps of :func:`multilat.network.adjust.distance.adjust.adjust` around its main loop: the minimum search from
the first adjustment (:func:`search_minimum`), a start the solver refused as a partial fit, the
one-gross-error rule, and the result's parts read from the last fit (bars and weighted control,
w-test failure groups, the covariance scaled by σ̂0²)."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust import statistics as st
from multilat.network.model.data import Observations
from multilat.network.adjust.distance.fit import raise_unconverged
from multilat.network.adjust.distance.fit_state import Fit
from multilat.network.model.problem import Params
from multilat.network.adjust.distance.result import Start
from multilat.network.adjust.approximate.search import P_MIN, p_value
from multilat.network.adjust.approximate.starts import PARTIAL_RESTARTS

__all__ = ["coupling_results", "scaled_cov", "search_minimum", "start_as_partial", "w_failure_groups"]


def coupling_results(core: Fit) -> tuple[tuple, tuple]:
    """The scale bars' and weighted control points' residuals and redundancy numbers (JSON-ready)."""
    c = core.coupled
    if c is None:
        return (), ()
    cp, res, red = c["couplings"], c["residual_m"], c["redundancy"]
    k = cp.bar_a.size
    w = st.w_statistics(res, cp.sigma_m, red)          # Baarda w, as the distances' (v / σ√r)
    bars = tuple({"target_a": a, "target_b": b, "length_m": float(cp.bar_length_m[q]), "sigma_m": float(cp.bar_sigma_m[q]),
                  "adjusted_m": float(cp.bar_length_m[q] - res[q]), "residual_m": float(res[q]),
                  "redundancy": float(red[q]), "w": float(w[q])} for q, (a, b) in enumerate(cp.bar_ids))
    ctrl = tuple({"point": pid, "xyz_m": cp.prior_value_m[3 * q:3 * q + 3].tolist(),
                  "std_m": cp.prior_sigma_m[3 * q:3 * q + 3].tolist(),
                  "residual_m": res[k + 3 * q:k + 3 * q + 3].tolist(),
                  "redundancy": red[k + 3 * q:k + 3 * q + 3].tolist(),
                  "w": w[k + 3 * q:k + 3 * q + 3].tolist()} for q, pid in enumerate(cp.prior_ids))
    return bars, ctrl


def scaled_cov(cov, f: float):
    """The covariance ``cov`` times ``f`` (σ̂0² with an unknown variance factor); a low-rank ``extra``
    term (a reference length's own uncertainty) is not scaled."""
    import copy

    c = copy.copy(cov)
    c.factor = cov.factor * f
    if cov.G is not None:
        c.CHt = cov.CHt * f
        c.HCHt = cov.HCHt * f
    return c


def search_minimum(obs, core: Fit, start, model, rng):
    """:func:`multilat.network.adjust.approximate.search.find_minimum` from the first adjustment ``core`` (converged or
    the lowest-cost point it reached) of the network ``model`` (:class:`multilat.network.adjust.distance.adjust.Model`);
    returns the best fit and the search record. Raises the non-convergence error when no start
    converges."""
    from types import SimpleNamespace

    from multilat.network.adjust.approximate.search import Candidate, find_minimum

    used = np.ones(obs.n_obs, bool)

    def wrap(c):
        return SimpleNamespace(station_xyz_m=c.sx, target_xyz_m=c.tx, offset_m=c.off,
                               vtpv=c.vtpv, dof=c.dof, core=c)

    def solve(st_, *, held_offsets=False):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return wrap(model.fit(obs, st_, start, obs, used, warn=False, cost="distance",
                                  held_offsets=held_offsets))

    def continuation(st_):
        """Offsets held at zero first (a better conditioned problem for weak, flat networks), then
        the full problem from there."""
        return solve(solve(st_, held_offsets=True))

    gen = np.random.default_rng(rng)
    restarts = []
    if core.partial:
        # the first solve did not converge: the same start by continuation, then other initial
        # values (the random starts of initial_values), before searching around the lowest-cost
        # point it reached
        from multilat.network.adjust.approximate.bounds import RESTART_SECONDS, Bound, report
        from multilat.network.adjust.approximate.initial import initial_values

        bound = Bound("restarts after a first solve that did not converge", max_work=PARTIAL_RESTARTS,
                      max_seconds=RESTART_SECONDS)

        def starts():
            yield "the first start, offsets held then freed", lambda: continuation(start)
            while not bound.exhausted():       # bounded by work and wall time (network/adjust/approximate/bounds.py)
                bound.spend()
                report(f"first solve did not converge: random start {bound.work} of {PARTIAL_RESTARTS}")
                yield (f"initial values, random start {bound.work}, offsets held then freed",
                       lambda: continuation(initial_values(obs, rng=gen, deadline=bound.deadline)))

        for label, attempt in starts():
            try:
                cand = attempt()
            except MultilatError as exc:
                restarts.append({"label": label, "cost": None, "note": str(exc)[:200]})
                continue
            restarts.append({"label": label, "cost": cand.vtpv})
            core = cand.core
            break
        bound.warn_if_timed_out()
    first = wrap(core)
    if not core.partial and _one_gross_error(core):
        # one observation carries most of the excess: a gross error, for data snooping, not a wrong
        # minimum (which spreads its misfit over many distances); the search is not run
        res = _without_core(find_minimum(obs, solve, first, rng=gen, max_rounds=0))
        return core, replace(res, warning=None, candidates=(Candidate(
            "not searched: one observation carries most of the excess (a gross error)", None, None,
            False),))
    res = find_minimum(obs, solve, first, rng=gen)
    if restarts:
        res = replace(res, candidates=tuple(Candidate(r["label"], r["cost"], None, r["cost"] is not None,
                                                      r.get("note", "")) for r in restarts) + res.candidates)
    best = res.solution.core
    if best.partial:
        if best.error is not None:
            raise best.error
        raise_unconverged(obs, Params(best.sx, best.tx, best.off, np.zeros(obs.n_stations)), best.convergence)
    return best, _without_core(res)


def _without_core(res):
    """The search record without its solution's adjustment (the caller holds that one as ``core``;
    the record, kept to the end of :func:`adjust`, would otherwise keep the first adjustment's
    arrays alive through every later one: ~300 MB at 1.6 M distances)."""
    from types import SimpleNamespace

    sol = SimpleNamespace(**{k: v for k, v in vars(res.solution).items() if k != "core"})
    return replace(res, solution=sol)


def start_as_partial(obs: Observations, start: Start, error: MultilatError) -> Fit:
    """A start that the solver refused (near-degenerate there) as the lowest-cost point of a first
    solve: the minimum search restarts from other initial values; ``error`` is raised if none works."""
    from multilat.network.adjust.solve import Convergence

    rho = np.linalg.norm(start.station_xyz_m[obs.station_index] - start.target_xyz_m[obs.target_index], axis=1)
    v = (obs.distance_m - rho - start.offset_m[obs.station_index]) / obs.sigma_m
    n_unknown = 4 * obs.n_stations + 3 * obs.n_targets - 6
    return Fit(partial=True, sx=start.station_xyz_m, tx=start.target_xyz_m, off=start.offset_m,
               vtpv=float(v @ v), dof=obs.n_obs - n_unknown, error=error,
               convergence=Convergence(False, 0, float("inf"), str(error)))


def _one_gross_error(core) -> bool:
    """Whether one observation explains the failure: without its squared normalised residual
    ``w_k^2`` (its contribution to vtpv when rejected) the global test no longer fails by far. A single
    blunder does; a wrong minimum spreads its misfit over many distances and does not."""
    red = core.redundancy
    w = st.w_statistics(core.residual_w, None, red)
    w2 = float(np.max(w ** 2, initial=0.0))
    return core.dof > 1 and p_value(core.vtpv - w2, core.dof - 1) >= P_MIN


def w_failure_groups(core: Fit, used, crit, limit: int = 50) -> tuple:
    """Every w-test failing at the end (|w| > crit), grouped by perfect correlation (|rho| > 1 - 1e-6):
    a group of several is a fault the data cannot locate. Indices into the full observations; at
    most ``limit`` groups, largest |w| first."""
    red = core.redundancy
    w = st.w_statistics(core.residual_w, None, red)
    fail = np.flatnonzero(np.abs(w) > crit)
    fail = fail[np.argsort(-np.abs(w[fail]))]
    idx = np.flatnonzero(used)
    seen: set[int] = set()
    groups = []
    for k in fail:
        if int(k) in seen or len(groups) >= limit:
            continue
        members = [int(q) for q in core.cov.perfectly_correlated(int(k), red)]
        members = [int(k)] + [q for q in members if q != k]
        seen.update(members)
        groups.append(tuple(int(idx[q]) for q in members))
    return tuple(groups)
