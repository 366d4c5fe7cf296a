"""The design's covariance on the adjustment's own layer: the ``dense`` and ``blocked`` back ends
(:mod:`.backends`).

:func:`blocked_covariance` computes the covariance of a layout's parameters for exact distances the
way :func:`multilat.network.adjust.distance.adjust.adjust` does at its solution
(:func:`multilat.network.adjust.distance.fit.fit_once`), with no algebra of its own:

1. the exact observations of the layout in the 3-2-1 frame of its three widest heads, the internal
   minimal constraint holding 6 of their coordinates (:func:`multilat.network.adjust.distance.fit.pick_321_stations`);
2. the solve's back end's Schur-reduced normal equations ``S = N_gg - sum_j N_gj N_jj^-1 N_jg`` over
   the per-target 3 x 3 blocks (:mod:`multilat.network.adjust.solve`: ``dense`` numpy or ``sparse``
   compiled kernels), inverted by :func:`multilat.network.adjust.solve.loop.solve_reduced` (with its
   conditioning check: a degenerate layout raises);
3. :class:`multilat.network.adjust.covariance.NetworkCovariance` rotates back to the layout's frame and
   S-transforms to the datum (:func:`multilat.network.model.datum.datum_matrices`; ``free`` over all
   points by default).

:class:`BlockedBackend` keeps it so (target 3 x 3 blocks, the station block, the hat diagonal in
``O(t s^2)``, never the full matrix); :class:`DenseBackend` forms the whole matrix in the adjustment's
parameter layout (:meth:`~multilat.network.model.parameter_layout.ParameterLayout.adjustment`) and
reads every number from it. Tested equal to ``adjust``'s covariance of the same exact observations
(1e-9) and to each other.
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.design.backends import DesignBackend
from multilat.network.model.datum import Datum, apply_rigid, datum_matrices, frame_321, parse_datum
from multilat.network.model.distance import Q, line_of_sight, range_m, residuals_and_jacobian
from multilat.network.model.parameter_layout import STATION_FIELDS, XYZ, ParameterLayout

__all__ = ["BlockedBackend", "DenseBackend", "blocked_covariance", "external_reliability_m"]


class BlockedBackend(DesignBackend):
    """The ``blocked`` back end: the covariance of a layout's parameters as the adjustment keeps it
    (never the full matrix).

    cov : NetworkCovariance  in the layout's frame and the datum (m²); inner : the same in the inner
    datum over all points (the external reliability); sigma_m, station_index, target_index : (m,)
    the observations (``Layout.pairs`` order)
    """

    name = "blocked"

    def __init__(self, layout, sigma_m, cov, inner, station_index, target_index):
        super().__init__(layout, sigma_m)
        self.cov, self.inner = cov, inner
        self.station_index, self.target_index = station_index, target_index

    def target_cov_m2(self) -> np.ndarray:
        return self.cov.target_blocks()

    def redundancy(self) -> np.ndarray:
        return np.clip(1.0 - self.cov.hat_diagonal(), 0.0, 1.0)

    def station_cov(self) -> np.ndarray:
        return self.cov.global_block()

    def block(self, rows) -> np.ndarray:
        return self.cov.block(rows)


#: columns of the identity per product when the dense back end forms the whole matrix (memory
#: ``m x 5 x chunk`` floats: 100 MB at 10 000 distances)
FULL_CHUNK_COLUMNS = 256


def _whole(cov) -> np.ndarray:
    """The whole matrix (n, n) of a :class:`~multilat.network.adjust.covariance.NetworkCovariance`,
    ``C I`` in chunks of :data:`FULL_CHUNK_COLUMNS` columns, symmetrised."""
    n = cov.n
    out = np.empty((n, n))
    for lo in range(0, n, FULL_CHUNK_COLUMNS):
        k = np.arange(lo, min(lo + FULL_CHUNK_COLUMNS, n))
        E = np.zeros((n, k.size))
        E[k, np.arange(k.size)] = 1.0
        out[:, k] = cov.times(E)
    return 0.5 * (out + out.T)


class DenseBackend(BlockedBackend):
    """The ``dense`` back end: the same covariance formed as the whole matrix ``full`` (n, n) in the
    adjustment's layout and the datum (``C I``, in chunks of columns), every number read from it; the
    redundancy numbers ``1 - diag(A C Aᵀ)`` from the dense whitened design ``A`` (m, n)."""

    name = "dense"

    def __init__(self, *args):
        super().__init__(*args)
        self.full = _whole(self.cov)

    def target_cov_m2(self) -> np.ndarray:
        tb = self.columns.target_block()
        return self.full[tb[:, :, None], tb[:, None, :]]

    def station_cov(self) -> np.ndarray:
        sb = self.columns.station_block().ravel()
        return self.full[np.ix_(sb, sb)]

    def block(self, rows) -> np.ndarray:
        rows = np.asarray(rows, np.intp)
        return self.full[np.ix_(rows, rows)]

    def redundancy(self) -> np.ndarray:
        """``1 - diag(A C Aᵀ)`` with ``A`` the whitened design at the layout's own coordinates (the
        model's Jacobian; rows orthogonal to the rigid motions, so the datum does not matter: ``C`` in
        the inner datum, whose entries are smallest, so that no rounding of large ones cancels)."""
        lay, si, ti = self.layout, self.station_index, self.target_index
        sx, tx = lay.station_xyz_m, lay.target_xyz_m
        zero = np.zeros(lay.n_stations)
        _, Js, Jt = residuals_and_jacobian(range_m(sx[si] - tx[ti]), sx, tx, zero, zero, si, ti)
        w = 1.0 / self.sigma_m[:, None]
        A = np.zeros((si.size, self.columns.n))
        k = np.arange(si.size)[:, None]
        A[k, self.columns.station_block()[si]] = Js * w          # held columns: zero rows of C
        A[k, self.columns.target_block()[ti]] = Jt * w
        C = self.full if self.inner is self.cov else _whole(self.inner)     # the inner datum: no cancellation
        return np.clip(1.0 - np.einsum("ki,ki->k", A @ C, A), 0.0, 1.0)


def blocked_covariance(layout, sigma_m, *, offsets: bool = True, datum="free", solver: str = "auto",
                       dense: bool = False) -> BlockedBackend:
    """Covariance of a :class:`~multilat.network.design.preanalysis.Layout` for exact distances: the
    ``blocked`` back end, or with ``dense`` the ``dense`` one (the whole matrix formed).

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
    return (DenseBackend if dense else BlockedBackend)(layout, sig, cov, inner, si, ti)


def external_reliability_m(bc: BlockedBackend, layout, mdb_m, *, offsets: bool = True,
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
