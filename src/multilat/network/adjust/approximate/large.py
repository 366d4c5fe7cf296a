"""Initial values of large self-calibrating networks from distances alone.

The adjustment (:func:`multilat.network.adjust.distance.adjust.adjust`) converges from approximate values good to
about a centimetre. For small networks :func:`multilat.network.adjust.approximate.initial.initial_values` finds them
from all distances at once; for networks of thousands of targets :func:`large_initial_values` does
it in two steps, and the adjustment's sparse back end takes over:

1. **Seed network.** A few dozen targets seen by many stations (:func:`select_seed_targets`: three
   complete blocks of 4+ stations x 12 common targets, then targets that cover every station at
   least 6 times) are handed with all their distances to
   :func:`multilat.network.adjust.approximate.initial.initial_values`. It gives every station's coordinates and
   offset.
2. **Every target by multilateration** from those stations and offsets, vectorised over all
   targets (:func:`multilaterate_targets`): the linearised (differenced) equations
   ``-2 (H_k - c).(T - c) = (r_k^2 - |H_k - c|^2) - mean_k(...)``, ``r_k = d_k - o_k``, ``c`` the
   centroid of the target's stations (a 3x3 system per target), then Gauss-Newton steps on the
   distances with the stations held. A target whose stations are (nearly) coplanar has two mirror
   solutions about their plane; it is put on the side of the plane where the seed targets are, and
   doubtful ones are re-fitted from both mirror positions.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.angles import polar_to_xyz
from multilat.network.model.datum import rigid_fit
from multilat.network.model.distance import line_of_sight

__all__ = ["LargeStart", "large_initial_values", "multilaterate_targets", "polar_targets", "select_seed_targets"]


@dataclass(frozen=True, eq=False)
class LargeStart:
    """Initial values of a large network (:func:`large_initial_values`); metres.

    station_xyz_m (s, 3), target_xyz_m (t, 3), offset_m (s,): the start of the adjustment.
    seed_target_ids : the targets of the seed network; method : how it was solved;
    seed_rms_m, multilateration_rms_m : RMS residuals of the seed network and of all distances
    after multilateration (both at the noise level for a sound network); timings_s : seconds.
    """

    station_xyz_m: np.ndarray
    target_xyz_m: np.ndarray
    offset_m: np.ndarray
    seed_target_ids: tuple
    method: str
    seed_rms_m: float
    multilateration_rms_m: float
    timings_s: dict


# ---------------------------------------------------------------------------------------------
def _check_pattern(si, ti, s, t, station_ids, target_ids):
    """Duplicate (station, target) pairs and ids used as both; vectorised for millions of rows."""
    both = set(station_ids) & set(target_ids)
    if both:
        raise MultilatError(f"id {sorted(both)[0]!r} is used both as a station and as a target")
    key = ti * s + si
    if s * t <= 50_000_000:
        cnt = np.bincount(key, minlength=s * t)
        dup = np.flatnonzero(cnt > 1)
        k = int(dup[0]) if dup.size else -1
    else:
        srt = np.sort(key)
        d = np.flatnonzero(srt[1:] == srt[:-1])
        k = int(srt[d[0]]) if d.size else -1
    if k >= 0:
        raise MultilatError(f"duplicate observation {station_ids[k % s]}->{target_ids[k // s]}; "
                            "average repeated measurements into one row")


def select_seed_targets(station_index, target_index, n_stations: int, n_targets: int, *,
                        size: int = 48, blocks: int = 3, per_block: int = 12, min_cover: int = 6,
                        pool: int = 4000, rng=None) -> np.ndarray:
    """Targets for the seed network: complete blocks first, then coverage of every station.

    Parameters
    ----------
    station_index, target_index : ndarray of int, shape (m,)
    n_stations, n_targets : int
    size : int
        Target number of seed targets (more are taken if the coverage needs them, at most
        ``2 size``).
    blocks, per_block : int
        Complete blocks wanted: each a set of >= 4 stations (grown greedily from a different
        well-observed station, adding the station that keeps most common targets) and
        ``per_block`` targets seen by all of them (``initial_values`` solves such a block in closed
        form when it has >= 10 targets).
    min_cover : int
        Every station should see at least this many seed targets (``initial_values`` needs 4;
        with offsets, 7 make a station's multilateration over-determined).
    pool : int
        Candidates: the ``pool`` targets seen by the most stations (ties broken at random).
    rng : numpy Generator, int or None

    Returns
    -------
    ndarray of int
        Sorted target indices.
    """
    gen = np.random.default_rng(rng)
    si = np.asarray(station_index, np.int64)
    ti = np.asarray(target_index, np.int64)
    s, t = int(n_stations), int(n_targets)
    counts = np.bincount(ti, minlength=t)
    key = counts + 0.5 * gen.random(t)
    key[counts < 4] = -1.0
    npool = int(min(pool, np.count_nonzero(counts >= 4)))
    if npool < 4:
        raise MultilatError("fewer than 4 targets are seen by 4 or more stations: no seed network")
    cand = np.argpartition(-key, npool - 1)[:npool] if npool < t else np.arange(t)
    cand = cand[np.argsort(-key[cand], kind="stable")]
    pos = np.full(t, -1, np.int64)
    pos[cand] = np.arange(npool)
    sel = pos[ti] >= 0
    V = np.zeros((npool, s), bool)
    V[pos[ti[sel]], si[sel]] = True
    chosen: list[int] = []
    taken = np.zeros(npool, bool)
    starts = np.argsort(-V.sum(axis=0), kind="stable")
    for b in range(min(blocks, s)):
        st = [int(starts[b])]
        common = V[:, st[0]].copy()
        while True:
            n_with = (V & common[:, None]).sum(axis=0)
            n_with[st] = -1
            i = int(np.argmax(n_with))
            if n_with[i] < (per_block if len(st) >= 4 else 1):
                break
            st.append(i)
            common &= V[:, i]
            if len(st) >= 6:
                break
        if len(st) < 4:
            continue
        new = np.flatnonzero(common & ~taken)[:per_block]      # pool order: most stations first
        taken[new] = True
        chosen.extend(new.tolist())
    cover = V[taken].sum(axis=0)
    limit = 2 * size
    while len(chosen) < limit and cover.min() < min_cover:
        i = int(np.argmin(cover))
        c = np.flatnonzero(V[:, i] & ~taken)
        if c.size == 0:
            break
        gain = (V[c] & (cover < min_cover)).sum(axis=1)
        k = int(c[np.argmax(gain)])                         # ties: pool order
        taken[k] = True
        chosen.append(k)
        cover += V[k]
    rest = np.flatnonzero(~taken)
    if len(chosen) < size and rest.size:
        extra = rest[: size - len(chosen)]
        taken[extra] = True
        chosen.extend(extra.tolist())
    return np.sort(cand[np.array(chosen, np.int64)])


# ---------------------------------------------------------------------------------------------
def _group_by_target(station_index, target_index, n_targets, *arrays):
    """Observations grouped by target (stable sort when needed) and the target pointers (t + 1,)."""
    si = np.asarray(station_index, np.int64)
    ti = np.asarray(target_index, np.int64)
    arrays = [np.asarray(a, float) for a in arrays]
    if np.any(np.diff(ti) < 0):
        order = np.argsort(ti, kind="stable")
        si, ti = si[order], ti[order]
        arrays = [a[order] for a in arrays]
    tptr = np.zeros(n_targets + 1, np.int64)
    np.cumsum(np.bincount(ti, minlength=n_targets), out=tptr[1:])
    return si, ti, tptr, arrays


def multilaterate_targets(station_xyz_m, offset_m, station_index, target_index, distance_m, sigma_m,
                          n_targets: int, *, side_point_m=None, iterations: int = 3, flat_tol: float = 1e-3,
                          target_ids=None):
    """Every target from known stations and offsets (one compiled pass over the targets).

    Per target, with ``r_k = d_k - o_k`` and ``c`` the centroid of its stations ``H_k``: the linear
    solution of the differenced squared-distance equations ``-2 (H_k - c).(T - c) = (r_k^2 -
    |H_k - c|^2) - mean_k(...)`` (``M (T - c) = b``, ``M = sum (H_k - c)(H_k - c)^T``), then
    ``iterations`` Gauss-Newton steps on the distances with the stations held (weights
    ``1/sigma^2``). When the target's stations are (nearly) coplanar (smallest eigenvalue of ``M``
    below ``flat_tol`` times the largest: spread normal to their plane under ~3 % of the in-plane
    spread) the linear equations do not fix the height above the plane; it follows from the mean of
    ``r^2 - |in-plane offset|^2``, on the side of ``side_point_m`` (the two mirror positions fit the
    distances equally well).

    Parameters
    ----------
    station_xyz_m : ndarray, shape (s, 3)
    offset_m : ndarray, shape (s,)
    station_index, target_index : ndarray of int, shape (m,)
    distance_m, sigma_m : ndarray, shape (m,)
    n_targets : int
        ``t``; every target needs >= 3 observations (with 3, or with coplanar stations, the mirror
        position through their plane fits equally: the side of ``side_point_m`` is taken).
    side_point_m : ndarray, shape (3,), optional
        Mirror choice for coplanar stations (default: the stations' centroid + 1 m in +z).
    iterations : int
        Gauss-Newton steps after the linear solution.
    flat_tol : float
        Coplanarity threshold on the eigenvalue ratio of ``M``.
    target_ids : sequence of str, optional
        For error messages.

    Returns
    -------
    target_xyz_m : ndarray, shape (t, 3)
    rms_residual_m : ndarray, shape (t,)
        RMS distance residual of each target.
    coplanar : ndarray of bool, shape (t,)
        Targets placed with the mirror rule.
    """
    from multilat.network.adjust.solve import _sparse_kernels as K

    h = np.ascontiguousarray(station_xyz_m, float)
    o = np.ascontiguousarray(offset_m, float)
    t = int(n_targets)
    si, ti, tptr, (d, sig) = _group_by_target(station_index, target_index, t, distance_m, sigma_m)
    counts = np.diff(tptr)
    name = (lambda j: repr(target_ids[j])) if target_ids is not None else (lambda j: f"index {j}")
    if counts.min() < 3:
        j = int(np.argmin(counts))
        raise MultilatError(f"target {name(j)} has {int(counts[j])} observations (needs >= 3)")
    side = (np.asarray(side_point_m, float) if side_point_m is not None
            else h.mean(axis=0) + np.array([0.0, 0.0, 1.0]))
    x = np.empty((t, 3))
    rms = np.empty(t)
    status = np.zeros(t, np.int64)
    K.multilaterate(h, o, d, 1.0 / sig**2, si, tptr, side, int(iterations), float(flat_tol), x, rms, status)
    if np.any(status >= 2):     # undetermined targets: named, left out by the adjustment (exclusion.py)
        from multilat.network.adjust.distance.exclusion import COPLANAR_REASON, UndeterminedTargets

        why = {2: "is undetermined: its stations are collinear", 3: COPLANAR_REASON}
        raise UndeterminedTargets({(target_ids[j] if target_ids is not None else f"index {j}"):
                                   why[int(status[j])] for j in np.flatnonzero(status >= 2)})
    return x, rms, status == 1


#: largest RMS misfit (of unit vectors, about radians) of a station's angle frame fitted to its placed
#: targets for it to place a target by angles (:func:`polar_targets`): a wrong hand or a bad start
#: misfits by order 1, a sound one by the start's error over the range (~1e-3)
POLAR_MISFIT = 0.05


def polar_targets(obs, station_xyz_m, offset_m, tx, placed, targets) -> dict:
    """{target: position} of the ``targets`` (indices) a station reading azimuth and elevation places
    as a polar point ``H + (d - o) R u(az, el)`` (stations ``station_xyz_m``, ``offset_m``), ``R`` that
    station's frame fitted (Kabsch) to its readings of the ``placed`` targets (positions ``tx``), at
    least 3 not on one line; only where the fit misfits by less than :data:`POLAR_MISFIT`. The distance path's initial values (small:
    :mod:`.starts`; large: :func:`large_initial_values`) place a target whose distance sights are
    exactly coplanar this way instead of leaving it out."""
    az, el = obs.azimuth_rad, obs.elevation_rad
    if az is None or el is None:
        return {}
    read = np.isfinite(az) & np.isfinite(el)
    u = polar_to_xyz(np.zeros(3), np.zeros(3), 1.0, az, el)     # unit sights in each station's frame
    H, o = station_xyz_m, offset_m
    out = {}
    for j in targets:
        for k in np.flatnonzero(read & (obs.target_index == j)):
            i = obs.station_index[k]
            ref = np.flatnonzero(read & (obs.station_index == i) & placed[obs.target_index])
            _, w = line_of_sight(tx[obs.target_index[ref]] - H[i])
            if len(ref) < 3 or np.linalg.svd(w - w.mean(0), compute_uv=False)[1] <= 1e-6:
                continue
            # rays from one origin: the origin is a point too (as the general chain's frames.orient)
            try:
                R, _ = rigid_fit(np.vstack([np.zeros(3), u[ref]]), np.vstack([np.zeros(3), w]))
            except MultilatError:                   # its readings on one line: no frame
                continue
            if np.sqrt(np.mean(np.sum((u[ref] @ R.T - w) ** 2, axis=1))) < POLAR_MISFIT:
                out[int(j)] = H[i] + (obs.distance_m[k] - o[i]) * (R @ u[k])
                break
    return out


def _multilaterated_or_polar(obs, iv, si, ti, d, sig):
    """:func:`multilaterate_targets` of every target of ``obs`` from the seed's stations ``iv`` (rows
    ``si``, ``ti``, ``d``, ``sig`` grouped by target); a target whose sights are exactly coplanar
    (:class:`~multilat.network.adjust.distance.exclusion.UndeterminedTargets`) placed by a tracker's
    angles where read (:func:`polar_targets`, from the others), else refused as undetermined."""
    from multilat.network.adjust.distance.exclusion import UndeterminedTargets

    t, tids = obs.n_targets, tuple(obs.target_ids)
    H, o, side = iv.station_xyz_m, iv.offset_m, iv.target_xyz_m.mean(axis=0)
    try:
        return multilaterate_targets(H, o, si, ti, d, sig, t, side_point_m=side, target_ids=tids)
    except UndeterminedTargets as e:
        why = e.reasons
    bad = np.array([tids.index(k) for k in why], np.int64)
    ok = np.ones(t, bool)
    ok[bad] = False
    keep = np.flatnonzero(ok)
    remap = np.full(t, -1, np.int64)
    remap[keep] = np.arange(keep.size)
    r = ok[ti]
    tg, trms, flat = np.full((t, 3), np.nan), np.zeros(t), np.zeros(t, bool)
    tg[keep], trms[keep], flat[keep] = multilaterate_targets(H, o, si[r], remap[ti[r]], d[r], sig[r], keep.size,
                                                             side_point_m=side, target_ids=[tids[j] for j in keep])
    polar = polar_targets(obs, H, o, tg, ok, bad)
    left = {tids[j]: why[tids[j]] for j in bad if int(j) not in polar}
    if left:
        raise UndeterminedTargets(left)
    for j, p in polar.items():
        k = ti == j
        tg[j] = p
        trms[j] = float(np.sqrt(np.mean((d[k] - o[si[k]] - np.linalg.norm(p - H[si[k]], axis=1)) ** 2)))
    return tg, trms, flat


def _refit_ambiguous(x, rms, flagged, station_xyz_m, offset_m, station_index, tptr, distance_m, sigma_m,
                     *, iterations: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Re-place the targets whose multilateration is doubtful, choosing between mirror positions.

    A target whose stations are nearly coplanar (``flagged``: placed by the mirror rule) or whose RMS
    residual is far above the network's noise has two candidate positions: its current one and its
    mirror image in the best-fit plane of its stations. Each is refined by ``iterations``
    Gauss-Newton steps on the distances (stations held) and the one with the smaller weighted RMS
    residual is kept: targets on either side of a flat ring of stations are placed correctly, which
    one ``side_point_m`` cannot do. Loops over the doubtful targets only (a few per mille).

    Parameters
    ----------
    x : ndarray, shape (t, 3)   target positions (m), modified copy returned
    rms : ndarray, shape (t,)   their RMS residuals (m)
    flagged : ndarray of bool, shape (t,)
    station_xyz_m, offset_m : station positions (s, 3) and offsets (s,), metres
    station_index, tptr, distance_m, sigma_m : observations grouped by target (see ``_group_by_target``)
    """
    x = x.copy()
    rms = rms.copy()
    noise = float(np.median(rms))
    doubtful = np.flatnonzero(flagged | (rms > 10.0 * max(noise, 1e-12)))
    for j in doubtful:
        k = slice(tptr[j], tptr[j + 1])
        h = station_xyz_m[station_index[k]]
        r = distance_m[k] - offset_m[station_index[k]]
        w = 1.0 / sigma_m[k] ** 2
        c = h.mean(axis=0)
        normal = np.linalg.svd(h - c)[2][-1]
        best = (np.inf, x[j])
        for start in (x[j], x[j] - 2.0 * np.dot(x[j] - c, normal) * normal):
            p, _ = refit_point(start, h, r, w, iterations)
            res = r - np.linalg.norm(p - h, axis=1)
            q = float(np.sqrt(np.mean(res**2)))
            if q < best[0]:
                best = (q, p)
        rms[j], x[j] = best
    return x, rms


def refit_point(p0, nb, r, w, iterations: int = 20):
    """Gauss-Newton on one point's position with its neighbours ``nb`` (k, 3) held: minimise
    ``sum w (r - |p - nb|)^2`` from ``p0``; stops on a step below 1e-12 m or a singular system.
    Returns ``(p, cost)``. Used by the initial values' re-trial of doubtful targets here and by the
    mirror test of :mod:`multilat.network.adjust.distance.ambiguity`."""
    p = np.array(p0, float)
    for _ in range(iterations):
        g, a = line_of_sight(p - nb)
        e = r - g
        try:
            step = np.linalg.solve((a * w[:, None]).T @ a, (a * w[:, None]).T @ e)
        except np.linalg.LinAlgError:
            break
        p = p + step
        if np.linalg.norm(step) < 1e-12:
            break
    e = r - np.linalg.norm(p - nb, axis=1)
    return p, float(np.sum(w * e * e))


# ---------------------------------------------------------------------------------------------
def large_initial_values(obs, *, rng=None, seed_size: int = 48) -> LargeStart:
    """Initial values of a large network from its distances alone (steps 1-2 of the module doc).

    Parameters
    ----------
    obs : Observations
        Every station needs >= 4 targets; targets seen by 3 stations are placed on the side of their
        stations' plane where the seed targets are.
    rng : numpy Generator, int or None
        Seed-target tie-breaking and ``initial_values``' random starts.
    seed_size : int
        About how many targets form the seed network (:func:`select_seed_targets`).

    Returns
    -------
    LargeStart
    """
    from multilat.network.model.data import Observations
    from multilat.network.adjust.approximate.initial import initial_values

    t0 = time.perf_counter()
    sids, tids = tuple(obs.station_ids), tuple(obs.target_ids)
    si = np.asarray(obs.station_index, np.int64)
    ti = np.asarray(obs.target_index, np.int64)
    d = np.asarray(obs.distance_m, float)
    sig = np.asarray(obs.sigma_m, float)
    s, t, m = len(sids), len(tids), len(d)
    counts = np.bincount(ti, minlength=t)
    if s < 4:
        raise MultilatError(f"initial values need at least 4 stations, got {s}")
    gen = np.random.default_rng(rng)
    # 1. seed network
    seed = select_seed_targets(si, ti, s, t, size=seed_size, rng=gen)
    remap = np.full(t, -1, np.int64)
    remap[seed] = np.arange(len(seed))
    keep = remap[ti] >= 0
    sub = Observations(sids, tuple(tids[j] for j in seed), si[keep], remap[ti[keep]], d[keep], sig[keep])
    if np.bincount(sub.station_index, minlength=s).min() < 4:
        i = int(np.argmin(np.bincount(sub.station_index, minlength=s)))
        raise MultilatError(f"station {sids[i]!r} sees too few well-observed targets for the seed network")
    iv = initial_values(sub, rng=gen)
    t1 = time.perf_counter()
    # 2. every target from the stations
    si, ti, _, (d, sig) = _group_by_target(si, ti, t, d, sig)
    tg, trms, flat = _multilaterated_or_polar(obs, iv, si, ti, d, sig)
    tptr = np.zeros(t + 1, np.int64)
    np.cumsum(counts, out=tptr[1:])
    tg, trms = _refit_ambiguous(tg, trms, flat, iv.station_xyz_m, iv.offset_m, si, tptr, d, sig)
    ml_rms = float(np.sqrt(np.sum(trms**2 * counts) / m))
    return LargeStart(iv.station_xyz_m, tg, iv.offset_m, tuple(tids[j] for j in seed),
                      f"seed network ({iv.method}) + multilateration", iv.rms_residual_m, ml_rms,
                      {"seed": t1 - t0, "multilaterate": time.perf_counter() - t1})
