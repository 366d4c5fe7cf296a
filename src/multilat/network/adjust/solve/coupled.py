"""The dense back end's coupled path: networks with observations that couple points (scale bars
between two targets, weighted control; :mod:`multilat.network.model.couplings`).

A scale bar couples two target blocks, so the targets are no longer eliminated one 3x3 block at a
time: the whole normal matrix ``N`` (5s + 3t) is assembled (distances and couplings) and all free
targets are eliminated at once::

    N_red = N_gg - N_gt N_tt^-1 N_tg,    b_red = b_g - N_gt N_tt^-1 b_t,    dt = N_tt^-1 (b_t - N_tg dg)

the same reduced system (5s) the loop, the tie of heads and the datum work on. Memory ``O((3t)^2)``:
for networks of up to a few thousand targets (the sparse back end refuses couplings; ``auto`` picks
this path). The covariance keeps this Schur form (:class:`multilat.network.adjust.covariance.CoupledCovariance`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from multilat.errors import MultilatError
from multilat.network.model.couplings import flatten_params
from multilat.network.model.distance import inv3
from multilat.network.model.parameter_layout import STATION_FIELDS, XYZ, ParameterLayout
from multilat.network.model.problem import Params, Problem
from multilat.network.adjust.solve.system import Assembly, whitened

__all__ = ["CoupledTargets", "assemble_coupled", "MAX_COUPLED_PARAMS"]

MAX_COUPLED_PARAMS = 12_000      # 5s + 3t above this: refused (the dense target block would be > 1 GB)


@dataclass(frozen=True, eq=False)
class CoupledTargets:
    """All free targets eliminated at once: ``X = N_tt^-1 N_tg`` (3t, 5s) and ``N_tt^-1`` (3t, 3t),
    zero rows/columns for held targets."""

    X: np.ndarray
    Ntt_inv: np.ndarray


def distance_rows(problem: Problem, p: Params):
    """Whitened residuals (m,), the sparse whitened Jacobian (m, 5s + 3t) of the distances and the
    blocks ``Js_w``, ``Jt_w``."""
    o = problem.obs
    lay = ParameterLayout.adjustment(o.n_stations, o.n_targets)
    r_w, Js_w, Jt_w = whitened(problem, p)
    cols = np.concatenate([lay.station_block()[o.station_index], lay.target_block()[o.target_index]], axis=1)
    vals = np.concatenate([Js_w, Jt_w], axis=1)
    A = sp.csr_matrix((vals.ravel(), (np.repeat(np.arange(o.n_obs), cols.shape[1]), cols.ravel())),
                      shape=(o.n_obs, lay.n))
    return r_w, A, Js_w, Jt_w


def assemble_coupled(problem: Problem, p: Params, damping: float = 0.0) -> Assembly:
    o = problem.obs
    s, t = o.n_stations, o.n_targets
    ang = problem.angles
    n_o = 0 if ang is None else ang.n_orientation
    lay = ParameterLayout.adjustment(s, t, 0 if ang is None else int(ang.oriented.sum()))
    n = lay.n
    if n > MAX_COUPLED_PARAMS:
        raise MultilatError(f"scale bars, weighted control or angles with {s} stations and {t} targets ({n} "
                            f"parameters): the coupled solver handles up to {MAX_COUPLED_PARAMS} parameters")
    r_w, A, _, _ = distance_rows(problem, p)
    dc = ParameterLayout.adjustment(s, t).index_in(lay)          # the distances' (and couplings') columns
    N = np.zeros((n, n))
    N[np.ix_(dc, dc)] = (A.T @ A).toarray()
    b = np.zeros(n)
    b[dc] = A.T @ r_w
    o_free = np.ones(0, bool) if ang is None else ang.orientation_free
    free = lay.free_mask(station={f: problem.station_free[:, i] for i, f in enumerate(STATION_FIELDS)},
                         target={f: problem.target_free for f in XYZ})
    ocols = lay.block("orientation").ravel()
    free[ocols] = o_free
    vtpv = float(r_w @ r_w)
    if problem.couplings is not None:
        e_w, E = problem.couplings.whitened(flatten_params(p))
        E = E * free[dc]
        N[np.ix_(dc, dc)] += E.T @ E
        b[dc] += E.T @ e_w
        vtpv += float(e_w @ e_w)
    if ang is not None:
        a_w, E = ang.whitened(p.station_xyz_m, p.target_xyz_m, p.orientation_rad, s, t)
        E = E * free
        N += E.T @ E
        b += E.T @ a_w
        vtpv += float(a_w @ a_w)
    if damping:
        N[np.arange(n), np.arange(n)] *= 1.0 + damping
    g = ParameterLayout.adjustment(s).index_in(lay)                # the reduced system's columns
    # eliminated with the targets: the free targets and the orientation unknowns
    elim = np.concatenate([lay.target_block().ravel(), ocols])
    tr = elim[free[elim]]
    Ntt_f = N[np.ix_(tr, tr)]
    try:
        fac = sla.cho_factor(Ntt_f)
        X_f = sla.cho_solve(fac, N[np.ix_(tr, g)])
        y = sla.cho_solve(fac, b[tr])
        Ninv_f = sla.cho_solve(fac, np.eye(tr.size))
    except (np.linalg.LinAlgError, ValueError):
        raise MultilatError("near-degenerate geometry: the targets' normal matrix (with the scale bars, "
                            "weighted control or the stations' orientations) is singular") from None
    Ngt = N[np.ix_(g, tr)]
    N_red = N[np.ix_(g, g)] - Ngt @ X_f
    b_red = b[g] - Ngt @ y
    pos = np.full(n, -1)
    pos[elim] = np.arange(elim.size)                             # column -> row of the eliminated space
    rows = pos[tr]
    X = np.zeros((elim.size, g.size))
    Ninv = np.zeros((elim.size, elim.size))
    X[rows] = X_f
    Ninv[np.ix_(rows, rows)] = Ninv_f
    tb = lay.target_block()
    Ntt = np.ascontiguousarray(N[tb[:, :, None], tb[:, None, :]])                       # (t, 3, 3)
    Ntt_inv = np.zeros_like(Ntt)
    Ntt_inv[problem.target_free] = inv3(Ntt[problem.target_free])
    t_rows, o_rows = pos[tb], pos[ocols]

    def solve_eliminated(dg):
        out = np.zeros(elim.size)
        out[rows] = y - X_f @ dg
        return out

    def back(dg):
        return solve_eliminated(dg)[t_rows]

    def back_orientation(dg):
        return solve_eliminated(dg)[o_rows]

    return Assembly(N=0.5 * (N_red + N_red.T), b=b_red, Ntt=Ntt, Ntt_inv=Ntt_inv, vtpv=vtpv,
                    back_substitute=back, coupled=CoupledTargets(X, Ninv),
                    back_orientation=back_orientation if n_o else None)
