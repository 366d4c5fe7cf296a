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
from dataclasses import dataclass, replace

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust import statistics as st
from multilat.network.adjust.distance.ambiguity import check_geometry, side_fixed_targets
from multilat.network.model.data import Observations, Points, ReferenceLengths
from multilat.network.model.datum import Datum, parse_datum
from multilat.network.adjust.distance.exclusion import (UndeterminedTargets, exclude_weak_points, leaving_out_undetermined,
                                        raise_undetermined, zero_redundancy_warnings)
from multilat.network.adjust.distance.fit import (as_start, check_control, check_network, control_ids, fit_once, raise_if_flat,
                                  station_map, target_map)
from multilat.network.adjust.distance.adjust_steps import (coupling_results, scaled_cov, start_as_partial, w_failure_groups,
                                           search_minimum as _search_minimum)
from multilat.network.adjust.distance.fit_state import Fit
from multilat.network.adjust.distance.options import NetworkOptions
from multilat.network.adjust.distance.result import (AdjustmentResult, InterpointDistance, Outlier, Start,
                                     build_result)
from multilat.network.adjust.approximate.search import P_MIN, false_minimum_text, p_value
from multilat.network.model.sigma_source import describe as describe_sigma
from multilat.network.model.couplings import coupling_spec
from multilat.network.model.angle_rows import angle_results
from multilat.network.adjust.distance.snooping import (LINEAR_W_MAX, LinearRounds, Procedure, Rounds, angle_outliers, n_tested,
                                       snooping_round)
from multilat.network.model.scale_datum import check_scale_datum
from multilat.network.adjust.approximate.starts import initial_for
from multilat.network.adjust.distance.unit_slip import check_unit_slip, noise_free

__all__ = ["adjust", "AdjustmentResult", "Model", "NetworkOptions", "Outlier", "InterpointDistance", "Start"]


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


def _fixed_offsets(offsets, obs: Observations, what: str = "offsets"):
    """(offset_free (s,) bool, fixed values (s,)) from the ``offsets_m`` option (None/"estimate", one
    value, or a mapping whose keys are head ids; also called by the general layer's table reader)."""
    s = obs.n_stations
    free = np.ones(s, bool)
    val = np.zeros(s)
    if offsets is None or (isinstance(offsets, str) and offsets == "estimate"):
        return free, val
    if isinstance(offsets, Mapping):
        for k, v in offsets.items():
            m = _head_stations(k, obs, what)
            if not np.isfinite(v):
                raise MultilatError(f"{what}: value for {k!r} must be finite")
            free[m], val[m] = False, float(v)
        return free, val
    try:
        v = float(offsets)
    except (TypeError, ValueError):
        raise MultilatError(f"{what} must be None/'estimate', a number or a mapping, got {offsets!r}") from None
    if not np.isfinite(v):
        raise MultilatError(f"{what} must be finite")
    return np.zeros(s, bool), np.full(s, v)


def _scale_flags(scales, obs, what: str = "scales"):
    s = obs.n_stations
    if scales is False or scales is None:
        return np.zeros(s, bool)
    if scales is True:
        return np.ones(s, bool)
    out = np.zeros(s, bool)
    for k in scales:
        out |= _head_stations(k, obs, what)
    return out


# ====================================================================== public
@dataclass(frozen=True, eq=False)
class Model:
    """The network model of one adjustment, resolved against its observations: what every solve of
    it needs (the first, the minimum search's, the control test's, the snooping rounds', the mirror
    test's). ``off_free``, ``off_val``, ``sc_free``: (s,) per station of ``obs``."""

    datum: Datum
    points: Points | None
    cost: str
    off_free: np.ndarray
    off_val: np.ndarray
    sc_free: np.ndarray
    max_iter: int
    solver: str
    chunk_targets: int
    couplings: object = None

    def fit(self, sub, start, ref_start, obs, used, *, warn: bool, partial_ok: bool = False,
            cost: str | None = None, held_offsets: bool = False) -> Fit:
        """One adjustment of ``sub`` (rows ``used`` of ``obs``) from ``start``
        (:func:`multilat.network.adjust.distance.fit.fit_once`); ``held_offsets``: every offset held at zero."""
        of, ov = ((np.zeros_like(self.off_free), np.zeros_like(self.off_val)) if held_offsets
                  else (self.off_free, self.off_val))
        return fit_once(sub, self.datum, start, ref_start, obs, used, self.points, cost or self.cost, of, ov,
                        self.sc_free, self.max_iter, self.solver, self.chunk_targets, warn=warn,
                        partial_ok=partial_ok, couplings=self.couplings)


def adjust(obs: Observations, options: NetworkOptions | None = None, *, initial=None,
           points: Points | None = None, references: ReferenceLengths | None = None,
           scale_bars: ReferenceLengths | None = None, scale_bar: ReferenceLengths | None = None,
           sigma_source: dict | None = None, rng=0, **option_fields) -> AdjustmentResult:
    """Adjust a self-calibrating multilateration network.

    Unknowns: station coordinates, target coordinates, one additive offset per station (estimated
    unless fixed) and optionally one scale per station; model ``d = (1 + k_i)|H_i - T_j| + o_i``.
    Solved by Gauss-Newton with Levenberg-Marquardt damping on the normal equations reduced by the
    Schur complement over the 3x3 target blocks (cost linear in the number of targets).

    The options are one :class:`~multilat.network.adjust.distance.options.NetworkOptions` (``options``), or its fields
    as keywords (``datum="321:A,B,C"``, ``alpha=0.01``, ...; given with ``options`` they replace its
    values); a bad value is one line naming the option. The data are ``obs``, ``points``,
    ``references`` (with ``scale_bars=True`` in the options: the scale bars), ``initial`` and
    ``sigma_source``; ``rng`` seeds the initial values.

    Parameters
    ----------
    obs : Observations
        Distances with a-priori uncertainties ``sigma_m``.
    options : NetworkOptions, optional
        Every option below (defaults: those of ``multilat adjust``).
    datum : Datum or str
        ``"free"`` (inner constraints over all points; ``"free:P1,P2,.."`` over chosen points),
        ``"321:A,B,C"`` (A at origin, B on +x, C in xy-plane), or ``"control"`` /
        ``"control:P1,.."`` (the given ``points`` held fixed). See :mod:`multilat.network.model.datum`.
    initial : object with ``station_xyz_m`` (s, 3), ``target_xyz_m`` (t, 3), ``offset_m`` (s,), optional
        Initial values. Default: ``points`` when they cover every point, else
        :func:`multilat.network.adjust.approximate.initial.initial_values` from the distances (rigidly fitted onto
        ``points`` when >= 3 are given).
    points : Points, optional
        Approximate coordinates (their frame is the frame of the ``free`` datum) or control. Ids
        that are in no observation are ignored with a ``UserWarning`` naming them.
    cost : "distance" or "squared"
        ``"distance"``: residuals in metres weighted by ``1/sigma``; ``"squared"``: the paper's
        eq. (6), unweighted squared-distance differences (covariance scaled by the a-posteriori
        variance; no global test or data snooping, which need known weights).
    offsets_m (alias offsets) : None, "estimate", float or mapping head -> metres
        Estimate all offsets (default), fix all to one value, or fix the named heads' ones (a head
        is its station when ``obs`` names no heads; a head occupying several stations has one offset).
    scales : bool or iterable of head ids
        Estimate a scale per head (all, or the named ones). Default: none. With every station's
        scale estimated the network's scale is a 7th datum defect: give ``scale_bar``.
    references : ReferenceLengths, optional
        With the option ``scale_bars=True``: the scale bars (below).
    scale_bars : ReferenceLengths (or, as an option, bool), optional
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
        its redundancy number is below ``r_min`` (:mod:`multilat.network.adjust.distance.reliability`).
    sigma_source : dict, optional
        Where the σ of the observations came from (kept in the result and its JSON).
    snooping : bool
        Detection, identification, adaptation: while the detection test fails (the global test; the
        largest τ with an unknown variance factor) reject the observation with the largest ``|w|``
        above the critical value and re-adjust, while the network stays solvable (at most
        ``max_rejections``).
    max_iter : int
        Iteration limit of the Gauss-Newton loop (the stopping rule is relative to sigma:
        :mod:`multilat.network.adjust.solve.convergence`).
    solver : "auto", "dense" or "sparse"
        Linear-algebra back end (:mod:`multilat.network.adjust.solve`): a choice of speed only, the
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
    bars_given = scale_bars if not isinstance(scale_bars, bool) else None
    if isinstance(scale_bars, bool):      # the option (the data then come as references)
        option_fields["scale_bars"] = scale_bars
    if bars_given is not None and scale_bar is not None:
        raise MultilatError("give scale_bars or scale_bar (the same), not both")
    bars = bars_given if bars_given is not None else scale_bar
    opts = NetworkOptions.of(options, **option_fields)
    if bars is None and opts.scale_bars:
        if references is None:
            raise MultilatError(f"{opts.name('scale_bars')} needs the reference lengths (references=; "
                                "--references FILE): the bars' lengths with u_m")
        bars = references
    if not isinstance(obs, Observations):
        raise MultilatError("adjust: obs must be an Observations")
    obs = opts.prepare(obs)

    def once(undetermined):       # a target found undetermined is left out and the network adjusted again
        return _adjust(obs, opts, initial=initial, points=points, bars=bars, sigma_source=sigma_source,
                       rng=rng, undetermined=undetermined)

    return leaving_out_undetermined(once, strict=opts.strict)


@dataclass(frozen=True, eq=False)
class Prepared:
    """An adjustment before its first solve: the observations kept (weak points left out, named in
    ``excluded``), the network ``model``, the ``start`` and how it was found (``how``), the warnings so
    far (``notes``) and the control points (``ctrl``)."""

    obs: Observations
    model: Model
    start: Start
    how: dict
    excluded: tuple
    notes: list
    ctrl: set


def _prepare(obs: Observations, opts: NetworkOptions, *, initial, points, bars, rng, undetermined) -> Prepared:
    """The options resolved against ``obs`` (held offsets, scales, datum, couplings), weak points left
    out, the network checked and the initial values: everything before the first solve."""
    cost, strict = opts.cost, opts.strict
    datum = parse_datum(opts.datum)
    if bars is not None and cost != "distance":
        raise MultilatError("scale bars need the distance cost (weighted observations)")
    if points is not None and points.std_m is not None and datum.kind != "control":
        warnings.warn("points: the standard uncertainties (sx_m, sy_m, sz_m) make weighted control under "
                      "--datum control only; here the points are approximate coordinates", UserWarning,
                      stacklevel=3)
    off_free, off_val = _fixed_offsets(opts.offsets_m, obs, opts.name("offsets_m"))
    sc_free = _scale_flags(opts.scale_heads(obs), obs, opts.name("scales"))
    if datum.kind == "control" and points is None:
        raise MultilatError("datum control needs control coordinates (points)")
    if points is not None:
        known = set(obs.station_ids) | set(obs.target_ids)
        stray = [i for i in points.ids if i not in known]
        if stray:
            warnings.warn(f"points: {len(stray)} id(s) not in the observations, ignored: "
                          f"{', '.join(stray[:8])}{'...' if len(stray) > 8 else ''}",
                          UserWarning, stacklevel=3)
    given = None if initial is None else as_start(initial, obs)
    if obs.n_stations < 3:
        raise MultilatError(f"a self-calibrating network needs at least 3 stations, got {obs.n_stations} "
                            f"({', '.join(obs.station_ids)})")
    # weak points are left out (named), not a reason to refuse the network
    ctrl = control_ids(obs, datum, points) if datum.kind == "control" else set()
    keep, excluded = exclude_weak_points(obs, offset_free=off_free, scale_free=sc_free, fixed_targets=ctrl,
                                         strict=strict, undetermined=undetermined)
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
    model = Model(datum, points, cost, off_free, off_val, sc_free, opts.max_iter, opts.solver, opts.chunk_targets,
                  cspec)
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
    return Prepared(obs, model, start, how, excluded, notes, ctrl)


def _adjust(obs: Observations, opts: NetworkOptions, *, initial, points, bars, sigma_source, rng,
            undetermined) -> AdjustmentResult:
    """:func:`adjust` with the options validated and the undetermined targets of the earlier tries."""
    cost, alpha, power, alpha_family = opts.cost, opts.alpha, opts.power, opts.alpha_family
    test_method, alpha_global = opts.test_method_resolved, opts.alpha_global_resolved
    variance_factor, snooping, max_rejections = opts.variance_factor, opts.snooping, opts.max_rejections
    # the tests' levels (alpha_g(dof): the global test's); alpha is from here on the w-tests' (Šidák's)
    alpha_g = st.test_levels(n_tested(obs), alpha0=alpha, power=power, method=test_method,
                             alpha_global=alpha_global, alpha_family=alpha_family)
    alpha = alpha_g.alpha0
    # MDBs: Baarda's reference at the given alpha0 (as the design's); the w-tests' own: tests.lambda0_w
    lam0 = st.noncentrality(alpha_g.alpha0_given, power)
    prep = _prepare(obs, opts, initial=initial, points=points, bars=bars, rng=rng, undetermined=undetermined)
    obs, model, start, how, datum = prep.obs, prep.model, prep.start, prep.how, prep.model.datum
    do_snoop = snooping and cost == "distance"
    used = np.ones(obs.n_obs, bool)
    rounds = Rounds()
    rejected, steps = rounds.rejected, rounds.steps
    limit = obs.n_obs if max_rejections is None else int(max_rejections)
    crit = st.w_critical(alpha)
    unknown = variance_factor == "unknown"
    proc = Procedure(do_snoop, limit, unknown, alpha, alpha_g, lam0, crit)
    warn = True
    guess = start
    unlocated: tuple = ()
    reason = ""
    first = True
    search_ok = cost == "distance" and datum.kind != "control"
    search = None
    obs_w = obs                      # the observations with the rejected angles left out (σ NaN)
    lin = None                       # rounds downdated since the last adjustment (large networks)
    refit = True
    while True:
        if refit:
            # the last adjustment and its downdates go before the next is built (peak memory)
            core = lin = None
            sub = obs_w if used.all() else obs_w.subset(used)
            core = _fit_or_partial(model, sub, guess, start, obs, used, warn=warn, partial_ok=first and search_ok,
                                   how=how)
            if first:
                core, search = _check_first_fit(obs, core, prep, opts, points=points, alpha_g=alpha_g,
                                                sigma_source=sigma_source, rng=rng, search_ok=search_ok)
            first = False
            # the next adjustment (after a rejection) starts from this solution
            gs, gt_, go = guess.station_xyz_m.copy(), guess.target_xyz_m.copy(), guess.offset_m.copy()
            gs[core.smap], gt_[core.tmap], go[core.smap] = core.sx, core.tx, core.off
            guess = Start(gs, gt_, go)
            warn = False
            refit = False
            lin = (LinearRounds(core, np.flatnonzero(used), sub.station_index, sub.target_index,
                                sub.n_stations, sub.n_targets)
                   if do_snoop and not core.partial and LinearRounds.applies(core, sub, datum) else None)
        n_steps = len(steps)
        go_on = snooping_round(obs, obs_w, used, core, lin, rounds, proc, model)
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
    return _finish(core, prep, opts, obs_w=obs_w, used=used, rounds=rounds, proc=proc, search=search,
                   unlocated=unlocated, reason=reason, sigma_source=sigma_source)


def _fit_or_partial(model, sub, guess, start, obs, used, *, warn, partial_ok, how):
    """One adjustment of the observations ``sub`` (``used`` of ``obs``) from ``guess``; on the first one
    with the minimum search to come (``partial_ok``), a start computed from distances that looks
    degenerate gives the start as a partial result instead of the error."""
    try:
        return model.fit(sub, guess, start, obs, used, warn=warn, partial_ok=partial_ok)
    except MultilatError as exc:
        # computed initial values can make a solvable network look degenerate (a collapsed
        # start): the search's restarts get their chance before the error is final
        if not (partial_ok and how["method"].startswith("distances")
                and ("near-degenerate" in str(exc) or isinstance(exc, UndeterminedTargets))):
            raise
        return start_as_partial(obs, start, exc)


def _check_first_fit(obs, core, prep, opts, *, points, alpha_g, sigma_source, rng, search_ok):
    """The checks of the first adjustment, before any rejection: a unit slip, the search for a false
    minimum (``search_ok``), coplanar lines of sight, inconsistent control. Raises on a failure;
    returns the (searched) adjustment and the search (None without one)."""
    model, start, how = prep.model, prep.start, prep.how
    datum, cspec, cost = model.datum, model.couplings, opts.cost
    search = None
    slip = cost == "distance" and opts.variance_factor != "unknown"    # a unit slip stops (unit_slip.py)
    if slip and how.get("far_minimum_again"):   # the restarts found this minimum twice: no search
        check_unit_slip(obs, core, sigma_source)
    if search_ok:
        # a converged result failing the global test by far may be a wrong minimum: search
        # (not under control points: they give the frame and the start; a failing test there
        # is tested as inconsistent control just below)
        core, search = _search_minimum(obs, core, start, model, rng)
        how["search"] = search.as_dict()
    if not core.partial:   # coplanar lines of sight: left out, adjusted again
        raise_undetermined(obs, core, side_fixed_targets(obs, prep.ctrl, cspec))
    if datum.kind == "control" and cost == "distance":
        # a failed global test under control may be the control coordinates, not the distances:
        # test them (against the free network) before data snooping blames the distances
        check_control(obs, core, start, points, model.off_free, model.off_val, model.sc_free, alpha_g(core.dof),
                      model.max_iter, model.solver, model.chunk_targets, datum, cspec)
    if slip:    # after the search (its best solution) and the control test (control at fault)
        check_unit_slip(obs, core, sigma_source)
    return core, search


def _finish(core, prep, opts, *, obs_w, used, rounds, proc, search, unlocated, reason, sigma_source):
    """The result of the last adjustment ``core`` after the snooping rounds: the false-minimum and
    σ0 warnings, the variance factor applied, the tests' record, the couplings, angles and
    mirror-ambiguous points."""
    obs, model, start, how, excluded, notes, ctrl = (prep.obs, prep.model, prep.start, prep.how, prep.excluded,
                                                     prep.notes, prep.ctrl)
    datum, sc_free, cspec = model.datum, model.sc_free, model.couplings
    n_bars = 0 if cspec is None else len(cspec.bars)
    cost, power, variance_factor, strict = opts.cost, opts.power, opts.variance_factor, opts.strict
    mdb_limit_sigma, r_min = opts.mdb_limit_sigma, opts.r_min
    alpha, alpha_g, lam0, crit, unknown = proc.alpha, proc.alpha_g, proc.lam0, proc.crit, proc.unknown
    do_snoop = proc.do_snoop
    rejected, steps, ang_rejected = rounds.rejected, rounds.steps, rounds.ang_rejected
    if search is not None and p_value(core.vtpv, core.dof) < P_MIN:
        # still failing by far after data snooping: a possible false minimum, never passed as ordinary
        msg = search.warning or false_minimum_text(core.sigma0, p_value(core.vtpv, core.dof), searched=False)
        notes.append(msg)
        warnings.warn(msg, UserWarning, stacklevel=3)
    if n_bars and datum.kind != "control" and np.all(sc_free):
        how["scale_datum"] = {"kind": "scale bars", "n_bars": n_bars,
                              "points": [cspec.bars[0][0], cspec.bars[0][1]]}
    if unlocated and steps:
        steps[-1]["action"] = f"not rejected: {reason}"
    s0 = core.sigma0 if unknown and cost == "distance" and np.isfinite(core.sigma0) else 1.0
    if s0 != 1.0:
        core = replace(core, cov=scaled_cov(core.cov, s0 ** 2))
    final_crit = st.tau_critical(alpha, core.dof) * s0 if unknown else crit
    res = build_result(obs, used, rejected, unlocated, core, datum, cost, alpha_g.alpha0_given, power,
                       alpha_g(core.dof), reason=reason, snooped=do_snoop, sigma_scale=s0,
                       mdb_limit_sigma=mdb_limit_sigma, r_min=r_min)
    groups = w_failure_groups(core, used, final_crit) if cost == "distance" else ()
    tests = {"method": alpha_g.method, "variance_factor": variance_factor, "alpha0": alpha, "power": power,
             "lambda0": lam0, "lambda0_w": st.noncentrality(alpha, power), "w_critical": crit,
             "tau_critical": st.tau_critical(alpha, core.dof) if unknown else None,
             "alpha_global": alpha_g(core.dof), **alpha_g.as_dict(), "steps": steps}
    judged = cost == "distance" and not noise_free(obs, res.residuals_m[used])   # σ0 in m² for eq. 6
    check = st.sigma0_check(res.sigma0 if judged else float("nan"), res.dof,
                            variance_factor=variance_factor, source=describe_sigma(sigma_source or {}))
    if check["message"]:
        notes.append(check["message"])
        warnings.warn(check["message"], UserWarning, stacklevel=3)
    bars_out, ctrl_out = coupling_results(core)
    ang_out, orient = angle_results(core, lam0, final_crit)
    res = replace(res, excluded=excluded, warnings=tuple(notes), w_failure_groups=groups, initial=how,
                  sigma0_check=check,
                   scale_bars=bars_out, weighted_control=ctrl_out, tests=tests,
                   sigma_source=dict(sigma_source or {}), angles=ang_out, orientations=orient,
                   angle_design_w=None if core.angles is None else core.angles["design_w"])
    # geometry distances cannot fix: a flat network is refused, mirror-ambiguous points named
    amb, note = check_geometry(res, lambda st_: model.fit(
        obs_w if used.all() else obs_w.subset(used), st_, start, obs, used, warn=False),
        lambda0=lam0, strict=strict, control=ctrl, couplings=cspec)
    if note:
        warnings.warn(note, UserWarning, stacklevel=3)
        res = replace(res, ambiguous=amb, warnings=res.warnings + (note,))
    return replace(res, angle_outliers=angle_outliers(obs, ang_rejected, res))
