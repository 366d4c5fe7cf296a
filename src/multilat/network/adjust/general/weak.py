"""The general layer's weak points: :func:`multilat.network.model.weak_points.weak_points` fed from
its system, so that a network gives the same verdict here as on the distance path.

At the adjusted parameters, for every point whose three coordinates are free:

* its **distance sights**: the ``slope_distance`` rows from a station to it (the sight vector
  ``P_to + to_dh - P_from - from_dh`` and the row's σ);
* its **other information**: the 3x3 block, on its own coordinates, of the whitened normal matrix of
  every other row (tracker angles, directions, zenith angles, weighted or observed coordinates,
  levelling, ...; a correlated block whitened with its Cholesky factor).

Not tested, as on the distance path: held or partly held points, the points observations are made
from (stations, set-ups), and the ends of a distance between two targets (a scale bar: placed by the
bar and its other end as well).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from multilat.network.model import kinds as kinds_registry
from multilat.network.model.kinds.geometry import sight
from multilat.network.model.points import FREE
from multilat.network.model.weak_points import weak_points

__all__ = ["weak_points_of"]

_DISTANCE = "slope_distance"


def _other_information(system, x, n: int) -> np.ndarray:
    """(n, 3, 3): each point's block of the whitened normal matrix of the rows other than distances."""
    out = np.zeros((n, 3, 3))
    lay = system.layout
    for b, cols, chol in zip(system.blocks, system.cols, system.chol):
        if b.kind == _DISTANCE:
            continue
        _, values, columns = kinds_registry.kind(b.kind).evaluate(b, lay, cols, x)
        pc = (columns >= 0) & (columns < 3 * n)
        if not pc.any():
            continue
        if chol is not None:                 # correlated rows: whiten the block's point columns densely
            pts = np.unique(columns[pc] // 3)
            full = (3 * pts[:, None] + np.arange(3)).ravel()
            pos = np.full(3 * n, -1)
            pos[full] = np.arange(full.size)
            jb = np.zeros((b.n_rows, full.size))
            r, c = np.nonzero(pc)
            np.add.at(jb, (r, pos[columns[r, c]]), values[r, c])
            jw = scipy.linalg.solve_triangular(chol, jb, lower=True).reshape(b.n_rows, pts.size, 3)
            out[pts] += np.einsum("rpi,rpj->pij", jw, jw)
            continue
        vw = values / np.asarray(b.sigma, float)[:, None]
        for a in range(columns.shape[1]):
            for c in range(columns.shape[1]):
                sel = pc[:, a] & pc[:, c] & (columns[:, a] // 3 == columns[:, c] // 3)
                if sel.any():
                    np.add.at(out, (columns[sel, a] // 3, columns[sel, a] % 3, columns[sel, c] % 3),
                              vw[sel, a] * vw[sel, c])
    return out


def weak_points_of(system, x) -> tuple[dict, int]:
    """({point id: reason} of the weak points of ``system`` at parameters ``x``, the number of points
    tested) (module docstring)."""
    pts = system.network.points
    n = pts.n
    dist = [b for b in system.blocks if b.kind == _DISTANCE]
    origin = np.zeros(n, bool)               # points observations are made from
    for b in system.blocks:
        if "from" in b.index:
            origin[np.asarray(b.index["from"], int)] = True
    target = np.zeros(n, bool)
    for b in dist:
        target[np.asarray(b.index["to"], int)] = True
    tested = np.all(pts.status == FREE, axis=1) & ~origin & np.all(np.isfinite(x[system.layout.point_cols]), axis=1)
    idx, sights, sig = [], [], []
    for b in dist:
        fr, to = np.asarray(b.index["from"], int), np.asarray(b.index["to"], int)
        bar = target[fr]                     # a distance from a target: a scale bar, its ends not tested
        tested[to[bar]] = False
        idx.append(to)
        sights.append(sight(b, system.layout, x))
        sig.append(np.asarray(b.sigma, float))
    if not idx or not tested.any():
        return {}, 0
    found = weak_points(np.concatenate(idx), np.concatenate(sights), np.concatenate(sig), n, tested=tested,
                        other=_other_information(system, x, n))
    return {pts.ids[j]: why for j, why in found.items()}, int(tested.sum())
