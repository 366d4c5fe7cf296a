"""Initial values for self-calibrating multilateration: from the heads' angles, or from distances alone.

The adjustment (:func:`multilat.network.adjust.distance.adjust.adjust`) is a local method: it converges from
approximate coordinates good to about 10 mm (seed 000 §4.3). This module finds them.

Two routes
----------
**Angles** (seed 000 eq. 7). When one head reports its pointing angles for the targets it sees, the
targets follow in that head's frame (origin at the head, azimuth from +x towards +y, elevation above
the xy-plane)::

    T_j = H_h + (d_hj - o_h) [cos(el) cos(az), cos(el) sin(az), sin(el)]

with ``o_h = 0`` at first. (The paper writes ``sin(phi) cos(theta)``, ..., ``cos(phi)``: its
``phi`` is a *zenith* angle, ``phi = pi/2 - el``.) The other heads follow by classical
multilateration (linearised least squares in the algebraic form of Norrdine, ref. [27], extended
by the offset), then the remaining targets likewise, then a least-squares refinement.

**Distances alone** (no angles, no approximate coordinates). With ``o_i = 0`` the squared
distances of a complete block of ``p >= 4`` stations and ``q >= 10`` targets obey
``D2_ij = |H_i|^2 - 2 H_i.T_j + |T_j|^2``; double centring gives the rank-3 matrix
``M = -2 (H_i - H_mean).(T_j - T_mean)``. Its SVD yields both point sets up to an unknown
affine map ``A``; the column means ``mean_i D2_ij = c + 2 b.v_j + v_j^T G v_j`` are *linear* in the
symmetric ``G = A^-T A^-1``, ``b`` and ``c`` (10 unknowns, hence ``q >= 10``), which fixes ``A``
up to a rotation and a reflection (the TOA self-calibration idea of Kuang, Burgess, Torstensson
and Åström, ICASSP 2013). The 12 affine unknowns and the block's offsets are then fitted to the
distances themselves (Levenberg-Marquardt), and the factorisation is redone with the offsets
removed until they settle (blocks of 6-9 common targets start this fit from random affine maps).
Stations and targets outside the block are added by multilateration, re-fitting after each round;
then a least-squares refinement over every coordinate and offset. A solution is *good* when its RMS
residual is within 10 x RMS(sigma); blocks are tried until two reach the same RMS (or three are
good), then random restarts of the refinement if none is good; the lowest RMS is kept. docs/network-simulation.md gives the measured
convergence rates. The restarts are bounded by their number and by wall time
(:data:`~multilat.network.adjust.approximate.bounds.RESTART_SECONDS`, :mod:`multilat.network.adjust.approximate.bounds`), and end early
when a restart reaches the best RMS again while it is still :data:`~multilat.network.adjust.distance.unit_slip.SLIP_FACTOR`
times RMS(sigma) or more: a minimum found twice from unrelated starts with residuals that large is
a scale error of the data (a unit slip, :mod:`multilat.network.adjust.distance.unit_slip`) or gross errors, which
no restart can lower.

Frame and mirror
----------------
Distances cannot tell a network from its mirror image: both are exact solutions. From distances
alone the result is given in a 3-2-1 frame on three *frame stations* (the first three stations in
id order whose triangle is well shaped): the first at the origin, the second on +x, the third in the
xy-plane with y > 0, and the mirror chosen so that the first other station (in id order) off that
plane has z > 0 (if all stations are coplanar: the target farthest from the plane has z > 0). From
angles, the result is in the angle-giving head's frame (the angles fix the mirror).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust.approximate.bounds import RESTART_SECONDS, Bound, report
from multilat.network.model.datum import rigid_fit
from multilat.network.model.distance import line_of_sight, range_m
from multilat.network.adjust.distance.unit_slip import SLIP_FACTOR
from multilat.network.adjust.approximate.initial_refine import (choose_frame, fix_mirror, levenberg_marquardt,
                                             refine as refine_fit, refine_unmirrored, to_frame)

__all__ = ["InitialValues", "initial_values", "rigid_fit", "multilaterate"]


@dataclass(frozen=True, eq=False)
class InitialValues:
    """Approximate coordinates and offsets of a network.

    Attributes
    ----------
    station_xyz_m : ndarray, shape (s, 3), metres, in ``obs.station_ids`` order
    target_xyz_m : ndarray, shape (t, 3), metres, in ``obs.target_ids`` order
    offset_m : ndarray, shape (s,), metres (``distance = |H - T| + offset``)
    method : str
        ``"angles"``, ``"algebraic"`` (closed form from distances) or ``"restarts"``.
    rms_residual_m : float
        RMS of the distance residuals after the refinement (a converged network shows the noise level).
    refinement : Convergence or None
        How the final least-squares refinement ended (None without refinement).
    bounded : str or None
        Set when a bound (:mod:`multilat.network.adjust.approximate.bounds`) stopped the random restarts: which one.
    far_minimum_again : bool
        A random restart reached the best RMS again while it was >= SLIP_FACTOR x RMS(sigma) (the
        restarts stopped there): the minimum is the data's, no start can lower it.
    """

    station_xyz_m: np.ndarray
    target_xyz_m: np.ndarray
    offset_m: np.ndarray
    method: str
    rms_residual_m: float
    refinement: object = None
    bounded: str | None = None
    far_minimum_again: bool = False


# ----------------------------------------------------------------------------- helpers


def multilaterate(anchor_xyz_m, distance_m, *, with_offset: bool = False):
    """Position of one point from distances to known anchors, linearised (Norrdine's algebraic form).

    Solves ``d_k = |p - a_k| + o`` from ``d_k^2 - |a_k|^2 = (|p|^2 - o^2) - 2 a_k.p + 2 d_k o``,
    linear in ``(|p|^2 - o^2, p, o)`` (``o = 0`` and dropped unless ``with_offset``), by least
    squares in coordinates centred on the anchors, followed by three Gauss-Newton steps.

    Parameters
    ----------
    anchor_xyz_m : ndarray, shape (n, 3); n >= 4 (>= 5 with the offset)
    distance_m : ndarray, shape (n,)

    Returns
    -------
    xyz_m : ndarray (3,), offset_m : float
    """
    a = np.asarray(anchor_xyz_m, float)
    d = np.asarray(distance_m, float)
    c = a.mean(0)
    a0 = a - c
    cols = [np.ones(len(d)), -2 * a0[:, 0], -2 * a0[:, 1], -2 * a0[:, 2]]
    if with_offset:
        cols.append(2 * d)
    A = np.column_stack(cols)
    y = d ** 2 - np.einsum("ij,ij->i", a0, a0)
    sol, *_ = np.linalg.lstsq(A, y, rcond=None)
    p = sol[1:4]
    o = float(sol[4]) if with_offset else 0.0
    for _ in range(3):  # Gauss-Newton on the distances themselves
        rho, J = line_of_sight(p - a0, floor_m=1e-12)
        rho = np.where(rho > 0, rho, 1e-12)
        if with_offset:
            J = np.column_stack([J, np.ones(len(d))])
        r = d - rho - o
        step, *_ = np.linalg.lstsq(J, r, rcond=None)
        p = p + step[:3]
        if with_offset:
            o += float(step[3])
    return p + c, o


def distance_matrix(obs):
    s, t = len(obs.station_ids), len(obs.target_ids)
    D = np.full((s, t), np.nan)
    W = np.zeros((s, t))
    D[obs.station_index, obs.target_index] = obs.distance_m
    W[obs.station_index, obs.target_index] = 1.0 / np.asarray(obs.sigma_m, float) ** 2
    return D, W


def _algebraic_block(D2):
    """Stations (p, 3) and targets (q, 3) from a complete block of squared distances (p, q).

    Returns None when the algebra fails (G not positive definite, rank < 3).
    """
    p, q = D2.shape
    rm = D2.mean(1, keepdims=True)
    cm = D2.mean(0, keepdims=True)
    M = D2 - rm - cm + D2.mean()
    U, S, Vt = np.linalg.svd(M, full_matrices=False)
    if len(S) < 3 or S[2] <= 1e-9 * S[0]:
        return None
    sq = np.sqrt(S[:3])
    Ut = U[:, :3] * sq                 # h_i = A^T ut_i
    Vv = -0.5 * Vt[:3].T * sq          # T_j - T_mean = A^-1 vv_j ; M = -2 Ut Vv^T
    # mean over stations of D2_ij = c + 2 b.v_j + v_j^T G v_j, linear in (c, b, G)
    v = Vv
    rows = np.column_stack([np.ones(q), 2 * v[:, 0], 2 * v[:, 1], 2 * v[:, 2],
                            v[:, 0] ** 2, v[:, 1] ** 2, v[:, 2] ** 2,
                            2 * v[:, 0] * v[:, 1], 2 * v[:, 0] * v[:, 2], 2 * v[:, 1] * v[:, 2]])
    sol, *_ = np.linalg.lstsq(rows, cm.ravel(), rcond=None)
    b = sol[1:4]
    G = np.array([[sol[4], sol[7], sol[8]], [sol[7], sol[5], sol[9]], [sol[8], sol[9], sol[6]]])
    lam, W = np.linalg.eigh(G)
    if lam[0] <= 1e-12 * max(lam[-1], 1e-300):
        return None
    Ainv = np.sqrt(lam)[:, None] * W.T         # A^-1 = L^1/2 W^T, so A^-T A^-1 = G
    At = W.T / np.sqrt(lam)[:, None]           # A = W L^-1/2, so A^T = L^-1/2 W^T
    delta = At @ b                              # T_mean - H_mean, with H_mean = 0
    H = Ut @ At.T
    T = delta + Vv @ Ainv.T
    return H, T


def _affine_fit(D, Ut, Vv, A, delta, o):
    """Refine the affine unknowns (A (3, 3), delta (3,)) and offsets o (p,) of a factorised block:
    ``H_i = A^T ut_i``, ``T_j = delta + A^-1 vv_j``, residual ``D_ij - |H_i - T_j| - o_i``.
    Returns (H, T, o, rms) or None."""
    p, q = D.shape

    def fun(x):
        Ax = x[:9].reshape(3, 3)
        try:
            Ai = np.linalg.inv(Ax)
        except np.linalg.LinAlgError:
            return np.full(p * q, 1e3)
        H = Ut @ Ax
        T = x[9:12] + Vv @ Ai.T
        rho = range_m(H[:, None, :] - T[None, :, :])
        return (D - rho - x[12:, None]).ravel()

    def jac(x):
        Ax = x[:9].reshape(3, 3)
        try:
            Ai = np.linalg.inv(Ax)
        except np.linalg.LinAlgError:
            return np.zeros((p * q, len(x)))
        H = Ut @ Ax
        Wt = Vv @ Ai.T                                   # T_j - delta
        diff = H[:, None, :] - (x[9:12] + Wt)[None, :, :]
        _, U = line_of_sight(diff, floor_m=1e-12)                    # (p, q, 3)
        # d r_ij / d A_lk = -(u_ij,k ut_il + (u_ij . Ai[:, l]) w_jk)
        t1 = U[:, :, None, :] * Ut[:, None, :, None]
        t2 = (U @ Ai)[:, :, :, None] * Wt[None, :, None, :]
        J = np.empty((p, q, len(x)))
        J[:, :, :9] = -(t1 + t2).reshape(p, q, 9)
        J[:, :, 9:12] = U
        J[:, :, 12:] = 0.0
        J[np.arange(p), :, 12 + np.arange(p)] = -1.0
        return J.reshape(p * q, len(x))

    x0 = np.concatenate([A.ravel(), delta, o])
    x, _ = levenberg_marquardt(fun, jac, x0, max_iter=200)   # judged by the residuals after it
    Ax = x[:9].reshape(3, 3)
    if not np.all(np.isfinite(x)) or abs(np.linalg.det(Ax)) < 1e-300:
        return None
    r = fun(x)
    return Ut @ Ax, x[9:12] + Vv @ np.linalg.inv(Ax).T, x[12:], float(np.sqrt(np.mean(r ** 2)))


def _factorise(D2):
    """Double-centred rank-3 factors (ut (p, 3), vv (q, 3)) of squared distances, or None."""
    M = D2 - D2.mean(1, keepdims=True) - D2.mean(0, keepdims=True) + D2.mean()
    U, S, Vt = np.linalg.svd(M, full_matrices=False)
    if len(S) < 3 or S[2] <= 1e-9 * S[0]:
        return None
    sq = np.sqrt(S[:3])
    return U[:, :3] * sq, -0.5 * Vt[:3].T * sq


def _block_solve(D, *, rng, starts=8):
    """Stations (p, 3), targets (q, 3), offsets (p,) of a complete block of distances (p, q),
    p >= 4: closed form (q >= 10) or random affine starts, refined by :func:`_affine_fit`; then the
    factorisation is redone with the offsets removed until they settle. Returns None on failure."""
    p, q = D.shape
    f = _factorise(D ** 2)
    if f is None:
        return None
    Ut, Vv = f
    cands = []
    if q >= 10:
        lin = _algebraic_block(D ** 2)
        if lin is not None:
            Hl, Tl = lin
            A, *_ = np.linalg.lstsq(Ut, Hl - Hl.mean(0), rcond=None)
            cands.append((A, Tl.mean(0) - Hl.mean(0)))
    if not cands:
        scale = float(np.median(D))
        sv = np.linalg.norm(Ut, axis=0)
        for _k in range(starts):
            Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
            A = Q * (scale / np.sqrt(p) / np.maximum(sv, 1e-300))[:, None]
            cands.append((A, rng.normal(scale=0.5 * scale, size=3)))
    best = None
    for A, delta in cands:
        fit = _affine_fit(D, Ut, Vv, A, delta, np.zeros(p))
        if fit is not None and (best is None or fit[3] < best[3]):
            best = fit
    if best is None:
        return None
    for _ in range(3):  # redo the factorisation without the offsets
        H, T, o, _rms = best
        f = _factorise((D - o[:, None]) ** 2)
        if f is None:
            break
        Ut, Vv = f
        A, *_ = np.linalg.lstsq(Ut, H - H.mean(0), rcond=None)
        fit = _affine_fit(D, Ut, Vv, A, T.mean(0) - H.mean(0), o)
        if fit is None:
            break
        done = np.max(np.abs(fit[2] - o)) < 1e-7 * float(np.median(D))
        if fit[3] <= best[3]:
            best = fit
        if done:
            break
    return best


def _blocks(mask, *, min_targets=10, limit=6):
    """Complete blocks ``(station indices, target indices)``, best first: for the 4-station sets
    sharing the most targets (at least 6), greedily more stations while at least ``min_targets``
    and 3/4 of the common targets remain. At most ``limit`` blocks."""
    s, t = mask.shape
    cand = range(s)
    if s > 14:  # keep the search small: the 14 best-observed stations
        cand = sorted(np.argsort(-mask.sum(1), kind="stable")[:14].tolist())
    scored = []
    for c in itertools.combinations(cand, 4):
        n = int(np.all(mask[list(c)], axis=0).sum())
        if n >= 6:
            scored.append((-n, c))
    scored.sort()
    out = []
    for _, c in scored[:limit]:
        st = list(c)
        common = np.all(mask[st], axis=0)
        for i in np.argsort(-mask.sum(1), kind="stable"):
            if i in st:
                continue
            c2 = common & mask[i]
            if c2.sum() >= max(min(min_targets, common.sum()), int(0.75 * common.sum())):
                st.append(int(i))
                common = c2
        blk = (sorted(st), np.flatnonzero(common))
        if not any(blk[0] == b[0] and np.array_equal(blk[1], b[1]) for b in out):   # no duplicates
            out.append(blk)
    return out


# ----------------------------------------------------------------------------- growing


def _grow(D, W, H, T, o, placedH, placedT):
    """Multilaterate unplaced targets from placed stations and unplaced stations from placed
    targets, refining the placed sub-network after each round, until nothing changes.
    Arrays are modified in place."""
    obs = np.isfinite(D)
    changed = True
    while changed:
        changed = False
        for j in np.flatnonzero(~placedT):
            sts = np.flatnonzero(obs[:, j] & placedH)
            if len(sts) >= 4:
                T[j], _ = multilaterate(H[sts], D[sts, j] - o[sts])
                placedT[j] = True
                changed = True
        for i in np.flatnonzero(~placedH):
            tg = np.flatnonzero(obs[i] & placedT)
            if len(tg) >= 4:
                H[i], o[i] = multilaterate(T[tg], D[i, tg], with_offset=len(tg) >= 7)
                placedH[i] = True
                changed = True
        if changed and not (placedH.all() and placedT.all()):   # the caller refines the whole
            si, ti = np.flatnonzero(placedH), np.flatnonzero(placedT)
            Dsub = np.where(obs[np.ix_(si, ti)], D[np.ix_(si, ti)], np.nan)
            if placedH.sum() >= 3:
                frame = choose_frame(H[si])
                Hs, Ts = to_frame(H[si], T[ti], frame)
                Hs, Ts, os_, _, _, _ = refine_fit(Dsub, W[np.ix_(si, ti)], Hs, Ts, o[si], frame, robust=False)
                H[si], T[ti], o[si] = Hs, Ts, os_


# ----------------------------------------------------------------------------- refinement


def _check_coverage(obs, seen) -> None:
    """Raise unless every target is seen by 4 stations and every station sees 4 targets (``seen``:
    stations x targets)."""
    s, t = seen.shape
    for j in range(t):
        if seen[:, j].sum() < 4:
            raise MultilatError(f"target {obs.target_ids[j]!r} is seen by {int(seen[:, j].sum())} "
                                "station(s); at least 4 are needed")
    for i in range(s):
        if seen[i].sum() < 4:
            raise MultilatError(f"station {obs.station_ids[i]!r} sees {int(seen[i].sum())} "
                                "target(s); at least 4 are needed")


def _from_angles(obs, D, W, *, refine: bool) -> InitialValues | None:
    """The angles route: the station with the most azimuth/elevation readings (at least 4) places its
    targets by polar coordinates, the rest grows from them by multilateration (refined unless not
    ``refine``), in that station's frame. None where the angles cannot place the whole network."""
    s, t = len(obs.station_ids), len(obs.target_ids)
    az, el = getattr(obs, "azimuth_rad", None), getattr(obs, "elevation_rad", None)
    if az is None or el is None:
        return None
    ok = np.isfinite(az) & np.isfinite(el)
    if not ok.any():
        return None
    counts = np.bincount(obs.station_index[ok], minlength=s)
    h = int(np.argmax(counts))
    if counts[h] < 4:
        return None
    H = np.full((s, 3), np.nan)
    T = np.full((t, 3), np.nan)
    o = np.zeros(s)
    k = np.flatnonzero(ok & (obs.station_index == h))
    j = obs.target_index[k]
    dd = obs.distance_m[k]
    u = np.column_stack([np.cos(el[k]) * np.cos(az[k]), np.cos(el[k]) * np.sin(az[k]),
                         np.sin(el[k])])
    H[h] = 0.0
    T[j] = dd[:, None] * u
    placedH = np.zeros(s, bool)
    placedH[h] = True
    placedT = np.zeros(t, bool)
    placedT[j] = True
    _grow(D, W, H, T, o, placedH, placedT)
    if not (placedH.all() and placedT.all()):
        return None
    angle_frame = (H.copy(), T.copy())
    frame = choose_frame(H)
    H, T = to_frame(H, T, frame)
    rms = float("nan")
    if refine:
        H, T, o, rms, _, conv = refine_fit(D, W, H, T, o, frame)
    Hs, Ts = angle_frame
    R, tr = rigid_fit(np.vstack([H, T]), np.vstack([Hs, Ts]))
    return InitialValues(H @ R.T + tr, T @ R.T + tr, o, "angles", rms, conv if refine else None)


def _best_block(D, W, seen, *, rng, good: float):
    """Distances alone: complete blocks (best first) solved algebraically, grown to the whole network
    and refined, until two reach the same RMS at the noise level ``good`` or three reach it.
    Returns the best ``(H, T, o, frame, rms, robust, "algebraic", convergence)`` or None."""
    s, t = seen.shape
    best = None
    n_good = 0
    blocks = _blocks(seen)
    for st, tg in blocks:
        out = _block_solve(D[np.ix_(st, tg)], rng=rng)
        if out is None:
            continue
        H = np.full((s, 3), np.nan)
        T = np.full((t, 3), np.nan)
        o = np.zeros(s)
        H[st], T[tg], o[st], _ = out
        placedH = np.zeros(s, bool)
        placedH[st] = True
        placedT = np.zeros(t, bool)
        placedT[tg] = True
        _grow(D, W, H, T, o, placedH, placedT)
        if not (placedH.all() and placedT.all()):
            continue
        frame = choose_frame(H)
        H, T = to_frame(H, T, frame)
        H, T, o, rms, rob, conv = refine_unmirrored(D, W, H, T, o, frame)
        # a second block reaching the same RMS confirms the minimum; a lower one replaces it
        # (a false minimum can fit the noise level too: seen in ~0.5 % of gappy networks)
        confirmed = best is not None and best[4] <= good and abs(rms - best[4]) <= 1e-6 * best[4]
        if best is None or rms < best[4]:
            best = (H, T, o, frame, rms, rob, "algebraic", conv)
        if rms <= good:
            n_good += 1
        if confirmed or n_good >= 3:
            break
    return best


def initial_values(obs, *, rng=None, refine: bool = True, restarts: int = 20,
                   deadline: float | None = None) -> InitialValues:
    """Approximate station and target coordinates and station offsets of a network.

    Parameters
    ----------
    obs : multilat.network.model.data.Observations
        ``distance_m = |H_i - T_j| + offset_i``; ``azimuth_rad``/``elevation_rad`` used when given
        (per observation, NaN where unknown; azimuth from +x towards +y, elevation above the
        xy-plane of the head).
    rng : numpy.random.Generator, int or None
        Used by the random affine starts of blocks with fewer than 10 common targets and by the
        fallback (random restarts).
    refine : bool
        Angles route only: finish with a least-squares refinement of every coordinate and offset
        (default); ``False`` returns the plain eq. 7 + multilateration values. Distances alone
        always refine (the refinement decides between candidate blocks).
    restarts : int
        Number of random starts of the fallback (its work bound; its wall-time bound is
        :data:`~multilat.network.adjust.approximate.bounds.RESTART_SECONDS` from its first start).
    deadline : float, optional
        A :func:`time.monotonic` value after which no further random start begins (a search
        that calls this inside its own bound).

    Returns
    -------
    InitialValues

    Raises
    ------
    MultilatError
        Fewer than 4 stations, a target seen by fewer than 4 stations, a station seeing fewer than
        4 targets, or a network nothing could place.
    """
    s = len(obs.station_ids)
    if s < 4:
        raise MultilatError(f"initial values need at least 4 stations, got {s}")
    D, W = distance_matrix(obs)
    seen = np.isfinite(D)
    _check_coverage(obs, seen)

    from_angles = _from_angles(obs, D, W, refine=refine)
    if from_angles is not None:
        return from_angles

    # distances alone: complete blocks, best first, until the fit reaches the noise level
    gen = np.random.default_rng(rng)
    sig = np.sqrt(1.0 / W[seen])
    good = 10.0 * float(np.sqrt(np.mean(sig ** 2)))   # RMS residual of a converged network
    best = _best_block(D, W, seen, rng=gen, good=good)
    bound = None
    again = False
    if best is None or best[4] > good:
        bound = Bound("initial values, random restarts", max_work=restarts, max_seconds=RESTART_SECONDS,
                      deadline=deadline)
        alt, again = _restarts(D, W, rng=gen, bound=bound, best_rms=None if best is None else best[4],
                               far=SLIP_FACTOR * good / 10.0)
        if alt is not None and (best is None or alt[4] < best[4]):
            best = alt[:6] + ("restarts", alt[6])
        bound.warn_if_timed_out()
    if best is None:
        raise MultilatError("initial values: the network could not be built up from its distances "
                            "(disconnected or too few common targets)")
    H, T, o, frame, rms, _, method, conv = best
    H, T = fix_mirror(H, T, frame)
    return InitialValues(H, T, o, method, rms, conv, None if bound is None else bound.note(), again)


def _restarts(D, W, *, rng, bound, best_rms=None, far=np.inf):
    """Fallback: refinement from random starts while ``bound`` allows (its ``work`` counts the starts),
    the lowest RMS as (H, T, o, frame, rms, robust scale, convergence) or None, and whether it ended
    early because a start reached ``best_rms`` (the blocks' best, or an earlier start's) again while
    that is >= ``far``."""
    s, t = D.shape
    L = float(np.nanmax(D))
    best = None
    while not bound.exhausted():
        bound.spend()
        report(f"initial values: random start {bound.work} of {bound.max_work}")
        H = rng.uniform(-0.5 * L, 0.5 * L, (s, 3))
        T = rng.uniform(-0.5 * L, 0.5 * L, (t, 3))
        frame = choose_frame(H)
        H, T = to_frame(H, T, frame)
        Hr, Tr, orr, rms, rob, conv = refine_unmirrored(D, W, H, T, np.zeros(s), frame, max_nfev=100,
                                                        deadline=bound.deadline)
        if not np.isfinite(rms):
            continue
        again = best_rms is not None and best_rms >= far and abs(rms - best_rms) <= 1e-6 * best_rms
        if best is None or rms < best[4]:
            best = (Hr, Tr, orr, frame, rms, rob, conv)
        if again:
            return best, True
        best_rms = best[4] if best_rms is None else min(best_rms, best[4])
    return best, False
