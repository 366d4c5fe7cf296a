"""Pre-analysis on the adjustment's own reduced system: the criterion of a layout in ``O(t s^2)``.

The dense pre-analysis (:func:`multilat.network.design.preanalysis.covariance`) inverts the whole
``(4s + 3t)`` normal matrix: ``O(t^3)``, ~27 ms for 4 heads x 100 targets, hopeless for 1000 targets.
This module computes the same numbers the way :func:`multilat.network.adjust.distance.adjust.adjust` does at its
solution (:func:`multilat.network.adjust.distance.fit.fit_once`), with no new algebra:

1. the exact observations of the layout in the 3-2-1 frame of its three widest heads, the internal
   minimal constraint holding 6 of their coordinates (:func:`multilat.network.adjust.distance.fit.pick_321_stations`);
2. the back end's Schur-reduced normal equations ``S = N_gg - sum_j N_gj N_jj^-1 N_jg`` over the
   per-target 3 x 3 blocks (:mod:`multilat.network.adjust.solve`: ``dense`` numpy or ``sparse`` compiled
   kernels), inverted by :func:`multilat.network.adjust.solve.loop.solve_reduced` (with its conditioning
   check: a degenerate layout raises);
3. :class:`multilat.network.adjust.covariance.NetworkCovariance` rotates back to the layout's frame and
   S-transforms to the datum (``free`` over all points by default): target 3 x 3 blocks, the
   station block and the hat diagonal (redundancy numbers) without the full matrix.

Tested equal to the dense pre-analysis (and so to ``adjust``) to 1e-9 relative.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust import statistics as st
from multilat.network.model.datum import Datum, apply_rigid, datum_matrices, frame_321, parse_datum
from multilat.network.model.distance import Q, line_of_sight, range_m
from multilat.network.model.parameter_layout import STATION_FIELDS, XYZ, ParameterLayout

__all__ = ["BlockedCovariance", "blocked_covariance", "blocked_criterion"]


@dataclass(frozen=True, eq=False)
class BlockedCovariance:
    """The covariance of a layout's parameters as the adjustment keeps it (never the full matrix).

    cov : NetworkCovariance  in the layout's frame and the datum (m²)
    sigma_m : (m,) ; station_index, target_index : (m,)  the observations (``Layout.pairs`` order)
    """

    cov: object
    inner: object
    sigma_m: np.ndarray
    station_index: np.ndarray
    target_index: np.ndarray

    def target_cov_m2(self) -> np.ndarray:
        return self.cov.target_blocks()

    def redundancy(self) -> np.ndarray:
        return np.clip(1.0 - self.cov.hat_diagonal(), 0.0, 1.0)


def blocked_covariance(layout, sigma_m, *, offsets: bool = True, datum="free",
                       solver: str = "auto") -> BlockedCovariance:
    """Covariance of a :class:`~multilat.network.design.preanalysis.Layout` for exact distances.

    Parameters
    ----------
    layout : Layout
    sigma_m : ndarray (m,)  standard uncertainty of each observation (``layout.pairs()`` order), m
    offsets : bool  estimate one offset per station
    datum : Datum or str  ``free`` (all points), ``free:P,..``, ``321:A,B,C``
    solver : "auto", "dense" or "sparse"  the back end assembling the reduced system

    Raises
    ------
    MultilatError  a degenerate layout (a target not determined, a singular reduced system)
    """
    from multilat.network.adjust.covariance import NetworkCovariance
    from multilat.network.model.data import Observations
    from multilat.network.adjust.distance.fit import pick_321_stations
    from multilat.network.model.problem import Params, Problem
    from multilat.network.adjust.solve.loop import (check_target_blocks, choose_backend, make_backend,
                                             solve_reduced)
    from multilat.network.adjust.solve.system import whitened

    dat = datum if isinstance(datum, Datum) else parse_datum(datum)
    if dat.kind not in ("free", "321"):
        raise MultilatError("design supports the free and 321 datums (not control)")
    s, t = layout.n_stations, layout.n_targets
    ids = layout.station_ids + layout.target_ids
    if dat.points is not None:
        for p in dat.points:
            if p not in ids:
                raise MultilatError(f"datum point {p!r} is neither a station nor a target")
    si, ti = layout.pairs()
    sx, tx = layout.station_xyz_m, layout.target_xyz_m
    a, b, c = pick_321_stations(sx)
    R0, t0 = frame_321(sx[a], sx[b], sx[c])
    sx0, tx0 = apply_rigid(R0, t0, sx), apply_rigid(R0, t0, tx)
    d = range_m(sx0[si] - tx0[ti])
    sig = np.asarray(sigma_m, float)
    obs = Observations(layout.station_ids, layout.target_ids, si, ti, d, sig)
    gfree = np.ones((s, Q), bool)                  # the adjustment's station block, STATION_FIELDS
    field = STATION_FIELDS.index
    gfree[:, field("offset")] = offsets
    gfree[:, field("scale")] = False
    gfree[a, [field("x"), field("y"), field("z")]] = False          # the 3-2-1 minimal constraint
    gfree[b, [field("y"), field("z")]] = False
    gfree[c, field("z")] = False
    pb = Problem(obs, "distance", gfree, np.ones(t, bool))
    p = Params(sx0, tx0, np.zeros(s), np.zeros(s))
    backend = make_backend(pb, choose_backend(pb, solver))
    fin = backend.assemble(p, 0.0)
    check_target_blocks(fin.Ntt, pb)
    _, Qgg, _ = solve_reduced(fin.N, fin.b, gfree.ravel(), pb, p)
    _, Js_w, Jt_w = whitened(pb, p)
    G, E = datum_matrices(dat, layout.station_ids, layout.target_ids, sx, tx)
    cov = NetworkCovariance(Qgg, fin.Ntt_inv, Js_w, Jt_w, si, ti, R=R0.T, G=G, E=E)
    inner = cov if (dat.kind == "free" and dat.points is None) else \
        NetworkCovariance(Qgg, fin.Ntt_inv, Js_w, Jt_w, si, ti, R=R0.T, G=G, E=G)
    return BlockedCovariance(cov, inner, sig, si, ti)


def external_reliability_m(bc: BlockedCovariance, layout, mdb_m, *, offsets: bool = True,
                           chunk: int = 256) -> np.ndarray:
    """Largest shift of any target (m) caused by a bias of one MDB in each observation, in the inner
    datum (as the dense pre-analysis): ``N^+ a_k mdb_k / sigma_k`` with ``a_k`` the whitened row."""
    lay = ParameterLayout.adjustment(layout.n_stations, layout.n_targets)
    sb, tb = lay.station_block(XYZ), lay.target_block()
    si, ti, sig = bc.station_index, bc.target_index, bc.sigma_m
    u = line_of_sight(layout.station_xyz_m[si] - layout.target_xyz_m[ti])[1] / sig[:, None]
    m = si.size
    scale = np.where(np.isfinite(mdb_m), mdb_m, 0.0) / sig
    out = np.empty(m)
    for lo in range(0, m, chunk):
        k = np.arange(lo, min(lo + chunk, m))
        V = np.zeros((lay.n, k.size))
        cols = np.arange(k.size)[:, None]
        V[sb[si[k]], cols] = u[k]
        V[tb[ti[k]], cols] = -u[k]
        if offsets:
            V[lay.station_columns("offset")[si[k]], cols[:, 0]] = 1.0 / sig[k]
        sh = np.ascontiguousarray(bc.inner.times(V)[tb]) * scale[k]
        out[k] = np.sqrt((sh ** 2).sum(axis=1)).max(axis=0)
    out[~np.isfinite(mdb_m)] = np.inf
    return out


def blocked_criterion(name: str, layout, sigma_m, *, offsets=True, datum="free", lengths=(),
                      alpha=0.001, power=0.80, solver: str = "auto") -> float:
    """The design criterion ``name`` from :func:`blocked_covariance` (metres; inf when degenerate)."""
    try:
        bc = blocked_covariance(layout, sigma_m, offsets=offsets, datum=datum, solver=solver)
    except MultilatError:
        return float("inf")
    from multilat.network.design.preanalysis import _length_u, target_criterion

    if name in ("max_u95", "rms_u"):
        return target_criterion(name, bc.target_cov_m2())
    if name == "length_u":
        return float(max(u for _, u in _length_u(layout, bc.cov, lengths)))
    if name == "max_mdb":
        return float(st.minimal_detectable_bias_m(bc.sigma_m, bc.redundancy(), alpha=alpha,
                                                  power=power).max())
    raise MultilatError(f"unknown criterion {name!r}")
