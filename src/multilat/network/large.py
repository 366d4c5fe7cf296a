"""Large self-calibrating networks from distances alone: initial values, sparse solve, covariances.

:func:`multilat.network.sparse.solve_large` solves a network of hundreds of thousands of targets in
a fraction of a second, but only from initial values good to about a centimetre.
:func:`adjust_large` finds them itself, from the distances alone, in three steps:

1. **Seed network.** A few dozen targets seen by many stations (:func:`select_seed_targets`: three
   complete blocks of 4+ stations x 12 common targets, then targets that cover every station at
   least 6 times) are handed with all their distances to
   :func:`multilat.network.initial.initial_values`, the closed-form/affine self-calibration of
   small networks. It gives every station's coordinates and offset, in its frame convention
   (3-2-1 on three well-shaped stations, mirror fixed by the first other station off their plane).
2. **Every target by multilateration** from those stations and offsets, vectorised over all
   targets (:func:`multilaterate_targets`): the linearised (differenced) equations
   ``-2 (H_k - c).(T - c) = (r_k^2 - |H_k - c|^2) - mean_k(...)``, ``r_k = d_k - o_k``, ``c`` the
   centroid of the target's stations (a 3x3 system per target), then Gauss-Newton steps on the
   distances with the stations held. A target whose stations are (nearly) coplanar has two mirror
   solutions about their plane; it is put on the side of the plane where the seed targets are.
3. **Sparse Gauss-Newton** (:func:`multilat.network.sparse.solve_large`) of everything, with the
   full station/offset covariance and a 3x3 covariance per target.

Datum: free network, inner constraints over the stations (minimum trace of the station
coordinates' covariance), positioned on the seed network's frame (the solution is moved rigidly to
fit the seed station coordinates). Offsets, interpoint distances, sigma0 and the global test do not
depend on it. No data snooping is run (the redundancy numbers of a 10^6-observation network are not
computed); a gross error shows in the global test.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.fastio import read_observations_fast
from multilat.network.statistics import GlobalTest, global_test

__all__ = ["LargeResult", "adjust_large", "large_result_to_json", "multilaterate_targets",
           "select_seed_targets", "read_observations_fast"]


@dataclass(frozen=True, eq=False)
class LargeResult:
    """Result of :func:`adjust_large`. Arrays follow ``station_ids`` / ``target_ids``; metres.

    Attributes
    ----------
    station_ids, target_ids : tuple of str
    station_xyz_m : ndarray, shape (s, 3)
    offset_m : ndarray, shape (s,)
        Additive instrument offsets (``distance = |H - T| + offset``).
    station_cov_m2 : ndarray, shape (4s, 4s)
        Full covariance of ``[station xyz (station-major, 3s), offsets (s)]`` in the datum, m^2
        (a-priori variance factor 1, i.e. ``sigma_m`` taken as known).
    target_xyz_m : ndarray, shape (t, 3)
    target_cov_m2 : ndarray, shape (t, 3, 3)
        Covariance of each target in the same datum, m^2.
    sigma0 : float
        A-posteriori standard deviation of unit weight.
    dof : int
        Observations - unknowns + 6 (datum defect).
    global_test : statistics.GlobalTest
        chi^2 test of ``sigma0^2 dof`` (upper, ``alpha_global``).
    iterations : int
        Gauss-Newton iterations of the sparse solve.
    n_obs : int
    seed_target_ids : tuple of str
        The targets of the seed network (step 1).
    initial_method : str
        How ``initial_values`` solved the seed network (``"algebraic"`` or ``"restarts"``).
    initial_rms_m : float
        RMS residual of the seed network; ``multilateration_rms_m``: RMS residual of all distances
        after step 2 (both at the noise level for a sound network).
    multilateration_rms_m : float
    datum : str
        Description of the datum.
    timings_s : dict
        Wall times of ``seed``, ``multilaterate``, ``solve``, ``covariance`` (seconds).
    """

    station_ids: tuple
    target_ids: tuple
    station_xyz_m: np.ndarray
    offset_m: np.ndarray
    station_cov_m2: np.ndarray
    target_xyz_m: np.ndarray
    target_cov_m2: np.ndarray
    sigma0: float
    dof: int
    global_test: GlobalTest
    iterations: int
    n_obs: int
    seed_target_ids: tuple
    initial_method: str
    initial_rms_m: float
    multilateration_rms_m: float
    datum: str
    timings_s: dict

    @property
    def offset_std_m(self) -> np.ndarray:
        """Standard uncertainty of each offset, shape (s,)."""
        s = len(self.station_ids)
        return np.sqrt(np.clip(np.diag(self.station_cov_m2)[3 * s:], 0, None))

    @property
    def station_point_cov_m2(self) -> np.ndarray:
        """3x3 covariance of each station's coordinates, shape (s, 3, 3)."""
        s = len(self.station_ids)
        idx = 3 * np.arange(s)[:, None] + np.arange(3)
        return self.station_cov_m2[idx[:, :, None], idx[:, None, :]]


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
        ``t``; every target needs >= 4 observations.
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
    from multilat.network import _sparse_kernels as K

    h = np.ascontiguousarray(station_xyz_m, float)
    o = np.ascontiguousarray(offset_m, float)
    t = int(n_targets)
    si, ti, tptr, (d, sig) = _group_by_target(station_index, target_index, t, distance_m, sigma_m)
    counts = np.diff(tptr)
    name = (lambda j: repr(target_ids[j])) if target_ids is not None else (lambda j: f"index {j}")
    if counts.min() < 4:
        j = int(np.argmin(counts))
        raise MultilatError(f"target {name(j)} has {int(counts[j])} observations (needs >= 4 from "
                            "distances alone)")
    side = (np.asarray(side_point_m, float) if side_point_m is not None
            else h.mean(axis=0) + np.array([0.0, 0.0, 1.0]))
    x = np.empty((t, 3))
    rms = np.empty(t)
    status = np.zeros(t, np.int64)
    K.multilaterate(h, o, d, 1.0 / sig**2, si, tptr, side, int(iterations), float(flat_tol), x, rms, status)
    if np.any(status == 2):
        j = int(np.argmax(status == 2))
        raise MultilatError(f"target {name(j)}: its stations are collinear (position undetermined)")
    if np.any(status == 3):
        j = int(np.argmax(status == 3))
        raise MultilatError(f"target {name(j)}: its lines of sight are coplanar (position undetermined)")
    return x, rms, status == 1


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
            p = start.astype(float).copy()
            for _ in range(iterations):
                v = p - h
                g = np.linalg.norm(v, axis=1)
                a = v / g[:, None]
                e = r - g
                n = (a * w[:, None]).T @ a
                try:
                    step = np.linalg.solve(n, (a * w[:, None]).T @ e)
                except np.linalg.LinAlgError:
                    break
                p = p + step
                if np.linalg.norm(step) < 1e-12:
                    break
            res = r - np.linalg.norm(p - h, axis=1)
            q = float(np.sqrt(np.mean(res**2)))
            if q < best[0]:
                best = (q, p)
        rms[j], x[j] = best
    return x, rms


# ---------------------------------------------------------------------------------------------
def adjust_large(obs, *, sigma_m=None, rng=None, seed_size: int = 48, alpha_global: float = 0.05,
                 tol_m: float = 1e-10, max_iter: int = 30, covariance: bool = True) -> LargeResult:
    """Adjust a large self-calibrating network from its distances alone.

    Parameters
    ----------
    obs : Observations or FastObservations
        Any object with ``station_ids``, ``target_ids``, ``station_index``, ``target_index``,
        ``distance_m`` and ``sigma_m`` (:class:`multilat.network.data.Observations`, or
        :func:`read_observations_fast` for files of millions of rows). Every target needs >= 4
        stations (from distances alone a target seen by 3 has two mirror positions).
    sigma_m : float or ndarray (m,), optional
        Replaces the observations' standard uncertainties (metres, > 0).
    rng : numpy Generator, int or None
        Seed-target tie-breaking and ``initial_values``' random starts.
    seed_size : int
        About how many targets form the seed network (:func:`select_seed_targets`).
    alpha_global : float
        Significance of the global chi^2 test.
    tol_m, max_iter
        Convergence of the sparse Gauss-Newton (largest step, metres; iteration limit).
    covariance : bool
        Compute the covariances (else ``station_cov_m2`` / ``target_cov_m2`` are None).

    Returns
    -------
    LargeResult

    Raises
    ------
    MultilatError
        Bad input (shapes, non-finite or non-positive values, duplicate pairs, an id used as station
        and target, a target with < 4 stations), a seed network that cannot be solved, collinear
        stations of a target, or no convergence.
    """
    from multilat.network.data import Observations
    from multilat.network.initial import initial_values
    from multilat.network.sparse import solve_large

    t0 = time.perf_counter()
    if not (0 < alpha_global < 1):
        raise MultilatError(f"alpha_global must be in (0, 1), got {alpha_global!r}")
    try:
        sids = tuple(obs.station_ids)
        tids = tuple(obs.target_ids)
        si = np.asarray(obs.station_index, np.int64)
        ti = np.asarray(obs.target_index, np.int64)
        d = np.asarray(obs.distance_m, float)
        sig = np.asarray(obs.sigma_m if sigma_m is None else sigma_m, float)
    except AttributeError as e:
        raise MultilatError(f"adjust_large: obs lacks {e.name!r} (give Observations or FastObservations)") \
            from None
    s, t, m = len(sids), len(tids), len(d)
    sig = np.broadcast_to(sig, (m,)) if sig.ndim == 0 else sig
    if not (si.shape == ti.shape == d.shape == sig.shape == (m,)) or m == 0:
        raise MultilatError("station_index, target_index, distance_m and sigma_m must be 1-D of one length")
    if si.min() < 0 or si.max() >= s or ti.min() < 0 or ti.max() >= t:
        raise MultilatError("observation indices out of range of station_ids / target_ids")
    for name, v in (("distance_m", d), ("sigma_m", sig)):
        bad = ~(np.isfinite(v) & (v > 0))
        if bad.any():
            k = int(np.argmax(bad))
            raise MultilatError(f"{name} must be finite and > 0: observation {k} "
                                f"({sids[si[k]]}->{tids[ti[k]]}) has {v[k]!r}")
    _check_pattern(si, ti, s, t, sids, tids)
    counts = np.bincount(ti, minlength=t)
    if counts.min() < 4:
        j = int(np.argmin(counts))
        raise MultilatError(f"target {tids[j]!r} is seen by {int(counts[j])} station(s); from distances "
                            "alone at least 4 are needed")
    scount = np.bincount(si, minlength=s)
    if scount.min() < 4:
        i = int(np.argmin(scount))
        raise MultilatError(f"station {sids[i]!r} sees {int(scount[i])} target(s); at least 4 are needed")
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
    si, ti, _, (d, sig) = _group_by_target(si, ti, t, d, sig)    # once, for both passes
    tg, trms, flat = multilaterate_targets(iv.station_xyz_m, iv.offset_m, si, ti, d, sig, t,
                                           side_point_m=iv.target_xyz_m.mean(axis=0), target_ids=tids)
    tptr = np.zeros(t + 1, np.int64)
    np.cumsum(counts, out=tptr[1:])
    tg, trms = _refit_ambiguous(tg, trms, flat, iv.station_xyz_m, iv.offset_m, si, tptr, d, sig)
    ml_rms = float(np.sqrt(np.sum(trms**2 * counts) / m))
    t2 = time.perf_counter()

    # 3. sparse Gauss-Newton
    sol = solve_large(si, ti, d, sig, iv.station_xyz_m, iv.offset_m, tg, covariance=covariance,
                      tol_m=tol_m, max_iter=max_iter)
    if not sol.converged:
        raise MultilatError(f"the sparse adjustment did not converge in {sol.iterations} iterations (last "
                            f"step {sol.last_step_m:.3g} m); multilateration RMS residual {ml_rms:.3g} m")
    gt = global_test(sol.sigma0**2 * sol.dof, sol.dof, alpha=alpha_global)
    frame = _frame_names(iv.station_xyz_m, sids)
    datum = ("free network, inner constraints over the stations (frame of the initial values: "
             f"{frame})")
    timings = {"seed": t1 - t0, "multilaterate": t2 - t1, "solve": sol.timings_s["solve"],
               "covariance": sol.timings_s["covariance"], "total": time.perf_counter() - t0}
    return LargeResult(sids, tids, sol.station_xyz_m, sol.offset_m, sol.station_cov_m2, sol.target_xyz_m,
                       sol.target_cov_m2, sol.sigma0, sol.dof, gt, sol.iterations, m,
                       tuple(tids[j] for j in seed), iv.method, iv.rms_residual_m, ml_rms, datum, timings)


def _frame_names(h, sids) -> str:
    """Which stations define the initial values' 3-2-1 frame (origin, +x, xy-plane)."""
    a = int(np.argmin(np.linalg.norm(h, axis=1)))
    rest = [i for i in range(len(h)) if i != a]
    onx = [i for i in rest if np.hypot(h[i, 1], h[i, 2]) <= 1e-9 * max(1.0, np.abs(h).max())]
    inxy = [i for i in rest if i not in onx and abs(h[i, 2]) <= 1e-9 * max(1.0, np.abs(h).max())]
    if onx and inxy:
        return f"3-2-1: {sids[a]} at origin, {sids[onx[0]]} on +x, {sids[inxy[0]]} in the xy-plane"
    return "3-2-1 on three stations"


def large_result_to_json(res: LargeResult) -> dict:
    """A JSON-ready dict with the keys of ``multilat adjust --json`` where they apply.

    ``stations{id: {xyz_m, offset_m, offset_u_m, offset_estimated, cov_m2}}``,
    ``targets{id: {xyz_m, cov_m2}}``, ``sigma0``, ``dof``, ``global_test{statistic, critical,
    passed, alpha}``, ``outliers`` and ``unlocated`` (always empty: data snooping is not run by the
    sparse solver, see ``note``), ``iterations``, ``datum``, ``cost``, ``n_obs``, ``n_used``, plus
    ``solver`` ("sparse") and ``initial`` (seed network, RMS residuals, timings).
    """
    s = len(res.station_ids)
    scov = res.station_point_cov_m2 if res.station_cov_m2 is not None else None
    ostd = res.offset_std_m if res.station_cov_m2 is not None else np.full(s, np.nan)
    stations = {sid: {"xyz_m": res.station_xyz_m[i].tolist(), "offset_m": float(res.offset_m[i]),
                      "offset_u_m": float(ostd[i]), "offset_estimated": True,
                      "cov_m2": None if scov is None else scov[i].tolist()}
                for i, sid in enumerate(res.station_ids)}
    txyz = res.target_xyz_m.tolist()
    tcov = res.target_cov_m2.tolist() if res.target_cov_m2 is not None else [None] * len(txyz)
    targets = {tid: {"xyz_m": txyz[j], "cov_m2": tcov[j]} for j, tid in enumerate(res.target_ids)}
    gt = res.global_test
    return {
        "datum": res.datum,
        "cost": "distance",
        "solver": "sparse",
        "n_obs": res.n_obs,
        "n_used": res.n_obs,
        "stations": stations,
        "targets": targets,
        "sigma0": res.sigma0,
        "dof": res.dof,
        "global_test": {"statistic": gt.statistic, "critical": gt.critical, "passed": gt.passed,
                        "alpha": gt.alpha},
        "outliers": [],
        "unlocated": [],
        "note": "data snooping is not run in the sparse path (no redundancy numbers for large networks); "
                "a gross error shows in the global test",
        "reference_lengths": [],
        "iterations": res.iterations,
        "initial": {"seed_targets": list(res.seed_target_ids), "method": res.initial_method,
                    "seed_rms_m": res.initial_rms_m, "multilateration_rms_m": res.multilateration_rms_m,
                    "timings_s": dict(res.timings_s)},
    }
