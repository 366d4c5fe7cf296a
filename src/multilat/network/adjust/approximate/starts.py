"""Initial values of an adjustment: given, from approximate coordinates of every point, or from
the distances alone (:func:`multilat.network.adjust.approximate.initial.initial_values` for small networks, the seed
network + multilateration of :mod:`multilat.network.adjust.approximate.large` for large ones)."""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust.approximate.bounds import RESTART_SECONDS, Bound, report
from multilat.network.model.data import Observations, Points
from multilat.network.model.datum import apply_rigid, rigid_fit
from multilat.network.adjust.distance.fit import as_start
from multilat.network.adjust.distance.result import Start
from multilat.network.adjust.distance.solvability import flat_geometry

__all__ = ["initial_for", "initial_from_distances", "onto_points", "PARTIAL_RESTARTS", "LARGE_TARGETS",
           "HANDEDNESS_RATIO"]


PARTIAL_RESTARTS = 6   # random initial-value starts tried when the first solve does not converge
LARGE_TARGETS = 500   # above: initial values from a seed network + multilateration (network.large)
#: the RMS misfit of the wrong hand must be this many times the right one's for the given points to
#: decide the handedness of initial values from distances (see :func:`onto_points`)
HANDEDNESS_RATIO = 3.0


def initial_for(obs: Observations, given: Start | None, points: Points | None, rng) -> tuple[Start, dict]:
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
        from multilat.network.adjust.approximate.large import large_initial_values

        raw = large_initial_values(obs, rng=rng)
        how = {"method": "distances: " + raw.method, "seed_targets": len(raw.seed_target_ids),
               "multilateration_rms_m": raw.multilateration_rms_m}
    else:
        raw, how = initial_from_distances(obs, rng)
    iv = as_start(raw, obs)
    if points is not None:
        iv = onto_points(iv, obs, points, how)
    return iv, how


def onto_points(iv: Start, obs: Observations, points: Points, how: dict) -> Start:
    """Initial values from distances moved onto the given ``points`` (>= 3 of them) by a rigid fit of
    the solution **and of its mirror image** (distances cannot tell them apart); the hand with the
    smaller RMS misfit is taken. ``how["handedness"]`` records both misfits and whether the points
    decided it.

    Decided when the wrong hand's RMS misfit is at least ``HANDEDNESS_RATIO`` (3) times the right
    one's. Why 3: with the misfit of the right hand noise of unknown scale ε on the 3n fitted
    coordinates (rough coordinates, control σ, the initial values' own error), the likelihood ratio
    of the two hands is ``(e_wrong / e_right)^(3n)``: 3 gives 3^12 ≈ 5e5 for the fewest (n = 4)
    non-coplanar points, a margin kept for errors that are not Gaussian. The geometry sets the
    difference: the mirror fits the given points only as well as they lie in one plane (its misfit
    is about twice their RMS spread off their best-fit plane), so 3 asks for the points to stand
    out of their plane by about 1.4 times the misfit level. Coplanar points (or only 3) give equal
    misfits: not decided, named by :func:`multilat.network.adjust.distance.ambiguity.check_geometry` (``ambiguous``
    and a warning), the smaller misfit kept."""
    allids = obs.station_ids + obs.target_ids
    ids = [i for i in allids if points.get(i) is not None]
    if len(ids) < 3:
        return iv
    allx = np.vstack([iv.station_xyz_m, iv.target_xyz_m])
    src = np.array([allx[allids.index(i)] for i in ids])
    dst = np.array([points.get(i) for i in ids])
    mirror = np.diag([1.0, 1.0, -1.0])
    fits = []
    for m in (np.eye(3), mirror):
        try:
            R, t = rigid_fit(src @ m, dst)
        except MultilatError:      # collinear points: no rotation from them, the frame as computed
            return iv
        e = float(np.sqrt(np.mean(np.sum((apply_rigid(R, t, src @ m) - dst) ** 2, axis=1))))
        fits.append((e, R @ m, t))
    k = int(fits[1][0] < fits[0][0])
    e_in, e_out = fits[k][0], fits[1 - k][0]
    extent = float(np.sqrt(np.mean(np.sum((dst - dst.mean(axis=0)) ** 2, axis=1))))
    floor = 1e-9 * max(extent, 1e-300)
    decided = e_out >= HANDEDNESS_RATIO * max(e_in, floor)
    c = dst.mean(axis=0)
    n = np.linalg.svd(dst - c, full_matrices=False)[2][-1]
    how["handedness"] = {"decided": bool(decided), "mirrored": bool(k), "points": ids,
                         "misfit_rms_m": e_in, "mirror_misfit_rms_m": e_out, "ratio_needed": HANDEDNESS_RATIO,
                         "plane_spread_rms_m": float(np.sqrt(np.mean(((dst - c) @ n) ** 2))),
                         "plane_normal": [float(v) for v in n], "plane_point_m": [float(v) for v in c]}
    R, t = fits[k][1], fits[k][2]
    return Start(apply_rigid(R, t, iv.station_xyz_m), apply_rigid(R, t, iv.target_xyz_m), iv.offset_m)


def initial_from_distances(obs: Observations, rng):
    """:func:`initial_values` on the targets seen by 4+ stations, then the others (3 stations:
    two mirror positions) by multilateration from those stations, on the side of the rest
    (:func:`_weak_targets`; one with exactly coplanar sights by a tracker's angles where read).

    Initial values that come out flat (stations on one plane, targets on one line, where the
    distances say otherwise: a collapsed solution of a weak network) are retried from other random
    starts, up to ``PARTIAL_RESTARTS`` times."""
    from multilat.network.adjust.approximate.initial import initial_values

    gen = np.random.default_rng(rng)
    weak = np.bincount(obs.target_index, minlength=obs.n_targets) < 4
    strong_obs = ~weak[obs.target_index]
    # before the subset (which refuses an empty one with a bare "no observations": issue 25, 8d)
    if np.unique(obs.station_index[strong_obs]).size != obs.n_stations:
        n_strong = int((~weak).sum())
        raise MultilatError(f"initial values from distances need every station to see targets that 4 or "
                            f"more stations see ({n_strong} of {obs.n_targets} targets are seen by 4 or "
                            "more); give approximate coordinates of every station and target (--points)")
    sub = obs if not weak.any() else obs.subset(strong_obs)
    bound = Bound("initial values, flat-solution restarts", max_work=PARTIAL_RESTARTS + 1,
                  max_seconds=RESTART_SECONDS)
    while True:
        bound.spend()
        if bound.work > 1:
            report(f"initial values: flat solution, new start {bound.work - 1} of {PARTIAL_RESTARTS}")
        raw = initial_values(sub, rng=gen, deadline=None if bound.work == 1 else bound.deadline)
        if not flat_geometry(raw.station_xyz_m, raw.target_xyz_m, sigma_m=float(np.median(sub.sigma_m)),
                             n_obs=sub.n_obs) or bound.exhausted():
            break
    attempt = bound.work - 1
    bound.warn_if_timed_out()
    how = {"method": f"distances: {raw.method}", "residual_rms_m": float(raw.rms_residual_m)}
    if raw.far_minimum_again:   # the restarts found it twice: a unit slip or gross errors, not a start
        how["far_minimum_again"] = True
    notes = [n for n in (raw.bounded, bound.note() if bound.stopped_by == "time" else None) if n]
    if notes:
        how["bounded"] = "; ".join(notes)
    if raw.refinement is not None:
        how["refinement"] = raw.refinement.to_json()
    if attempt:
        how["flat_restarts"] = attempt
    if not weak.any():
        return raw, how
    return Start(raw.station_xyz_m, _weak_targets(obs, raw, weak, how), raw.offset_m), how


def _weak_targets(obs: Observations, raw, weak, how: dict) -> np.ndarray:
    """Every target's coordinates (t, 3): those seen by 4+ stations from ``raw``, the ``weak`` ones
    (seen by 3) multilaterated from its stations on the side of the rest; a weak target whose sights
    are exactly coplanar (:class:`~multilat.network.adjust.distance.exclusion.UndeterminedTargets`)
    placed by a tracker's angles where read
    (:func:`~multilat.network.adjust.approximate.large.polar_targets`), else refused as undetermined
    (the distance path leaves it out). ``how["method"]`` says which."""
    from multilat.network.adjust.approximate.large import multilaterate_targets, polar_targets
    from multilat.network.adjust.distance.exclusion import UndeterminedTargets

    tx = np.empty((obs.n_targets, 3))
    tx[~weak] = raw.target_xyz_m
    wk = np.flatnonzero(weak)
    rows = weak[obs.target_index]

    def multilaterated(ok):
        r = rows & ok[obs.target_index]
        sel = wk[ok[wk]]
        if not sel.size:
            return
        re = np.full(obs.n_targets, -1)
        re[sel] = np.arange(sel.size)
        x, _, _ = multilaterate_targets(raw.station_xyz_m, raw.offset_m, obs.station_index[r],
                                        re[obs.target_index[r]], obs.distance_m[r], obs.sigma_m[r],
                                        sel.size, side_point_m=raw.target_xyz_m.mean(axis=0),
                                        target_ids=[obs.target_ids[j] for j in sel])
        tx[sel] = x

    polar = {}
    try:
        multilaterated(np.ones(obs.n_targets, bool))
    except UndeterminedTargets as e:        # coplanar sights: placed by a tracker's angles, if read
        polar = polar_targets(obs, raw.station_xyz_m, raw.offset_m, tx, ~weak,
                              [obs.target_ids.index(t) for t in e.reasons])
        left = {t: why for t, why in e.reasons.items() if obs.target_ids.index(t) not in polar}
        if left:
            raise UndeterminedTargets(left) from None
        ok = np.ones(obs.n_targets, bool)
        ok[list(polar)] = False
        multilaterated(ok)
        for j, p in polar.items():
            tx[j] = p
        how["method"] += f" + {len(polar)} target(s) with coplanar sights placed by angles"
    if wk.size > len(polar):
        how["method"] += f" + multilateration of {wk.size - len(polar)} target(s) seen by 3"
    return tx

