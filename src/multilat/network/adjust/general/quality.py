"""Statistics of a general-network adjustment: σ0 and the global χ² test, per-row redundancy numbers,
standardized residuals and w-tests (or Pope's τ-tests), minimal detectable biases, and the 95 %
confidence ellipsoid of every point.

An adapter, not a second implementation: every statistic is computed by the array functions of
:mod:`multilat.network.adjust.statistics` (``global_test``, ``b_method_alpha_global``, ``w_statistics``,
``w_critical``, ``tau_critical``, ``noncentrality``, ``minimal_detectable_bias_m``,
``bias_to_noise_ratio``, ``confidence_ellipsoid``), the functions the distance-only adjustment
uses; this module only feeds them the general layer's whitened rows.

Rows: one per observation row of the adjusted system (a vector has three, a weighted coordinate is
an ``observed_coordinates`` row), in the system's block order. A correlated block's rows are
decorrelated by the Cholesky factor of its covariance in the block's row order (as the redundancy
numbers, :mod:`.adjust`): its w, r and MDB are those of the decorrelated rows (gama-local's
convention); independent rows are the observations themselves.

Tests, as the distance-only ``multilat adjust`` does them (``docs/reliability.md``), by one rule,
:func:`multilat.network.adjust.statistics.test_levels`: ``method="auto"`` (the default) runs Baarda's
B-method with ``alpha`` while the rows' family-wise α stays within ``alpha_family``, Šidák's α0
beyond (the global test then the variance factor's, at ``alpha_family``); ``"b-method"``,
``"sidak"`` force one, ``"fixed"`` takes ``alpha_global``. MDBs stay at Baarda's reference
(``alpha``, power 80 %), as on the distance-only path. ``variance_factor="known"``: the global χ² test
decides and each row's w-test uses the a-priori σ; ``"unknown"``: σ0 is estimated, the global test is information only, each row gets
Pope's τ = w / σ̂0, and the covariances and MDBs are scaled by σ̂0². No observation is rejected here:
data snooping (:mod:`.snooping`) calls this once per round with the levels fixed at its start
(``levels``).

External reliability (``external=True``, the default): each row's largest point shift caused by a bias
of its MDB, and which point (:func:`.reliability.external_shifts`, ``∇x = Q Jᵀ P ∇l``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.network.adjust import statistics as st
from multilat.network.model import kinds as kinds_registry
from multilat.network.adjust.general import reliability as rel

__all__ = ["GeneralStatistics", "statistics", "POWER"]

#: power of the w-test against a bias of the MDB's size (as the distance-only path)
POWER = 0.80


@dataclass(frozen=True, eq=False)
class GeneralStatistics:
    """Per row (R,): ``residual`` (observed - adjusted, SI), ``sigma`` (a-priori σ, SI), ``angular``
    (bool), ``redundancy``, ``w`` (standardized residual v / (σ sqrt(r)) of the whitened row; 0 where
    r = 0), ``statistic`` (w, or τ = w / σ̂0 with the variance factor unknown), ``passed``,
    ``mdb`` (SI; inf where r = 0), ``mdb_sigma`` (MDB / σ), ``bias_to_noise``.
    Per point (n,): ``cov_m2`` (n, 3, 3) (a posteriori with the variance factor unknown),
    ``semi_axes_95_m`` (n, 3) ascending, ``axes_95`` (n, 3, 3). ``shift_max_m`` (R,): the largest point shift caused by the row's MDB (inf
    where r = 0; NaN when not computed), ``shift_point`` its point's id. ``levels``: the test
    procedure (:class:`~multilat.network.adjust.statistics.TestLevels`).
    """

    sigma0: float
    dof: int
    test_method: str
    vtpv: float
    global_test: st.GlobalTest
    alpha0: float
    critical: float
    test: str
    variance_factor: str
    lambda0: float
    rule: str
    residual: np.ndarray
    sigma: np.ndarray
    angular: np.ndarray
    redundancy: np.ndarray
    w: np.ndarray
    statistic: np.ndarray
    passed: np.ndarray
    mdb: np.ndarray
    mdb_sigma: np.ndarray
    bias_to_noise: np.ndarray
    cov_m2: np.ndarray
    semi_axes_95_m: np.ndarray
    axes_95: np.ndarray
    shift_max_m: np.ndarray
    shift_point: tuple
    levels: st.TestLevels


def statistics(system, result, *, alpha: float = 0.001, variance_factor: str = "known",
               alpha_global: float | None = None, power: float = POWER, method: str | None = None,
               alpha_family: float = st.ALPHA_FAMILY, levels: st.TestLevels | None = None,
               external: bool = True) -> GeneralStatistics:
    """The statistics of ``result`` (a :class:`~.adjust.GeneralResult` of ``system``); the tests'
    levels by :func:`~multilat.network.adjust.statistics.test_levels` (``method`` None: ``"fixed"`` when
    ``alpha_global`` is given, else ``"auto"``), or ``levels`` as given (data snooping keeps those of
    its first round)."""
    rw = system.whiten(result.residuals)
    vtpv = float(rw @ rw)
    dof = result.dof
    red = result.redundancy
    method = method or ("fixed" if alpha_global is not None else "auto")
    if levels is None:
        levels = st.test_levels(int(np.count_nonzero(red > st.R_ZERO)), alpha0=alpha, power=power,
                                method=method, alpha_global=alpha_global, alpha_family=alpha_family)
    lam = st.noncentrality(alpha, power)
    gt = st.global_test(vtpv, dof, alpha=levels(dof), lambda0=lam)
    alpha_w = levels.alpha0                                # each row's test: Šidák's α0 on large networks
    w = st.w_statistics(rw, None, red)                     # whitened rows: σ = 1
    sigma = np.concatenate([np.asarray(b.sigma, float) for b in system.blocks])
    angular = np.concatenate([np.full(b.n_rows, kinds_registry.kind(b.kind).ANGULAR) for b in system.blocks])
    unknown = variance_factor == "unknown"
    scale = result.sigma0 if unknown and np.isfinite(result.sigma0) else 1.0
    if unknown:
        stat, crit, test = w / scale, st.tau_critical(alpha_w, dof), "tau"
    else:
        stat, crit, test = w, st.w_critical(alpha_w), "w"
    controlled = red > st.R_ZERO
    passed = ~controlled | ~(np.abs(stat) > crit)          # an uncontrolled row cannot fail (nor pass a real test)
    mdb = st.minimal_detectable_bias_m(sigma * scale, red, alpha=alpha, power=power)
    cov = point_cofactors(result) * scale ** 2
    semi, axes = st.confidence_ellipsoid(cov, level=0.95)
    if external:
        jw = rel.whitened_jacobian(system, result)
        shift, where = rel.external_shifts(result, jw, rel.mdb_whitened(red, alpha=alpha, power=power, scale=scale))
    else:
        shift, where = np.full(red.shape, np.nan), ("",) * red.size
    return GeneralStatistics(
        sigma0=result.sigma0, dof=dof, test_method=levels.method, vtpv=vtpv,
        global_test=gt, alpha0=alpha_w, critical=float(crit), test=test,
        variance_factor=variance_factor, lambda0=lam, rule=levels.rule, residual=result.residuals, sigma=sigma, angular=angular,
        redundancy=red, w=w, statistic=stat, passed=passed, mdb=mdb, mdb_sigma=mdb / sigma,
        bias_to_noise=st.bias_to_noise_ratio(red, alpha=alpha, power=power), cov_m2=cov, semi_axes_95_m=semi,
        axes_95=axes, shift_max_m=shift, shift_point=tuple(where), levels=levels)


def point_cofactors(result) -> np.ndarray:
    """(n, 3, 3) cofactor of every point's coordinates (zero rows/columns for held coordinates), in
    ``result.ids`` order: :meth:`~.adjust.GeneralResult.point_cofactor` for all points at once (the
    sparse back end's blocks as kept; the dense ``Q`` gathered by :func:`.reliability.point_columns`,
    not a search of the free names per point)."""
    if not result.ids:
        return np.zeros((0, 3, 3))
    if result.blocks is not None:
        return np.array(result.blocks.point, float)
    cols = rel.point_columns(result)                       # n_free where held: the zero row / column
    nf = len(result.free_names)
    q = np.zeros((nf + 1, nf + 1))
    q[:nf, :nf] = result.cofactor
    return q[cols[:, :, None], cols[:, None, :]]
