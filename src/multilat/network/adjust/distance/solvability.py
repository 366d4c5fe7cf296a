"""Can this network be solved? Checks before solving, and a diagnosis when geometry is degenerate.

Rules (documented in ``docs/network.md``):

* at least 3 stations; every station needs more observations than its own unknowns
  (3 coordinates + offset if estimated + scale if estimated), i.e. >= 4 targets with offsets;
* every target needs >= 3 observations (its 3 coordinates). With exactly 3 it is determined but
  has zero redundancy, contributes nothing to the stations/offsets and its observations are
  uncontrolled (a blunder cannot be seen): allowed, with a warning;
* the station-target graph must be connected (otherwise the parts float against each other);
* counting: ``m >= 3 s + 3 t + n_offsets + n_scales - 6 - (fixed)``. For 4 stations with offsets
  and every target seen by all 4: ``4 n >= 3 n + 10``, so ``n >= 10`` targets determine the
  network (zero redundancy) and ``n >= 11`` give redundancy (the paper's "nine" counts 9 system
  unknowns, as if the datum took 7 parameters, i.e. the scale too, which distances do determine);
* shape (:func:`flat_geometry`, on the initial coordinates and again when the solver fails):
  stations off one plane and targets off one line by more than the spread the distances resolve,
  ``h_min = sqrt(sigma L / sqrt(m))`` (:func:`resolvable_spread_m`), and all points together off
  one plane by more than noise bends a flat network, ``K_BEND sqrt(sigma L)``
  (:func:`bending_spread_m`); after the adjustment :mod:`.ambiguity` checks the same with the
  covariance (a flat network, mirror-ambiguous points);
* geometry: the reduced normal matrix (after the datum), scaled to unit diagonal, must be well
  conditioned; otherwise the cause is named (coplanar stations, collinear targets, or the
  parameters of the weakest direction).
"""

from __future__ import annotations

import warnings

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.data import Observations

__all__ = ["check_structure", "count_unknowns", "diagnose_degeneracy", "flat_geometry",
           "resolvable_spread_m", "bending_spread_m", "CONDITION_LIMIT", "K_BEND"]

#: largest acceptable condition number of the unit-diagonal reduced normal matrix
CONDITION_LIMIT = 1e10


def count_unknowns(n_stations: int, n_targets: int, n_offsets: int, n_scales: int, *,
                   datum_defect: int = 6) -> int:
    """Number of unknowns after the datum: ``3 s + 3 t + offsets + scales - datum_defect``."""
    return 3 * n_stations + 3 * n_targets + n_offsets + n_scales - datum_defect


#: edges up to which :func:`graph_components` stays in numpy (above, scipy.sparse.csgraph)
GRAPH_NUMPY_MAX_EDGES = 20_000


def graph_components(n_nodes: int, a, b) -> tuple[int, np.ndarray]:
    """Connected components of the undirected graph on ``n_nodes`` nodes with edges ``(a[k], b[k])``:
    ``(count, label per node)``, components numbered by their lowest node, as
    ``scipy.sparse.csgraph.connected_components`` numbers them. Up to ``GRAPH_NUMPY_MAX_EDGES`` edges in
    numpy (so that a small ``adjust`` does not import scipy.sparse, issue 29): each round hooks every
    edge's larger root onto the smaller one, then jumps pointers to the roots; an edge whose ends share
    a root is dropped (O(log n) rounds). Above, scipy's csgraph (2-4x faster at 10^6 edges)."""
    a, b = np.asarray(a, np.intp), np.asarray(b, np.intp)
    if a.size > GRAPH_NUMPY_MAX_EDGES:
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        g = coo_matrix((np.ones(a.size), (a, b)), shape=(n_nodes, n_nodes))
        n, lab = connected_components(g, directed=False)
        return int(n), lab
    lab = np.arange(int(n_nodes))
    while a.size:
        la, lb = lab[a], lab[b]
        open_ = la != lb                       # edges inside one tree are done for good
        a, b, la, lb = a[open_], b[open_], la[open_], lb[open_]
        np.minimum.at(lab, np.maximum(la, lb), np.minimum(la, lb))
        while True:
            nxt = lab[lab]
            if np.array_equal(nxt, lab):
                break
            lab = nxt
    roots, lab = np.unique(lab, return_inverse=True)
    return int(roots.size), lab


def _components(obs: Observations) -> tuple[int, np.ndarray]:
    s, t = obs.n_stations, obs.n_targets
    return graph_components(s + t, obs.station_index, s + obs.target_index)


def check_structure(obs: Observations, *, offset_free, scale_free, fixed_targets=None,
                    fixed_station_coords: int = 0, datum_defect: int = 6, warn: bool = True,
                    extra_obs: int = 0) -> int:
    """Raise :class:`MultilatError` if the observation pattern cannot determine the unknowns.

    Parameters
    ----------
    obs : Observations
    offset_free, scale_free : ndarray of bool (s,)  which offsets / scales are estimated
    fixed_targets : ndarray of bool (t,), optional   targets held fixed (control)
    fixed_station_coords : int   station coordinates held fixed (control)
    datum_defect : int   6 for a free network, 0 when control points fix the frame
    extra_obs : int   observations beside the distances (scale bars)

    Returns
    -------
    dof : int  the redundancy ``m - unknowns`` (>= 0)
    """
    s, t, m = obs.n_stations, obs.n_targets, obs.n_obs + int(extra_obs)
    if s < 3:
        raise MultilatError(f"a self-calibrating network needs at least 3 stations, got {s} "
                            f"({', '.join(obs.station_ids)})")
    fixed_targets = np.zeros(t, bool) if fixed_targets is None else np.asarray(fixed_targets, bool)
    pair = obs.distinct_pairs()              # distinct pairs:
    per_station = np.bincount(pair // t, minlength=s)                        # repeated readings add
    per_target = np.bincount(pair % t, minlength=t)                          # no geometry
    # a head's offset and scale are unknowns of that station only when the head occupies no other
    hi = obs.head_index
    alone = (np.bincount(hi)[hi] == 1).astype(int)
    need_s = 3 + alone * (np.asarray(offset_free, int) + np.asarray(scale_free, int))
    lead = np.unique(hi, return_index=True)[1]
    for i in range(s):
        if per_station[i] < need_s[i] + 1:
            raise MultilatError(
                f"station {obs.station_ids[i]!r} has {per_station[i]} observation(s); it needs at least "
                f"{need_s[i] + 1} (its {need_s[i]} unknowns + 1 for redundancy)")
    for j in range(t):
        if fixed_targets[j]:
            continue
        if per_target[j] < 3:
            raise MultilatError(f"target {obs.target_ids[j]!r} has {per_target[j]} observation(s); "
                                "it needs at least 3 (4 for redundancy)")
    ncomp, _ = _components(obs)
    if ncomp > 1:
        _, lab = _components(obs)
        parts = []
        for c in range(min(ncomp, 2)):
            ids = [obs.station_ids[i] for i in range(s) if lab[i] == c]
            ids += [obs.target_ids[j] for j in range(t) if lab[s + j] == c]
            parts.append(",".join(ids[:4]) + ("..." if len(ids) > 4 else ""))
        raise MultilatError(f"the network is disconnected into {ncomp} parts ({' | '.join(parts)}); "
                            "each part must be adjusted separately or linked by common targets")
    n_unknown = (3 * s - fixed_station_coords + 3 * int((~fixed_targets).sum())
                 + int(np.sum(np.asarray(offset_free)[lead])) + int(np.sum(np.asarray(scale_free)[lead]))
                 - datum_defect)
    dof = m - n_unknown
    if dof < 0:
        n_off = int(np.sum(np.asarray(offset_free)[lead]))
        hint = ""
        if datum_defect == 6 and not np.any(scale_free):
            per_t = s - 3   # net equations per target seen by all stations
            if per_t > 0:
                need = -(-(3 * s + n_off - 6) // per_t)
                hint = (f"; with every target seen by all {s} stations at least {need} targets are "
                        f"needed ({need + 1} for redundancy)")
        raise MultilatError(f"too few observations: {m} distances for {n_unknown} unknowns "
                            f"({s} stations, {t} targets, {n_off} offsets, datum {datum_defect}){hint}")
    if warn:
        if dof == 0:
            warnings.warn("zero redundancy: the adjustment is exactly determined, no statistics",
                          UserWarning, stacklevel=3)
    return dof


def _flatness(xyz) -> tuple[float, float, float]:
    """Singular values of centred points (descending, length 3, zeros padded)."""
    x = np.asarray(xyz, float)
    if x.shape[0] < 2:
        return 0.0, 0.0, 0.0
    sv = np.linalg.svd(x - x.mean(axis=0), compute_uv=False)
    sv = np.concatenate([sv, np.zeros(3 - sv.size)])
    return tuple(float(v) for v in sv[:3])


def resolvable_spread_m(extent_m: float, sigma_m: float, n_obs: int) -> float:
    """Smallest RMS spread off a plane (stations) or off a line (targets) that distances resolve.

    Near a degenerate configuration (coplanar stations, collinear targets) the distances depend on
    the flattening direction only through the small spread ``h``: the information along it grows
    like ``(h / L)^2 m / sigma^2``, so its standard uncertainty is about ``sigma L / (h sqrt(m))``
    (``L`` the RMS extent, ``m`` the number of distances). The spread is resolved when this is
    below ``h`` itself, i.e. ``h > sqrt(sigma L / sqrt(m))``; this function returns that bound.
    (Measured on 5 stations 1.2 m apart, 15 targets, 5 µm: the stations' out-of-plane standard
    uncertainty is 0.43 sigma L / (h sqrt(m)), i.e. 0.4 h at the bound; tests/test_network_solvability.py.)

    Parameters
    ----------
    extent_m : float   RMS extent of the point set along its main axis, m
    sigma_m : float    typical (median) standard uncertainty of a distance, m
    n_obs : int        number of distances

    Returns
    -------
    float, metres
    """
    return float(np.sqrt(max(sigma_m, 0.0) * max(extent_m, 0.0) / np.sqrt(max(n_obs, 1))))


def flat_geometry(station_xyz_m, target_xyz_m, *, sigma_m: float, n_obs: int) -> str | None:
    """Name a degenerate shape of the network, or return None.

    Degenerate (see :func:`resolvable_spread_m` for the bound ``h_min``): the stations' RMS spread
    off their best-fit line or plane below ``h_min`` (collinear / coplanar stations: each target may
    be mirrored, and with offsets the network bends), or the targets' RMS distance from their
    best-fit line below ``h_min`` (collinear targets: each station may turn about the line), or
    all points' RMS spread off their plane below :func:`bending_spread_m` (a flat network).
    Coplanar targets are not a continuous defect with distances and offsets; they leave each
    station's side of their plane open (a discrete mirror, named after the adjustment by
    :mod:`multilat.network.adjust.distance.ambiguity`).

    Parameters
    ----------
    station_xyz_m : (s, 3) ; target_xyz_m : (t, 3)   coordinates, m (any frame)
    sigma_m : float   typical distance uncertainty, m
    n_obs : int

    Returns
    -------
    str or None  one phrase naming the cause with the numbers
    """
    causes = []
    H = np.asarray(station_xyz_m, float)
    T = np.asarray(target_xyz_m, float)
    s, t = len(H), len(T)
    if s >= 3:
        sv = np.array(_flatness(H)) / np.sqrt(s)          # RMS spreads along the principal axes
        h_min = resolvable_spread_m(sv[0], sigma_m, n_obs)
        if sv[1] < h_min:
            causes.append(f"the {s} stations are (nearly) collinear (RMS distance from their line "
                          f"{sv[1]:.2g} m, resolvable {h_min:.2g} m); self-calibration needs them off "
                          "one plane")
        elif sv[2] < h_min:
            causes.append(f"the {s} stations are (nearly) coplanar (RMS out-of-plane spread "
                          f"{sv[2]:.2g} m, resolvable {h_min:.2g} m); self-calibration needs them off "
                          "one plane")
    if t >= 3:
        sv = np.array(_flatness(T)) / np.sqrt(t)
        h_min = resolvable_spread_m(sv[0], sigma_m, n_obs)
        if sv[1] < h_min:
            causes.append(f"the {t} targets are (nearly) collinear (RMS distance from their line "
                          f"{sv[1]:.2g} m, resolvable {h_min:.2g} m); they must span a plane or a volume")
    if s + t >= 4 and not causes:
        sv = np.array(_flatness(np.vstack([H, T]))) / np.sqrt(s + t)
        h_flat = bending_spread_m(sv[0], sigma_m)
        if sv[2] < h_flat:
            causes.append(f"all {s + t} points ({s} stations, {t} targets) lie (nearly) in one plane (RMS "
                          f"out-of-plane spread {sv[2]:.2g} m, resolvable {h_flat:.2g} m): distances fix "
                          "their out-of-plane coordinates only to second order; stations and targets must "
                          "span a volume")
    return "; ".join(causes) if causes else None


#: a flat network's points are bent off their plane by noise by about 2 sqrt(sigma L) (measured on
#: flat networks of 4-8 stations, 20-1000 targets, sigma 5-50 µm, L 1-10 m: 1-2.2 times); a spread
#: below K_BEND sqrt(sigma L) is not a volume the distances resolve
K_BEND = 10.0


def bending_spread_m(extent_m: float, sigma_m: float) -> float:
    """Smallest RMS out-of-plane spread of *all* points (stations and targets) that is a volume
    rather than a flat network bent by noise: ``K_BEND sqrt(sigma L)``.

    In a flat network a point's displacement ``z`` off the plane changes its distances by about
    ``z² / (2 L)`` (second order), so noise of ``sigma`` bends the network off its plane by
    ``sqrt(2 sigma L)``-ish; the out-of-plane coordinates are then not determined (their linearised
    σ is of the order of the bending itself). ``L`` the RMS extent along the main axis, m.
    """
    return float(K_BEND * np.sqrt(max(sigma_m, 0.0) * max(extent_m, 0.0)))


def diagnose_degeneracy(station_xyz_m, target_xyz_m, station_ids, target_ids, null_vector=None,
                        param_names=None, *, condition: float, sigma_m: float | None = None,
                        n_obs: int | None = None) -> str:
    """A one-line explanation of a near-singular reduced normal matrix.

    Checks (:func:`flat_geometry`, when ``sigma_m`` and ``n_obs`` are given; otherwise a relative
    bound 1e-4 on the singular values): all stations (nearly) in one plane (2 extra defects); all
    targets on a line (3 extra defects: each station may turn about the line). Coplanar targets are
    *not* a rank defect with distances and offsets (checked by the rank of the Jacobian in the tests);
    their mirror ambiguity is named by :mod:`multilat.network.adjust.distance.ambiguity`.
    Otherwise names the parameters dominating the weakest direction ``null_vector``.
    """
    causes = []
    if sigma_m is not None and n_obs is not None:
        c = flat_geometry(station_xyz_m, target_xyz_m, sigma_m=sigma_m, n_obs=n_obs)
        if c:
            causes.append(c)
    else:
        sv_s = _flatness(station_xyz_m)
        sv_t = _flatness(target_xyz_m)
        rel = 1e-4
        if sv_s[2] <= rel * sv_s[0]:
            causes.append(f"the {len(station_ids)} stations are (nearly) coplanar "
                          f"(out-of-plane spread {sv_s[2] / np.sqrt(len(station_ids)):.2g} m); "
                          "self-calibration needs them off one plane")
        if sv_t[1] <= rel * sv_t[0]:
            causes.append("the targets are (nearly) collinear")
    if not causes and null_vector is not None and param_names is not None:
        v = np.abs(np.asarray(null_vector))
        top = np.argsort(v)[::-1][:3]
        causes.append("weakest direction involves " + ", ".join(param_names[k] for k in top))
    return (f"near-degenerate geometry (condition number {condition:.2g}): " + "; ".join(causes or
            ["cause not identified"]))
