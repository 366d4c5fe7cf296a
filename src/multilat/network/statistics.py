"""Adjustment statistics as pure functions: variance factor, global test, Baarda's w-test and
minimal detectable biases, confidence ellipsoids.

Conventions: residuals are *observed minus computed* (metres); ``sigma_m`` is the a-priori standard
uncertainty; redundancy numbers ``r_k = 1 - h_k`` with ``h_k`` the diagonal of the hat matrix
``A (A^T P A)^- A^T P`` (whitened), ``sum r_k = dof``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GlobalTest", "global_test", "w_statistics", "w_critical", "noncentrality", "chi2_ppf", "chi2_sf",
           "norm_ppf", "correlated_with", "minimal_detectable_bias_m", "confidence_ellipsoid", "b_method_alpha_global",
           "test_power", "tau_critical", "bias_to_noise_ratio", "TEST_METHODS", "VARIANCE_FACTORS"]

TEST_METHODS = ("b-method", "fixed")
VARIANCE_FACTORS = ("known", "unknown")


@dataclass(frozen=True)
class GlobalTest:
    """Global (χ²) test of the a-posteriori variance factor against 1.

    ``statistic = sum (v_k / sigma_k)**2`` ~ χ²(dof) under the model; one-sided upper test at
    ``alpha``: ``passed = statistic <= critical``; ``critical_low`` is the lower ``alpha`` quantile
    (a statistic below it hints at pessimistic a-priori uncertainties; not a failure).
    None for a statistic that does not apply (``dof == 0`` or unweighted cost).
    """

    statistic: float | None
    critical: float | None
    critical_low: float | None
    passed: bool | None
    alpha: float
    dof: int
    power: float | None = None
    lambda0: float | None = None


def global_test(weighted_sum_sq: float, dof: int, *, alpha: float = 0.05,
                lambda0: float | None = None) -> GlobalTest:
    """χ² test of ``weighted_sum_sq`` (= vᵀPv) with ``dof`` degrees of freedom; with ``lambda0`` the
    record carries the test's power against that non-centrality (:func:`test_power`)."""
    pw = None if lambda0 is None or dof <= 0 else test_power(alpha, dof, lambda0)
    if dof <= 0 or not np.isfinite(weighted_sum_sq):
        return GlobalTest(None, None, None, None, alpha, dof, pw, lambda0)
    crit = chi2_ppf(1.0 - alpha, dof)
    low = chi2_ppf(alpha, dof)
    return GlobalTest(float(weighted_sum_sq), crit, low, bool(weighted_sum_sq <= crit), alpha, dof,
                      pw, lambda0)


def test_power(alpha: float, dof: int, lambda0: float) -> float:
    """Power of the one-sided χ²(``dof``) test at significance ``alpha`` against a non-centrality
    ``lambda0``: ``P(χ'²(dof, lambda0) > χ²_{1-alpha}(dof))``."""
    from scipy.special import chndtr

    crit = chi2_ppf(1.0 - alpha, dof)
    return float(1.0 - chndtr(crit, dof, lambda0))


def b_method_alpha_global(dof: int, *, alpha0: float = 0.001, power: float = 0.80) -> float:
    """Baarda's B-method: the significance of the global (``dof``-dimensional) test that detects the
    same non-centrality ``lambda0 = noncentrality(alpha0, power)`` as the 1-D w-test at ``alpha0``
    with the same ``power`` (Baarda 1968; Teunissen, *Testing theory*, 2000/2006, §4.5; JAG3D).

    The critical value is the ``1 - power`` quantile of the non-central χ'²(dof, lambda0); alpha is
    the central χ²(dof) tail beyond it. ``dof == 1`` gives ``alpha0``; it grows with ``dof``
    (about 0.04 at 10, 0.40 at 100).
    """
    if dof <= 0:
        return float("nan")
    lam = noncentrality(alpha0, power)
    from scipy.special import chndtrix

    crit = float(chndtrix(1.0 - power, dof, lam))       # the (1 - power) quantile of chi'2(dof, lam)
    return chi2_sf(crit, dof)


def tau_critical(alpha: float, dof: int) -> float:
    """Two-sided critical value of Pope's τ-test (variance factor unknown, Pope 1976) for one
    observation at significance ``alpha``: ``τ_c = sqrt(dof) t / sqrt(dof - 1 + t²)`` with
    ``t = t_{1-alpha/2}(dof - 1)`` (Student t); ``τ = w / σ̂0`` is bounded by ``sqrt(dof)``.
    NaN for ``dof < 2``."""
    if dof < 2:
        return float("nan")
    from scipy.special import stdtrit

    t = float(stdtrit(dof - 1, 1.0 - alpha / 2.0))
    return float(np.sqrt(dof) * t / np.sqrt(dof - 1 + t * t))


def bias_to_noise_ratio(redundancy, *, alpha: float, power: float = 0.80):
    """Baarda's external reliability ``λ̄_k = sqrt(lambda0 (1 - r_k) / r_k)``: the largest effect of
    an undetected bias of the size of observation k's MDB on any function of the unknowns, in units
    of that function's standard deviation (inf where ``r_k`` is 0)."""
    r = np.asarray(redundancy, float)
    lam = noncentrality(alpha, power)
    out = np.full_like(r, np.inf)
    ok = r > 1e-9
    out[ok] = np.sqrt(lam * np.clip(1.0 - r[ok], 0.0, None) / r[ok])
    return out


def w_critical(alpha: float) -> float:
    """Two-sided critical value of the w-test (standard normal) for significance ``alpha``."""
    return norm_ppf(1.0 - alpha / 2.0)


def noncentrality(alpha: float, power: float = 0.80) -> float:
    """Baarda's non-centrality ``lambda0 = (z_{1-alpha/2} + z_{power})**2`` of a 1-D test."""
    return float((norm_ppf(1.0 - alpha / 2.0) + norm_ppf(power)) ** 2)


# The quantiles come from scipy.special, the functions scipy.stats evaluates for them (the same
# numbers: ``chi2.ppf(p, k) = 2 gammaincinv(k/2, p)``, ``chi2.sf(x, k) = chdtrc(k, x)``,
# ``norm.ppf(p) = ndtri(p)``), imported on first use: importing scipy.stats costs ~0.4 s per command.
def chi2_ppf(p: float, dof) -> float:
    """Quantile ``p`` of the χ² distribution with ``dof`` degrees of freedom (0 < p < 1)."""
    from scipy.special import gammaincinv

    return float(2 * gammaincinv(dof / 2, p))


def chi2_sf(x: float, dof) -> float:
    """Upper tail probability ``P(χ²_dof > x)``."""
    from scipy.special import chdtrc

    return float(chdtrc(dof, x))


def norm_ppf(p: float) -> float:
    """Quantile ``p`` of the standard normal distribution."""
    from scipy.special import ndtri

    return float(ndtri(p))


def w_statistics(residual_m, sigma_m, redundancy):
    """Baarda's normalised residuals ``w_k = v_k / (sigma_k sqrt(r_k))`` (a-priori variance factor;
    ``sigma_m`` None: residuals already whitened, sigma 1).

    Observations with ``r_k <= 1e-9`` (uncontrolled: a fault in them does not show in the residuals)
    get ``w = 0``.
    """
    r = np.asarray(redundancy, float)
    ok = r > 1e-9
    # one array of the network's size, worked in place (10^6 rows per snooping round, and the w-tests
    # at the end run at the adjustment's peak memory): v / (sigma sqrt(r)), 0 where not controlled
    w = np.where(ok, r, 1.0)
    np.sqrt(w, out=w)
    if sigma_m is not None:
        np.multiply(np.asarray(sigma_m, float), w, out=w)
    np.divide(np.asarray(residual_m, float), w, out=w)
    w[~ok] = 0.0
    return w


def correlated_with(c: np.ndarray, red: np.ndarray, k: int, tol: float) -> np.ndarray:
    """Indices ``l`` with ``|c_l| / sqrt(r_k r_l) > 1 - tol`` (``c`` row ``k`` of the hat matrix, overwritten;
    a zero denominator counts when ``c_l != 0``): the arithmetic of ``abs(c) / sqrt(r_k * r)``, in place
    (two passes' worth of temporaries less over 10^6 observations)."""
    q = np.abs(c, out=c)
    den = np.multiply(red[k], red)
    np.sqrt(den, out=den)
    with np.errstate(divide="ignore", invalid="ignore"):
        np.divide(q, den, out=q)
    return np.flatnonzero(q > 1.0 - tol)


def minimal_detectable_bias_m(sigma_m, redundancy, *, alpha: float, power: float = 0.80):
    """Minimal detectable bias of each observation ``sigma_k sqrt(lambda0 / r_k)`` (inf where
    ``r_k`` is 0), metres."""
    r = np.asarray(redundancy, float)
    lam = noncentrality(alpha, power)
    out = np.full_like(r, np.inf)
    ok = r > 1e-9
    out[ok] = np.asarray(sigma_m)[ok] * np.sqrt(lam / r[ok])
    return out


def confidence_ellipsoid(cov_m2, *, level: float = 0.95):
    """Semi-axes and axes of the ``level`` confidence ellipsoid of 3-D points.

    Parameters
    ----------
    cov_m2 : ndarray (..., 3, 3)
    level : float

    Returns
    -------
    semi_axes_m : ndarray (..., 3)  ascending, ``sqrt(chi2_3(level) * eigenvalue)``
    axes : ndarray (..., 3, 3)      unit eigenvectors as columns

    A covariance with a non-finite entry (a point the network does not locate) has NaN semi-axes
    and axes.
    """
    c = np.asarray(cov_m2, float)
    k = chi2_ppf(level, 3)
    ok = np.isfinite(c).all(axis=(-2, -1))
    if ok.all():
        w, V = np.linalg.eigh(c)
    else:
        w, V = np.full(c.shape[:-1], np.nan), np.full(c.shape, np.nan)
        if ok.any():
            w[ok], V[ok] = np.linalg.eigh(c[ok])
    return np.sqrt(np.clip(w, 0.0, None) * k), V
