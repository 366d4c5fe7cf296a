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


def _moment(x, breaks, w, length):
    """Bending moment of the distributed load at ``x`` (sagging positive). Shapes: x (..., q),
    breaks (..., k+1), w (..., k), length (...)."""
    b0 = breaks[..., :-1]
    b1 = breaks[..., 1:]
    # left reaction: sum_i w_i * integral_{b0}^{b1} (L - s) ds / L
    seg_moment_about_b = w * ((length[..., None] - b0) ** 2 - (length[..., None] - b1) ** 2) / 2.0
    r_a = np.sum(seg_moment_about_b, axis=-1) / length
    xe = x[..., :, None]
    lo = b0[..., None, :]
    hi = np.minimum(np.maximum(xe, lo), b1[..., None, :])
    # load on [lo, hi] to the left of x: moment w * ((x-lo)^2 - (x-hi)^2) / 2
    loads = w[..., None, :] * (np.clip(xe - lo, 0.0, None) ** 2 - (xe - hi) ** 2) / 2.0
    loads = np.where(xe > lo, loads, 0.0)
    return r_a[..., None] * x - np.sum(loads, axis=-1)


def stepped_beam(breaks_m, ei_n_m2, w_n_per_m, at_m):
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
    at_m : array_like, shape (..., p)
        Stations where deflection and slope are wanted (0 <= a <= L).

    Returns
    -------
    v_m, slope_rad : ndarray, shape (..., p)
        Deflection (positive downwards) and slope ``dv/dx``.
    """
    breaks = np.asarray(breaks_m, dtype=float)
    ei = np.asarray(ei_n_m2, dtype=float)
    w = np.asarray(w_n_per_m, dtype=float)
    a = np.asarray(at_m, dtype=float)
    lead = np.broadcast_shapes(breaks.shape[:-1], ei.shape[:-1], w.shape[:-1], a.shape[:-1])
    k = breaks.shape[-1] - 1
    breaks = np.broadcast_to(breaks, lead + (k + 1,))
    ei = np.broadcast_to(ei, lead + (k,))
    w = np.broadcast_to(w, lead + (k,))
    a = np.broadcast_to(a, lead + (a.shape[-1],))
    length = breaks[..., -1]
    # sub-intervals per (station, segment): [b0, c] and [c, b1] with c = clip(a, b0, b1)
    b0 = breaks[..., None, :-1]                      # (..., 1, k)
    b1 = breaks[..., None, 1:]
    c = np.clip(a[..., :, None], b0, b1)             # (..., p, k)
    v = np.zeros(a.shape)
    th = np.zeros(a.shape)
    L = length[..., None, None]
    aa = a[..., :, None, None]
    for lo, hi in ((b0, c), (c, b1)):
        half = (hi - lo) / 2.0                       # (..., p, k)
        mid = (hi + lo) / 2.0
        xq = mid[..., None] + half[..., None] * _GL_X    # (..., p, k, 3)
        m_real = _moment(xq.reshape(lead + (-1,)), breaks, w, length).reshape(xq.shape)
        left = xq <= aa
        m_load = np.where(left, (1.0 - aa / L) * xq, aa * (1.0 - xq / L))
        m_couple = np.where(left, -xq / L, 1.0 - xq / L)
        wts = half[..., None] * _GL_W / ei[..., None, :, None]
        v += np.sum(m_real * m_load * wts, axis=(-2, -1))
        th += np.sum(m_real * m_couple * wts, axis=(-2, -1))
    return v, th
