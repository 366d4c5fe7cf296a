"""Sparse back end: the Schur-reduced normal equations assembled by compiled kernels in one pass over
the observations grouped by target (:mod:`multilat.network.adjust.solve._sparse_kernels`, numba when installed).

The same reduced system as :mod:`.dense` (the reduced camera system of bundle adjustment)::

    S = N_gg - sum_j N_gj N_jj^-1 N_jg,     b' = b_g - sum_j N_gj N_jj^-1 b_j,

built without per-observation intermediate arrays: time and memory linear in the number of
targets, for networks of 10^5-10^6 distances. Supported: the weighted distance cost with offsets
free or held; not scales nor fixed targets (control points) — :func:`supports` says why, and the
dense back end handles those.
"""

from __future__ import annotations

import numpy as np

from multilat.network.model.distance import segment_sum
from multilat.network.model.parameter_layout import XYZ, ParameterLayout
from multilat.network.model.problem import Params, Problem
from multilat.network.adjust.solve.system import Assembly

__all__ = ["SparseBackend", "supports"]


def supports(problem: Problem) -> str | None:
    """None when the sparse back end can solve ``problem``; else the reason (one phrase)."""
    if problem.cost != "distance":
        return f"the {problem.cost!r} cost"
    if problem.station_free[:, 4].any():
        return "estimated scales"
    if not problem.target_free.all():
        return "fixed control targets"
    if problem.couplings is not None:
        return "scale bars or weighted control points (they couple target blocks)"
    if problem.angles is not None:
        return "angle observations (the stations' orientations)"
    return None


def _kernels():
    """The compiled kernels (imported when a sparse back end is built: numba takes ~0.2 s to load,
    which a small network's adjustment, on the dense back end, does not pay)."""
    from multilat.network.adjust.solve import _sparse_kernels as K

    return K


def _nchunks() -> int:
    return max(1, 4 * _kernels().get_num_threads())


class SparseBackend:
    """Assemble the reduced normal equations of a :class:`Problem` with the compiled kernels."""

    name = "sparse"

    def __init__(self, problem: Problem):
        why = supports(problem)
        if why:
            raise ValueError(f"the sparse back end does not handle {why}")
        o = problem.obs
        self.problem = problem
        ti = o.target_index
        order = np.argsort(ti, kind="stable") if np.any(np.diff(ti) < 0) else np.arange(o.n_obs)
        self.si = np.ascontiguousarray(o.station_index[order], dtype=np.int64)
        self.d = np.ascontiguousarray(o.distance_m[order])
        self.w = np.ascontiguousarray(1.0 / o.sigma_m[order] ** 2)
        counts = np.bincount(ti, minlength=o.n_targets)
        self.tptr = np.zeros(o.n_targets + 1, np.int64)
        np.cumsum(counts, out=self.tptr[1:])
        self.maxk = int(counts.max())
        s = o.n_stations
        self.layout = ParameterLayout.adjustment(s)                     # the loop's reduced system
        self.cols = np.ascontiguousarray(self.layout.station_block(XYZ + ("offset",)), np.int64)   # (s, 4)
        self.nch = _nchunks()
        self.K = _kernels()

    def assemble(self, p: Params, damping: float = 0.0) -> Assembly:
        o = self.problem.obs
        t, m = o.n_targets, o.n_obs
        h = np.ascontiguousarray(p.station_xyz_m, dtype=float)
        off = np.ascontiguousarray(p.offset_m, dtype=float)
        tg = np.ascontiguousarray(p.target_xyz_m, dtype=float)
        u = np.empty((m, 3))
        Ntt = np.empty((t, 3, 3))
        ninv = np.empty((t, 3, 3))
        gt = np.empty((t, 3))
        N, b, vtpv, _ = self.K.assemble(h, off, tg, self.d, self.w, self.si, self.tptr, self.cols, self.layout.n,
                                        u, Ntt, ninv, gt, self.nch, self.maxk, float(damping))
        if damping:
            a2 = np.concatenate([u * u, np.ones((m, 1))], axis=1) * self.w[:, None]
            diag = self.cols.ravel()
            N[diag, diag] += damping * segment_sum(self.si, a2, o.n_stations).ravel()   # (s, 4)
        si, w, tptr, cols = self.si, self.w, self.tptr, self.cols

        def back(dg):
            dt = np.empty((t, 3))
            self.K.back_substitute(np.ascontiguousarray(dg, dtype=float), cols, gt, ninv, u, w, si, tptr, dt)
            return dt

        return Assembly(N=N, b=b, Ntt=Ntt, Ntt_inv=ninv, vtpv=float(vtpv), back_substitute=back)
