"""One adjustment of a fixed set of observations: the internal minimal constraint, the solver
loop (:mod:`multilat.network.adjust.solve`), the final normal equations, and the move to the requested
datum with the S-transformed covariance. :func:`multilat.network.adjust.distance.adjust.adjust` calls it once, then
again after each rejection of data snooping.
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import replace

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.couplings import flatten_params
from multilat.network.adjust.covariance import JACOBIAN_ON_DEMAND_OBS, CoupledCovariance, NetworkCovariance
from multilat.network.model.data import Observations
from multilat.network.adjust import statistics as st
from multilat.network.adjust.distance.fit_state import Fit
from multilat.network.model.datum import ABOUT_Z_COLUMNS, apply_rigid, datum_matrices, frame_321, parse_datum, rigid_fit
from multilat.network.model.distance import Q
from multilat.network.model.problem import Params, Problem, head_mean
from multilat.network.adjust.distance.result import Start
from multilat.network.adjust.distance.solvability import check_structure, flat_geometry
from multilat.network.adjust.solve import choose_backend, gauss_newton, make_backend, solve_reduced
from multilat.network.adjust.solve.loop import check_target_blocks
from multilat.network.adjust.solve.system import weighted_cost, whitened

__all__ = ["fit_once", "as_start", "check_network", "control_ids", "station_map", "target_map",
           "raise_if_flat", "raise_unconverged", "pick_321_stations", "check_control_scale",
           "CONTROL_SCALE_LIMIT"]

#: control coordinates whose scale differs from the distances' by this factor or more (either way)
#: are refused as a unit slip (a real scale error is ~1e-5; offsets of mm change short spacings by %)
CONTROL_SCALE_LIMIT = 2.0


def as_start(initial, obs: Observations) -> Start:
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


def pick_321_stations(sx) -> tuple[int, int, int]:
    """Three stations spanning the largest triangle (for the internal minimal constraint)."""
    s = sx.shape[0]
    if s <= 40:
        c = np.array(list(itertools.combinations(range(s), 3)), dtype=np.intp).reshape(-1, 3)
        area = np.linalg.norm(np.cross(sx[c[:, 1]] - sx[c[:, 0]], sx[c[:, 2]] - sx[c[:, 0]]), axis=1)
        return tuple(int(x) for x in c[int(np.argmax(area))]) if c.size else (0, 1, 2)
    b = int(np.argmax(np.linalg.norm(sx - sx[0], axis=1)))
    area = np.linalg.norm(np.cross(sx[b] - sx[0], sx - sx[0]), axis=1)
    return 0, b, int(np.argmax(area))


def raise_unconverged(obs, p: Params, conv) -> None:
    raise_if_flat(obs, p.station_xyz_m, p.target_xyz_m, "no convergence")
    raise MultilatError(f"the adjustment did not converge ({conv.reason} after {conv.iterations} "
                        f"iterations, last step {conv.last_step_sigma:.3g} sigma); check the initial "
                        "values, the geometry and the distances for gross errors")


def raise_if_flat(obs, sx, tx, when: str) -> None:
    """Raise the one-line 'near-degenerate geometry (when): cause' if the points are (nearly)
    coplanar stations or collinear targets by :func:`solvability.flat_geometry`."""
    cause = flat_geometry(sx, tx, sigma_m=float(np.median(obs.sigma_m)), n_obs=obs.n_obs)
    if cause:
        raise MultilatError(f"near-degenerate geometry ({when}): {cause}")


def station_map(obs, used):
    """Indices (into obs.station_ids) of the stations present in obs.subset(used), in its order."""
    return np.flatnonzero(np.bincount(obs.station_index[used], minlength=obs.n_stations) > 0)


def target_map(obs, used):
    return np.flatnonzero(np.bincount(obs.target_index[used], minlength=obs.n_targets) > 0)


def check_network(sub, datum, points, off_free, sc_free, *, warn, couplings=None):
    fixed_t = np.zeros(sub.n_targets, bool)
    fixed_sc = 0
    defect = 6
    if datum.kind == "control":
        ctrl = control_ids(sub, datum, points)
        fixed_t = np.array([t in ctrl for t in sub.target_ids])
        fixed_sc = 3 * sum(s in ctrl for s in sub.station_ids)
        defect = 0
    # weighted control points count as fixed: their 3 unknowns come with 3 observations
    c = None if couplings is None else couplings.resolve(sub)
    return check_structure(sub, offset_free=off_free, scale_free=sc_free, fixed_targets=fixed_t,
                           fixed_station_coords=fixed_sc, datum_defect=defect, warn=warn,
                           extra_obs=0 if c is None else c.bar_a.size)


def control_ids(sub, datum, points):
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


def _control_scale(sub, ctrl, points, sx0, tx0) -> tuple[float, int, str]:
    """(median ratio of control-coordinate lengths to the distances' lengths, number of lengths, how):
    from the observed pairs whose both ends have coordinates in ``points`` (3 or more), else from the
    control points' spacings against those of the start ``sx0``/``tx0`` (computed from the distances)."""
    def xyz(ids):
        return np.array([points.get(i) if points.get(i) is not None else (np.nan,) * 3 for i in ids], float)

    P = np.vstack([xyz(sub.station_ids), xyz(sub.target_ids)])
    a, b = sub.station_index, sub.n_stations + sub.target_index
    lc = np.linalg.norm(P[a] - P[b], axis=1)
    ok = np.isfinite(lc) & (lc > 0) & (sub.distance_m > 0)
    if ok.sum() >= 3:
        return float(np.median(lc[ok] / sub.distance_m[ok])), int(ok.sum()), "observed distances"
    ids = sub.station_ids + sub.target_ids
    k = [ids.index(i) for i in sorted(ctrl)]
    S = np.vstack([sx0, tx0])[k]
    iu = np.triu_indices(len(k), 1)
    lc = np.linalg.norm(P[k][:, None] - P[k][None], axis=2)[iu]
    ls = np.linalg.norm(S[:, None] - S[None], axis=2)[iu]
    ok = (lc > 0) & (ls > 0)
    return (float(np.median(lc[ok] / ls[ok])) if ok.any() else 1.0), int(ok.sum()), \
        "the same points' spacings from the distances"


def check_control_scale(sub, ctrl, points, sx0, tx0) -> None:
    """Raise :class:`~multilat.network.adjust.distance.unit_slip.UnitSlipError` (source ``points``) when the control
    coordinates and the distances differ in scale by :data:`CONTROL_SCALE_LIMIT` or more: control in
    mm with distances in metres made the adjustment fail with a message blaming the distances."""
    from multilat.network.adjust.distance.unit_slip import UnitSlipError, likely_unit

    ratio, n, how = _control_scale(sub, ctrl, points, sx0, tx0)
    if 1.0 / CONTROL_SCALE_LIMIT < ratio < CONTROL_SCALE_LIMIT:
        return
    big = ratio >= 1.0
    k = ratio if big else 1.0 / ratio
    unit = likely_unit(k)
    if big:
        guess = (f"x_m, y_m, z_m in {unit[1]} while distance_m is in metres?" if unit
                 else "control coordinates and distances in different units?")
    else:
        guess = (f"distance_m in {unit[1]} while the control coordinates are in metres?" if unit
                 else "control coordinates and distances in different units?")
    raise UnitSlipError(f"the control coordinates are ~{k:.3g}x {'larger' if big else 'smaller'} in scale "
                        f"than the distances (median ratio {ratio:.4g} over {n} lengths, against {how}): "
                        f"{guess}", source="points")


def _levelled_frame(sub, ang, sx0, tx0, a):
    """The internal frame when the vertical is observed (levelled stations): rotate the start so that
    the first levelled station's vertical axis (fitted to its directions) is +z, put station ``a`` at
    the origin and the station farthest from it horizontally, ``b``, on the xz-plane (y = 0).
    Returns ``(R0, t0, b)``: 4 coordinates to hold (a's x, y, z and b's y)."""
    from multilat.network.model.angle_rows import AngleRows, initial_orientations
    from multilat.network.model.angles import rotation_matrix

    i = int(np.flatnonzero(ang.levelled & ang.oriented)[0])
    one = AngleRows(ang.obs_index, ang.kind, ang.value_rad, ang.sigma_rad, ang.station_index, ang.target_index,
                    np.arange(ang.oriented.size) == i)                       # fitted with 3 angles
    v = rotation_matrix(initial_orientations(sub, one, sx0, tx0))[:, 2]     # its z axis in the start frame
    ez = np.array([0.0, 0.0, 1.0])
    k = np.cross(v, ez)
    sn, cs = np.linalg.norm(k), float(v @ ez)
    K = np.zeros((3, 3)) if sn < 1e-15 else np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]]) / sn
    Rv = np.eye(3) + sn * K + (1 - cs) * (K @ K)
    x = sx0 @ Rv.T
    hd = np.linalg.norm((x - x[a])[:, :2], axis=1)
    b = int(np.argmax(hd))
    th = -np.arctan2(x[b, 1] - x[a, 1], x[b, 0] - x[a, 0])
    Rz = np.array([[np.cos(th), -np.sin(th), 0.0], [np.sin(th), np.cos(th), 0.0], [0.0, 0.0, 1.0]])
    R0 = Rz @ Rv
    return R0, -R0 @ sx0[a], b


def _hold_frame(sub, datum, points, sx0, tx0, gfree, tfree, ang):
    """The initial coordinates ``sx0``, ``tx0`` in the datum's frame and the coordinates it holds
    (cleared in ``gfree``/``tfree`` in place): the control points' (a rigid fit on them; weighted
    control stays free), or the 3-2-1 frame of three stations (4 held coordinates under a rotation
    about z when the vertical is observed). Returns the moved ``sx0``, ``tx0``."""
    all_ids = sub.station_ids + sub.target_ids
    levelled = ang is not None and ang.any_levelled
    if datum.kind == "control":
        ctrl = control_ids(sub, datum, points)
        check_control_scale(sub, ctrl, points, sx0, tx0)
        # bring the initial values into the control frame first (rigid fit on the control points)
        cur = dict(zip(all_ids, np.vstack([sx0, tx0])))
        cids = sorted(ctrl)
        Rc, tc = rigid_fit(np.array([cur[i] for i in cids]), np.array([points.get(i) for i in cids]))
        sx0, tx0 = apply_rigid(Rc, tc, sx0), apply_rigid(Rc, tc, tx0)
        for i, sid in enumerate(sub.station_ids):
            if sid in ctrl:
                sx0[i] = points.get(sid)
                gfree[i, :3] = points.std(sid) is not None     # weighted control: free, observed
        for j, tid in enumerate(sub.target_ids):
            if tid in ctrl:
                tx0[j] = points.get(tid)
                tfree[j] = points.std(tid) is not None
    else:
        if datum.kind == "321":
            for p in datum.points:
                if p not in all_ids:
                    raise MultilatError(f"datum 321: unknown point id {p!r}")
            if levelled:
                raise MultilatError("datum 321 would tilt a network whose vertical is observed (levelled "
                                    "stations): use the free or the control datum")
        a, b, c = pick_321_stations(sx0)
        if levelled:      # the vertical is observed: frame by a rotation about z only, 4 held coordinates
            R0, t0, b = _levelled_frame(sub, ang, sx0, tx0, a)
            sx0, tx0 = apply_rigid(R0, t0, sx0), apply_rigid(R0, t0, tx0)
            gfree[a, :3] = False
            gfree[b, 1] = False
        else:
            R0, t0 = frame_321(sx0[a], sx0[b], sx0[c])
            sx0, tx0 = apply_rigid(R0, t0, sx0), apply_rigid(R0, t0, tx0)
            gfree[a, :3] = False
            gfree[b, 1:3] = False
            gfree[c, 2] = False
    return sx0, tx0


def _move_to_datum(sub, datum, points, ref_start, smap, tmap, sx, tx, *, levelled):
    """The adjusted coordinates ``sx``, ``tx`` moved to the requested datum (control: as they are;
    3-2-1: the frame of its three points; free: a rigid fit to the reference coordinates ``ref_start``
    (rows ``smap``, ``tmap``), or the given points' where there are some, about z only when levelled). Returns
    ``(sx, tx, R, G, E)``: the rotation applied and the datum's constraint matrices (None under
    control)."""
    all_ids = sub.station_ids + sub.target_ids
    if datum.kind == "control":
        R, tr, G, E = np.eye(3), np.zeros(3), None, None
    else:
        if datum.kind == "321":
            xyz = {i: p for i, p in zip(all_ids, np.vstack([sx, tx]))}
            R, tr = frame_321(xyz[datum.points[0]], xyz[datum.points[1]], xyz[datum.points[2]])
        else:
            pos = {pid: k for k, pid in enumerate(all_ids)}
            if datum.points is None:
                sel = np.arange(len(all_ids))
            else:
                for pid in datum.points:
                    if pid not in pos:
                        raise MultilatError(f"datum free: unknown point id {pid!r}")
                sel = np.array([pos[pid] for pid in datum.points])
            ref = np.vstack([ref_start.station_xyz_m[smap], ref_start.target_xyz_m[tmap]])[sel]
            if points is not None:
                given = points.as_dict()
                for n, k in enumerate(sel):
                    v = given.get(all_ids[k])
                    if v is not None:
                        ref[n] = v
            R, tr = rigid_fit(np.vstack([sx, tx])[sel], ref, about_z=levelled)
        sx, tx = apply_rigid(R, tr, sx), apply_rigid(R, tr, tx)
        G, E = datum_matrices(datum, sub.station_ids, sub.target_ids, sx, tx)
        if levelled:      # 4 defects: the translations and the rotation about z
            G, E = G[:, ABOUT_Z_COLUMNS], E[:, ABOUT_Z_COLUMNS]
    return sx, tx, R, G, E


def _angle_fit(sub, ang, pb, p, cov, A_rows, R, G, E, *, levelled):
    """The angles' part of the adjustment at the solution ``p``: residuals, redundancy numbers and the
    orientations with their covariance in the datum (rotation ``R``, constraints ``G``, ``E``)."""
    from multilat.network.model.angle_rows import orientation_covariance, rotate_orientations

    s, t = sub.n_stations, sub.n_targets
    free_all = np.concatenate([pb.station_free.ravel(), np.repeat(pb.target_free, 3), ang.orientation_free])
    r_a = np.clip(1.0 - cov.quadratic(A_rows * free_all), 0.0, 1.0)
    o_cov = orientation_covariance(cov, ang, p.orientation_rad, R, G, E, s, t,
                                   rotation_axes=(2,) if levelled else (0, 1, 2))
    return dict(rows=ang, residual_rad=ang.residuals(p.station_xyz_m, p.target_xyz_m, p.orientation_rad),
                redundancy=r_a, orientation_rad=rotate_orientations(ang, p.orientation_rad, R),
                orientation_cov=o_cov, station_ids=sub.station_ids, target_ids=sub.target_ids,
                design_w=A_rows * free_all)


class _JacobianAt:
    """The whitened Jacobian blocks ``(Js_w, Jt_w)`` of ``pb`` at ``p``, recomputed on each call (for
    :meth:`NetworkCovariance.release_jacobian`): holds the problem and a copy of the parameters only,
    and pickles (process pools) where a closure would not."""

    def __init__(self, pb: Problem, p: Params):
        self.pb = pb
        self.p = Params(*(np.array(a, copy=True) for a in (p.station_xyz_m, p.target_xyz_m, p.offset_m,
                                                           p.scale, p.orientation_rad)))

    def __call__(self):
        return whitened(self.pb, self.p)[1:]


def fit_once(sub, datum, start, ref_start, obs, used, points, cost, off_free_all, off_val_all,
                 sc_free_all, max_iter, solver, chunk_targets, *, warn, partial_ok=False, couplings=None):
    """One adjustment of the observations ``sub`` (a subset of ``obs``) from ``start``;
    ``ref_start`` gives the reference coordinates of the free datum; ``couplings`` (a
    :class:`~multilat.network.model.couplings.CouplingSpec`) adds scale bars and weighted control.
    Returns a :class:`~multilat.network.adjust.distance.fit_state.Fit` in ``sub``'s order with the maps back."""
    smap, tmap = station_map(obs, used), target_map(obs, used)
    off_free, off_val, sc_free = off_free_all[smap], off_val_all[smap], sc_free_all[smap]
    check_network(sub, datum, points, off_free, sc_free, warn=False, couplings=couplings)
    cpl = None if couplings is None else couplings.resolve(sub)
    from multilat.network.model.angle_rows import angle_rows, initial_orientations

    ang = angle_rows(sub)
    levelled = ang is not None and ang.any_levelled
    s, t = sub.n_stations, sub.n_targets
    sx0 = start.station_xyz_m[smap].copy()
    tx0 = start.target_xyz_m[tmap].copy()
    # heads that occupy several stations: one offset and scale each (the tie, problem.py); the
    # initial values may have treated the stations independently, so start from their mean
    off0 = head_mean(np.where(off_free, start.offset_m[smap], off_val), sub)
    sc0 = head_mean(np.asarray(getattr(start, "scale", np.zeros(len(start.offset_m))), float)[smap], sub)
    gfree = np.ones((s, Q), bool)
    gfree[:, 3] = off_free
    gfree[:, 4] = sc_free
    tfree = np.ones(t, bool)
    sx0, tx0 = _hold_frame(sub, datum, points, sx0, tx0, gfree, tfree, ang)
    if ang is not None and cost != "distance":
        raise MultilatError("angle observations need the distance cost (weighted observations)")
    o0 = None if ang is None else initial_orientations(sub, ang, sx0, tx0)
    pb = Problem(sub, cost, gfree, tfree, couplings=cpl, angles=ang)
    backend = make_backend(pb, choose_backend(pb, solver), chunk_targets=chunk_targets)
    p, conv = gauss_newton(pb, Params(sx0, tx0, off0, sc0, o0), backend, max_iter=max_iter)
    if not conv.converged:
        if partial_ok:      # the lowest-cost point reached: a start for the minimum search
            return Fit(partial=True, sx=p.station_xyz_m, tx=p.target_xyz_m, off=p.offset_m,
                       vtpv=weighted_cost(pb, p), dof=pb.dof, convergence=conv)
        raise_unconverged(sub, p, conv)
    sx, tx, off, sc = p.station_xyz_m, p.target_xyz_m, p.offset_m, p.scale
    # final normal equations at the solution
    fin = backend.assemble(p, 0.0)
    check_target_blocks(fin.Ntt, pb)
    _, Qgg, cond = solve_reduced(fin.N, fin.b, gfree.ravel(), pb, p)
    r_w, Js_w, Jt_w = whitened(pb, p)
    dof = pb.dof
    vtpv = float(r_w @ r_w)
    if cpl is not None:
        e_w, E_rows = cpl.whitened(flatten_params(p))
        vtpv += float(e_w @ e_w)
    if ang is not None:
        a_w, A_rows = ang.whitened(p.station_xyz_m, p.target_xyz_m, p.orientation_rad, s, t)
        vtpv += float(a_w @ a_w)
    sigma0 = float(np.sqrt(vtpv / dof)) if dof > 0 else float("nan")
    factor = 1.0 if cost == "distance" else (sigma0 ** 2 if dof > 0 else float("nan"))
    sx, tx, R, G, E = _move_to_datum(sub, datum, points, ref_start, smap, tmap, sx, tx, levelled=levelled)
    if fin.coupled is not None:
        cov = CoupledCovariance(Qgg, fin.coupled, fin.Ntt_inv, Js_w, Jt_w, sub.station_index,
                                sub.target_index, factor=factor, R=R, G=G, E=E)
    else:
        cov = NetworkCovariance(Qgg, fin.Ntt_inv, Js_w, Jt_w, sub.station_index, sub.target_index,
                                factor=factor, R=R, G=G, E=E, jacobian=_JacobianAt(pb, p))
    h = cov.hat_diagonal(chunk_targets)
    del Js_w, Jt_w
    if sub.n_obs >= JACOBIAN_ON_DEMAND_OBS:      # 135 MiB at 1.6 M distances, live at the command's peak
        cov.release_jacobian()
    red = np.clip(1.0 - h, 0.0, 1.0)
    coupled = None
    if cpl is not None:
        # the couplings' own residuals and redundancy numbers (bars, then control coordinates)
        free_full = np.concatenate([pb.station_free.ravel(), np.repeat(pb.target_free, 3)])
        r_c = 1.0 - cov.quadratic(E_rows * free_full)
        coupled = dict(couplings=cpl, residual_m=cpl.residuals(flatten_params(p)),
                       redundancy=np.clip(r_c, 0.0, 1.0))
    angles = None if ang is None else _angle_fit(sub, ang, pb, p, cov, A_rows, R, G, E, levelled=levelled)
    return Fit(smap=smap, tmap=tmap, sx=sx, tx=tx, off=off, sc=sc, off_free=off_free, sc_free=sc_free, angles=angles,
               chunk_targets=chunk_targets, residual_w=r_w, redundancy=red, sigma0=sigma0, dof=dof,
               vtpv=vtpv, iterations=conv.iterations, cond=cond, cov=cov, convergence=conv,
               solver=backend.name, coupled=coupled)


def check_control(obs, core, start, points, off_free, off_val, sc_free, alpha_global, max_iter,
                   solver, chunk_targets, datum, cspec=None) -> None:
    """Raise if the control coordinates are inconsistent with the distances.

    The adjustment with the control held fixed has ``Omega_c = v^T P v`` on ``dof_c``; the free
    network of the same distances ``Omega_f`` on ``dof_f``. With a-priori weights, consistent
    control gives ``Omega_c - Omega_f ~ chi2(dof_c - dof_f)`` independent of the distances' own
    misfit (a blunder inflates both). Only run when the global test under control fails.
    """
    gt = st.global_test(core.vtpv, core.dof, alpha=alpha_global)
    if gt.side != "upper":
        return
    used = np.ones(obs.n_obs, bool)
    ctrl = sorted(control_ids(obs, datum, points))
    guess = Start(core.sx, core.tx, core.off)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            bars_only = None if cspec is None or not cspec.bars else replace(cspec, control=())
            free = fit_once(obs, parse_datum("free"), guess, guess, obs, used, None, "distance",
                            off_free, off_val, sc_free, max_iter, solver, chunk_targets, warn=False,
                            couplings=bars_only)
    except MultilatError:
        return            # not solvable without the control: nothing to compare; snooping goes on
    k = core.dof - free.dof
    if k <= 0:
        return
    stat = core.vtpv - free.vtpv
    crit = st.chi2_ppf(1.0 - alpha_global, k)
    if not stat > crit:
        return
    ids = obs.station_ids + obs.target_ids
    xyz = dict(zip(ids, np.vstack([free.sx, free.tx])))
    src = np.array([xyz[i] for i in ctrl])
    dst = np.array([points.get(i) for i in ctrl])
    R, t = rigid_fit(src, dst)
    mis = np.linalg.norm(apply_rigid(R, t, src) - dst, axis=1)
    w = int(np.argmax(mis))
    raise MultilatError(
        f"control coordinates inconsistent with the distances (σ0 = {core.sigma0:.3g} with the "
        f"control held fixed, {free.sigma0:.3g} free; global test {gt.statistic:.1f} > "
        f"{gt.critical:.1f}; control test χ² = {stat:.1f} > {crit:.1f} on {k} dof; largest misfit "
        f"{ctrl[w]!r} {mis[w] * 1e3:.2f} mm after a rigid fit): check the control points or use "
        "--datum free")
