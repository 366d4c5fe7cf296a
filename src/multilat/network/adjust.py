"""Self-calibrating multilateration: one least-squares adjustment for station coordinates, target
coordinates and station offsets (and optionally scales) from distances alone, with statistics.

Entry point :func:`adjust`: options, weak points left out (:mod:`.exclusion`), initial values
(:mod:`.starts`), the first adjustment (:mod:`.fit`, on the solver family :mod:`.solve`), the
minimum search (:mod:`.search`), data snooping, the scale datum (:mod:`.scale_datum`); the result
is an :class:`~.result.AdjustmentResult`. Model: :mod:`.model`; datum: :mod:`.datum`;
statistics: :mod:`.statistics`; solvability: :mod:`.solvability`.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from multilat.errors import MultilatError
from multilat.network import statistics as st
from multilat.network.ambiguity import check_geometry, side_fixed_targets
from multilat.network.data import Observations, Points, ReferenceLengths
from multilat.network.datum import Datum, parse_datum
from multilat.network.exclusion import (UndeterminedTargets, exclude_weak_points, leaving_out_undetermined,
                                        raise_undetermined, zero_redundancy_warnings)
from multilat.network.fit import (as_start, check_control, check_network, control_ids, fit_once, raise_if_flat,
                                  raise_unconverged, station_map, target_map)
from multilat.network.model import COSTS
from multilat.network.problem import Params
from multilat.network.result import (AdjustmentResult, InterpointDistance, Outlier, Start,
                                     build_result)
from multilat.network.search import P_MIN, p_value
from multilat.network.sigma_source import describe as describe_sigma
from multilat.network.couplings import coupling_spec
from multilat.network.angle_rows import angle_results
from multilat.network.snooping import LINEAR_W_MAX, LinearRounds, angle_outliers, n_tested, snooping_round
from multilat.network.scale_datum import check_scale_datum
from multilat.network.starts import PARTIAL_RESTARTS, initial_for
from multilat.network.unit_slip import check_unit_slip, noise_free

__all__ = ["adjust", "AdjustmentResult", "Outlier", "InterpointDistance", "Start"]


def _head_stations(key, obs: Observations, what: str) -> np.ndarray:
    """Mask (s,) of the stations of head ``key`` (offsets and scales belong to heads; a head is its
    station when the observations name no heads)."""
    hos = obs.head_of_station
    if key not in hos:
        if key in obs.station_ids:
            i = obs.station_ids.index(key)
            raise MultilatError(f"{what}: {key!r} is a station of head {hos[i]!r}; offsets and scales belong "
                                "to heads: name the head")
        raise MultilatError(f"{what}: unknown {'station' if obs.station_heads is None else 'head'} id {key!r}")
    return np.array([h == key for h in hos])


def _fixed_offsets(offsets, obs: Observations):
    """(offset_free (s,) bool, fixed values (s,)) from the ``offsets`` option (keys: head ids)."""
    s = obs.n_stations
    free = np.ones(s, bool)
    val = np.zeros(s)
    if offsets is None or (isinstance(offsets, str) and offsets == "estimate"):
        return free, val
    if isinstance(offsets, Mapping):
        for k, v in offsets.items():
            m = _head_stations(k, obs, "offsets")
            if not np.isfinite(v):
                raise MultilatError(f"offsets: value for {k!r} must be finite")
            free[m], val[m] = False, float(v)
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
        out |= _head_stations(k, obs, "scales")
    return out


# ====================================================================== public
def adjust(obs: Observations, *, datum: Datum | str | None = "free", initial=None,
           points: Points | None = None, cost: str = "distance", offsets=None, scales=False,
           alpha: float = 0.001, power: float = 0.80, alpha_global: float | None = None,
           test_method: str | None = None, variance_factor: str = "known", mdb_limit_sigma: float = 10.0,
           alpha_family: float = st.ALPHA_FAMILY,
           r_min: float = 0.1, sigma_source: dict | None = None, snooping: bool = True,
           max_rejections: int | None = None, max_iter: int = 100, solver: str = "auto", strict: bool = False,
           scale_bars: ReferenceLengths | None = None, scale_bar: ReferenceLengths | None = None,
           chunk_targets: int = 20000, rng=0, _undetermined: dict | None = None) -> AdjustmentResult:
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
    offsets : None, "estimate", float or mapping head -> metres
        Estimate all offsets (default), fix all to one value, or fix the named heads' ones (a head
        is its station when ``obs`` names no heads; a head occupying several stations has one offset).
    scales : bool or iterable of head ids
        Estimate a scale per head (all, or the named ones). Default: none. With every station's
        scale estimated the network's scale is a 7th datum defect: give ``scale_bar``.
    scale_bars : ReferenceLengths, optional
        Reference lengths between points used as **observations** (scale bars), each weighted by its
        standard uncertainty ``u_m`` (> 0): they take part in the adjustment (residuals, redundancy,
        the global test) and are enough to be the scale datum when every head's scale is estimated
        (one bar: its adjusted length is the reference, its uncertainty enters every coordinate's
        covariance along the scale direction). ``scale_bar`` is the same (older name).
    points : with ``sx_m, sy_m, sz_m`` (``Points.std_m``) under ``datum="control"``: the rows with
        uncertainties are **weighted control** (their coordinates are observations), the others hard.
    strict : bool
        Refuse the network when a point is too weakly observed, instead of leaving it out
        (``excluded`` in the result, with a warning).
    alpha : float
        alpha0: significance of each one-observation test (Baarda's w-test, or Pope's τ-test with
        ``variance_factor="unknown"``), two-sided; also the MDBs' alpha; with ``auto`` an upper bound.
    alpha_family : float
        Family-wise significance of the w-tests (``auto``, ``sidak``: :func:`statistics.test_levels`).
    power : float
        Power of the tests for the minimal detectable biases (Baarda: 0.80).
    alpha_global : float, optional
        Significance of the global χ² test (one-sided, upper); giving it means ``test_method="fixed"``
        (whose default is 0.05).
    test_method : "auto", "b-method", "sidak", "fixed" or None
        None: ``fixed`` when ``alpha_global`` is given, else ``auto`` (the B-method while its w-tests'
        family-wise alpha is at most ``alpha_family``, else ``sidak``: :func:`statistics.test_levels`).
        ``b-method``: Baarda's, the global test's alpha derived from ``alpha``, ``power`` and the dof
        (:func:`statistics.b_method_alpha_global`); ``fixed``: ``alpha_global`` as given.
    variance_factor : "known" or "unknown"
        ``known`` (default): the a-priori σ are right in scale; detection by the global χ² test,
        identification by w-tests. ``unknown``: σ0 is estimated; identification by Pope's τ-test
        (τ = w / σ̂0, Student-t based critical value), covariances and MDBs scaled by σ̂0².
    mdb_limit_sigma, r_min : float
        An observation is poorly controlled when its MDB exceeds ``mdb_limit_sigma`` times its σ or
        its redundancy number is below ``r_min`` (:mod:`multilat.network.reliability`).
    sigma_source : dict, optional
        Where the σ of the observations came from (kept in the result and its JSON).
    snooping : bool
        Detection, identification, adaptation: while the detection test fails (the global test; the
        largest τ with an unknown variance factor) reject the observation with the largest ``|w|``
        above the critical value and re-adjust, while the network stays solvable (at most
        ``max_rejections``).
    max_iter : int
        Iteration limit of the Gauss-Newton loop (the stopping rule is relative to sigma:
        :mod:`multilat.network.solve.convergence`).
    solver : "auto", "dense" or "sparse"
        Linear-algebra back end (:mod:`multilat.network.solve`): a choice of speed only, the
        results are the same. ``auto``: sparse above 20 000 observations when it applies.
    chunk_targets : int
        Targets per chunk in the normal-equation assembly.
    rng : numpy Generator, int or None
        Seed of the initial values from distances and of the minimum search (if used). The free
        datum is fitted onto the initial values, so the default 0 gives the same coordinates on
        every run; None draws fresh entropy.

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
    if _undetermined is None:   # a target found undetermined is left out and the network adjusted again
        args = dict(locals())
        return leaving_out_undetermined(lambda u: adjust(**{**args, "_undetermined": u}), strict=strict)
    if not isinstance(obs, Observations):
        raise MultilatError("adjust: obs must be an Observations")
    if cost not in COSTS:
        raise MultilatError(f"cost must be one of {', '.join(COSTS)}, got {cost!r}")
    if test_method is None:     # alpha_global given: a fixed global test; otherwise the rule of test_levels
        test_method = "fixed" if alpha_global is not None else "auto"
    if test_method not in st.TEST_METHODS:
        raise MultilatError(f"test_method must be one of {', '.join(st.TEST_METHODS)}, got {test_method!r}")
    if variance_factor not in st.VARIANCE_FACTORS:
        raise MultilatError(f"variance_factor must be known or unknown, got {variance_factor!r}")
    if alpha_global is not None and test_method != "fixed":
        raise MultilatError(f"alpha_global is derived by test_method={test_method!r}: give test_method='fixed' "
                            "to set it")
    if alpha_global is None and test_method == "fixed":
        alpha_global = 0.05
    for name, v in (("alpha", alpha), ("power", power), ("alpha_global", alpha_global),
                    ("alpha_family", alpha_family)):
        if v is not None and not (0 < v < 1):
            raise MultilatError(f"{name} must be in (0, 1), got {v!r}")
    if not (np.isfinite(mdb_limit_sigma) and mdb_limit_sigma > 0):
        raise MultilatError(f"mdb_limit_sigma must be > 0, got {mdb_limit_sigma!r}")
    # the tests' levels (alpha_g(dof): the global test's); alpha is from here on the w-tests' (Šidák's)
    alpha_g = st.test_levels(n_tested(obs), alpha0=alpha, power=power, method=test_method,
                             alpha_global=alpha_global, alpha_family=alpha_family)
    alpha = alpha_g.alpha0
    # MDBs: Baarda's reference at the given alpha0 (as the design's); the w-tests' own: tests.lambda0_w
    lam0 = st.noncentrality(alpha_g.alpha0_given, power)
    datum = parse_datum(datum)
    if scale_bars is not None and scale_bar is not None:
        raise MultilatError("give scale_bars or scale_bar (the same), not both")
    bars = scale_bars if scale_bars is not None else scale_bar
    if bars is not None and cost != "distance":
        raise MultilatError("scale bars need the distance cost (weighted observations)")
    if points is not None and points.std_m is not None and datum.kind != "control":
        warnings.warn("points: the standard uncertainties (sx_m, sy_m, sz_m) make weighted control under "
                      "--datum control only; here the points are approximate coordinates", UserWarning,
                      stacklevel=2)
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
    given = None if initial is None else as_start(initial, obs)
    if obs.n_stations < 3:
        raise MultilatError(f"a self-calibrating network needs at least 3 stations, got {obs.n_stations} "
                            f"({', '.join(obs.station_ids)})")
    # weak points are left out (named), not a reason to refuse the network
    ctrl = control_ids(obs, datum, points) if datum.kind == "control" else set()
    keep, excluded = exclude_weak_points(obs, offset_free=off_free, scale_free=sc_free, fixed_targets=ctrl,
                                         strict=strict, undetermined=_undetermined)
    if excluded:
        if not keep.any():
            raise MultilatError(f"nothing left to adjust: {excluded[0].kind} {excluded[0].id!r} "
                                f"{excluded[0].reason}")
        for e in excluded:
            warnings.warn(f"{e.kind} {e.id!r} left out: {e.reason}", UserWarning, stacklevel=2)
        smap, tmap = station_map(obs, keep), target_map(obs, keep)
        obs = obs.subset(keep)
        off_free, off_val, sc_free = off_free[smap], off_val[smap], sc_free[smap]
        if given is not None:
            given = Start(given.station_xyz_m[smap], given.target_xyz_m[tmap], given.offset_m[smap])
    cspec = coupling_spec(obs, bars=bars, points=points, control=datum.kind == "control")
    n_bars = 0 if cspec is None else len(cspec.bars)
    check_scale_datum(obs, sc_free, datum, bars=n_bars > 0)
    try:
        check_network(obs, datum, points, off_free, sc_free, warn=True, couplings=cspec)   # before any initial values
    except MultilatError as exc:
        if not excluded:
            raise
        left = "; ".join(f"{e.kind} {e.id!r} ({e.reason})" for e in excluded[:3])
        raise MultilatError(f"{exc} — after leaving out {left}") from None
    notes = zero_redundancy_warnings(obs, ctrl)
    for msg in notes:
        warnings.warn(msg, UserWarning, stacklevel=2)
    start, how = initial_for(obs, given, points, rng)
    if how["method"] in ("given", "points"):
        # coplanar stations / collinear targets make the problem singular: say so before solving
        # (computed initial values that came out flat are a bad start, left to the solver and the search)
        raise_if_flat(obs, start.station_xyz_m, start.target_xyz_m, "initial coordinates")
    start = Start(start.station_xyz_m, start.target_xyz_m,
                  np.where(off_free, start.offset_m, off_val))
    do_snoop = snooping and cost == "distance"
    used = np.ones(obs.n_obs, bool)
    rejected: list[tuple[int, float]] = []
    steps: list[dict] = []
    limit = obs.n_obs if max_rejections is None else int(max_rejections)
    crit = st.w_critical(alpha)
    unknown = variance_factor == "unknown"
    warn = True
    guess = start
    unlocated: tuple = ()
    reason = ""
    first = True
    search_ok = cost == "distance" and datum.kind != "control"
    search = None
    obs_w = obs                      # the observations with the rejected angles left out (σ NaN)
    ang_rejected: list[dict] = []
    lin = None                       # rounds downdated since the last adjustment (large networks)
    refit = True
    while True:
        if refit:
            # the last adjustment and its downdates go before the next is built (peak memory)
            core = lin = None
            sub = obs_w if used.all() else obs_w.subset(used)
            try:
                core = fit_once(sub, datum, guess, start, obs, used, points, cost, off_free, off_val,
                                sc_free, max_iter, solver, chunk_targets, warn=warn,
                                partial_ok=first and search_ok, couplings=cspec)
            except MultilatError as exc:
                # computed initial values can make a solvable network look degenerate (a collapsed
                # start): the search's restarts get their chance before the error is final
                if not (first and search_ok and how["method"].startswith("distances")
                        and ("near-degenerate" in str(exc) or isinstance(exc, UndeterminedTargets))):
                    raise
                core = _start_as_partial(obs, start, exc)
            slip = first and cost == "distance" and not unknown    # a unit slip stops (unit_slip.py)
            if slip and how.get("far_minimum_again"):   # the restarts found this minimum twice: no search
                check_unit_slip(obs, core, sigma_source)
            if first and search_ok:
                # a converged result failing the global test by far may be a wrong minimum: search
                # (not under control points: they give the frame and the start; a failing test there
                # is tested as inconsistent control just below)
                core, search = _search_minimum(obs, core, start, points, datum, off_free, off_val, sc_free,
                                               max_iter, solver, chunk_targets, rng, cspec)
                how["search"] = search.as_dict()
            if first and not core.get("partial"):   # coplanar lines of sight: left out, adjusted again
                raise_undetermined(obs, core, side_fixed_targets(obs, ctrl, cspec))
            if first and datum.kind == "control" and cost == "distance":
                # a failed global test under control may be the control coordinates, not the distances:
                # test them (against the free network) before data snooping blames the distances
                check_control(obs, core, start, points, off_free, off_val, sc_free, alpha_g(core["dof"]),
                               max_iter, solver, chunk_targets, datum, cspec)
            if slip:    # after the search (its best solution) and the control test (control at fault)
                check_unit_slip(obs, core, sigma_source)
            first = False
            # the next adjustment (after a rejection) starts from this solution
            gs, gt_, go = guess.station_xyz_m.copy(), guess.target_xyz_m.copy(), guess.offset_m.copy()
            gs[core["smap"]], gt_[core["tmap"]], go[core["smap"]] = core["sx"], core["tx"], core["off"]
            guess = Start(gs, gt_, go)
            warn = False
            refit = False
            lin = (LinearRounds(core, np.flatnonzero(used), sub.station_index, sub.target_index,
                                sub.n_stations, sub.n_targets)
                   if do_snoop and not core.get("partial") and LinearRounds.applies(core, sub, datum) else None)
        n_steps = len(steps)
        go_on = snooping_round(obs, obs_w, used, core, lin, steps, rejected, ang_rejected, limit, do_snoop,
                                unknown, alpha, alpha_g, lam0, crit, datum, points, off_free, sc_free, cspec)
        if lin is not None and lin.pending and go_on[0] == "stop":
            # the procedure would stop on downdated statistics: adjust again and decide on exact ones
            del steps[n_steps:]
            refit = True
            continue
        action, payload = go_on
        if action == "stop":
            unlocated, reason = payload
            break
        if action == "angle":
            obs_w = payload
            refit = True
        else:                          # a distance rejected
            used = payload
            # a gross error moves the solution far enough for the curvature to matter: adjust again
            refit = lin is None or lin.full or abs(rejected[-1][1]) > LINEAR_W_MAX
    # the rounds' state and the last adjustment's copy of the observations are not needed for the
    # result (at 1.6 M distances ~80 MB, live at the command's peak)
    lin = sub = None
    if search is not None and p_value(core["vtpv"], core["dof"]) < P_MIN:
        # still failing by far after data snooping: a possible false minimum, never passed as ordinary
        msg = search.warning or (
            f"possible false minimum: the global test fails by far (sigma0 "
            f"{core['sigma0']:.3g}, chi-square p {p_value(core['vtpv'], core['dof']):.1e}): check for gross "
            "errors, a-priori sigma too small, or give approximate coordinates")
        notes.append(msg)
        warnings.warn(msg, UserWarning, stacklevel=2)
    if n_bars and datum.kind != "control" and np.all(sc_free):
        how["scale_datum"] = {"kind": "scale bars", "n_bars": n_bars,
                              "points": [cspec.bars[0][0], cspec.bars[0][1]]}
    if unlocated and steps:
        steps[-1]["action"] = f"not rejected: {reason}"
    s0 = core["sigma0"] if unknown and cost == "distance" and np.isfinite(core["sigma0"]) else 1.0
    if s0 != 1.0:
        core = dict(core, cov=_scaled_cov(core["cov"], s0 ** 2))
    final_crit = st.tau_critical(alpha, core["dof"]) * s0 if unknown else crit
    res = build_result(obs, used, rejected, unlocated, core, datum, cost, alpha_g.alpha0_given, power,
                       alpha_g(core["dof"]), reason=reason, snooped=do_snoop, sigma_scale=s0,
                       mdb_limit_sigma=mdb_limit_sigma, r_min=r_min)
    groups = _w_failure_groups(core, used, final_crit) if cost == "distance" else ()
    tests = {"method": alpha_g.method, "variance_factor": variance_factor, "alpha0": alpha, "power": power,
             "lambda0": lam0, "lambda0_w": st.noncentrality(alpha, power), "w_critical": crit,
             "tau_critical": st.tau_critical(alpha, core["dof"]) if unknown else None,
             "alpha_global": alpha_g(core["dof"]), **alpha_g.as_dict(), "steps": steps}
    judged = cost == "distance" and not noise_free(obs, res.residuals_m[used])   # σ0 in m² for eq. 6
    check = st.sigma0_check(res.sigma0 if judged else float("nan"), res.dof,
                            variance_factor=variance_factor, source=describe_sigma(sigma_source or {}))
    if check["message"]:
        notes.append(check["message"])
        warnings.warn(check["message"], UserWarning, stacklevel=2)
    bars_out, ctrl_out = coupling_results(core)
    ang_out, orient = angle_results(core, lam0, final_crit)
    res = replace(res, excluded=excluded, warnings=tuple(notes), w_failure_groups=groups, initial=how,
                  sigma0_check=check,
                   scale_bars=bars_out, weighted_control=ctrl_out, tests=tests,
                   sigma_source=dict(sigma_source or {}), angles=ang_out, orientations=orient,
                   angle_design_w=None if core.get("angles") is None else core["angles"]["design_w"])
    # geometry distances cannot fix: a flat network is refused, mirror-ambiguous points named
    amb, note = check_geometry(res, lambda st_: fit_once(
        obs_w if used.all() else obs_w.subset(used), datum, st_, start, obs, used, points, cost, off_free,
        off_val, sc_free, max_iter, solver, chunk_targets, warn=False, couplings=cspec),
        lambda0=lam0, strict=strict, control=ctrl, couplings=cspec)
    if note:
        warnings.warn(note, UserWarning, stacklevel=2)
        res = replace(res, ambiguous=amb, warnings=res.warnings + (note,))
    return replace(res, angle_outliers=angle_outliers(obs, ang_rejected, res))


def coupling_results(core) -> tuple[tuple, tuple]:
    """The scale bars' and weighted control points' residuals and redundancy numbers (JSON-ready)."""
    c = core.get("coupled")
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


def _scaled_cov(cov, f: float):
    """The covariance ``cov`` times ``f`` (σ̂0² with an unknown variance factor); a low-rank ``extra``
    term (a reference length's own uncertainty) is not scaled."""
    import copy

    c = copy.copy(cov)
    c.factor = cov.factor * f
    if cov.G is not None:
        c.CHt = cov.CHt * f
        c.HCHt = cov.HCHt * f
    return c


def _search_minimum(obs, core, start, points, datum, off_free, off_val, sc_free, max_iter, solver,
                    chunk_targets, rng, cspec=None):
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
            return wrap(fit_once(obs, datum, st_, start, obs, used, points, "distance", of,
                                     ov, sc_free, max_iter, solver, chunk_targets, warn=False,
                                     couplings=cspec))

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
        from multilat.network.bounds import RESTART_SECONDS, Bound, report
        from multilat.network.initial import initial_values

        bound = Bound("restarts after a first solve that did not converge", max_work=PARTIAL_RESTARTS,
                      max_seconds=RESTART_SECONDS)

        def starts():
            yield "the first start, offsets held then freed", lambda: continuation(start)
            while not bound.exhausted():       # bounded by work and wall time (network/bounds.py)
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
    if not core.get("partial") and _one_gross_error(core):
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
    if best.get("partial"):
        if best.get("error") is not None:
            raise best["error"]
        conv = best["convergence"]
        raise_unconverged(obs, Params(best["sx"], best["tx"], best["off"], np.zeros(obs.n_stations)), conv)
    return best, _without_core(res)


def _without_core(res):
    """The search record without its solution's adjustment (the caller holds that one as ``core``;
    the record, kept to the end of :func:`adjust`, would otherwise keep the first adjustment's
    arrays alive through every later one: ~300 MB at 1.6 M distances)."""
    from types import SimpleNamespace

    sol = SimpleNamespace(**{k: v for k, v in vars(res.solution).items() if k != "core"})
    return replace(res, solution=sol)


def _start_as_partial(obs: Observations, start: Start, error: MultilatError) -> dict:
    """A start that the solver refused (near-degenerate there) as the lowest-cost point of a first
    solve: the minimum search restarts from other initial values; ``error`` is raised if none works."""
    from multilat.network.solve import Convergence

    rho = np.linalg.norm(start.station_xyz_m[obs.station_index] - start.target_xyz_m[obs.target_index], axis=1)
    v = (obs.distance_m - rho - start.offset_m[obs.station_index]) / obs.sigma_m
    n_unknown = 4 * obs.n_stations + 3 * obs.n_targets - 6
    return dict(partial=True, sx=start.station_xyz_m, tx=start.target_xyz_m, off=start.offset_m,
                vtpv=float(v @ v), dof=obs.n_obs - n_unknown, error=error,
                convergence=Convergence(False, 0, float("inf"), str(error)))


def _one_gross_error(core) -> bool:
    """Whether one observation explains the failure: without its squared normalised residual
    ``w_k^2`` (its contribution to vtpv when rejected) the global test no longer fails by far. A single
    blunder does; a wrong minimum spreads its misfit over many distances and does not."""
    red = core["redundancy"]
    w = st.w_statistics(core["residual_w"], None, red)
    w2 = float(np.max(w ** 2, initial=0.0))
    return core["dof"] > 1 and p_value(core["vtpv"] - w2, core["dof"] - 1) >= P_MIN


def _w_failure_groups(core, used, crit, limit: int = 50) -> tuple:
    """Every w-test failing at the end (|w| > crit), grouped by perfect correlation (|rho| > 1 - 1e-6):
    a group of several is a fault the data cannot locate. Indices into the full observations; at
    most ``limit`` groups, largest |w| first."""
    red = core["redundancy"]
    w = st.w_statistics(core["residual_w"], None, red)
    fail = np.flatnonzero(np.abs(w) > crit)
    fail = fail[np.argsort(-np.abs(w[fail]))]
    idx = np.flatnonzero(used)
    seen: set[int] = set()
    groups = []
    for k in fail:
        if int(k) in seen or len(groups) >= limit:
            continue
        members = [int(q) for q in core["cov"].perfectly_correlated(int(k), red)]
        members = [int(k)] + [q for q in members if q != k]
        seen.update(members)
        groups.append(tuple(int(idx[q]) for q in members))
    return tuple(groups)
