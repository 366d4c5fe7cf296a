"""The normal equations of the distance path, reduced by the Schur complement over the targets.

From the whitened residuals and Jacobian blocks of :mod:`multilat.network.model.distance` (parameter
layout there: ``Q = 5`` per station, then ``3`` per target). The normal equations are reduced by the
Schur complement over the 3x3 target blocks, so the linear algebra is a dense ``5s x 5s`` system plus
``t`` 3x3 inverses: cost linear in the number of targets. :func:`reduced_normal_equations` works in
chunks of targets to bound memory. The pair table of :func:`target_slots` (with :func:`slot_gain`,
:func:`repeat_share` for repeated readings) serves the covariance too
(:mod:`multilat.network.adjust.covariance`). The dense back end (:mod:`.dense`) calls this; the sparse
one (:mod:`.sparse`) the compiled kernels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.network.model.distance import Q, inv3, segment_sum
from multilat.network.model.parameter_layout import ParameterLayout

__all__ = ["target_slots", "slot_gain", "repeat_share", "ReducedSystem", "reduced_normal_equations",
           "back_substitute"]


def target_slots(station_index, target_index, n_stations, n_targets):
    """Dense ``(t, s)`` table of observation indices (-1 where a target is not seen by a station).

    With repeated readings of a pair the table holds one of them; :func:`slot_gain` scales its
    whitened row so that it stands for all of them.
    """
    slots = np.full((n_targets, n_stations), -1, dtype=np.intp)
    slots[target_index, station_index] = np.arange(station_index.shape[0])
    return slots


def slot_gain(slots, station_index, target_index, *rows):
    """Per-observation factors ``g`` (m,) for the pair table of :func:`target_slots`, or None when
    every pair has one reading.

    Repeated readings of one (station, target) pair have proportional whitened Jacobian rows (same
    geometry, weights ``1/sigma_k**2``), so their sum of outer products is that of the table's
    reading scaled by ``g**2 = sum_k |row_k|**2 / |row_slot|**2``; ``rows`` are the whitened blocks
    (e.g. ``Js_w, Jt_w``) whose concatenation is the row.
    """
    m = station_index.shape[0]
    n2 = sum(np.einsum("mi,mi->m", r, r) for r in rows)
    key = target_index.astype(np.int64) * slots.shape[1] + station_index
    flat = slots.ravel()
    if np.count_nonzero(flat >= 0) == m:
        return None
    tot = np.bincount(key, weights=n2, minlength=flat.size)
    g = np.ones(m)
    own = n2[flat[flat >= 0]]
    ok = own > 0
    idx = flat[flat >= 0]
    g[idx[ok]] = np.sqrt(tot[flat >= 0][ok] / own[ok])
    return g


def repeat_share(slots, station_index, target_index, *rows):
    """Share ``|row_k|**2 / sum over the pair's readings`` (m,) of each reading (1 without repeats)."""
    n2 = sum(np.einsum("mi,mi->m", r, r) for r in rows)
    key = target_index.astype(np.int64) * slots.shape[1] + station_index
    tot = np.bincount(key, weights=n2, minlength=slots.size)[key]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(tot > 0, n2 / np.where(tot > 0, tot, 1.0), 1.0)


@dataclass(frozen=True)
class ReducedSystem:
    """Normal equations ``N dx = b`` reduced to the station/offset/scale parameters.

    Attributes
    ----------
    N : ndarray (5s, 5s)   reduced normal matrix ``N_gg - N_gt N_tt^-1 N_tg`` (fixed columns zero)
    b : ndarray (5s,)      reduced right-hand side
    Ntt : ndarray (t, 3, 3)  target blocks of the (damped) normal matrix
    Ntt_inv : ndarray (t, 3, 3)  their inverses (zero for fixed targets)
    bt : ndarray (t, 3)    target right-hand sides
    layout : ParameterLayout  the columns of ``N`` and ``b`` (the adjustment's station system)
    """

    N: np.ndarray
    b: np.ndarray
    Ntt: np.ndarray
    Ntt_inv: np.ndarray
    bt: np.ndarray
    layout: ParameterLayout = None


def reduced_normal_equations(r_w, Js_w, Jt_w, station_index, target_index, n_stations, n_targets, *,
                             target_free=None, damping=0.0, chunk_targets=20000):
    """Assemble the Schur-reduced normal equations from whitened Jacobian blocks.

    Parameters
    ----------
    r_w : ndarray (m,)          whitened residuals ``r_k / sigma_k``
    Js_w : ndarray (m, 5)       whitened station blocks (columns of fixed parameters set to zero)
    Jt_w : ndarray (m, 3)       whitened target blocks
    station_index, target_index : ndarray of int (m,)
    n_stations, n_targets : int
    target_free : ndarray of bool (t,), optional
        False for targets held fixed (control points): their blocks are dropped.
    damping : float
        Levenberg-Marquardt factor: every diagonal element ``N_ii`` becomes ``(1 + damping) N_ii``.
    chunk_targets : int
        Targets per chunk in the coupling term (memory ``chunk * s**2`` floats).

    Returns
    -------
    ReducedSystem
    """
    s, t = n_stations, n_targets
    if target_free is None:
        target_free = np.ones(t, dtype=bool)
    Jt_w = Jt_w * target_free[target_index][:, None]
    # target blocks and rhs
    Ntt = segment_sum(target_index, Jt_w[:, :, None] * Jt_w[:, None, :], t)
    bt = segment_sum(target_index, Jt_w * r_w[:, None], t)
    if damping:
        idx = np.arange(3)
        Ntt[:, idx, idx] *= 1.0 + damping
    Minv = np.zeros_like(Ntt)
    Minv[target_free] = inv3(Ntt[target_free])
    # station blocks (block diagonal in stations) and rhs
    Ngg = segment_sum(station_index, Js_w[:, :, None] * Js_w[:, None, :], s)
    if damping:
        idx = np.arange(Q)
        Ngg[:, idx, idx] *= 1.0 + damping
    bg = segment_sum(station_index, Js_w * r_w[:, None], s)
    # rhs reduction: b_g - sum_j N_gj M_j b_j
    y = np.einsum("tij,tj->ti", Minv, bt)                      # (t, 3)
    e = np.einsum("mi,mi->m", Jt_w, y[target_index])           # (m,)
    bg -= segment_sum(station_index, Js_w * e[:, None], s)
    # coupling: sum_j N_gj M_j N_jg in station-slot form
    slots = target_slots(station_index, target_index, s, t)
    gain = slot_gain(slots, station_index, target_index, Js_w, Jt_w)     # repeated readings
    R = np.zeros((s, Q, s, Q))
    for lo in range(0, t, chunk_targets):
        sl = slots[lo:lo + chunk_targets]                       # (c, s)
        seen = sl >= 0
        ix = np.where(seen, sl, 0)
        sc = seen if gain is None else seen * gain[ix]
        A = Js_w[ix] * sc[..., None]                            # (c, s, Q)
        B = Jt_w[ix] * sc[..., None]                            # (c, s, 3)
        MB = np.einsum("cij,csj->csi", Minv[lo:lo + chunk_targets], B)
        C = np.einsum("cai,cbi->cab", B, MB)                    # (c, s, s)
        R += np.einsum("caq,cab,cbr->aqbr", A, C, A, optimize=True)
    lay = ParameterLayout.adjustment(s)
    cols = lay.station_block()                                  # (s, Q)
    N = np.zeros((cols.size, cols.size))
    N[cols.reshape(-1, 1), cols.reshape(1, -1)] = -R.reshape(cols.size, cols.size)
    for i in range(s):
        N[np.ix_(cols[i], cols[i])] += Ngg[i]
    b = np.zeros(cols.size)
    b[cols] = bg
    return ReducedSystem(N=N, b=b, Ntt=Ntt, Ntt_inv=Minv, bt=bt, layout=lay)


def back_substitute(system: ReducedSystem, dg, Js_w, Jt_w, station_index, target_index):
    """Target steps ``dt_j = M_j (b_j - N_jg dg)`` from the global step ``dg`` (5s,) -> (t, 3)."""
    n_t = system.bt.shape[0]
    cols = system.layout.station_block()
    s_k = np.einsum("mq,mq->m", Js_w, dg[cols][station_index])
    ng = segment_sum(target_index, Jt_w * s_k[:, None], n_t)
    return np.einsum("tij,tj->ti", system.Ntt_inv, system.bt - ng)
