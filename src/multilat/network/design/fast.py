"""The search's evaluator: the criterion of a layout from the Schur complement in (heads x targets) arrays.

A search calls the criterion thousands of times on layouts that differ only in head positions. The
adjustment's own layer pays for generality per call (:mod:`.blocked`, the dense and blocked back
ends: observation lists, a 3-2-1 frame, the solve's back end, the ``NetworkCovariance`` object).
Here the same algebra runs on fixed-shape arrays, the pairs a head does not see weighted zero:

* per observation (head ``i``, target ``j``) the whitened Jacobian ``[u, 1] / σ`` (head ``x, y, z``,
  offset) and ``-u / σ`` (target), ``u`` the unit vector from target to head;
* target blocks ``D_j = Σ_i w u uᵀ``, head blocks ``A_i``, couplings ``B_ij``; the Schur complement
  ``S = A - Σ_j B_j D_j⁻¹ B_jᵀ`` (``4s x 4s``);
* a generalised inverse ``X = (N + c E Eᵀ)⁻¹`` with ``E`` the rigid motions of the heads only (it
  touches the head block only, so ``X``'s blocks follow from ``(S + c E Eᵀ)⁻¹``);
* the datum by the S-transform ``C = (I - G Hᵀ) X (I - G Hᵀ)ᵀ``, ``H = E_d (Gᵀ E_d)⁻¹``
  (:func:`multilat.network.model.datum.datum_matrices`): every target's 3 x 3 block from ``X``'s blocks and
  ``X H`` (6 columns), never the full matrix;
* redundancy numbers ``1 - a_kᵀ X a_k`` (datum-free: ``a_k`` lies in the range of ``N``).

:class:`FastBackend` is the ``fast`` back end of the one criterion (:mod:`.backends`). Tested equal
to the dense back end (1e-9). ``length_u`` is left to the dense and blocked back ends.
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.design.backends import DesignBackend
from multilat.network.model.datum import Datum, datum_matrices, helmert_basis, parse_datum, s_coefficients
from multilat.network.model.distance import inv3, line_of_sight
from multilat.network.model.parameter_layout import ParameterLayout

__all__ = ["FastBackend", "fast_target_cov_m2"]


def _datum_GH(layout, datum, system: ParameterLayout):
    """Rigid motions ``G`` and ``H = E_d (Gᵀ E_d)⁻¹`` on the head rows (sp, 6) and per target (t, 3, 6),
    ``system`` the heads' and targets' columns."""
    sx, tx = layout.station_xyz_m, layout.target_xyz_m
    rows_s, rows_t = system.station_block().ravel(), system.target_block()
    if datum.kind == "free" and datum.points is None:          # inner constraints over all points
        Gp = helmert_basis(np.vstack([sx, tx]))                  # (3(s + t), 6)
        G, HT = system.datum_rows(Gp), system.datum_rows(s_coefficients(Gp, Gp).T).T
    else:                                                       # the adjustment's layout, taken
        G, E = datum_matrices(datum, layout.station_ids, layout.target_ids, sx, tx)
        own = system.index_in(ParameterLayout.adjustment(system.n_stations, system.n_targets))
        G, HT = G[own], s_coefficients(G, E)[:, own]                    # H^T (6, n)
    c = np.ascontiguousarray
    # H's target rows keep the memory order of a transposed matrix (the order matmul sums in)
    return c(G[rows_s]), c(HT.T[rows_s]), c(G[rows_t]), c(HT[:, rows_t]).transpose(1, 2, 0)


def _parts(layout, sig_mat, offsets, datum):
    sx, tx, vis = layout.station_xyz_m, layout.target_xyz_m, layout.visible
    s, t = vis.shape
    system = ParameterLayout.station_system(s, t, offsets=offsets)      # head rows, then the targets'
    cols = system.station_block()                                       # (s, p)
    sp = cols.size
    _, u = line_of_sight((sx[:, None, :] - tx[None]).transpose(1, 0, 2))   # (t, s, 3)
    w = np.where(vis, 1.0 / np.where(vis, sig_mat, 1.0) ** 2, 0.0).T    # (t, s)
    a = np.concatenate([u, np.ones((t, s, 1))], axis=2) if offsets else u   # (t, s, p)
    wu = w[..., None] * u
    D = np.swapaxes(wu, 1, 2) @ u                                       # (t, 3, 3)
    Dinv = inv3(D)
    det_rel = np.linalg.det(D) / (np.trace(D, axis1=1, axis2=2) / 3.0) ** 3
    if not np.all(det_rel > 1e-12):
        raise MultilatError("a target is not determined")
    B = np.empty((t, sp, 3))                                            # -(coupling) head x target
    B[:, cols] = a[..., :, None] * wu[..., None, :]
    F = B @ Dinv                                                        # (t, sp, 3)
    Fm = F.transpose(1, 0, 2).reshape(sp, -1)
    S = -(Fm @ B.transpose(1, 0, 2).reshape(sp, -1).T)                  # - sum_j B_j D_j^-1 B_j^T
    A = np.einsum("ts,tsp,tsq->spq", w, a, a)                           # (s, p, p)
    for i in range(s):
        S[np.ix_(cols[i], cols[i])] += A[i]
    # generalised inverse: the heads' rigid motions added to the head block
    Es = ParameterLayout.station_system(s, offsets=offsets).datum_rows(helmert_basis(sx))
    c = np.trace(S) / sp
    try:
        L = np.linalg.cholesky(S + c * (Es @ Es.T))
    except np.linalg.LinAlgError:
        raise MultilatError("the layout is singular") from None
    Linv = np.linalg.inv(L)
    Sinv = Linv.T @ Linv
    if not np.all(np.isfinite(Sinv)) or np.abs(Sinv).max() * c > 1e12:
        raise MultilatError("the layout is (nearly) singular")
    # the coupling is -B: X_st = -S^-1 (-B) D^-1 ... signs: F here is (-coupling) D^-1
    Z = Sinv @ F                                                        # (t, sp, 3)
    FT = np.swapaxes(F, 1, 2)
    Xtt = Dinv + FT @ Z                                                 # target blocks of X
    Gs, Hs, Gt, Ht = _datum_GH(layout, datum, system)
    Ys = Sinv @ (Hs + Fm @ Ht.reshape(-1, 6))                           # X H, head rows
    Yt = Dinv @ Ht + FT @ Ys                                            # X H, target rows (t, 3, 6)
    HXH = Hs.T @ Ys + Ht.reshape(-1, 6).T @ Yt.reshape(-1, 6)
    GtT, YtT = np.swapaxes(Gt, 1, 2), np.swapaxes(Yt, 1, 2)
    cov = Xtt - Gt @ YtT - Yt @ GtT + Gt @ HXH @ GtT
    return dict(cov=0.5 * (cov + np.swapaxes(cov, 1, 2)), w=w, a=a, u=u, Sinv=Sinv, Z=Z, Dinv=Dinv,
                F=F, Xtt=Xtt, cols=cols)


def fast_target_cov_m2(layout, sig_mat, *, offsets=True, datum="free"):
    """Every target's 3 x 3 covariance in the datum (t, 3, 3); ``sig_mat`` (s, t) the distance
    uncertainties (ignored where not visible). Raises MultilatError for a singular layout."""
    dat = datum if isinstance(datum, Datum) else parse_datum(datum)
    return _parts(layout, sig_mat, offsets, dat)["cov"]


def _hat(P):
    """Whitened ``a_kᵀ X a_k`` for every (target, head) pair (t, s)."""
    cols = P["cols"]
    a, u, w = P["a"], P["u"], P["w"]
    Sii = np.ascontiguousarray(P["Sinv"][cols[:, :, None], cols[:, None, :]])   # (s, p, p)
    h1 = np.einsum("tsp,spq,tsq->ts", a, Sii, a)
    Zs = np.ascontiguousarray(P["Z"][:, cols])                          # (t, s, p, 3): X_st = +S^-1 F (F from -B)
    h2 = -np.einsum("tsp,tspa,tsa->ts", a, Zs, u)                       # a^T X_st b, b = -u
    h3 = np.einsum("tsa,tab,tsb->ts", u, P["Xtt"], u)
    return w * (h1 + 2.0 * h2 + h3)


class FastBackend(DesignBackend):
    """The ``fast`` back end (:mod:`.backends`): the targets' covariances and the redundancy numbers
    from :func:`_parts` (computed on construction: raises for a singular layout)."""

    name = "fast"

    def __init__(self, layout, sigma_m, *, offsets=True, datum="free"):
        super().__init__(layout, sigma_m)
        si, ti = layout.pairs()
        sig_mat = np.ones(layout.visible.shape)
        sig_mat[si, ti] = self.sigma_m
        self._P = _parts(layout, sig_mat, offsets, datum if isinstance(datum, Datum) else parse_datum(datum))

    def target_cov_m2(self) -> np.ndarray:
        return self._P["cov"]

    def redundancy(self) -> np.ndarray:
        return np.clip(1.0 - _hat(self._P).T[self.layout.visible], 0.0, 1.0)
