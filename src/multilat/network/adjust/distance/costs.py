"""The two costs compared: weighted distances (default) against the paper's eq. (6), unweighted
squared distances.

Both costs have the same noise-free minimum; they differ in how noise reaches the estimate. To
first order the squared residual ``(d + e - o)**2 - rho**2 ~ 2 rho e`` has standard deviation
``2 rho sigma``: eq. (6) is a distance fit with weights ``rho**2 / sigma**2`` instead of
``1 / sigma**2`` -- long distances count up to (11.54 / 0.34)**2 ~ 1000 times more in the large
volume. The weighted distance cost is the best linear unbiased estimator (Gauss-Markov); eq. (6)'s
true covariance is the sandwich ``A Sigma A^T``, ``A = (J^T J)^-1 J^T``, with
``Sigma = diag((2 rho sigma)**2)``; its *reported* covariance ``s**2 (J^T J)^-1`` assumes equal
variances of the squared residuals, wrong when the distances differ.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from multilat.network.model.distance import Q, dense_jacobian, line_of_sight, residuals_and_jacobian

__all__ = ["CostComparison", "compare_costs_linear", "compare_costs_mc"]


@dataclass(frozen=True)
class CostComparison:
    """Standard uncertainties (m) of interpoint distances (all target pairs or given pairs) and of
    the offsets, under each cost. ``*_distance``: weighted distance cost; ``*_squared``: eq. (6)."""

    pairs: tuple
    u_pairs_distance: np.ndarray
    u_pairs_squared: np.ndarray
    u_offsets_distance: np.ndarray
    u_offsets_squared: np.ndarray


def _design(H, T, off, sigma_m, cost):
    s, t = len(H), len(T)
    si, ti = np.repeat(np.arange(s), t), np.tile(np.arange(t), s)
    d = np.linalg.norm(H[si] - T[ti], axis=1) + off[si]
    _, Js, Jt = residuals_and_jacobian(d, H, T, off, np.zeros(s), si, ti, cost=cost)
    J = dense_jacobian(Js, Jt, si, ti, s, t)
    keep = np.ones(J.shape[1], bool)
    keep[4:Q * s:Q] = False
    return J[:, keep], keep, np.linalg.norm(H[si] - T[ti], axis=1)


def compare_costs_linear(station_xyz_m, target_xyz_m, offset_m, sigma_m: float, *, pairs=None):
    """First-order uncertainties under both costs for a network where every station sees every
    target and every distance has standard uncertainty ``sigma_m``.

    Parameters
    ----------
    station_xyz_m (s, 3), target_xyz_m (t, 3), offset_m (s,) : the (true) network, metres
    sigma_m : float
    pairs : sequence of (j, k) target index pairs, optional (default all pairs)

    Returns
    -------
    CostComparison
    """
    H, T, off = (np.asarray(a, float) for a in (station_xyz_m, target_xyz_m, offset_m))
    s, t = len(H), len(T)
    pairs = tuple(itertools.combinations(range(t), 2)) if pairs is None else tuple(pairs)
    Jd, keep, rho = _design(H, T, off, sigma_m, "distance")
    Cd = np.linalg.pinv(Jd.T @ Jd / sigma_m ** 2, rcond=1e-13, hermitian=True)
    Js, _, _ = _design(H, T, off, sigma_m, "squared")
    A = np.linalg.pinv(Js.T @ Js, rcond=1e-13, hermitian=True) @ Js.T
    Cs = (A * (2 * rho * sigma_m) ** 2) @ A.T
    # parameter positions in the kept vector: station i x,y,z,offset = 4 i + (0..3); targets after
    tpos = 4 * s + 3 * np.arange(t)
    G = np.zeros((len(pairs), keep.sum()))
    for r, (j, k) in enumerate(pairs):
        _, u = line_of_sight(T[j] - T[k])
        G[r, tpos[j]:tpos[j] + 3] = u
        G[r, tpos[k]:tpos[k] + 3] = -u
    opos = 4 * np.arange(s) + 3
    ud = np.sqrt(np.einsum("ri,ij,rj->r", G, Cd, G))
    us = np.sqrt(np.einsum("ri,ij,rj->r", G, Cs, G))
    return CostComparison(pairs, ud, us, np.sqrt(np.diag(Cd)[opos]), np.sqrt(np.diag(Cs)[opos]))


def compare_costs_mc(station_xyz_m, target_xyz_m, offset_m, sigma_m: float, *, trials: int, rng=None,
                     pairs=None):
    """Monte Carlo of both costs (gaussian noise ``sigma_m``, adjustment from the truth): RMS error
    of the interpoint distances ``pairs`` (default all) and of the offsets, shape (2, n_pairs) and
    (2, s) for (distance, squared)."""
    from multilat.network.adjust.distance.adjust import Start, adjust
    from multilat.network.model.data import Observations

    rng = np.random.default_rng(rng)
    H, T, off = (np.asarray(a, float) for a in (station_xyz_m, target_xyz_m, offset_m))
    s, t = len(H), len(T)
    pairs = tuple(itertools.combinations(range(t), 2)) if pairs is None else tuple(pairs)
    si, ti = np.repeat(np.arange(s), t), np.tile(np.arange(t), s)
    d0 = np.linalg.norm(H[si] - T[ti], axis=1) + off[si]
    L0 = np.array([np.linalg.norm(T[j] - T[k]) for j, k in pairs])
    err_p = np.zeros((2, len(pairs)))
    err_o = np.zeros((2, s))
    start = Start(H, T, off)
    for _ in range(trials):
        obs = Observations([f"S{i}" for i in range(s)], [f"T{j}" for j in range(t)], si, ti,
                           d0 + rng.normal(0, sigma_m, d0.size), np.full(d0.size, sigma_m))
        for c, cost in enumerate(("distance", "squared")):
            r = adjust(obs, initial=start, cost=cost, snooping=False)
            L = np.array([np.linalg.norm(r.target_xyz_m[j] - r.target_xyz_m[k]) for j, k in pairs])
            err_p[c] += (L - L0) ** 2
            err_o[c] += (r.offset_m - off) ** 2
    return np.sqrt(err_p / trials), np.sqrt(err_o / trials)
