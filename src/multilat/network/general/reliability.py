"""External reliability of a general-network adjustment: the coordinate shift caused by an undetected
bias of the size of each row's minimal detectable bias.

A bias ``∇l`` in the observations moves the adjusted parameters by ``∇x = Q Jᵀ P ∇l`` (``Q`` the
cofactor matrix of the free parameters in the datum of the adjustment: the bordered inverse of a free
network, so the response is the one the inner constraints give). In the whitened rows (``J_w = L⁻¹ J``,
``P = L⁻ᵀ L⁻¹``) a bias of ``b_k`` whitened units in row ``k`` is ``∇x_k = Q J_wᵀ e_k b_k``; the MDB of
the row is ``b_k = sqrt(λ0 / r_k)`` whitened units (× σ̂0 with the variance factor unknown), which for an
independent row is ``MDB_k / σ_k`` (as :func:`multilat.network.reliability.external_shifts` on the
distance path). A correlated block's rows are the decorrelated ones (the convention of the w-tests).
The sparse back end on a large network (:data:`.adjust.EXTERNAL_MAX_WORK`) does not compute it (NaN,
listed in the result's ``not_computed``): it costs ``rows x unknowns``.

Reported per row: the largest point shift ``max_p |∇x_k,p|`` (metres, over the three coordinates of
every point; a held coordinate does not move) and which point, by
:func:`multilat.network.reliability.largest_point_shift`. Cost: the product ``Q J_wᵀ`` in batches of
rows (no loop per row, no matrix of rows × rows); the dense back end holds ``Q`` and ``J_w`` anyway.
Checked against re-adjusting with the MDB added to one row (``tests/test_general_snooping.py``).
"""

from __future__ import annotations

import numpy as np

from multilat.network import statistics as st
from multilat.network.reliability import largest_point_shift

__all__ = ["whitened_jacobian", "dense_rows", "point_columns", "external_shifts", "mdb_whitened", "BATCH"]

#: rows per batch of the product ``Q J_wᵀ`` (memory: n_free × BATCH floats)
BATCH = 2048


def whitened_jacobian(system, result):
    """``J_w`` (R, n_free) at the adjusted parameters of ``result``: dense, or CSR when the sparse
    back end kept no dense cofactor matrix (a large network)."""
    if result.cofactor is None:
        from multilat.network.general.sparse import assemble
        return assemble(system, result.parameters)[2]
    _, jac = system.evaluate(result.parameters)
    return system.whiten(jac)


def dense_rows(jw, idx) -> np.ndarray:
    """Rows ``idx`` of a dense or sparse ``J_w`` as a dense array."""
    sub = jw[idx]
    return sub.toarray() if hasattr(sub, "toarray") else np.asarray(sub)


def point_columns(result) -> np.ndarray:
    """(n_points, 3) column of each point coordinate in the free parameters, ``n_free`` (a zero row)
    where the coordinate is held."""
    idx = {n: k for k, n in enumerate(result.free_names)}
    nf = len(result.free_names)
    return np.array([[idx.get(f"{c}:{p}", nf) for c in "xyz"] for p in result.ids], dtype=np.intp).reshape(-1, 3)


def external_shifts(result, jw: np.ndarray, bias_w: np.ndarray, *, batch: int = BATCH):
    """Largest point shift (R,) in metres and its point's id (R,) caused by a bias of ``bias_w[k]``
    whitened units in each row ``k`` (inf where the bias is not finite: an uncontrolled row; "" as
    its point). ``jw``: the whitened Jacobian at the solution (:func:`whitened_jacobian`)."""
    R = jw.shape[0]
    cols = point_columns(result)
    ids = list(result.ids)
    shift, point = np.full(R, np.inf), [""] * R
    if R == 0 or cols.size == 0:
        return np.zeros(R), tuple(point)
    if "external reliability" in result.not_computed:      # the sparse back end on a large network
        return np.full(R, np.nan), tuple(point)
    b = np.asarray(bias_w, float)
    ok = np.isfinite(b)
    nf = len(result.free_names)
    for lo in range(0, R, batch):
        hi = min(lo + batch, R)
        D = np.zeros((nf + 1, hi - lo))
        D[:-1] = result.cofactor_times(dense_rows(jw, slice(lo, hi)).T)   # response to one whitened unit per row
        D[:-1] *= np.where(ok[lo:hi], b[lo:hi], 0.0)
        norm, where = largest_point_shift(D[cols])     # (points, 3, k)
        shift[lo:hi] = np.where(ok[lo:hi], norm, np.inf)
        for k in range(hi - lo):
            if ok[lo + k]:
                point[lo + k] = ids[int(where[k])]
    return shift, tuple(point)


def mdb_whitened(redundancy, *, alpha: float, power: float, scale: float = 1.0) -> np.ndarray:
    """Each row's MDB in whitened units, ``sqrt(λ0 / r_k)`` × ``scale`` (σ̂0 with the variance factor
    unknown); inf where the row is not controlled (:func:`multilat.network.statistics.minimal_detectable_bias_m`
    with σ = 1)."""
    r = np.asarray(redundancy, float)
    return st.minimal_detectable_bias_m(np.full(r.shape, float(scale)), r, alpha=alpha, power=power)
