"""Monte Carlo engine: JCGM 101 §9 published results, closed forms, reproducibility, edge cases.

Tolerances are Monte Carlo standard errors (SE) of our run, times 5, plus the rounding of the
published value and, where the published number is itself a Monte Carlo result (JCGM 101 used
M = 10^6 trials), its own SE:
* mean: u / sqrt(M);
* standard deviation: u * sqrt((kurtosis - 1) / (4 M));
* a quantile at probability a: sqrt(a (1 - a) / M) / f(y_a), f the output density there.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from functools import partial

import numpy as np
import pytest
from scipy import optimize, stats

from multilat.distributions import Arcsine, Cauchy, Constant, MultivariateNormal, Normal, Uniform
from multilat.errors import MultilatError
from multilat.montecarlo import (
    BLOCK,
    budget,
    coverage_interval,
    gum_linear,
    numerical_tolerance,
    run_mc,
    summarize,
    validate_gum,
)

M = 1_000_000


def additive(x1, x2, x3, x4):
    return x1 + x2 + x3 + x4


def mass_model(m_rc, dm_rc, rho_a, rho_w, rho_r):
    """JCGM 101 §9.3, in mg: dm = (m_R,c + dm_R,c)(1 + (rho_a - rho_a0)(1/rho_W - 1/rho_R)) - m_nom."""
    return (m_rc + dm_rc) * (1.0 + (rho_a - 1.2) * (1.0 / rho_w - 1.0 / rho_r)) - 100_000.0


MASS_INPUTS = dict(
    m_rc=Normal(100_000.0, 0.050),
    dm_rc=Normal(1.234, 0.020),
    rho_a=Uniform(1.10, 1.30),
    rho_w=Uniform(7000.0, 9000.0),
    rho_r=Uniform(7950.0, 8050.0),
)


def eq3_error_m(rf, crosstalk, ampm, noise, distance_m=20.0):
    """Seed 000 eq. (3): Rm - Rt, metres."""
    return distance_m * rf + crosstalk + ampm + noise


EQ3_INPUTS = dict(
    rf=Normal(0.0, 1.5e-9),
    crosstalk=Arcsine.from_amplitude(2.7e-6),
    ampm=Uniform.from_std(0.2e-6),
    noise=Normal(0.0, 0.8e-6),
)


def _quantile_se(samples, a):
    """SE of the a-quantile from the sample itself (density by a +-0.5 % order-statistic slope)."""
    y = np.sort(samples)
    m = y.size
    d = 0.005
    f = 2 * d / (y[int((a + d) * m)] - y[int((a - d) * m)])
    return math.sqrt(a * (1 - a) / m) / f


# ------------------------------------------------------------------ JCGM 101 §9.2 additive model
def test_jcgm101_9_2_normal_inputs():
    inputs = {f"x{i}": Normal(0.0, 1.0) for i in range(1, 5)}
    r = run_mc(additive, inputs, trials=M, rng=101)
    assert r.trials == M and r.quantile_method == "exact"
    assert abs(r.estimate) <= 5 * 2 / math.sqrt(M)
    assert abs(r.std - 2.0) <= 5 * 2 * math.sqrt(2 / (4 * M))
    # published (JCGM 101 Table 2): [-3.92, 3.92]; exact: +-1.959964 * 2
    se = math.sqrt(0.025 * 0.975 / M) / (stats.norm.pdf(1.959964) / 2)
    for got, exact in zip(r.interval_symmetric, (-3.919928, 3.919928)):
        assert abs(got - exact) <= 5 * se
        assert abs(got - math.copysign(3.92, exact)) <= 5 * se + 0.005
    g = gum_linear(additive, inputs)
    assert g.std == pytest.approx(2.0, rel=1e-9)
    assert g.interval == pytest.approx([-3.919928, 3.919928], abs=1e-6)
    assert validate_gum(r, g, ndigits=2).valid


def test_jcgm101_9_2_rectangular_inputs_irwin_hall():
    inputs = {f"x{i}": Uniform.from_std(1.0) for i in range(1, 5)}  # each U(-sqrt3, sqrt3)

    # exact 97.5 % point of the sum: Irwin-Hall(4) scaled by 2 sqrt(3), shifted by -4 sqrt(3)
    def ih_cdf(x):
        return sum((-1) ** k * math.comb(4, k) * max(x - k, 0.0) ** 4 for k in range(5)) / 24.0

    y975 = 2 * math.sqrt(3) * (optimize.brentq(lambda x: ih_cdf(x) - 0.975, 2.0, 4.0) - 2.0)
    assert y975 == pytest.approx(3.8794, abs=1e-4)  # JCGM 101 Table 3: 3.88 (MCM)
    r = run_mc(additive, inputs, trials=M, rng=102)
    # kurtosis of the sum: 3 - 1.2/4 = 2.7
    assert abs(r.std - 2.0) <= 5 * 2 * math.sqrt((2.7 - 1) / (4 * M))
    pdf_at = 2 * math.sqrt(3)  # density of the sum at y975 from the Irwin-Hall pdf
    x = y975 / (2 * math.sqrt(3)) + 2.0
    f = sum((-1) ** k * math.comb(4, k) * max(x - k, 0.0) ** 3 for k in range(5)) / 6.0 / pdf_at
    se = math.sqrt(0.025 * 0.975 / M) / f
    assert r.interval_symmetric == pytest.approx([-y975, y975], abs=5 * se)
    assert r.interval_symmetric == pytest.approx([-3.88, 3.88], abs=5 * se + 0.005)
    # GUM: +-3.92 against the MC +-3.88: d = 0.0405 in the population, against delta = 0.05 for 2
    # significant digits of u = 2.0 (a borderline case that MC noise can tip either way) and
    # delta = 0.005 for 3 digits (clearly not validated)
    g = gum_linear(additive, inputs)
    assert g.interval == pytest.approx([-3.92, 3.92], abs=0.005)
    v2, v3 = validate_gum(r, g, ndigits=2), validate_gum(r, g, ndigits=3)
    assert v2.tolerance == 0.05 and v2.valid == (max(v2.d_low, v2.d_high) <= 0.05)
    assert v3.tolerance == 0.005 and not v3.valid
    for d in (v2.d_low, v2.d_high):
        assert d == pytest.approx(3.919928 - y975, abs=5 * se)


# ------------------------------------------------------------------ JCGM 101 §9.3 mass calibration
def _mass_exact_moments():
    """Closed-form mean and u of the §9.3 model (independent inputs, products of moments)."""
    ea = 100_000.0 + 1.234
    ea2 = ea**2 + 0.050**2 + 0.020**2
    ec2 = 0.2**2 / 12
    e1w, e1w2 = math.log(9000 / 7000) / 2000, (1 / 7000 - 1 / 9000) / 2000
    e1r, e1r2 = math.log(8050 / 7950) / 100, (1 / 7950 - 1 / 8050) / 100
    ed2 = e1w2 - 2 * e1w * e1r + e1r2
    return ea - 100_000.0, math.sqrt(ea2 * (1 + ec2 * ed2) - ea**2)


def test_jcgm101_9_3_mass_calibration():
    mean_exact, u_exact = _mass_exact_moments()
    assert u_exact == pytest.approx(0.0755, abs=1e-4)
    r = run_mc(mass_model, MASS_INPUTS, trials=M, rng=93)
    y = r.samples
    kurt = stats.kurtosis(y, fisher=False)
    se_u = u_exact * math.sqrt((kurt - 1) / (4 * M))
    se_m = u_exact / math.sqrt(M)
    # closed form
    assert abs(r.estimate - mean_exact) <= 5 * se_m
    assert abs(r.std - u_exact) <= 5 * se_u
    # published MCM (JCGM 101 Table 9, M = 10^6): 1.2341 mg, 0.0754 mg, shortest [1.0834, 1.3825] mg
    assert abs(r.estimate - 1.2341) <= 5 * math.hypot(se_m, se_m) + 0.00005
    assert abs(r.std - 0.0754) <= 5 * math.hypot(se_u, se_u) + 0.00005
    se_lo, se_hi = _quantile_se(y, 0.025), _quantile_se(y, 0.975)
    length = r.interval_shortest[1] - r.interval_shortest[0]
    assert abs(length - (1.3825 - 1.0834)) <= 5 * math.hypot(se_lo, se_hi) * math.sqrt(2) + 0.0001
    # the output is symmetric about 1.234 mg: the symmetric interval is centred there
    assert abs(r.interval_symmetric.mean() - mean_exact) <= 5 * math.hypot(se_lo, se_hi) / 2
    # the shortest interval's location is only weakly determined (its length is flat near the
    # optimum), so the published ends are checked through what they mean: [1.0834, 1.3825] mg must
    # hold 95 % of our distribution (binomial SE of ours and of theirs, plus the 0.00005 mg rounding
    # of each end times the density there)
    inside = np.count_nonzero((y >= 1.0834) & (y <= 1.3825)) / M
    f_ends = math.sqrt(0.025 * 0.975 / M) / _quantile_se(y, 0.025)  # output density at the lower end
    tol = 5 * math.sqrt(2 * 0.95 * 0.05 / M) + 2 * 0.00005 * f_ends
    assert abs(inside - 0.95) <= tol
    # GUF (JCGM 101 Table 9): 1.2340 mg, 0.0539 mg, [1.1285, 1.3395] mg; not validated
    g = gum_linear(mass_model, MASS_INPUTS)
    assert g.estimate == pytest.approx(1.2340, abs=5e-5)
    assert g.std == pytest.approx(0.0539, abs=5e-5)
    assert g.interval == pytest.approx([1.1285, 1.3395], abs=5e-5)
    v = validate_gum(r, g, ndigits=2)
    assert not v.valid and v.d_low > 0.04 and v.d_high > 0.04


# ------------------------------------------------------------------ the seed's eq. (3)
def test_eq3_linearisation_fails():
    r = run_mc(eq3_error_m, EQ3_INPUTS, trials=400_000, rng=3)
    g = gum_linear(eq3_error_m, EQ3_INPUTS)
    u_exact = math.sqrt((20 * 1.5e-9) ** 2 + (2.7e-6 / math.sqrt(2)) ** 2 + 0.2e-6**2 + 0.8e-6**2)
    assert g.std == pytest.approx(u_exact, rel=1e-6)
    se_u = u_exact * math.sqrt((stats.kurtosis(r.samples, fisher=False) - 1) / (4 * r.trials))
    assert abs(r.std - u_exact) <= 5 * se_u  # same standard uncertainty (2.1 um)...
    assert round(r.std * 1e6, 1) == 2.1
    # ...but the GUM interval (normal, +-4.08 um) is far wider than the MC one (about +-3.55 um)
    v = validate_gum(r, g, ndigits=2)
    assert not v.valid
    assert g.interval[1] - r.interval_symmetric[1] > 0.4e-6


# ------------------------------------------------------------------ reproducibility
@pytest.mark.parametrize("chunk_size", [1, BLOCK, 3 * BLOCK + 5, 10**9])
def test_identical_whatever_the_chunk_size(chunk_size):
    trials = 5 * BLOCK + 1234
    ref = run_mc(eq3_error_m, EQ3_INPUTS, trials=trials, rng=42, chunk_size=2 * BLOCK)
    r = run_mc(eq3_error_m, EQ3_INPUTS, trials=trials, rng=42, chunk_size=chunk_size)
    assert r.estimate == ref.estimate and r.std == ref.std
    assert np.array_equal(r.interval_symmetric, ref.interval_symmetric)
    assert np.array_equal(r.interval_shortest, ref.interval_shortest)
    assert np.array_equal(r.samples, ref.samples)


def test_in_process_tail_candidates_give_the_exact_intervals():
    # in-process runs collect tail candidates block by block; the intervals must equal a full scan
    r = run_mc(eq3_error_m, EQ3_INPUTS, trials=5 * BLOCK, rng=77)
    assert np.array_equal(r.interval_symmetric, coverage_interval(r.samples, 0.95, "symmetric"))
    assert np.array_equal(r.interval_shortest, coverage_interval(r.samples, 0.95, "shortest"))
    with ThreadPoolExecutor(1) as pool:  # a map: no candidates, the samples are scanned
        p = run_mc(eq3_error_m, EQ3_INPUTS, trials=5 * BLOCK, rng=77, map=pool)
    assert np.array_equal(p.interval_shortest, r.interval_shortest)


def test_identical_through_a_pool_map_and_histogram_mode():
    trials = 4 * BLOCK
    ref = run_mc(eq3_error_m, EQ3_INPUTS, trials=trials, rng=7, quantiles="histogram")
    with ThreadPoolExecutor(2) as pool:
        r = run_mc(eq3_error_m, EQ3_INPUTS, trials=trials, rng=7, quantiles="histogram", chunk_size=BLOCK, map=pool)
    assert r.estimate == ref.estimate and r.std == ref.std
    assert np.array_equal(r._hist_counts, ref._hist_counts)
    assert np.array_equal(r.interval_symmetric, ref.interval_symmetric)


def test_seed_forms():
    a = run_mc(additive, {f"x{i}": Normal() for i in range(1, 5)}, trials=1000, rng=5)
    b = run_mc(additive, {f"x{i}": Normal() for i in range(1, 5)}, trials=1000, rng=np.random.SeedSequence(5))
    assert a.estimate == b.estimate and a.seed_entropy == 5
    g = np.random.default_rng(9)
    c = run_mc(additive, {f"x{i}": Normal() for i in range(1, 5)}, trials=1000, rng=g)
    d = run_mc(additive, {f"x{i}": Normal() for i in range(1, 5)}, trials=1000, rng=g)
    assert c.estimate != d.estimate  # a generator is consumed, like any other use of it


def test_histogram_mode_agrees_with_exact_on_the_same_samples():
    trials = 8 * BLOCK
    ex = run_mc(mass_model, MASS_INPUTS, trials=trials, rng=11, quantiles="exact")
    hi = run_mc(mass_model, MASS_INPUTS, trials=trials, rng=11, quantiles="histogram")
    assert hi.samples is None and hi.quantile_method == "histogram"
    assert hi.estimate == ex.estimate and hi.std == ex.std  # same streamed moments
    width = hi._hist_edges[0, 1] - hi._hist_edges[0, 0]
    # exact order statistic vs interpolated cdf: within a bin plus the spacing of order statistics
    tol = 2 * width + 2 * _quantile_se(ex.samples, 0.025) / 5
    assert hi.interval_symmetric == pytest.approx(ex.interval_symmetric, abs=tol)
    assert hi.interval_shortest[1] - hi.interval_shortest[0] == pytest.approx(
        ex.interval_shortest[1] - ex.interval_shortest[0], abs=2 * tol
    )
    counts, edges = hi.histogram(50)
    assert counts.sum() == trials and edges.size == counts.size + 1 and counts.size <= 50
    counts, edges = ex.histogram(40)
    assert counts.sum() == trials and counts.size == 40


def test_histogram_mode_heavy_tails_cauchy():
    # the histogram range comes from pilot quantiles, not extremes: Cauchy bins stay fine
    ex = run_mc(lambda a: a, {"a": Cauchy(0.0, 1.0)}, trials=4 * BLOCK, rng=3, quantiles="exact")
    hi = run_mc(lambda a: a, {"a": Cauchy(0.0, 1.0)}, trials=4 * BLOCK, rng=3, quantiles="histogram")
    assert ex.quantile_resolution == 0.0 and 0 < hi.quantile_resolution < 0.1
    tol = 2 * hi.quantile_resolution + 2 * _quantile_se(ex.samples, 0.975) / 5
    assert hi.interval_symmetric == pytest.approx(ex.interval_symmetric, abs=tol)
    # exact 97.5 % point of the standard Cauchy: tan(0.475 pi) = 12.706
    assert abs(hi.interval_symmetric[1] - math.tan(0.475 * math.pi)) <= 5 * _quantile_se(ex.samples, 0.975) + tol


# ------------------------------------------------------------------ adaptive (JCGM 101 §7.9)
def test_adaptive_meets_its_tolerance_and_matches_fixed_run():
    inputs = {f"x{i}": Normal(0.0, 1.0) for i in range(1, 5)}
    r = run_mc(additive, inputs, adaptive=True, ndigits=2, rng=21)
    assert r.converged is True and r.trials % BLOCK == 0 and r.trials >= 2 * BLOCK
    assert r.tolerance == numerical_tolerance(r.std, 2) == 0.05
    assert abs(r.std - 2.0) <= 2 * r.tolerance
    # adaptive batches are ordinary blocks: the same numbers as a fixed run of that many trials
    f = run_mc(additive, inputs, trials=r.trials, rng=21)
    assert f.std == r.std and np.array_equal(f.interval_symmetric, r.interval_symmetric)
    with ThreadPoolExecutor(2) as pool:  # rounds of 3 batches through a map: same stopping point
        rp = run_mc(additive, inputs, adaptive=True, ndigits=2, rng=21, map=pool, batches_per_round=3)
    assert rp.trials == r.trials and rp.std == r.std
    r1 = run_mc(additive, inputs, adaptive=True, ndigits=1, rng=21)
    assert r1.trials <= r.trials
    r3 = run_mc(additive, inputs, adaptive=True, ndigits=3, rng=21, max_trials=4 * BLOCK)
    assert r3.converged is False and r3.trials == 4 * BLOCK


def test_adaptive_exact_quantiles_stay_exact_or_are_refused():
    """``quantiles="exact"`` in an adaptive run is honoured: exact intervals (the samples kept, the
    same bits as a fixed exact run of that length); when the run would need more than ``exact_limit``
    values it stops with an error naming the option, never switching to histogram intervals (it
    did, saying only ``quantile_method='histogram'``). "auto" still switches and says so."""
    inputs = {f"x{i}": Normal(0.0, 1.0) for i in range(1, 5)}
    r = run_mc(additive, inputs, adaptive=True, ndigits=2, rng=21, quantiles="exact")
    assert r.quantile_method == "exact" and r.samples.shape == (r.trials,)
    f = run_mc(additive, inputs, trials=r.trials, rng=21, quantiles="exact")
    assert np.array_equal(f.interval_symmetric, r.interval_symmetric)
    assert np.array_equal(f.interval_shortest, r.interval_shortest)
    with pytest.raises(MultilatError, match=r"quantiles='exact'.*exact_limit=65,536"):
        run_mc(additive, inputs, adaptive=True, ndigits=2, rng=21, quantiles="exact", exact_limit=BLOCK)
    a = run_mc(additive, inputs, adaptive=True, ndigits=2, rng=21, quantiles="auto", exact_limit=BLOCK)
    assert a.quantile_method == "histogram" and a.as_dict()["quantile_method"] == "histogram"


def test_numerical_tolerance_examples():
    # JCGM 101 §7.9.2 example: u = 0.028 (2 digits) -> delta = 0.0005
    assert numerical_tolerance(0.028, 2) == pytest.approx(0.0005)
    assert numerical_tolerance(2.0, 2) == pytest.approx(0.05)
    assert numerical_tolerance(1.5e-6, 1) == pytest.approx(0.5e-6)
    assert numerical_tolerance(0.0996, 2) == pytest.approx(0.005)  # u = 0.10 to 2 digits


# ------------------------------------------------------------------ intervals and summaries
def test_coverage_interval_matches_brute_force():
    rng = np.random.default_rng(0)
    for m in (40, 101, 1000):
        y = rng.gamma(2.0, size=m)
        ys = np.sort(y)
        q = int(math.floor(0.9 * m + 0.5))
        lengths = [ys[r + q] - ys[r] for r in range(m - q)]
        r = int(np.argmin(lengths))
        assert np.array_equal(coverage_interval(y, 0.9, "shortest"), [ys[r], ys[r + q]])
        rs = (m - q + 1) // 2 - 1
        assert np.array_equal(coverage_interval(y, 0.9, "symmetric"), [ys[rs], ys[rs + q]])


def test_shortest_tie_rule_lowest_and_ambiguity_flag():
    y = np.arange(1000.0)  # every candidate has the same length: the lowest is reported
    assert np.array_equal(coverage_interval(y, 0.9, "shortest"), [0.0, 900.0])
    arc = summarize(Arcsine(-1.0, 1.0).sample(np.random.default_rng(1), 200_000))
    assert arc.shortest_ambiguous  # two mirror-image shortest intervals (bimodal)
    assert arc.interval_shortest[0] == pytest.approx(-1.0, abs=1e-3) or arc.interval_shortest[1] == pytest.approx(
        1.0, abs=1e-3
    )
    nor = summarize(np.random.default_rng(2).standard_normal(200_000))
    assert not nor.shortest_ambiguous


def test_summarize_vector_output_covariance():
    rng = np.random.default_rng(4)
    cov = np.array([[1.0, 0.6], [0.6, 2.0]])
    y = rng.multivariate_normal([1.0, -1.0], cov, size=100_000)
    s = summarize(y, coverage=0.9)
    assert s.estimate.shape == (2,) and s.interval_symmetric.shape == (2, 2)
    assert np.allclose(s.cov, np.cov(y.T), rtol=1e-12)
    assert np.allclose(s.std, y.std(axis=0, ddof=1), rtol=1e-12)


def test_run_mc_vector_output():
    def two(a, b):
        return np.stack([a + b, a - b], axis=1)

    r = run_mc(two, {"a": Normal(0, 1), "b": Normal(0, 2)}, trials=200_000, rng=8)
    assert r.estimate.shape == (2,) and r.cov.shape == (2, 2)
    se = 5 * 5 * math.sqrt(2 / 200_000)  # variance 5, SE of var ~ 5 sqrt(2/M)
    np.testing.assert_allclose(r.cov, [[5, -3], [-3, 5]], atol=se)
    counts, _ = r.histogram(10, component=1)
    assert counts.sum() == 200_000
    with pytest.raises(MultilatError, match="component"):
        r.histogram(10)


def test_progress_and_nonfinite():
    seen = []
    run_mc(additive, {f"x{i}": Normal() for i in range(1, 5)}, trials=3 * BLOCK, rng=1, chunk_size=BLOCK,
           progress=lambda d, t: seen.append((d, t)))
    assert seen == [(BLOCK, 3 * BLOCK), (2 * BLOCK, 3 * BLOCK), (3 * BLOCK, 3 * BLOCK)]

    def sqrt_model(x):
        with np.errstate(invalid="ignore"):
            return np.sqrt(x)

    with pytest.raises(MultilatError, match="non-finite"):
        run_mc(sqrt_model, {"x": Normal(1.0, 1.0)}, trials=1000, rng=1)
    r = run_mc(sqrt_model, {"x": Normal(1.0, 1.0)}, trials=10_000, rng=1, nonfinite="drop")
    assert r.n_rejected > 0 and r.trials + r.n_rejected == 10_000
    assert abs(r.n_rejected / 10_000 - stats.norm.cdf(-1)) <= 5 * math.sqrt(0.16 * 0.84 / 10_000)


# ------------------------------------------------------------------ budget
def test_budget_additive_model_ranked():
    inputs = {"a": Normal(0, 3.0), "b": Uniform.from_std(1.0), "c": Arcsine.from_amplitude(2.0 * math.sqrt(2)),
              "d": Constant(5.0)}

    def model(a, b, c, d):
        return 2.0 * a + b - c + d

    bud = budget(model, inputs, trials=100_000, rng=1)
    assert bud.ranked_names() == ["a", "c", "b", "d"]
    expect = {"a": 6.0, "b": 1.0, "c": 2.0, "d": 0.0}
    for comp in bud.components:
        assert comp.u_linear == pytest.approx(expect[comp.name], rel=1e-6, abs=1e-12)
        assert abs(comp.std - expect[comp.name]) <= 5 * max(expect[comp.name], 1e-9) * math.sqrt(1 / 100_000)
    assert sum(c.variance_fraction for c in bud.components) == pytest.approx(1.0, abs=0.02)
    assert bud.combined.std == pytest.approx(math.sqrt(41.0), rel=0.02)


@pytest.mark.parametrize("rng", [None, np.random.default_rng(5), 7])
def test_budget_reported_seed_reproduces_its_combined_run(rng):
    """The combined run's reported seed (its JSON's ``seed``) re-runs it with ``run_mc``: the same
    numbers, bit for bit (the combined run was on a spawned branch whose entropy alone seeded a
    different run: std 1.5306 against 1.5370). A component, on its own branch, reports its spawn key
    and is reproduced from both."""
    inputs = {"a": Normal(0, 1.0), "b": Uniform.from_std(1.0), "c": Arcsine.from_amplitude(1.0)}

    def model(a, b, c):
        return a + b * c + c

    bud = budget(model, inputs, trials=20_000, rng=rng)
    doc = bud.combined.as_dict()
    assert "seed_spawn_key" not in doc
    again = run_mc(model, inputs, trials=20_000, rng=doc["seed"])
    assert again.std == bud.combined.std and again.estimate == bud.combined.estimate
    assert np.array_equal(again.interval_symmetric, bud.combined.interval_symmetric)
    held = {"a": inputs["a"], "b": Constant(0.0), "c": Constant(0.0)}
    branch = np.random.SeedSequence(doc["seed"], spawn_key=(0xB0D6E7, 1))
    comp = run_mc(model, held, trials=20_000, rng=branch)
    assert comp.as_dict()["seed_spawn_key"] == [0xB0D6E7, 1]
    assert {c.name: c for c in bud.components}["a"].std == comp.std
    rerun = run_mc(model, held, trials=20_000,
                   rng=np.random.SeedSequence(comp.seed_entropy, spawn_key=comp.seed_spawn_key))
    assert rerun.std == comp.std


def test_budget_holds_cauchy_at_its_centre():
    bud = budget(lambda a, b: a + b, {"a": Normal(0, 1), "b": Cauchy(2.0, 1e-3)}, trials=20_000, rng=2)
    by = {c.name: c for c in bud.components}
    assert by["b"].u_linear is None and by["a"].u_linear == pytest.approx(1.0)


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(coverage=1.5), "coverage"),
        (dict(trials=1), "trials"),
        (dict(trials=10.5), "trials"),
        (dict(chunk_size=0), "chunk_size"),
        (dict(rng=-1), "rng"),
        (dict(rng="abc"), "rng"),
        (dict(quantiles="fast"), "quantiles"),
        (dict(nonfinite="ignore"), "nonfinite"),
        (dict(map=5), "map"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(MultilatError, match=match):
        run_mc(additive, {f"x{i}": Normal() for i in range(1, 5)}, **({"trials": 100} | kwargs))


def test_bad_inputs_and_models():
    with pytest.raises(MultilatError, match="inputs"):
        run_mc(additive, {}, trials=100)
    with pytest.raises(MultilatError, match="sample"):
        run_mc(additive, {"x1": 1.0}, trials=100)
    with pytest.raises(MultilatError, match="shape"):
        run_mc(lambda x: x[:-1], {"x": Normal()}, trials=100)
    with pytest.raises(MultilatError, match="GUM"):
        gum_linear(lambda x: x, {"x": Cauchy()})
    with pytest.raises(MultilatError, match="finite"):
        summarize([1.0, np.nan, 2.0])
    with pytest.raises(MultilatError, match="kind"):
        coverage_interval([1.0, 2.0, 3.0], 0.5, kind="median")


def test_as_dict_is_plain_json():
    import json

    r = run_mc(eq3_error_m, EQ3_INPUTS, trials=2000, rng=1)
    d = json.loads(json.dumps(r.as_dict()))
    assert d["trials"] == 2000 and len(d["interval_symmetric"]) == 2 and "samples" not in d
    assert d["std"] == r.std


def test_correlated_vector_input():
    cov = [[4.0, 1.2], [1.2, 1.0]]
    inputs = {"p": MultivariateNormal([1.0, 2.0], cov), "e": Normal(0.0, 0.5)}

    def model(p, e):
        return p[:, 0] + p[:, 1] + e

    r = run_mc(model, inputs, trials=200_000, rng=12)
    var = 4.0 + 1.0 + 2 * 1.2 + 0.25
    assert abs(r.estimate - 3.0) <= 5 * math.sqrt(var / 200_000)
    assert abs(r.std - math.sqrt(var)) <= 5 * math.sqrt(var) * math.sqrt(2 / (4 * 200_000))
    bud = budget(model, inputs, trials=50_000, rng=1)
    by = {c.name: c for c in bud.components}
    assert by["p"].u_linear is None and abs(by["p"].std - math.sqrt(7.4)) <= 5 * math.sqrt(7.4 / (2 * 50_000))
    assert by["e"].u_linear == pytest.approx(0.5)
    with pytest.raises(MultilatError, match="scalar inputs"):
        gum_linear(model, inputs)


def test_partial_model_is_accepted():
    r = run_mc(partial(eq3_error_m, distance_m=0.0), EQ3_INPUTS, trials=1000, rng=1)
    assert r.trials == 1000


def test_chunk_ranges_are_whole_blocks_covering_the_run():
    from multilat.montecarlo import block_trials, chunk_ranges

    for trials, chunk, block in ((3500, 1700, 1000), (4000, 1000, 1000), (10, 1, 3), (2 * BLOCK + 5, 1, BLOCK)):
        ch = chunk_ranges(trials, chunk, block)
        blocks = [b for s, e in ch for b in range(s, e)]
        assert blocks == list(range(-(-trials // block)))                    # every block once, in order
        assert all(e - s == max(1, -(-chunk // block)) for s, e in ch[:-1])  # whole blocks per chunk
        assert sum(block_trials(b, trials, block) for b in blocks) == trials
    assert chunk_ranges(20_000, 3000, 1000, first_block=10) == [(10, 13), (13, 16), (16, 19), (19, 20)]


def test_adaptive_rule_pools_u_and_stops_at_max_batches():
    """u(y) pooled from batch means/stds equals the std of all samples (1e-12 relative); a rule that cannot
    converge stops after max_batches with converged False."""
    from multilat.montecarlo import AdaptiveRule

    rng = np.random.default_rng(3)
    rule = AdaptiveRule(0.95, 2, max_trials=30_000, block=1000)
    assert (rule.batch_trials, rule.max_batches, rule.batch_range(2)) == (10_000, 3, (20, 30))
    ys = [rng.normal(h, 1 + h, (10_000, 2)) for h in range(3)]   # drifting batches: never stable
    stops = [rule.add(y) for y in ys]
    assert stops == [False, False, True] and rule.converged is False
    np.testing.assert_allclose(rule.u(), np.concatenate(ys).std(axis=0, ddof=1), rtol=1e-12)
