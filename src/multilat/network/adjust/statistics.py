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
           "test_power", "tau_critical", "bias_to_noise_ratio", "TEST_METHODS", "VARIANCE_FACTORS", "R_ZERO",
           "ALPHA_FAMILY", "ALPHA_LOW", "SIGMA0_FACTOR", "TestLevels", "test_levels", "sidak_alpha",
           "sigma0_check"]

TEST_METHODS = ("auto", "b-method", "sidak", "fixed")
VARIANCE_FACTORS = ("known", "unknown")

#: a redundancy number at or below this is zero: the observation is not controlled (its w-test is not
#: computed, w = 0) and never counted as correlated with another. The computed r = 1 - h carries a
#: rounding error of a few eps times the normal equations' condition (1e-12 on the ill-conditioned
#: networks of the tests; 2e-16 on the well-conditioned), and the exact r of a controlled distance in
#: a network that can be solved is far above it (JAG3D's test is the same kind: r > sqrt(eps) ~ 1.5e-8).
R_ZERO = 1e-9
#: the family-wise significance of the w-tests of a whole network (the probability that a blunder-free
#: network loses an observation to data snooping; ``--alpha-family``): see :func:`test_levels`
ALPHA_FAMILY = 0.01
#: the lower tail of the global test: a vᵀPv below its ``ALPHA_LOW`` quantile fails the test (the
#: a-priori σ too large; σ0 = 0.000 never "passes")
ALPHA_LOW = 0.001
#: σ0 outside [1/SIGMA0_FACTOR, SIGMA0_FACTOR] and significant: named as implausible (:func:`sigma0_check`)
SIGMA0_FACTOR = 3.0


@dataclass(frozen=True)
class GlobalTest:
    """Global (χ²) test of the a-posteriori variance factor against 1.

    ``statistic = sum (v_k / sigma_k)**2`` ~ χ²(dof) under the model; the upper test at ``alpha``
    (``critical``, the detection test of the B-method) and a lower-tail check at :data:`ALPHA_LOW`
    (``critical_low``): ``passed = critical_low <= statistic <= critical``; ``side`` says which tail
    failed (``"upper"``, ``"lower"``, None). A statistic below ``critical_low`` means a-priori σ far too
    large (a unit slip); it starts no data snooping (no |w| is large then).
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
    side: str | None = None
    alpha_low: float = ALPHA_LOW


def global_test(weighted_sum_sq: float, dof: int, *, alpha: float = 0.05,
                lambda0: float | None = None) -> GlobalTest:
    """χ² test of ``weighted_sum_sq`` (= vᵀPv) with ``dof`` degrees of freedom, both tails (upper at
    ``alpha``, lower at :data:`ALPHA_LOW`); with ``lambda0`` the record carries the upper test's power
    against that non-centrality (:func:`test_power`)."""
    pw = None if lambda0 is None or dof <= 0 else test_power(alpha, dof, lambda0)
    if dof <= 0 or not np.isfinite(weighted_sum_sq):
        return GlobalTest(None, None, None, None, alpha, dof, pw, lambda0)
    crit = chi2_ppf(1.0 - alpha, dof)
    low = chi2_ppf(ALPHA_LOW, dof)
    side = "upper" if weighted_sum_sq > crit else "lower" if weighted_sum_sq < low else None
    return GlobalTest(float(weighted_sum_sq), crit, low, side is None, alpha, dof, pw, lambda0, side)


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
    ok = r > R_ZERO
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


def __getattr__(name: str):
    """``CHI2_3_95``: χ²₃(0.95) = :func:`chi2_ppf` ``(0.95, 3)``, the squared scale of a 95 % ellipsoid in
    3-D (JCGM 102), computed on first use (scipy is not imported by every command) and kept. The one
    value every module that draws or reports an ellipsoid uses (tests/test_constants.py)."""
    if name == "CHI2_3_95":
        value = globals()["CHI2_3_95"] = chi2_ppf(0.95, 3)
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


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

    Observations with ``r_k <= R_ZERO`` (uncontrolled: a fault in them does not show in the residuals)
    get ``w = 0``.
    """
    r = np.asarray(redundancy, float)
    ok = r > R_ZERO
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
    """Indices ``l`` with ``|c_l| / sqrt(r_k r_l) > 1 - tol`` (``c`` row ``k`` of the hat matrix, overwritten):
    the arithmetic of ``abs(c) / sqrt(r_k * r)``, in place (two passes' worth of temporaries less over
    10^6 observations).

    An observation with ``r_l <= R_ZERO`` is never correlated with another: its exact hat row is
    ``e_l`` (``h_ll = 1`` and ``sum_j h_lj^2 = h_ll``), so ``h_kl = 0`` for every ``k != l`` and what
    the computation gives is rounding noise, which a zero ``r_l`` would blow up to an infinite ρ (issue
    25 item 6). None when ``r_k`` itself is zero (its w-test is not computed)."""
    if not red[k] > R_ZERO:
        return np.zeros(0, dtype=np.intp)
    q = np.abs(c, out=c)
    den = np.multiply(red[k], red)
    np.sqrt(den, out=den)
    with np.errstate(divide="ignore", invalid="ignore"):
        np.divide(q, den, out=q)
    q[~(red > R_ZERO)] = 0.0
    return np.flatnonzero(q > 1.0 - tol)


def minimal_detectable_bias_m(sigma_m, redundancy, *, alpha: float, power: float = 0.80):
    """Minimal detectable bias of each observation ``sigma_k sqrt(lambda0 / r_k)`` (inf where
    ``r_k`` is 0), metres."""
    r = np.asarray(redundancy, float)
    lam = noncentrality(alpha, power)
    out = np.full_like(r, np.inf)
    ok = r > R_ZERO
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


# ------------------------------------------------------------------ the test procedure of a network
def sidak_alpha(alpha_family: float, n: int) -> float:
    """Šidák's per-test significance ``1 - (1 - alpha_family)^(1/n)`` for ``n`` tests whose family
    (any one failing) has significance ``alpha_family``; computed as ``-expm1(log1p(-α)/n)`` (no
    cancellation at n = 10^6). For the two-sided w-tests of correlated normal variables Šidák's
    inequality (Šidák 1967) makes the family's significance at most ``alpha_family`` whatever the
    correlations."""
    return float(-np.expm1(np.log1p(-alpha_family) / max(int(n), 1)))


@dataclass(frozen=True)
class TestLevels:
    """The significance levels of a network's tests and why (:func:`test_levels`).

    ``method`` the procedure that runs (``b-method``, ``sidak`` or ``fixed``), ``requested`` what was
    asked (``auto`` or one of those); ``alpha0`` each w-test's (τ-test's) significance, ``alpha0_given``
    the ``--alpha`` asked for; ``n_tests`` the observations tested (distances and angles);
    ``detection`` the test that starts data snooping: ``"global chi2"`` (the χ² test at
    :meth:`alpha_global`) or ``"max |w|"`` (the largest |w| beyond ``w_critical(alpha0)``, a test of
    the whole network at ``alpha_family``); ``rule`` one sentence for the summary and the JSON.
    Called with ``dof`` it gives the global test's α (the B-method's depends on dof)."""

    method: str
    requested: str
    alpha0: float
    alpha0_given: float
    power: float
    alpha_family: float
    n_tests: int
    alpha_global_fixed: float | None
    detection: str
    rule: str

    def __call__(self, dof: int) -> float:
        return self.alpha_global(dof)

    def alpha_global(self, dof: int) -> float:
        if self.method == "b-method":
            return b_method_alpha_global(dof, alpha0=self.alpha0, power=self.power)
        return float(self.alpha_global_fixed)

    def as_dict(self) -> dict:
        return {"requested": self.requested, "alpha0_given": self.alpha0_given,
                "alpha_family": self.alpha_family, "n_tests": self.n_tests, "detection": self.detection,
                "rule": self.rule}


def test_levels(n_tests: int, *, alpha0: float = 0.001, power: float = 0.80, method: str = "auto",
                alpha_global: float | None = None, alpha_family: float = ALPHA_FAMILY) -> TestLevels:
    """The test procedure for ``n_tests`` tested observations.

    ``auto`` (the default): Baarda's B-method with ``alpha0`` while its w-tests' family-wise
    significance ``1 - (1 - alpha0)^n`` is at most ``alpha_family`` (n <= 10 at the defaults 0.001,
    0.01); above that, Šidák's rule: each w-test at ``alpha0 = 1 - (1 - alpha_family)^(1/n)`` and
    the detection by the largest |w| against that critical value, so a blunder-free network of any size
    loses an observation with probability at most ``alpha_family`` (the B-method's global test at
    α_global = 0.79 on 92 805 dof fails on most blunder-free networks and its w-tests at 0.001 then
    find a false alarm among 10^5; the χ² test at a small α instead misses a single 20σ blunder among
    10^5 distances: its vᵀPv grows by 400 r against a spread of sqrt(2 dof) = 430). The χ² test is then
    the test of the variance factor, at ``alpha_family`` (both tails: :func:`global_test`). This is
    JAG3D's Šidák test statistic with the family-wise error rate (its ``SidakTestStatistic``: the local
    α from the global one by Šidák over the number of hypotheses).
    ``b-method``, ``sidak``: that method at any size; ``fixed``: ``alpha0`` and ``alpha_global`` as
    given, detection by the χ² test."""
    n = max(int(n_tests), 1)
    a_sidak = sidak_alpha(alpha_family, n)
    fw_b = float(-np.expm1(n * np.log1p(-alpha0)))        # 1 - (1 - alpha0)^n
    if method == "fixed":
        return TestLevels("fixed", method, alpha0, alpha0, power, alpha_family, n, alpha_global, "global chi2",
                          f"fixed: w-tests at α0 = {alpha0:g}, global χ² test at α = {alpha_global:g} "
                          "(as given)")
    use = method if method in ("b-method", "sidak") else ("b-method" if a_sidak >= alpha0 else "sidak")
    if use == "b-method":
        why = ("as asked" if method == "b-method" else
               f"{n} tests: their family-wise α {fw_b:.3g} <= α_family {alpha_family:g}")
        return TestLevels("b-method", method, alpha0, alpha0, power, alpha_family, n, None, "global chi2",
                          f"B-method: w-tests at α0 = {alpha0:g}, global test's α for equal power ({why})")
    why = "as asked" if method == "sidak" else (
        f"the B-method's α0 = {alpha0:g} over {n} tests would give a family-wise α of {fw_b:.3g}")
    return TestLevels("sidak", method, a_sidak, alpha0, power, alpha_family, n, alpha_family, "max |w|",
                      f"Šidák: {n} w-tests at α0 = 1 - (1 - {alpha_family:g})^(1/{n}) = {a_sidak:.3g}, the "
                      f"largest |w| detects ({why}); global χ² test of the variance factor at α = "
                      f"{alpha_family:g}")


def sigma0_check(sigma0: float, dof: int, *, variance_factor: str = "known", source: str = "") -> dict:
    """Is σ0 plausible? Implausible (``verdict`` ``"too low"`` / ``"too high"``) when it is outside
    [1/:data:`SIGMA0_FACTOR`, :data:`SIGMA0_FACTOR`] and the χ² tail on that side is below
    :data:`ALPHA_LOW` (a significant and large departure: a wrong unit of σ or of the distances, not
    a slightly pessimistic σ); ``message`` then names it with the σ ``source`` (one line, for the
    warnings). With ``variance_factor="unknown"`` σ0 is estimated and accepted: recorded, no message.
    """
    out = {"sigma0": float(sigma0), "dof": int(dof), "factor": SIGMA0_FACTOR, "alpha": ALPHA_LOW,
           "p_lower": None, "p_upper": None, "verdict": "not tested", "accepted": variance_factor == "unknown",
           "message": ""}
    if dof <= 0 or not np.isfinite(sigma0):
        return out
    from scipy.special import chdtr

    x = float(sigma0) ** 2 * dof
    out["p_lower"], out["p_upper"] = float(chdtr(dof, x)), chi2_sf(x, dof)
    low = sigma0 < 1.0 / SIGMA0_FACTOR and out["p_lower"] < ALPHA_LOW
    high = sigma0 > SIGMA0_FACTOR and out["p_upper"] < ALPHA_LOW
    out["verdict"] = "too low" if low else "too high" if high else "plausible"
    if (low or high) and variance_factor != "unknown":
        how = "larger" if low else "smaller"
        out["message"] = (
            f"σ0 = {sigma0:.3g} on {dof} dof is implausible ({out['verdict']}: χ² "
            f"{'lower' if low else 'upper'}-tail p = {out['p_lower' if low else 'p_upper']:.1e}): the a-priori σ "
            f"look about {(1 / sigma0 if sigma0 > 0 else np.inf) if low else sigma0:.3g}× {how} than the "
            f"data; {source or 'σ source not recorded'}. Check the unit of σ and of the distances"
            f"{'' if low else ' and the w-test failures left'}, or accept the scale with --variance-factor "
            "unknown")
    return out
