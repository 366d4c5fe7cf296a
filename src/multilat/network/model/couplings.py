"""Observations beside the distances that couple points: **scale bars** (a reference length between
two points, weighted by its uncertainty) and **weighted control** (a point's coordinates observed
with per-coordinate standard uncertainties).

A scale bar between two targets couples two target blocks and so breaks the per-target Schur
elimination; a network with couplings is solved by the dense back end's coupled path
(:mod:`multilat.network.adjust.solve.coupled`), which eliminates all targets at once. Layout of the full
parameter vector (:mod:`multilat.network.model.problem`): per station ``x, y, z, offset, scale`` (index
``5 i + c``), then per target ``x, y, z`` (``5 s + 3 j + c``).

Model (residuals *observed - computed*, Jacobian of the computed side as in :mod:`.model`)::

    bar k:        L_k - |X_a - X_b|        ∂/∂X_a = u,  ∂/∂X_b = -u,  u = (X_a - X_b)/|X_a - X_b|
    control p, c: x0_pc - X_pc             ∂/∂X_pc = 1
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.data import Observations, Points, ReferenceLengths
from multilat.network.model.distance import Q, line_of_sight

__all__ = ["CouplingSpec", "Couplings", "coupling_spec", "flatten_params"]


@dataclass(frozen=True)
class CouplingSpec:
    """Couplings by point id (independent of which observations are used).

    bars : tuple of (a, b, length_m, sigma_m)
    control : tuple of (point id, xyz_m (3,), std_m (3,))
    """

    bars: tuple = ()
    control: tuple = ()

    def resolve(self, obs: Observations) -> "Couplings | None":
        """The rows of the couplings in ``obs``'s layout; points not in ``obs`` are skipped."""
        s = obs.n_stations
        pos = {sid: Q * i for i, sid in enumerate(obs.station_ids)}
        pos.update({tid: Q * s + 3 * j for j, tid in enumerate(obs.target_ids)})
        bars = [b for b in self.bars if b[0] in pos and b[1] in pos]
        ctrl = [c for c in self.control if c[0] in pos]
        if not bars and not ctrl:
            return None
        rows = np.array([pos[c[0]] + k for c in ctrl for k in range(3)], dtype=np.intp)
        return Couplings(
            bar_a=np.array([pos[b[0]] for b in bars], dtype=np.intp),
            bar_b=np.array([pos[b[1]] for b in bars], dtype=np.intp),
            bar_length_m=np.array([b[2] for b in bars], float),
            bar_sigma_m=np.array([b[3] for b in bars], float),
            bar_ids=tuple((b[0], b[1]) for b in bars),
            prior_rows=rows,
            prior_value_m=np.array([c[1][k] for c in ctrl for k in range(3)], float),
            prior_sigma_m=np.array([c[2][k] for c in ctrl for k in range(3)], float),
            prior_ids=tuple(c[0] for c in ctrl))


@dataclass(frozen=True, eq=False)
class Couplings:
    """Couplings resolved to rows of the full parameter vector (see the module docstring)."""

    bar_a: np.ndarray
    bar_b: np.ndarray
    bar_length_m: np.ndarray
    bar_sigma_m: np.ndarray
    bar_ids: tuple
    prior_rows: np.ndarray
    prior_value_m: np.ndarray
    prior_sigma_m: np.ndarray
    prior_ids: tuple

    @property
    def n_rows(self) -> int:
        return int(self.bar_a.size + self.prior_rows.size)

    @property
    def sigma_m(self) -> np.ndarray:
        return np.concatenate([self.bar_sigma_m, self.prior_sigma_m])

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """Residuals (observed - computed), metres: bars then control coordinates."""
        ia, ib = self.bar_a[:, None] + np.arange(3), self.bar_b[:, None] + np.arange(3)
        L = np.linalg.norm(x[ia] - x[ib], axis=1)
        return np.concatenate([self.bar_length_m - L, self.prior_value_m - x[self.prior_rows]])

    def whitened(self, x: np.ndarray):
        """Whitened residuals (q,) and Jacobian rows (q, n) of the computed side."""
        n = x.size
        k = self.bar_a.size
        J = np.zeros((self.n_rows, n))
        ia, ib = self.bar_a[:, None] + np.arange(3), self.bar_b[:, None] + np.arange(3)
        _, u = line_of_sight(x[ia] - x[ib])
        rk = np.arange(k)[:, None]
        J[rk, ia] = u
        J[rk, ib] = -u
        J[k + np.arange(self.prior_rows.size), self.prior_rows] = 1.0
        w = 1.0 / self.sigma_m
        return self.residuals(x) * w, J * w[:, None]


def flatten_params(p) -> np.ndarray:
    """The full parameter vector (5s + 3t) of :class:`multilat.network.model.problem.Params`."""
    g = np.column_stack([p.station_xyz_m, p.offset_m, p.scale]).ravel()
    return np.concatenate([g, np.asarray(p.target_xyz_m, float).ravel()])


def coupling_spec(obs: Observations, *, bars: ReferenceLengths | None = None, points: Points | None = None,
                  control: bool = False) -> CouplingSpec | None:
    """Validate scale bars (every row needs ``u_m`` > 0: it is the bar's weight; its ends must be
    points of ``obs``: ``FILE:LINE: unknown point id``) and collect the weighted control points of
    ``points`` (used under the control datum only). None when there is nothing."""
    out_bars = []
    if bars is not None:
        bars.check_ids(obs.station_ids + obs.target_ids, what="scale bars")
        for k in range(len(bars)):
            u = float(bars.u_m[k])
            if not (u > 0):
                where = (f"{bars.path}:{bars.line_numbers[k]}" if bars.path and bars.line_numbers
                         else f"scale bars: row {k + 1}")
                raise MultilatError(f"{where}: a scale bar needs its standard uncertainty u_m > 0 (its "
                                    f"weight), got {u!r}")
            out_bars.append((bars.target_a[k], bars.target_b[k], float(bars.length_m[k]), u))
    ctrl = []
    if control and points is not None and points.std_m is not None:
        known = set(obs.station_ids) | set(obs.target_ids)
        for pid in points.ids:
            sd = points.std(pid)
            if sd is not None and pid in known:
                ctrl.append((pid, points.get(pid).copy(), sd.copy()))
    if not out_bars and not ctrl:
        return None
    return CouplingSpec(tuple(out_bars), tuple(ctrl))
