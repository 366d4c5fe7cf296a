"""How few targets calibrate the heads well enough: greedy removal from a candidate set (a heuristic).

The quantity a target set must deliver is the **work-volume uncertainty**: the largest 95 %
ellipsoid semi-axis of a point measured anywhere on the candidate set by the heads calibrated with
the chosen targets (:func:`multilat.network.design.preanalysis.probe_cov_m2`: the trilateration
covariance plus the heads' and offsets' covariance carried through, in the datum). Removing
targets weakens the calibration, so this value grows as the set shrinks.

Greedy backward elimination: from all candidates, repeatedly drop the target whose removal keeps
the work-volume value lowest, while it stays at or below the wanted value. ``O(t^2)`` evaluations.
It is a heuristic: the result is locally minimal (no single further removal meets the wanted
value; tested) but a smaller set may exist (the test compares with an exhaustive search on a small
case).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.design.backends import make_backend, u95_max_m
from multilat.network.design.preanalysis import Layout, probe_cov_m2

__all__ = ["TargetSelection", "select_targets", "work_volume_u95_m"]


@dataclass(frozen=True, eq=False)
class TargetSelection:
    """Result of :func:`select_targets`.

    wanted_u95_m : float
    feasible : bool  False when even all candidates exceed the wanted value
    target_ids : tuple of str  the kept targets (all candidates when infeasible)
    u95_m : float  work-volume value of the kept set
    all_u95_m : float  the same with every candidate
    path : tuple of (count, u95_m, removed id)  each removal, in order
    evaluations : int
    method : str
    """

    wanted_u95_m: float
    feasible: bool
    target_ids: tuple
    u95_m: float
    all_u95_m: float
    path: tuple
    evaluations: int
    method: str = "greedy backward elimination (heuristic)"


def work_volume_u95_m(layout: Layout, sigma_m, probe_xyz_m, probe_visible, *, offsets=True,
                      datum="free") -> float:
    """Largest 95 % semi-axis (m) over ``probe_xyz_m`` measured by ``layout``'s heads once they are
    calibrated on ``layout``'s targets (inf when the layout is singular or a probe point is seen by
    fewer than 3 heads). ``sigma_m``: per observation of the layout (``layout.pairs()`` order)."""
    sig = np.asarray(sigma_m, float)
    try:        # the heads' block only: the blocked back end (the adjustment's Schur form) at any size
        gcov = make_backend("blocked", layout, sig, offsets=offsets, datum=datum).station_cov()
    except MultilatError:
        return float("inf")
    c = probe_cov_m2(layout.station_xyz_m, gcov, float(np.mean(sig)), probe_xyz_m, offsets=offsets,
                     visible=probe_visible)
    if not np.all(np.isfinite(c)):
        return float("inf")
    return float(u95_max_m(c).max())


def select_targets(layout: Layout, sigma, wanted_u95_m: float, *, offsets: bool = True,
                   datum="free") -> TargetSelection:
    """The fewest targets of ``layout`` (its targets are the candidates, its ``visible`` which head
    sees which) whose calibration keeps the work-volume value at or below ``wanted_u95_m``.

    Parameters
    ----------
    layout : Layout  heads (fixed) and candidate targets
    sigma : SigmaModel  distance uncertainty
    wanted_u95_m : float  > 0
    offsets, datum : as :func:`~multilat.network.design.preanalysis.preanalyse` (a datum naming
        targets keeps them)
    """
    if not (np.isfinite(wanted_u95_m) and wanted_u95_m > 0):
        raise MultilatError(f"target_u95_m must be > 0, got {wanted_u95_m!r}")
    from multilat.network.model.datum import parse_datum

    dat = parse_datum(datum)
    keep_always = set(dat.points or ())
    t = layout.n_targets
    si_all, ti_all = layout.pairs()
    d_all = np.linalg.norm(layout.station_xyz_m[si_all] - layout.target_xyz_m[ti_all], axis=1)
    sig_all = sigma(d_all, si_all, layout.station_ids)
    sig_mat = np.full(layout.visible.shape, np.nan)
    sig_mat[si_all, ti_all] = sig_all
    probe_vis = layout.visible.T
    n_eval = 0

    def score(keep):
        nonlocal n_eval
        n_eval += 1
        k = np.flatnonzero(keep)
        sub = Layout(layout.station_ids, layout.station_xyz_m, tuple(layout.target_ids[j] for j in k),
                     layout.target_xyz_m[k], layout.visible[:, k])
        si, ti = sub.pairs()
        return work_volume_u95_m(sub, sig_mat[si, k[ti]], layout.target_xyz_m, probe_vis,
                                 offsets=offsets, datum=dat)

    keep = np.ones(t, bool)
    v_all = score(keep)
    if not v_all <= wanted_u95_m:
        return TargetSelection(float(wanted_u95_m), False, layout.target_ids, v_all, v_all, (), n_eval)
    v, path = v_all, []
    while keep.sum() > 1:
        best_j, best_v = -1, np.inf
        for j in np.flatnonzero(keep):
            if layout.target_ids[j] in keep_always:
                continue
            keep[j] = False
            vj = score(keep)
            keep[j] = True
            if vj < best_v:
                best_j, best_v = j, vj
        if best_j < 0 or not best_v <= wanted_u95_m:
            break
        keep[best_j] = False
        v = best_v
        path.append((int(keep.sum()), float(best_v), layout.target_ids[best_j]))
    ids = tuple(layout.target_ids[j] for j in np.flatnonzero(keep))
    return TargetSelection(float(wanted_u95_m), True, ids, float(v), float(v_all), tuple(path), n_eval)
