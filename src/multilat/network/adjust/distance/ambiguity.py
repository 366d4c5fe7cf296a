"""Geometry that distances cannot fix: a flat network, and points whose mirror image fits equally.

Distances are invariant under a reflection, so two defects survive a converged adjustment with a
passed global test (issue 25, item 12), and both are checked on the adjusted network:

* **A flat network** (:func:`flat_network`): stations and targets all (nearly) in one plane. A
  point's displacement along the plane's normal changes its distances only to second order (the
  first-order Jacobian has a flat direction per point beyond the datum), so noise bends the network
  out of the plane by about ``sqrt(sigma L)`` and the linearised σ of that direction is of the same
  order as the bending itself: the out-of-plane coordinates are not determined. Refused.
* **A mirror ambiguity** (:func:`mirror_ambiguities`): a point whose neighbours (the points it has
  distances to: a station's targets, a target's stations) lie in one plane has a mirror image through
  that plane that gives the same distances: all targets in one plane leave every station's side of
  it open, a target seen by 3 stations (or by coplanar ones) its side of their plane. A discrete
  ambiguity: the result is one of ``2^k`` equally good solutions, named as such (``--strict``
  refuses it).

One tolerance for "in one plane" (:data:`K_PLANE`): a point set is coplanar *within its
uncertainty* when its RMS spread off its best-fit plane is below ``K_PLANE`` times the RMS standard
uncertainty of its points along the plane's normal (from the adjustment's covariance). A real spread
of a few millimetres at 5 µm distances is hundreds of σ; noise bending of a flat network stays
within a few σ (measured in tests/test_ambiguous_geometry.py).

A mirror is named only when the data confirm it: the point is reflected through its neighbours'
plane, the network adjusted again from there (a station; its targets move with it) or the point
alone refitted with its stations held (a target: its stations are fixed by many other targets), and
the reflected solution must be a distinct position (the point moved by more than ``sqrt(lambda0)``
times its standard uncertainty) whose ``vᵀPv`` exceeds the original's by less than the tests'
non-centrality ``lambda0`` (the same power as a w-test has for an MDB). Angles, control or scale
bars to points off the plane break the symmetry and take part in the station's re-adjustment; a
target with an angle observation, a control target or one at the end of a scale bar is not tested
(its side is fixed by them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.network.adjust.approximate.large import refit_point
from multilat.network.model.weak_points import K_PLANE

__all__ = ["K_PLANE", "Ambiguous", "flat_network", "handedness_ambiguity", "mirror_ambiguities", "plane_spread"]


@dataclass(frozen=True)
class Ambiguous:
    """A point the distances do not place uniquely: ``kind`` station or target, ``cause`` "mirror"
    (its reflection through the plane of its neighbours fits equally), ``reason`` one phrase with the
    numbers, ``delta_vtpv`` the reflected solution's vᵀPv minus the original's."""

    id: str
    kind: str
    cause: str
    reason: str
    delta_vtpv: float

    def to_json(self) -> dict:
        return {"id": self.id, "kind": self.kind, "cause": self.cause, "reason": self.reason,
                "delta_vtpv": self.delta_vtpv}


def plane_spread(xyz, cov) -> tuple[float, float, np.ndarray, np.ndarray]:
    """RMS spread of points off their best-fit plane and the RMS standard uncertainty along its normal.

    Parameters
    ----------
    xyz : (k, 3) coordinates, m ; cov : (k, 3, 3) their covariances, m²

    Returns
    -------
    spread_m, sigma_normal_m : float ; centroid (3,) ; unit normal (3,)
    """
    x = np.asarray(xyz, float)
    c = x.mean(axis=0)
    n = np.linalg.svd(x - c, full_matrices=False)[2][-1]
    h = (x - c) @ n
    sn = np.einsum("i,kij,j->k", n, np.asarray(cov, float), n)
    return float(np.sqrt(np.mean(h ** 2))), float(np.sqrt(np.mean(np.clip(sn, 0, None)))), c, n


def _coplanar(spread_m: float, sigma_normal_m: float, centred) -> bool:
    """Coplanar within the uncertainty (``spread < K_PLANE sigma``), or exactly (points held fixed,
    e.g. control, have no uncertainty: a spread below 1e-9 of their RMS extent)."""
    extent = float(np.sqrt(np.mean(np.sum(np.asarray(centred) ** 2, axis=1))))
    return spread_m < K_PLANE * sigma_normal_m or spread_m <= 1e-9 * extent


def flat_network(station_xyz_m, target_xyz_m, station_cov_m2, target_cov_m2) -> str | None:
    """The one-line cause when every point lies in one plane within its uncertainty, else None."""
    xyz = np.vstack([station_xyz_m, target_xyz_m])
    cov = np.concatenate([station_cov_m2, target_cov_m2])
    ok = np.all(np.isfinite(xyz), axis=1) & np.all(np.isfinite(cov), axis=(1, 2))
    if ok.sum() < 4:
        return None
    h, sn, c, n = plane_spread(xyz[ok], cov[ok])
    if not _coplanar(h, sn, xyz[ok] - c):
        return None
    s, t = len(station_xyz_m), len(target_xyz_m)
    return (f"all {s + t} points ({s} stations, {t} targets) lie in one plane within their uncertainty "
            f"(RMS out-of-plane spread {h * 1e3:.3g} mm, {h / sn:.2g} times their out-of-plane "
            f"standard uncertainty {sn * 1e3:.2g} mm; {K_PLANE:g} times is needed): distances fix each "
            f"point's coordinate along the normal ({n[0]:+.3f}, {n[1]:+.3f}, {n[2]:+.3f}) only to second "
            "order, so it is undetermined; stations and targets must span a volume")


def _pair_codes(si, ti, t: int):
    """The distinct (station, target) pairs as sorted codes ``station * t + target``: a sort, not
    ``np.unique`` (numpy 2.4's hash-based unique took 4.5 s on 1.6 M rows, the sort 0.3 s)."""
    code = np.sort(si.astype(np.int64) * t + ti)
    return code[np.r_[True, code[1:] != code[:-1]]] if code.size else code


def _targets_of_stations(si, ti, s: int, t: int) -> list:
    """The distinct targets each station observes (s arrays)."""
    code = _pair_codes(si, ti, t)
    return np.split(code % t, np.cumsum(np.bincount(code // t, minlength=s))[:-1])


def _mirror(p, c, n):
    return p - 2.0 * np.dot(p - c, n) * n


def _candidate(nb_xyz, nb_cov):
    """(centroid, unit normal) of a point's neighbours when they are coplanar within their uncertainty
    (3 always are), else None; whether the point is off that plane is the caller's test."""
    if len(nb_xyz) < 3:
        return None
    if len(nb_xyz) == 3:            # three points always span a plane
        c = nb_xyz.mean(axis=0)
        n = np.cross(nb_xyz[1] - nb_xyz[0], nb_xyz[2] - nb_xyz[0])
        nn = np.linalg.norm(n)
        return None if nn == 0 else (c, n / nn)
    h, sn, c, n = plane_spread(nb_xyz, nb_cov)
    return (c, n) if _coplanar(h, sn, nb_xyz - c) else None


def _signed_height(p, tri) -> float:
    """Height of ``p`` above the oriented plane of the triangle ``tri`` (3, 3), m."""
    n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    return float(np.dot(p - tri[0], n) / max(np.linalg.norm(n), 1e-300))


def _sigma_along(cov, n) -> float:
    return float(np.sqrt(max(n @ cov @ n, 0.0)))


def mirror_ambiguities(res, readjust, *, lambda0: float, skip_targets=()) -> tuple[Ambiguous, ...]:
    """Stations and targets whose mirror image through their neighbours' plane fits equally.

    Parameters
    ----------
    res : AdjustmentResult (coordinates, covariances, ``obs`` and ``used``)
    readjust : callable(Start) -> Fit or None
        The adjustment from another start (a :class:`~multilat.network.adjust.distance.fit_state.Fit`: ``sx``, ``tx``,
        ``vtpv``), None when it fails; used for stations.
    lambda0 : float   the tests' non-centrality: a mirror with ``Δ vᵀPv < lambda0`` is not detected
    skip_targets : collection of str   targets whose side is fixed otherwise (control, angles, bars)

    Returns
    -------
    tuple of Ambiguous
    """
    from multilat.network.adjust.distance.fit import pick_321_stations
    from multilat.network.adjust.distance.result import Start

    obs, used = res.obs, np.asarray(res.used, bool)
    s, t = obs.n_stations, obs.n_targets
    si, ti = obs.station_index[used], obs.target_index[used]
    by_s = _targets_of_stations(si, ti, s, t)
    sx, tx = res.station_xyz_m, res.target_xyz_m
    scov, tcov = res.station_cov_m2, res.target_cov_m2
    base = float(res.sigma0 ** 2 * res.dof)               # the solution's vᵀPv
    # the squared cost is unweighted: its vᵀPv in units of the estimated variance of unit weight
    unit = 1.0 if res.cost == "distance" or not np.isfinite(res.sigma0) or res.sigma0 <= 0 else res.sigma0 ** 2
    k = float(np.sqrt(lambda0))
    out: list[Ambiguous] = []
    for i in range(s):
        cand = _candidate(tx[by_s[i]], tcov[by_s[i]])
        if cand is None:
            continue
        c, n = cand
        h = float(np.dot(sx[i] - c, n))
        if not 2 * abs(h) > k * _sigma_along(scov[i], n):
            continue
        gs = sx.copy()
        gs[i] = _mirror(sx[i], c, n)
        alt = readjust(Start(gs, tx.copy(), res.offset_m.copy()))
        if alt is None:
            continue
        # distinct: the station stayed on the other side of its targets (the re-adjustment may also
        # bring it back, or flip another station instead); the side is the sign of the volume of the
        # station over the largest triangle of its targets, in each solution
        tri = by_s[i][list(pick_321_stations(tx[by_s[i]]))]
        side0 = _signed_height(sx[i], tx[tri])
        side1 = _signed_height(alt.sx[i], alt.tx[tri])
        if not (side0 * side1 < 0 and abs(side1) > k * _sigma_along(scov[i], n)):
            continue
        delta = (float(alt.vtpv) - base) / unit
        if delta < lambda0:
            out.append(Ambiguous(obs.station_ids[i], "station", "mirror", (
                f"its {len(by_s[i])} targets lie in one plane within their uncertainty and it is "
                f"{abs(h):.3g} m off that plane: its mirror image through it fits the distances equally "
                f"(Δ vᵀPv {delta:+.2g}, undetectable below λ0 = {lambda0:.3g})"), delta))
    out.extend(_target_mirrors(res, si, ti, lambda0=lambda0, unit=unit, skip=set(skip_targets)))
    return tuple(out)


def _target_screen(sx, scov, code, t: int, tx):
    """Vectorised over targets: (candidate mask (t,), centroid (t, 3), unit normal (t, 3), height of
    each target off its stations' plane (t,)). A candidate's stations are coplanar within their
    uncertainty (3 stations always are) and the target is off their plane by more than
    ``sqrt(lambda0)``-ish times its own σ (the caller's factor ``k``, applied by the caller)."""
    st_, tg = code // t, code % t
    cnt = np.bincount(tg, minlength=t).astype(float)
    safe = np.maximum(cnt, 1.0)
    s1 = np.stack([np.bincount(tg, weights=sx[st_, a], minlength=t) for a in range(3)], axis=1)
    c = s1 / safe[:, None]
    d = sx[st_] - c[tg]
    M = np.zeros((t, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            M[:, a, b] = M[:, b, a] = np.bincount(tg, weights=d[:, a] * d[:, b], minlength=t)
    lam, vec = np.linalg.eigh(M)
    n = vec[:, :, 0]
    spread = np.sqrt(np.clip(lam[:, 0], 0, None) / safe)
    sn2 = np.empty(tg.size)
    for lo in range(0, tg.size, 1 << 16):      # in slices: no (m, 3, 3) gather (110 MiB at 1.6 M pairs)
        nk = n[tg[lo:lo + (1 << 16)]]
        sn2[lo:lo + (1 << 16)] = np.einsum("pi,pij,pj->p", nk, scov[st_[lo:lo + (1 << 16)]], nk)
    sig = np.sqrt(np.bincount(tg, weights=np.clip(sn2, 0, None), minlength=t) / safe)
    extent = np.sqrt(np.clip(np.trace(M, axis1=1, axis2=2), 0, None) / safe)
    cand = (cnt >= 3) & ((cnt == 3) | (spread < K_PLANE * sig) | (spread <= 1e-9 * extent))
    h = np.einsum("pi,pi->p", tx - c, n)
    return cand, c, n, h


def _target_mirrors(res, si, ti, *, lambda0: float, unit: float, skip: set) -> list:
    """The targets whose reflection through their stations' plane, refitted with the stations held,
    fits within ``lambda0`` (a target's stations are fixed by the other targets)."""
    obs = res.obs
    t = obs.n_targets
    sx, tx, scov, tcov = res.station_xyz_m, res.target_xyz_m, res.station_cov_m2, res.target_cov_m2
    code = _pair_codes(si, ti, t)
    cand, c, n, h = _target_screen(sx, scov, code, t, tx)
    k = float(np.sqrt(lambda0))
    sig_n = np.sqrt(np.clip(np.einsum("pi,pij,pj->p", n, tcov, n), 0, None))
    cand &= 2 * np.abs(h) > k * sig_n
    if not cand.any():
        return []
    order = np.argsort(ti, kind="stable")
    ptr = np.r_[0, np.cumsum(np.bincount(ti, minlength=t))]
    used = np.asarray(res.used, bool)
    d_all, w_all = obs.distance_m[used], 1.0 / obs.sigma_m[used] ** 2
    out = []
    for j in np.flatnonzero(cand):
        if obs.target_ids[j] in skip:
            continue
        rows = order[ptr[j]:ptr[j + 1]]
        sr = si[rows]
        r = (d_all[rows] - res.offset_m[sr]) / (1.0 + res.scale[sr])
        w = w_all[rows] * (1.0 + res.scale[sr]) ** 2
        p0, c0 = refit_point(tx[j], sx[sr], r, w)
        p1, c1 = refit_point(_mirror(tx[j], c[j], n[j]), sx[sr], r, w)
        if not np.linalg.norm(p1 - p0) > k * sig_n[j]:
            continue
        delta = (c1 - c0) / unit
        if delta < lambda0:
            m = int(np.unique(sr).size)
            what = "3 stations" if m == 3 else f"{m} stations that lie in one plane within their uncertainty"
            out.append(Ambiguous(obs.target_ids[j], "target", "mirror", (
                f"seen by {what}, {abs(h[j]):.3g} m off their plane: its mirror image through it fits the "
                f"distances equally (Δ vᵀPv {delta:+.2g}, undetectable below λ0 = {lambda0:.3g})"), delta))
    return out


def side_fixed_targets(obs, control=(), couplings=None) -> set:
    """Targets whose side is fixed beside their distances: control points, targets with an angle
    observation (finite σ), the ends of scale bars (a bar to a point off the plane breaks the mirror;
    not tested further)."""
    fixed = set(control)
    for name in ("sigma_azimuth_rad", "sigma_elevation_rad"):
        sig = getattr(obs, name)
        if sig is not None:
            fixed.update(obs.target_ids[j] for j in np.unique(obs.target_index[np.isfinite(sig)]))
    if couplings is not None:
        fixed.update(b[0] for b in couplings.bars)
        fixed.update(b[1] for b in couplings.bars)
        fixed.update(c[0] for c in couplings.control)
    return fixed


def handedness_ambiguity(res) -> Ambiguous | None:
    """The whole network's hand when the given points did not decide it (initial values from the
    distances fitted onto ``--points`` that lie in one plane, or only 3 of them: the network and its
    mirror image through their plane fit them equally; :func:`multilat.network.adjust.approximate.starts.onto_points`)."""
    h = (res.initial or {}).get("handedness")
    if not h or h["decided"]:
        return None
    ids = h["points"]
    n = h["plane_normal"]
    reason = (f"the {len(ids)} given point(s) ({_listed(ids)}) lie within {h['plane_spread_rms_m'] * 1e3:.3g} mm "
              f"RMS of one plane (normal ({n[0]:+.3f}, {n[1]:+.3f}, {n[2]:+.3f})): the network fits them "
              f"with RMS misfit {h['misfit_rms_m'] * 1e3:.3g} mm and its mirror image through that plane "
              f"with {h['mirror_misfit_rms_m'] * 1e3:.3g} mm ({h['ratio_needed']:g} times is needed to "
              "decide); the smaller was taken")
    return Ambiguous("network", "network", "mirror", reason, 0.0)


def _listed(items, n: int = 8) -> str:
    items = list(items)
    return ", ".join(items[:n]) + (f" and {len(items) - n} more" if len(items) > n else "")


def check_geometry(res, readjust, *, lambda0: float, strict: bool = False, control=(), couplings=None):
    """Refuse a flat network; name the mirror-ambiguous points (``strict``: refuse them).

    Parameters
    ----------
    res : AdjustmentResult
    readjust : callable(Start) -> Fit   the same adjustment from another start (may raise)
    lambda0 : float   the tests' non-centrality (the detection threshold of a mirror's Δ vᵀPv)
    strict : bool   refuse ambiguous points instead of naming them
    control, couplings : control point ids and the scale bars / weighted control

    Returns
    -------
    (ambiguous, note) : tuple of Ambiguous, and the warning line (None when nothing is ambiguous)

    Raises
    ------
    MultilatError  a flat network; with ``strict`` any ambiguous point
    """
    import warnings as _w

    from multilat.errors import MultilatError

    flat = flat_network(res.station_xyz_m, res.target_xyz_m, res.station_cov_m2, res.target_cov_m2)
    if flat:
        raise MultilatError(f"near-degenerate geometry (adjusted coordinates): {flat}")

    def quiet(start):
        try:
            with _w.catch_warnings():
                _w.simplefilter("ignore")
                return readjust(start)
        except MultilatError:
            return None

    amb = mirror_ambiguities(res, quiet, lambda0=lambda0,
                             skip_targets=side_fixed_targets(res.obs, control, couplings))
    hand = handedness_ambiguity(res)
    if hand is not None:
        hand_note = (f"ambiguous handedness: {hand.reason}; these coordinates may be the mirror image of the "
                     "network in the points' frame: give rough coordinates of a point off that plane in --points "
                     "(listed in 'ambiguous' as 'network')")
        if strict:
            raise MultilatError(f"{hand_note} (--strict: refused)")
    if not amb:
        return ((hand,), hand_note) if hand is not None else ((), None)
    st_ = [a.id for a in amb if a.kind == "station"]
    tg = [a.id for a in amb if a.kind == "target"]
    parts = ([f"{len(st_)} station(s) ({_listed(st_)})"] if st_ else []) + \
            ([f"{len(tg)} target(s) ({_listed(tg)})"] if tg else [])
    note = (f"ambiguous geometry: the side of {' and '.join(parts)} is not fixed by the distances: each "
            "could be mirrored through the plane of the points it is measured to with the same fit "
            f"(first: {amb[0].kind} {amb[0].id!r} {amb[0].reason}); these coordinates are one of several "
            "equally good solutions, listed in 'ambiguous': add targets off that plane, angles or control")
    if strict:
        raise MultilatError(f"{note} (--strict: refused)")
    if hand is None:
        return amb, note
    return (hand,) + tuple(amb), f"{hand_note}; {note}"
