"""Self-calibrating multilateration: one least-squares adjustment for station coordinates, target
coordinates and station offsets (and optionally scales) from distances alone, with statistics.

Entry point :func:`adjust`; the result is an :class:`AdjustmentResult` (frozen dataclass).
Model and costs: :mod:`multilat.network.model`; datum: :mod:`multilat.network.datum`;
statistics: :mod:`multilat.network.statistics`; solvability: :mod:`multilat.network.solvability`.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from multilat.errors import MultilatError
from multilat.network import statistics as st
from multilat.network.covariance import NetworkCovariance
from multilat.network.data import Observations, Points, ReferenceLengths
from multilat.network.datum import (Datum, apply_rigid, datum_matrices, frame_321, parse_datum,
                                    rigid_fit)
from multilat.network.model import COSTS, Q
from multilat.network.problem import Params, Problem
from multilat.network.result import (AdjustmentResult, InterpointDistance, Outlier, Start,
                                     build_result)
from multilat.network.exclusion import exclude_weak_points, zero_redundancy_warnings
from multilat.network.solvability import check_structure, flat_geometry
from multilat.network.solve import choose_backend, gauss_newton, make_backend, solve_reduced
from multilat.network.solve.loop import check_target_blocks
from multilat.network.solve.system import weighted_cost, whitened

__all__ = ["adjust", "AdjustmentResult", "Outlier", "InterpointDistance", "Start"]


# ====================================================================== solver internals
def _as_start(initial, obs: Observations) -> Start:
    try:
        sx = np.array(initial.station_xyz_m, dtype=float)
        tx = np.array(initial.target_xyz_m, dtype=float)
        off = np.array(initial.offset_m, dtype=float)
    except AttributeError:
        raise MultilatError("initial values need station_xyz_m, target_xyz_m and offset_m") from None
    if sx.shape != (obs.n_stations, 3) or tx.shape != (obs.n_targets, 3) or off.shape != (obs.n_stations,):
        raise MultilatError(f"initial values: expected shapes ({obs.n_stations}, 3), ({obs.n_targets}, 3), "
                            f"({obs.n_stations},), got {sx.shape}, {tx.shape}, {off.shape}")
    if not (np.all(np.isfinite(sx)) and np.all(np.isfinite(tx)) and np.all(np.isfinite(off))):
        raise MultilatError("initial values must be finite")
    return Start(sx, tx, off)


PARTIAL_RESTARTS = 6   # random initial-value starts tried when the first solve does not converge
LARGE_TARGETS = 500   # above: initial values from a seed network + multilateration (network.large)


def _initial(obs: Observations, given: Start | None, points: Points | None, rng) -> tuple[Start, dict]:
    """Initial values and how they were found: given; or all from ``points``; or from distances
    (fitted onto ``points``)."""
    if given is not None:
        return given, {"method": "given"}
    if points is not None:
        have = [points.get(i) is not None for i in obs.station_ids + obs.target_ids]
        if all(have):
            return Start(np.array([points.get(i) for i in obs.station_ids]),
                         np.array([points.get(i) for i in obs.target_ids]),
                         np.zeros(obs.n_stations)), {"method": "points"}
    if obs.n_targets > LARGE_TARGETS:
        from multilat.network.large import large_initial_values

        raw = large_initial_values(obs, rng=rng)
        how = {"method": "distances: " + raw.method, "seed_targets": len(raw.seed_target_ids),
               "multilateration_rms_m": raw.multilateration_rms_m}
    else:
        raw, how = _initial_small(obs, rng)
    iv = _as_start(raw, obs)
    if points is not None:
        ids = [i for i in obs.station_ids + obs.target_ids if points.get(i) is not None]
        if len(ids) >= 3:
            allx = np.vstack([iv.station_xyz_m, iv.target_xyz_m])
            allids = obs.station_ids + obs.target_ids
            src = np.array([allx[allids.index(i)] for i in ids])
            try:
                R, t = rigid_fit(src, np.array([points.get(i) for i in ids]))
            except MultilatError:
                R, t = np.eye(3), np.zeros(3)
            iv = Start(apply_rigid(R, t, iv.station_xyz_m), apply_rigid(R, t, iv.target_xyz_m), iv.offset_m)
    return iv, how


def _initial_small(obs: Observations, rng):
    """:func:`initial_values` on the targets seen by 4+ stations, then the others (3 stations:
    two mirror positions) by multilateration from those stations, on the side of the rest.

    Initial values that come out flat (stations on one plane, targets on one line, where the
    distances say otherwise: a collapsed solution of a weak network) are retried from other random
    starts, up to ``PARTIAL_RESTARTS`` times."""
    from multilat.network.initial import initial_values
    from multilat.network.large import multilaterate_targets

    gen = np.random.default_rng(rng)
    weak = np.bincount(obs.target_index, minlength=obs.n_targets) < 4
    strong_obs = ~weak[obs.target_index]
    sub = obs if not weak.any() else obs.subset(strong_obs)
    if sub.n_stations != obs.n_stations:
        raise MultilatError("initial values from distances need every station to see targets that 4 or "
                            "more stations see; give approximate coordinates (--points)")
    for attempt in range(PARTIAL_RESTARTS + 1):
        raw = initial_values(sub, rng=gen)
        if not flat_geometry(raw.station_xyz_m, raw.target_xyz_m, sigma_m=float(np.median(sub.sigma_m)),
                             n_obs=sub.n_obs):
            break
    how = {"method": f"distances: {raw.method}", "rms_residual_m": float(raw.rms_residual_m)}
    if attempt:
        how["flat_restarts"] = attempt
    if not weak.any():
        return raw, how
    tx = np.empty((obs.n_targets, 3))
    tx[~weak] = raw.target_xyz_m
    wk = np.flatnonzero(weak)
    remap = np.full(obs.n_targets, -1)
    remap[wk] = np.arange(wk.size)
    rows = ~strong_obs
    x, _, _ = multilaterate_targets(raw.station_xyz_m, raw.offset_m, obs.station_index[rows],
                                    remap[obs.target_index[rows]], obs.distance_m[rows], obs.sigma_m[rows],
                                    wk.size, side_point_m=raw.target_xyz_m.mean(axis=0),
                                    target_ids=[obs.target_ids[j] for j in wk])
    tx[wk] = x
    how["method"] += f" + multilateration of {wk.size} target(s) seen by 3"
    return Start(raw.station_xyz_m, tx, raw.offset_m), how


def _pick_321_stations(sx) -> tuple[int, int, int]:
    """Three stations spanning the largest triangle (for the internal minimal constraint)."""
    s = sx.shape[0]
    best, bi = -1.0, (0, 1, 2)
    combos = itertools.combinations(range(s), 3) if s <= 40 else [
        (0, int(np.argmax(np.linalg.norm(sx - sx[0], axis=1))), None)]
    for c in combos:
        if c[2] is None:
            a, b = c[0], c[1]
            area = np.linalg.norm(np.cross(sx[b] - sx[a], sx - sx[a]), axis=1)
            k = int(np.argmax(area))
            c = (a, b, k)
        a, b, k = c
        area = np.linalg.norm(np.cross(sx[b] - sx[a], sx[k] - sx[a]))
        if area > best:
            best, bi = area, (a, b, k)
    return bi


def _raise_unconverged(obs, p: Params, conv) -> None:
    _raise_if_flat(obs, p.station_xyz_m, p.target_xyz_m, "no convergence")
    raise MultilatError(f"the adjustment did not converge ({conv.reason} after {conv.iterations} "
                        f"iterations, last step {conv.last_step_sigma:.3g} sigma); check the initial "
                        "values, the geometry and the distances for gross errors")


def _raise_if_flat(obs, sx, tx, when: str) -> None:
    """Raise the one-line 'near-degenerate geometry (when): cause' if the points are (nearly)
    coplanar stations or collinear targets by :func:`solvability.flat_geometry`."""
    cause = flat_geometry(sx, tx, sigma_m=float(np.median(obs.sigma_m)), n_obs=obs.n_obs)
    if cause:
        raise MultilatError(f"near-degenerate geometry ({when}): {cause}")


def _fixed_offsets(offsets, obs: Observations):
    """(offset_free (s,) bool, fixed values (s,)) from the ``offsets`` option."""
    s = obs.n_stations
    free = np.ones(s, bool)
    val = np.zeros(s)
    if offsets is None or (isinstance(offsets, str) and offsets == "estimate"):
        return free, val
    if isinstance(offsets, Mapping):
        for k, v in offsets.items():
            if k not in obs.station_ids:
                raise MultilatError(f"offsets: unknown station id {k!r}")
            i = obs.station_ids.index(k)
            if not np.isfinite(v):
                raise MultilatError(f"offsets: value for {k!r} must be finite")
            free[i], val[i] = False, float(v)
        return free, val
    try:
        v = float(offsets)
    except (TypeError, ValueError):
        raise MultilatError(f"offsets must be None/'estimate', a number or a mapping, got {offsets!r}") from None
    if not np.isfinite(v):
        raise MultilatError("offsets must be finite")
    return np.zeros(s, bool), np.full(s, v)


def _scale_flags(scales, obs):
    s = obs.n_stations
    if scales is False or scales is None:
        return np.zeros(s, bool)
    if scales is True:
        return np.ones(s, bool)
    out = np.zeros(s, bool)
    for k in scales:
        if k not in obs.station_ids:
            raise MultilatError(f"scales: unknown station id {k!r}")
        out[obs.station_ids.index(k)] = True
    return out


# ====================================================================== public
def adjust(obs: Observations, *, datum: Datum | str | None = "free", initial=None,
           points: Points | None = None, cost: str = "distance", offsets=None, scales=False,
           alpha: float = 0.001, power: float = 0.80, alpha_global: float = 0.05,
           snooping: bool = True, max_rejections: int | None = None, max_iter: int = 100,
           solver: str = "auto", strict: bool = False, scale_bar: ReferenceLengths | None = None,
           chunk_targets: int = 20000, rng=None) -> AdjustmentResult:
    """Adjust a self-calibrating multilateration network.

    Unknowns: station coordinates, target coordinates, one additive offset per station (estimated
    unless fixed) and optionally one scale per station; model ``d = (1 + k_i)|H_i - T_j| + o_i``.
    Solved by Gauss-Newton with Levenberg-Marquardt damping on the normal equations reduced by the
    Schur complement over the 3x3 target blocks (cost linear in the number of targets).

    Parameters
    ----------
    obs : Observations
        Distances with a-priori uncertainties ``sigma_m``.
    datum : Datum or str
        ``"free"`` (inner constraints over all points; ``"free:P1,P2,.."`` over chosen points),
        ``"321:A,B,C"`` (A at origin, B on +x, C in xy-plane), or ``"control"`` /
        ``"control:P1,.."`` (the given ``points`` held fixed). See :mod:`multilat.network.datum`.
    initial : object with ``station_xyz_m`` (s, 3), ``target_xyz_m`` (t, 3), ``offset_m`` (s,), optional
        Initial values. Default: ``points`` when they cover every point, else
        :func:`multilat.network.initial.initial_values` from the distances (rigidly fitted onto
        ``points`` when >= 3 are given).
    points : Points, optional
        Approximate coordinates (their frame is the frame of the ``free`` datum) or control. Ids
        that are in no observation are ignored with a ``UserWarning`` naming them.
    cost : "distance" or "squared"
        ``"distance"``: residuals in metres weighted by ``1/sigma``; ``"squared"``: the paper's
        eq. (6), unweighted squared-distance differences (covariance scaled by the a-posteriori
        variance; no global test or data snooping, which need known weights).
    offsets : None, "estimate", float or mapping station -> metres
        Estimate all offsets (default), fix all to one value, or fix the named ones.
    scales : bool or iterable of station ids
        Estimate a scale per station (all, or the named ones). Default: none. With every station's
        scale estimated the network's scale is a 7th datum defect: give ``scale_bar``.
    scale_bar : ReferenceLengths with one row, optional
        A reference length (with its uncertainty ``u_m``) as the scale datum when every station's
        scale is estimated: the adjusted length equals it, and its uncertainty enters every
        coordinate's covariance along the scale direction.
    strict : bool
        Refuse the network when a point is too weakly observed, instead of leaving it out
        (``excluded`` in the result, with a warning).
    alpha : float
        Significance of Baarda's w-test (two-sided) for data snooping; also the MDBs' alpha.
    power : float
        Power of the test for the minimal detectable biases (Baarda: 0.80).
    alpha_global : float
        Significance of the global χ² test (one-sided, upper).
    snooping : bool
        Iteratively reject the observation with the largest ``|w|`` above the critical value and
        re-adjust, while the network stays solvable (at most ``max_rejections``).
    max_iter : int
        Iteration limit of the Gauss-Newton loop (the stopping rule is relative to sigma:
        :mod:`multilat.network.solve.convergence`).
    solver : "auto", "dense" or "sparse"
        Linear-algebra back end (:mod:`multilat.network.solve`): a choice of speed only, the
        results are the same. ``auto``: sparse above 20 000 observations when it applies.
    chunk_targets : int
        Targets per chunk in the normal-equation assembly.
    rng : numpy Generator, int or None
        Passed to ``initial_values`` (if used).

    Returns
    -------
    AdjustmentResult

    Raises
    ------
    MultilatError
        Unsolvable network (disconnected, too few observations, degenerate geometry: coplanar
        stations and collinear targets are tested on the initial coordinates), control coordinates
        inconsistent with the distances (``datum="control"``, tested before data snooping), bad
        options, or no convergence — one line naming the cause.
    """
    if not isinstance(obs, Observations):
        raise MultilatError("adjust: obs must be an Observations")
    if cost not in COSTS:
        raise MultilatError(f"cost must be one of {', '.join(COSTS)}, got {cost!r}")
    for name, v in (("alpha", alpha), ("power", power), ("alpha_global", alpha_global)):
        if not (0 < v < 1):
            raise MultilatError(f"{name} must be in (0, 1), got {v!r}")
    datum = parse_datum(datum)
    off_free, off_val = _fixed_offsets(offsets, obs)
    sc_free = _scale_flags(scales, obs)
    if datum.kind == "control" and points is None:
        raise MultilatError("datum control needs control coordinates (points)")
    if points is not None:
        known = set(obs.station_ids) | set(obs.target_ids)
        stray = [i for i in points.ids if i not in known]
        if stray:
            warnings.warn(f"points: {len(stray)} id(s) not in the observations, ignored: "
                          f"{', '.join(stray[:8])}{'...' if len(stray) > 8 else ''}",
                          UserWarning, stacklevel=2)
    given = None if initial is None else _as_start(initial, obs)
    if obs.n_stations < 3:
        raise MultilatError(f"a self-calibrating network needs at least 3 stations, got {obs.n_stations} "
                            f"({', '.join(obs.station_ids)})")
    # weak points are left out (named), not a reason to refuse the network
    ctrl = _control_ids(obs, datum, points) if datum.kind == "control" else set()
    keep, excluded = exclude_weak_points(obs, offset_free=off_free, scale_free=sc_free, fixed_targets=ctrl,
                                         strict=strict)
    if excluded:
        if not keep.any():
            raise MultilatError(f"nothing left to adjust: {excluded[0].kind} {excluded[0].id!r} "
                                f"{excluded[0].reason}")
        for e in excluded:
            warnings.warn(f"{e.kind} {e.id!r} left out: {e.reason}", UserWarning, stacklevel=2)
        smap, tmap = _station_map(obs, keep), _target_map(obs, keep)
        obs = obs.subset(keep)
        off_free, off_val, sc_free = off_free[smap], off_val[smap], sc_free[smap]
        if given is not None:
            given = Start(given.station_xyz_m[smap], given.target_xyz_m[tmap], given.offset_m[smap])
    bar = None
    if scale_bar is not None:
        bar = _scale_bar(scale_bar, obs, sc_free, datum, cost)
        sc_free = sc_free.copy()
        sc_free[0] = False          # the internal minimal constraint on the scale; the bar fixes it
    _check_scale_datum(obs, sc_free, datum)
    try:
        _structure(obs, datum, points, off_free, sc_free, warn=True)   # before any initial values
    except MultilatError as exc:
        if not excluded:
            raise
        left = "; ".join(f"{e.kind} {e.id!r} ({e.reason})" for e in excluded[:3])
        raise MultilatError(f"{exc} — after leaving out {left}") from None
    notes = zero_redundancy_warnings(obs, ctrl)
    for msg in notes:
        warnings.warn(msg, UserWarning, stacklevel=2)
    start, how = _initial(obs, given, points, rng)
    if how["method"] in ("given", "points"):
        # coplanar stations / collinear targets make the problem singular: say so before solving
        # (computed initial values that came out flat are a bad start, left to the solver and the search)
        _raise_if_flat(obs, start.station_xyz_m, start.target_xyz_m, "initial coordinates")
    start = Start(start.station_xyz_m, start.target_xyz_m,
                  np.where(off_free, start.offset_m, off_val))
    do_snoop = snooping and cost == "distance"
    used = np.ones(obs.n_obs, bool)
    rejected: list[tuple[int, float]] = []
    limit = obs.n_obs if max_rejections is None else int(max_rejections)
    crit = st.w_critical(alpha)
    warn = True
    guess = start
    unlocated: tuple = ()
    reason = ""
    first = True
    while True:
        sub = obs if used.all() else obs.subset(used)
        core = _adjust_once(sub, datum, guess, start, obs, used, points, cost, off_free, off_val,
                            sc_free, max_iter, solver, chunk_targets, warn=warn,
                            partial_ok=first and cost == "distance")
        if first and cost == "distance":
            # a converged result failing the global test by far may be a wrong minimum: search
            core, search = _search_minimum(obs, core, start, points, datum, off_free, off_val, sc_free,
                                           max_iter, solver, chunk_targets, rng)
            how["search"] = search.as_dict()
            if search.warning:
                notes.append(search.warning)
                warnings.warn(search.warning, UserWarning, stacklevel=2)
        if first and datum.kind == "control" and cost == "distance":
            # a failed global test under control may be the control coordinates, not the distances:
            # test them (against the free network) before data snooping blames the distances
            _check_control(obs, core, start, points, off_free, off_val, sc_free, alpha_global,
                           max_iter, solver, chunk_targets, datum)
        first = False
        # the next adjustment (after a rejection) starts from this solution
        gs, gt_, go = guess.station_xyz_m.copy(), guess.target_xyz_m.copy(), guess.offset_m.copy()
        gs[core["smap"]], gt_[core["tmap"]], go[core["smap"]] = core["sx"], core["tx"], core["off"]
        guess = Start(gs, gt_, go)
        warn = False
        if not do_snoop or len(rejected) >= limit:
            break
        w_sub = st.w_statistics(core["residual_w"], np.ones_like(core["residual_w"]), core["redundancy"])
        order = np.argsort(-np.abs(w_sub))
        k_sub = int(order[0])
        if not abs(w_sub[k_sub]) > crit:
            break
        k = int(np.flatnonzero(used)[k_sub])
        # is the fault locatable? another observation whose w-test is perfectly (|rho| > 1 - 1e-6)
        # correlated with this one would show the same |w|: the data cannot tell which is wrong
        red_sub = core["redundancy"]
        hrow = core["cov"].hat_row(k_sub)
        with np.errstate(divide="ignore", invalid="ignore"):
            rho = -hrow / np.sqrt(red_sub[k_sub] * red_sub)
        rho[k_sub] = 0.0
        twins = np.flatnonzero(np.abs(np.nan_to_num(rho)) > 1.0 - 1e-6)
        if twins.size:
            unlocated = tuple(int(np.flatnonzero(used)[q]) for q in np.concatenate([[k_sub], twins]))
            reason = "perfectly correlated w-tests: the data cannot tell which observation is wrong"
            break
        trial = used.copy()
        trial[k] = False
        why = _last_redundancy(obs, used, trial, k, datum, points)
        if why:
            unlocated, reason = (k,), why
            break
        try:
            _structure(obs.subset(trial), datum, points, off_free[_station_map(obs, trial)],
                       sc_free[_station_map(obs, trial)], warn=False)
        except MultilatError as exc:
            # rejecting it would make the network unsolvable: keep it, report it as not rejected
            unlocated, reason = (k,), f"rejecting it would leave the network unsolvable ({exc})"
            break
        rejected.append((k, float(w_sub[k_sub])))
        used = trial
    if bar is not None:
        core = _apply_scale_bar(core, bar, obs, used, datum, start, points, off_free, off_val, sc_free,
                                max_iter, solver, chunk_targets)
        how["scale_datum"] = {"kind": "reference length", "points": [bar[0], bar[1]], "length_m": bar[2],
                              "u_m": bar[3]}
    res = build_result(obs, used, rejected, unlocated, core, datum, cost, alpha, power, alpha_global,
                       reason=reason, snooped=do_snoop)
    groups = _w_failure_groups(core, used, crit) if cost == "distance" else ()
    return replace(res, excluded=excluded, warnings=tuple(notes), w_failure_groups=groups, initial=how)


def _search_minimum(obs, core, start, points, datum, off_free, off_val, sc_free, max_iter, solver,
                    chunk_targets, rng):
    """:func:`multilat.network.search.find_minimum` from the first adjustment (converged or the
    lowest-cost point it reached); returns the best core and the search record. Raises the
    non-convergence error when no start converges."""
    from types import SimpleNamespace

    from multilat.network.search import Candidate, find_minimum

    used = np.ones(obs.n_obs, bool)

    def wrap(c):
        return SimpleNamespace(station_xyz_m=c["sx"], target_xyz_m=c["tx"], offset_m=c["off"],
                               vtpv=c["vtpv"], dof=c["dof"], core=c)

    def solve(st_, *, held_offsets=False):
        of, ov = (np.zeros_like(off_free), np.zeros_like(off_val)) if held_offsets else (off_free, off_val)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return wrap(_adjust_once(obs, datum, st_, start, obs, used, points, "distance", of,
                                     ov, sc_free, max_iter, solver, chunk_targets, warn=False))

    def continuation(st_):
        """Offsets held at zero first (a better conditioned problem for weak, flat networks), then
        the full problem from there."""
        return solve(solve(st_, held_offsets=True))

    gen = np.random.default_rng(rng)
    restarts = []
    if core.get("partial"):
        # the first solve did not converge: the same start by continuation, then other initial
        # values (the random starts of initial_values), before searching around the lowest-cost
        # point it reached
        from multilat.network.initial import initial_values

        def starts():
            yield "the first start, offsets held then freed", lambda: continuation(start)
            for k in range(PARTIAL_RESTARTS):
                yield (f"initial values, random start {k + 1}, offsets held then freed",
                       lambda: continuation(initial_values(obs, rng=gen)))

        for label, attempt in starts():
            try:
                cand = attempt()
            except MultilatError as exc:
                restarts.append({"label": label, "cost": None, "note": str(exc)[:200]})
                continue
            restarts.append({"label": label, "cost": cand.vtpv})
            core = cand.core
            break
    first = wrap(core)
    res = find_minimum(obs, solve, first, rng=gen)
    if restarts:
        res = replace(res, candidates=tuple(Candidate(r["label"], r["cost"], None, r["cost"] is not None,
                                                      r.get("note", "")) for r in restarts) + res.candidates)
    best = res.solution.core
    if best.get("partial"):
        conv = best["convergence"]
        _raise_unconverged(obs, Params(best["sx"], best["tx"], best["off"], np.zeros(obs.n_stations)), conv)
    return best, res


def _w_failure_groups(core, used, crit, limit: int = 50) -> tuple:
    """Every w-test failing at the end (|w| > crit), grouped by perfect correlation (|rho| > 1 - 1e-6):
    a group of several is a fault the data cannot locate. Indices into the full observations; at
    most ``limit`` groups, largest |w| first."""
    red = core["redundancy"]
    w = st.w_statistics(core["residual_w"], np.ones_like(core["residual_w"]), red)
    fail = np.flatnonzero(np.abs(w) > crit)
    fail = fail[np.argsort(-np.abs(w[fail]))]
    idx = np.flatnonzero(used)
    seen: set[int] = set()
    groups = []
    for k in fail:
        if int(k) in seen or len(groups) >= limit:
            continue
        with np.errstate(divide="ignore", invalid="ignore"):
            rho = -core["cov"].hat_row(int(k)) / np.sqrt(red[k] * red)
        rho[k] = 1.0
        members = [int(q) for q in np.flatnonzero(np.abs(np.nan_to_num(rho)) > 1.0 - 1e-6)]
        members = [int(k)] + [q for q in members if q != k]
        seen.update(members)
        groups.append(tuple(int(idx[q]) for q in members))
    return tuple(groups)


def _check_scale_datum(obs: Observations, sc_free, datum) -> None:
    """Distances fix the size of a network through the scales held fixed: with every station's scale
    estimated (and no control points) the scale is a 7th datum defect."""
    if datum.kind == "control" or not np.all(sc_free):
        return
    raise MultilatError("every station's scale is estimated, so the network's scale is undetermined (a 7th "
                        "datum defect): estimate the scales of some stations only (--scales A,B) so the "
                        "others fix it, hold one station's scale (--fixed-scale STATION), or fix the "
                        "scale by a reference length (--references FILE --scale-bar)")


def _scale_bar(refs: ReferenceLengths, obs: Observations, sc_free, datum, cost):
    """Validate a reference length as the scale datum: (a, b, length_m, u_m)."""
    if len(refs) != 1:
        raise MultilatError(f"scale bar: one reference length fixes the scale, got {len(refs)} (several scale "
                            "bars as weighted observations are not supported yet)")
    refs.check_ids(obs.station_ids + obs.target_ids)
    if datum.kind == "control" or cost != "distance":
        raise MultilatError("scale bar: needs the free or 321 datum and the distance cost (control points "
                            "already fix the scale)")
    if not np.all(sc_free):
        raise MultilatError("scale bar: the stations whose scale is held already fix the network's scale; "
                            "a scale bar is the scale datum when every station's scale is estimated "
                            "(--scales)")
    u = float(refs.u_m[0])
    return refs.target_a[0], refs.target_b[0], float(refs.length_m[0]), 0.0 if np.isnan(u) else u


def _apply_scale_bar(core, bar, obs, used, datum, start, points, off_free, off_val, sc_free, max_iter,
                     solver, chunk_targets):
    """Move the adjusted network (scale held on its first station) along the exact similarity that
    leaves every distance residual unchanged — coordinates times ``f`` about their centroid, each
    ``1 + k_i`` divided by ``f`` — so that the bar's length is the reference; re-adjust there (the
    Jacobian at the scaled solution) and express the covariance in the datum whose 7th condition
    is the bar's length, plus the bar's own uncertainty along the scale direction."""
    from types import SimpleNamespace

    sub = obs if used.all() else obs.subset(used)
    smap, tmap = core["smap"], core["tmap"]
    ids = list(sub.station_ids + sub.target_ids)
    xyz = np.vstack([core["sx"], core["tx"]])
    a, b, L_ref, u_L = bar
    ia, ib = ids.index(a), ids.index(b)
    f = L_ref / float(np.linalg.norm(xyz[ia] - xyz[ib]))
    c = xyz.mean(axis=0)
    xyz = c + f * (xyz - c)
    s = sub.n_stations
    S_all, T_all = obs.n_stations, obs.n_targets
    sx_all, tx_all = np.zeros((S_all, 3)), np.zeros((T_all, 3))
    off_all, sc_all = np.zeros(S_all), np.zeros(S_all)
    sx_all[smap], tx_all[tmap] = xyz[:s], xyz[s:]
    off_all[smap], sc_all[smap] = core["off"], (1.0 + core["sc"]) / f - 1.0
    scaled = SimpleNamespace(station_xyz_m=sx_all, target_xyz_m=tx_all, offset_m=off_all, scale=sc_all)
    new = _adjust_once(sub, datum, scaled, start, obs, used, points, "distance", off_free, off_val, sc_free,
                       max_iter, solver, chunk_targets, warn=False)
    sx, tx, sc = new["sx"], new["tx"], new["sc"]
    G, E = datum_matrices(datum, sub.station_ids, sub.target_ids, sx, tx)
    n = G.shape[0]
    rows = np.concatenate([(Q * np.arange(s)[:, None] + np.arange(3)).ravel(), Q * s + np.arange(3 * sub.n_targets)])
    pts = np.vstack([sx, tx])
    g_s = np.zeros(n)
    g_s[rows] = (pts - pts.mean(axis=0)).ravel()
    g_s[Q * np.arange(s) + 4] = -(1.0 + sc)
    e_bar = np.zeros(n)
    d = pts[ia] - pts[ib]
    d /= np.linalg.norm(d)
    e_bar[rows[3 * ia:3 * ia + 3]] = d
    e_bar[rows[3 * ib:3 * ib + 3]] = -d
    g_hat = g_s - G @ np.linalg.solve(E.T @ G, E.T @ g_s)
    cov = new["cov"]
    new["cov"] = NetworkCovariance(cov.Qgg, cov.Minv, cov.Js_w, cov.Jt_w, cov.si, cov.ti, factor=cov.factor,
                                   R=cov.R, G=np.column_stack([G, g_s]), E=np.column_stack([E, e_bar]),
                                   extra=(u_L / L_ref) * g_hat[:, None] if u_L > 0 else None)
    new["sc_free"] = np.ones(s, bool)
    return new


def _last_redundancy(obs, used, trial, k, datum, points) -> str:
    """Why rejecting observation ``k`` must not happen (it takes a point's last redundancy), or ""."""
    j = int(obs.target_index[k])
    tid = obs.target_ids[j]
    before = int(np.sum(obs.target_index[used] == j))
    after = int(np.sum(obs.target_index[trial] == j))
    fixed = datum.kind == "control" and tid in _control_ids(obs.subset(used), datum, points)
    need = 1 if fixed else 4          # a control target: any distance checks it; a free one: 3 + 1
    if before >= need > after:
        what = "control point" if fixed else "target"
        return (f"rejecting it would leave {what} {tid!r} with {after} observation(s), without "
                "redundancy")
    return ""


def _check_control(obs, core, start, points, off_free, off_val, sc_free, alpha_global, max_iter,
                   solver, chunk_targets, datum) -> None:
    """Raise if the control coordinates are inconsistent with the distances.

    The adjustment with the control held fixed has ``Omega_c = v^T P v`` on ``dof_c``; the free
    network of the same distances ``Omega_f`` on ``dof_f``. With a-priori weights, consistent
    control gives ``Omega_c - Omega_f ~ chi2(dof_c - dof_f)`` independent of the distances' own
    misfit (a blunder inflates both). Only run when the global test under control fails.
    """
    gt = st.global_test(core["vtpv"], core["dof"], alpha=alpha_global)
    if gt.passed is None or gt.passed:
        return
    used = np.ones(obs.n_obs, bool)
    ctrl = sorted(_control_ids(obs, datum, points))
    guess = Start(core["sx"], core["tx"], core["off"])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            free = _adjust_once(obs, parse_datum("free"), guess, guess, obs, used, None, "distance",
                                off_free, off_val, sc_free, max_iter, solver, chunk_targets, warn=False)
    except MultilatError:
        return            # not solvable without the control: nothing to compare; snooping goes on
    k = core["dof"] - free["dof"]
    if k <= 0:
        return
    stat = core["vtpv"] - free["vtpv"]
    from scipy import stats

    crit = float(stats.chi2.ppf(1.0 - alpha_global, k))
    if not stat > crit:
        return
    ids = obs.station_ids + obs.target_ids
    xyz = dict(zip(ids, np.vstack([free["sx"], free["tx"]])))
    src = np.array([xyz[i] for i in ctrl])
    dst = np.array([points.get(i) for i in ctrl])
    R, t = rigid_fit(src, dst)
    mis = np.linalg.norm(apply_rigid(R, t, src) - dst, axis=1)
    w = int(np.argmax(mis))
    raise MultilatError(
        f"control coordinates inconsistent with the distances (σ0 = {core['sigma0']:.3g} with the "
        f"control held fixed, {free['sigma0']:.3g} free; global test {gt.statistic:.1f} > "
        f"{gt.critical:.1f}; control test χ² = {stat:.1f} > {crit:.1f} on {k} dof; largest misfit "
        f"{ctrl[w]!r} {mis[w] * 1e3:.2f} mm after a rigid fit): check the control points or use "
        "--datum free")


def _station_map(obs, used):
    """Indices (into obs.station_ids) of the stations present in obs.subset(used), in its order."""
    return np.flatnonzero(np.bincount(obs.station_index[used], minlength=obs.n_stations) > 0)


def _target_map(obs, used):
    return np.flatnonzero(np.bincount(obs.target_index[used], minlength=obs.n_targets) > 0)


def _structure(sub, datum, points, off_free, sc_free, *, warn):
    fixed_t = np.zeros(sub.n_targets, bool)
    fixed_sc = 0
    defect = 6
    if datum.kind == "control":
        ctrl = _control_ids(sub, datum, points)
        fixed_t = np.array([t in ctrl for t in sub.target_ids])
        fixed_sc = 3 * sum(s in ctrl for s in sub.station_ids)
        defect = 0
    return check_structure(sub, offset_free=off_free, scale_free=sc_free, fixed_targets=fixed_t,
                           fixed_station_coords=fixed_sc, datum_defect=defect, warn=warn)


def _control_ids(sub, datum, points):
    given = [i for i in sub.station_ids + sub.target_ids if points.get(i) is not None]
    ids = given if datum.points is None else list(datum.points)
    for i in ids:
        if i not in sub.station_ids + sub.target_ids:
            raise MultilatError(f"datum control: unknown point id {i!r}")
        if points.get(i) is None:
            raise MultilatError(f"datum control: no coordinates given for {i!r}")
    if len(ids) < 3:
        raise MultilatError(f"datum control needs at least 3 control points, got {len(ids)}")
    sv = np.linalg.svd(np.array([points.get(i) for i in ids]) - np.mean([points.get(i) for i in ids], 0),
                       compute_uv=False)
    if sv[1] <= 1e-9 * sv[0]:
        raise MultilatError("datum control: the control points are collinear")
    return set(ids)


def _adjust_once(sub, datum, start, ref_start, obs, used, points, cost, off_free_all, off_val_all,
                 sc_free_all, max_iter, solver, chunk_targets, *, warn, partial_ok=False):
    """One adjustment of the observations ``sub`` (a subset of ``obs``) from ``start``;
    ``ref_start`` gives the reference coordinates of the free datum. Returns a dict of arrays in
    ``sub``'s order plus the maps back."""
    smap, tmap = _station_map(obs, used), _target_map(obs, used)
    off_free, off_val, sc_free = off_free_all[smap], off_val_all[smap], sc_free_all[smap]
    _structure(sub, datum, points, off_free, sc_free, warn=False)
    s, t = sub.n_stations, sub.n_targets
    sx0 = start.station_xyz_m[smap].copy()
    tx0 = start.target_xyz_m[tmap].copy()
    off0 = np.where(off_free, start.offset_m[smap], off_val)
    sc0 = np.asarray(getattr(start, "scale", np.zeros(len(start.offset_m))), float)[smap].copy()
    gfree = np.ones((s, Q), bool)
    gfree[:, 3] = off_free
    gfree[:, 4] = sc_free
    tfree = np.ones(t, bool)
    all_ids = sub.station_ids + sub.target_ids
    if datum.kind == "control":
        ctrl = _control_ids(sub, datum, points)
        # bring the initial values into the control frame first (rigid fit on the control points)
        cur = dict(zip(all_ids, np.vstack([sx0, tx0])))
        cids = sorted(ctrl)
        Rc, tc = rigid_fit(np.array([cur[i] for i in cids]), np.array([points.get(i) for i in cids]))
        sx0, tx0 = apply_rigid(Rc, tc, sx0), apply_rigid(Rc, tc, tx0)
        for i, sid in enumerate(sub.station_ids):
            if sid in ctrl:
                sx0[i] = points.get(sid)
                gfree[i, :3] = False
        for j, tid in enumerate(sub.target_ids):
            if tid in ctrl:
                tx0[j] = points.get(tid)
                tfree[j] = False
        R0, t0 = np.eye(3), np.zeros(3)
    else:
        if datum.kind == "321":
            for p in datum.points:
                if p not in all_ids:
                    raise MultilatError(f"datum 321: unknown point id {p!r}")
        a, b, c = _pick_321_stations(sx0)
        R0, t0 = frame_321(sx0[a], sx0[b], sx0[c])
        sx0, tx0 = apply_rigid(R0, t0, sx0), apply_rigid(R0, t0, tx0)
        gfree[a, :3] = False
        gfree[b, 1:3] = False
        gfree[c, 2] = False
    pb = Problem(sub, cost, gfree, tfree)
    backend = make_backend(pb, choose_backend(pb, solver), chunk_targets=chunk_targets)
    p, conv = gauss_newton(pb, Params(sx0, tx0, off0, sc0), backend, max_iter=max_iter)
    if not conv.converged:
        if partial_ok:      # the lowest-cost point reached: a start for the minimum search
            return dict(partial=True, sx=p.station_xyz_m, tx=p.target_xyz_m, off=p.offset_m,
                        vtpv=weighted_cost(pb, p), dof=pb.dof, convergence=conv)
        _raise_unconverged(sub, p, conv)
    sx, tx, off, sc = p.station_xyz_m, p.target_xyz_m, p.offset_m, p.scale
    # final normal equations at the solution
    fin = backend.assemble(p, 0.0)
    check_target_blocks(fin.Ntt, pb)
    _, Qgg, cond = solve_reduced(fin.N, fin.b, gfree.ravel(), pb, p)
    r_w, Js_w, Jt_w = whitened(pb, p)
    dof = pb.dof
    vtpv = float(r_w @ r_w)
    sigma0 = float(np.sqrt(vtpv / dof)) if dof > 0 else float("nan")
    factor = 1.0 if cost == "distance" else (sigma0 ** 2 if dof > 0 else float("nan"))
    # move to the requested datum
    if datum.kind == "control":
        R, tr, G, E = np.eye(3), np.zeros(3), None, None
    else:
        if datum.kind == "321":
            xyz = {i: p for i, p in zip(all_ids, np.vstack([sx, tx]))}
            R, tr = frame_321(xyz[datum.points[0]], xyz[datum.points[1]], xyz[datum.points[2]])
        else:
            ids = all_ids if datum.points is None else datum.points
            for p in ids:
                if p not in all_ids:
                    raise MultilatError(f"datum free: unknown point id {p!r}")
            ref = {i: p for i, p in zip(all_ids, np.vstack([ref_start.station_xyz_m[smap],
                                                             ref_start.target_xyz_m[tmap]]))}
            if points is not None:
                ref.update({i: points.get(i) for i in ids if points.get(i) is not None})
            cur = {i: p for i, p in zip(all_ids, np.vstack([sx, tx]))}
            R, tr = rigid_fit(np.array([cur[i] for i in ids]), np.array([ref[i] for i in ids]))
        sx, tx = apply_rigid(R, tr, sx), apply_rigid(R, tr, tx)
        G, E = datum_matrices(datum, sub.station_ids, sub.target_ids, sx, tx)
    cov = NetworkCovariance(Qgg, fin.Ntt_inv, Js_w, Jt_w, sub.station_index, sub.target_index,
                            factor=factor, R=R, G=G, E=E)
    h = cov.hat_diagonal(chunk_targets)
    red = np.clip(1.0 - h, 0.0, 1.0)
    return dict(smap=smap, tmap=tmap, sx=sx, tx=tx, off=off, sc=sc, off_free=off_free, sc_free=sc_free,
                chunk_targets=chunk_targets, residual_w=r_w, redundancy=red, sigma0=sigma0, dof=dof,
                vtpv=vtpv, iterations=conv.iterations, cond=cond, cov=cov, convergence=conv,
                solver=backend.name)
