"""Variance components of a general network: one variance factor per group of observation rows,
Förstner's iterated estimator with Helmert's standard errors, as the distance path
(:mod:`multilat.network.adjust.distance.variance_components`, whose shape-independent core this calls:
:func:`~multilat.network.adjust.distance.variance_components.forstner_factors`,
:func:`~multilat.network.adjust.distance.variance_components.helmert_sums`,
:func:`~multilat.network.adjust.distance.variance_components.factor_variances`).

Groups (``grouping``): ``kind`` — one group per observation kind (``slope_distance``, ``direction``,
``zenith_angle``, ``height_difference``, ...; a tracker's azimuths and elevations are one kind,
``tracker_angles``); ``head`` — the slope distances by the instrument (head) that measured them
(``slope_distance:T1``), the other rows by kind. A correlated block is scaled as a whole (its
covariance × the factor). Weighted coordinates of control points are in no group: they keep their σ
and their share of the redundancy (as scale bars and control on the distance path).

Each iteration scales every group's a-priori σ by the square root of its factor
(``C_g ← θ_g C_g``), adjusts again (:func:`.adjust.adjust`, the same datum) and updates
``θ_g ← θ_g v_gᵀ P_g v_g / r_g`` until every step is 1 within ``tol``. The standard error of ``θ_g``:
Helmert's ``2 (S⁻¹)_gg`` with ``S_gk = Σ_{i∈g, j∈k} R_ij²`` of the whitened redundancy matrix (up to
:data:`multilat.network.adjust.distance.variance_components.RIGOROUS_MAX_OBS` rows, the shortcut ``2 / r_g`` above),
scaled to the original σ. The test of each factor against 1: ``z = (θ_g - 1) / sqrt(2 (S⁻¹)_gg)`` (the
standard error under the hypothesis θ_g = 1: the relative variance does not depend on the scale),
two-sided, at ``alpha`` (normal approximation of the estimator; ``p_value`` in the record).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust import statistics as st
from multilat.network.adjust.distance import variance_components as vc
from multilat.network.adjust.general import reliability as rel
from multilat.network.adjust.general.adjust import System, adjust
from multilat.network.model.observations import Network

__all__ = ["GROUPINGS", "GeneralVarianceComponents", "row_groups", "estimate", "scaled_network", "ALPHA"]

GROUPINGS = ("kind", "head")
#: significance of each factor's test against 1
ALPHA = 0.05


@dataclass(frozen=True, eq=False)
class GeneralVarianceComponents:
    """grouping; components: tuple of dicts (group, n, redundancy, variance_factor, variance_factor_std,
    sigma_scale, z, p_value, differs_from_1); iterations; converged; std_method; alpha;
    network: the network with the re-weighted σ (adjust it for the final result)."""

    grouping: str
    components: tuple
    iterations: int
    converged: bool
    std_method: str
    alpha: float
    network: Network

    def to_json(self) -> dict:
        return {"grouping": self.grouping, "method": "Förstner iterated (Koch 1999 §3.6.4)",
                "standard_error_method": self.std_method, "iterations": self.iterations,
                "converged": self.converged, "alpha": self.alpha,
                "components": [dict(c) for c in self.components]}


def row_groups(network: Network, grouping: str = "kind") -> tuple[list, tuple]:
    """Per block of ``network`` an (R,) array of group indices, and the groups' names."""
    if grouping not in GROUPINGS:
        raise MultilatError(f"--variance-components on the general path: grouping must be one of "
                            f"{', '.join(GROUPINGS)}, got {grouping!r}")
    names: dict = {}
    out = []
    for b in network.blocks:
        if grouping == "head" and b.kind == "slope_distance" and "instrument" in b.index:
            inst = np.asarray(b.index["instrument"], int)
            keys = [f"slope_distance:{b.names['instrument'][i]}" if i >= 0 else "slope_distance" for i in inst]
        else:
            keys = [b.kind] * b.n_rows
        out.append(np.array([names.setdefault(k, len(names)) for k in keys], np.int64))
    return out, tuple(names)


def scaled_network(network: Network, groups: list, theta: np.ndarray) -> Network:
    """``network`` with each row's a-priori variance × the factor of its group (a correlated block:
    ``C ← D C D`` with ``D = diag(sqrt(θ))``)."""
    blocks = []
    for b, g in zip(network.blocks, groups):
        f = np.sqrt(theta[g])
        cov = None if b.cov is None else np.asarray(b.cov) * np.outer(f, f)
        blocks.append(replace(b, sigma=np.asarray(b.sigma) * f, cov=cov))
    return Network(network.points, tuple(blocks), network.notes)


def estimate(network: Network, *, grouping: str = "kind", options=None, max_iter: int = 100,
             tol: float = 1e-4, alpha: float = ALPHA) -> GeneralVarianceComponents:
    """Estimate the factors on ``network`` (approximate coordinates given: the network of a
    :class:`~.run.NetworkAdjustment`, its undetermined points already left out)."""
    groups, names = row_groups(network, grouping)
    ng = len(names)
    theta, base = np.ones(ng), network
    for it in range(1, max_iter + 1):
        cur = scaled_network(base, groups, theta)
        res = adjust(cur, options=options)
        system = System(cur)
        gi = _system_groups(system, groups)
        f, red = vc.forstner_factors(system.whiten(res.residuals), res.redundancy, gi, names)
        theta = theta * f
        if np.all(np.abs(f - 1.0) < tol):
            break
        base = Network(base.points.with_xyz(res.xyz_m), base.blocks, base.notes)   # start from the last solution
    else:
        raise MultilatError(f"variance components did not converge in {max_iter} iterations (last factors "
                            f"{', '.join(f'{x:.3g}' for x in f)})")
    S = None
    if system.n_rows <= vc.RIGOROUS_MAX_OBS:
        jw = rel.whitened_jacobian(system, res)
        S = vc.helmert_sums(np.eye(system.n_rows) - jw @ res.cofactor_times(rel.dense_rows(jw, slice(None)).T), gi, ng)
    var, method = vc.factor_variances(S, red)
    n = np.bincount(gi[gi >= 0], minlength=ng)
    from scipy.special import ndtr

    zc = st.norm_ppf(1.0 - alpha / 2.0)
    comps = []
    for g in range(ng):
        se = float(theta[g] * np.sqrt(var[g]))
        se0 = float(np.sqrt(var[g]))                      # the standard error under H0 (θ = 1)
        z = float((theta[g] - 1.0) / se0) if se0 > 0 else float("nan")
        p = float(2.0 * ndtr(-abs(z))) if np.isfinite(z) else float("nan")
        comps.append({"group": names[g], "n": int(n[g]), "redundancy": float(red[g]),
                      "variance_factor": float(theta[g]), "variance_factor_std": se,
                      "sigma_scale": float(np.sqrt(theta[g])), "z": z, "p_value": p,
                      "differs_from_1": bool(abs(z) > zc)})
    return GeneralVarianceComponents(grouping, tuple(comps), it, True, method, float(alpha),
                                     scaled_network(base, groups, theta))


def _system_groups(system: System, groups: list) -> np.ndarray:
    """(R,) group of every row of ``system`` (-1: the weighted coordinates, in no group)."""
    out = np.full(system.n_rows, -1, np.int64)
    for sl, g in zip(system.rows, groups):
        out[sl] = g
    return out
