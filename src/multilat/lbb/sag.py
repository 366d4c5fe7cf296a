"""Gravity sag of the bar: a simply supported, stepped cross-section beam (seed 003, §3.1.1).

The bar rests on its two balls (supports at ``x = 0`` and ``x = L``) and carries its own weight.
Each of the ``k`` segments ``[b_i, b_{i+1}]`` has a uniform transverse load ``w_i`` (N/m, the
gravity component perpendicular to the bar) and bending stiffness ``EI_i`` (N·m²).

Castigliano's method: with the bending moment of the real load ``M(x)`` and the moment of a unit
dummy load at ``a``, ``m_a(x) = (1 - a/L) x`` (x <= a) or ``a (1 - x/L)`` (x > a), the
deflection at ``a`` is ``v(a) = ∫ M m_a / EI dx``; with a unit dummy moment at ``a``,
``m'_a(x) = -x/L`` (x < a) or ``1 - x/L`` (x > a), the slope is ``θ(a) = ∫ M m'_a / EI dx``.
Between breakpoints (segment ends and ``a``) the integrand is a cubic polynomial, integrated
exactly by 3-point Gauss-Legendre quadrature.

Signs: load, deflection ``v`` and slope ``θ = dv/dx`` are positive *downwards* (along gravity).
For a uniform beam: ``v(L/2) = 5 w L⁴ / (384 EI)``, ``θ(0) = -θ(L) = w L³ / (24 EI)``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["stepped_beam", "tube_section"]

_GL_X, _GL_W = np.polynomial.legendre.leggauss(3)


def tube_section(outer_diameter_m, wall_m, youngs_modulus_pa, density_kg_m3, gravity_m_s2=9.80665):
    """Bending stiffness (N·m²) and weight per length (N/m) of a round tube.

    Returns
    -------
    ei_n_m2, w_n_per_m : float
    """
    d_o = float(outer_diameter_m)
    d_i = d_o - 2.0 * float(wall_m)
    inertia = np.pi / 64.0 * (d_o**4 - d_i**4)
    area = np.pi / 4.0 * (d_o**2 - d_i**2)
    return float(youngs_modulus_pa) * inertia, float(density_kg_m3) * area * float(gravity_m_s2)


def stepped_beam(breaks_m, ei_n_m2, w_n_per_m, at_m=None):
    """Deflection and slope of a simply supported stepped beam under piecewise-uniform load.

    Parameters
    ----------
    breaks_m : array_like, shape (..., k+1)
        Segment ends, increasing, ``breaks[..., 0] = 0`` (left support), ``breaks[..., -1] = L``
        (right support), metres.
    ei_n_m2 : array_like, shape (..., k)
        Bending stiffness of each segment (N·m²), > 0.
    w_n_per_m : array_like, shape (..., k)
        Transverse load per length of each segment (N/m), positive along gravity.
    at_m : array_like, shape (..., p), optional
        Stations where deflection and slope are wanted (0 <= a <= L). Default: the segment ends
        themselves (p = k + 1; the fast path of the LBB model, no extra integration nodes).

    Returns
    -------
    v_m, slope_rad : ndarray, shape (..., p)
        Deflection (positive downwards) and slope ``dv/dx``.

    Notes
    -----
    The integration nodes are the segment ends and the stations, sorted: on each sub-interval
    the load, the stiffness and every dummy moment are polynomials (degree <= 3 in the product),
    so 3-point Gauss-Legendre is exact. The real moment is ``M(x) = R_A x - (W_j x - S_j) -
    w_j (x - b_j)² / 2`` in segment ``j``, with ``W_j``, ``S_j`` the load and first moment of
    the segments left of ``j``.
    """
    breaks = np.asarray(breaks_m, dtype=float)
    ei = np.asarray(ei_n_m2, dtype=float)
    w = np.asarray(w_n_per_m, dtype=float)
    a = breaks if at_m is None else np.asarray(at_m, dtype=float)
    lead = np.broadcast_shapes(breaks.shape[:-1], ei.shape[:-1], w.shape[:-1], a.shape[:-1])
    k = breaks.shape[-1] - 1
    breaks = np.broadcast_to(breaks, lead + (k + 1,))
    ei = np.broadcast_to(ei, lead + (k,))
    w = np.broadcast_to(w, lead + (k,))
    a = np.broadcast_to(a, lead + (a.shape[-1],))
    length = breaks[..., -1]
    b0, b1 = breaks[..., :-1], breaks[..., 1:]
    seg_load = w * (b1 - b0)                                  # (..., k)
    seg_first = seg_load * (b0 + b1) / 2.0                    # load x centroid
    r_a = np.sum(seg_load * length[..., None], axis=-1) / length - np.sum(seg_first, axis=-1) / length
    cum_w = np.cumsum(seg_load, axis=-1) - seg_load           # load left of segment j
    cum_s = np.cumsum(seg_first, axis=-1) - seg_first
    nodes = breaks if at_m is None else np.sort(np.concatenate([breaks, a], axis=-1), axis=-1)
    lo, hi = nodes[..., :-1], nodes[..., 1:]                  # (..., s)
    half = (hi - lo) / 2.0
    mid = (hi + lo) / 2.0
    seg = np.sum(mid[..., :, None] > b1[..., None, :-1], axis=-1)   # segment index, (..., s)

    def take(v):
        return np.take_along_axis(v, seg, axis=-1)[..., None]

    xq = mid[..., None] + half[..., None] * _GL_X              # (..., s, 3)
    m_real = (r_a[..., None, None] * xq - (take(cum_w) * xq - take(cum_s))
              - take(w) * (xq - take(b0)) ** 2 / 2.0)
    wts = m_real * half[..., None] * _GL_W / take(ei)          # (..., s, 3)
    xx = xq[..., None, :, :]                                   # (..., 1, s, 3)
    aa = a[..., :, None, None]                                 # (..., p, 1, 1)
    L = length[..., None, None, None]
    left = xx <= aa
    m_load = np.where(left, (1.0 - aa / L) * xx, aa * (1.0 - xx / L))
    m_couple = np.where(left, 0.0, 1.0) - xx / L
    ww = wts[..., None, :, :]
    return np.sum(ww * m_load, axis=(-2, -1)), np.sum(ww * m_couple, axis=(-2, -1))
