"""What the observations determine: the datum defect and the undetermined parameters, found from
the whitened Jacobian itself (never from counts of stations, targets or observations).

The whitened Jacobian ``J`` (R x n, free parameters) is scaled to unit column norms (so metres and
radians weigh alike) and factorised by SVD; singular values below ``rtol * s_max`` span its null
space ``G = D V_0`` (n x d): the directions along which the observations do not move. ``d`` is the
datum defect. A free network removes it by inner constraints on its datum coordinates ``S``
(minimum trace over them): possible when ``G_S`` (the rows of ``G`` on ``S``) has rank ``d``.
What ``G_S`` cannot remove is undetermined: the parameters with a non-zero share of those null
directions are named (a point seen along coplanar lines of sight, a target with two distances, a
direction set with no sight to a known point, ...).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

__all__ = ["Determinability", "analyse", "classify", "schur_null_space", "RTOL", "RTOL_SCHUR"]

#: relative singular-value threshold of the rank decision (column-scaled Jacobian)
RTOL = 1e-9


@dataclass(frozen=True, eq=False)
class Determinability:
    """defect : int  dimension of the null space of the observations
    null_space : ndarray (n, d)  its basis, in the free parameters' columns
    constraints : ndarray (n, d') or None  the datum rows ``B`` (``B^T dx = 0``) that remove it, None when d = 0
    undetermined : ndarray of int  free-parameter columns the observations and the datum leave undetermined
    singular_values : ndarray  of the column-scaled whitened Jacobian, descending
    """

    defect: int
    null_space: np.ndarray
    constraints: np.ndarray | None
    undetermined: np.ndarray
    singular_values: np.ndarray


def null_space(jw: np.ndarray, rtol: float = RTOL) -> tuple[np.ndarray, np.ndarray]:
    """Null-space basis (n, d) of the whitened Jacobian and its scaled singular values."""
    norms = np.linalg.norm(jw, axis=0)
    scale = np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 1.0)
    js = jw * scale
    # the full V only: U is (R, R) with full_matrices, R² memory (3.2 GB at 20 000 rows), and only
    # the null space's rows of V are used; with R >= n the economy V is already (n, n)
    _, s, vt = scipy.linalg.svd(js, full_matrices=js.shape[0] < js.shape[1], lapack_driver="gesvd")
    s_full = np.zeros(js.shape[1])
    s_full[:len(s)] = s
    smax = s_full.max() if s_full.size else 0.0
    null = s_full <= rtol * smax if smax > 0 else np.ones_like(s_full, bool)
    g = (vt[null].T) * scale[:, None]
    return g / np.linalg.norm(g, axis=0, keepdims=True).clip(1e-300), s_full


def analyse(jw: np.ndarray, datum_mask: np.ndarray, *, rtol: float = RTOL) -> Determinability:
    """Defect, datum constraints and undetermined columns.

    jw : (R, n) whitened Jacobian over the free parameters
    datum_mask : (n,) bool  the free columns that carry a free network's datum (minimum trace over
        them); all False for a datum of fixed points only
    """
    g, s = null_space(jw, rtol)
    return classify(g, s, datum_mask)


def classify(g: np.ndarray, s: np.ndarray, datum_mask: np.ndarray) -> Determinability:
    """The datum constraints and the undetermined columns of a null-space basis ``g`` (n, d) of the
    observations (either back end: the dense SVD above, or the sparse back end's Schur complement,
    :func:`schur_null_space`); ``s`` the singular values to record."""
    d = g.shape[1]
    if d == 0:
        return Determinability(0, g, None, np.zeros(0, int), s)
    gs = g * datum_mask[:, None]
    if not datum_mask.any():
        left = g
        b = None
    else:
        # gs is (n, d), n >= d: its right singular vectors are those of R in gs = QR (d x d: cheap for large n)
        _, sv, vt = np.linalg.svd(np.linalg.qr(gs, mode="r"), full_matrices=False)
        sv_full = np.zeros(d)
        sv_full[:len(sv)] = sv
        ok = sv_full > 1e-6 * max(sv_full.max(), 1e-300)
        b = gs @ vt[ok].T if ok.any() else None
        left = g @ vt[~ok].T
    share = np.abs(left).max(axis=1) if left.size else np.zeros(g.shape[0])
    undetermined = np.flatnonzero(share > 1e-6)
    return Determinability(d, g, b, undetermined, s)


#: relative eigenvalue threshold of the rank decision on the column-scaled Schur complement (sparse
#: back end). Normal equations square the condition number: the dense back end's singular-value
#: threshold ``RTOL = 1e-9`` would be an eigenvalue threshold of 1e-18, below the rounding of a
#: Schur complement formed in double precision (its error is ~ eps * cond(N_EE) relative, eps =
#: 2.2e-16, each eliminated block's condition bounded by ``sparse.RCOND_BLOCK``). 1e-12 (singular
#: values of the reduced Jacobian below 1e-6 of the largest) keeps a factor >= 1e2 above that
#: rounding floor in the worst case. Measured on the 38 networks of tests/test_general_sparse.py:
#: exact null eigenvalues <= 5e-16, determined ones >= 1e-3. A network with a direction between
#: 1e-9 and 1e-6 is determined for the dense back end and not for the sparse one (none in practice:
#: such a direction is not determined at any useful precision either).
RTOL_SCHUR = 1e-12


def schur_null_space(S: np.ndarray, col_norms: np.ndarray, rtol: float = RTOL_SCHUR):
    """Null-space basis (k, d) of the reduced normal matrix ``S`` (k, k; the Schur complement of the
    eliminated points), decided on ``D S D`` with ``D = 1 / col_norms`` (the whitened Jacobian's column
    norms, as the dense back end scales), and the square roots of its eigenvalues, descending."""
    scale = np.where(col_norms > 0, 1.0 / np.where(col_norms > 0, col_norms, 1.0), 1.0)
    ss = S * scale[:, None] * scale[None, :]
    w, v = scipy.linalg.eigh(0.5 * (ss + ss.T)) if S.size else (np.zeros(0), np.zeros((0, 0)))
    # relative to max(λ_max, 1): the scaled N_KK has a unit diagonal, so 1 is the scale of its
    # rounding; a Schur complement that is zero up to rounding (every K direction absorbed by the
    # eliminated points: a station with polar points only, free) has no λ_max of its own
    null = w <= rtol * max(w.max(initial=0.0), 1.0)
    return v[:, null], scale, np.sqrt(np.clip(w, 0, None))[::-1]
