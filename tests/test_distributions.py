"""Distributions: closed-form moments vs scipy.stats and vs large samples.

Sample tolerances are Monte Carlo standard errors: the sample mean of n draws has standard error
sigma/sqrt(n); the sample standard deviation has standard error ~ sigma*sqrt((excess_kurtosis + 2)/(4n)).
We allow 5 standard errors (a false alarm once in ~1.7 million runs; the seeds are fixed anyway).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import integrate, stats

from multilat.distributions import (
    Arcsine,
    Cauchy,
    Constant,
    CurvilinearTrapezoidal,
    MultivariateNormal,
    Normal,
    StudentT,
    Trapezoidal,
    Triangular,
    Uniform,
)
from multilat.errors import MultilatError

N = 200_000

WITH_SCIPY = [
    Normal(mean=1.5e-6, std=0.8e-6),
    Uniform(low=-2e-6, high=3e-6),
    Arcsine(low=-2.7e-6, high=2.7e-6),
    Arcsine(low=10.0, high=12.0),
    Triangular(low=-1.0, mode=0.25, high=2.0),
    Triangular.symmetric(0.5, centre=3.0),
    Trapezoidal(low=-1.0, high=3.0, beta=0.3),
    Trapezoidal(low=0.0, high=1.0, beta=0.0),
    StudentT(df=7, loc=2.0, scale=0.1),
]


@pytest.mark.parametrize("d", WITH_SCIPY, ids=lambda d: repr(d))
def test_closed_form_moments_match_scipy(d):
    ref = d.to_scipy()
    assert d.mean == pytest.approx(ref.mean(), rel=1e-12, abs=1e-15)
    assert d.std == pytest.approx(ref.std(), rel=1e-10)


@pytest.mark.parametrize("d", WITH_SCIPY, ids=lambda d: repr(d))
def test_samples_match_moments_and_law(d):
    rng = np.random.default_rng(20260522)
    x = d.sample(rng, N)
    assert x.shape == (N,) and x.dtype == np.float64
    ek = float(d.to_scipy().stats(moments="k"))
    assert abs(x.mean() - d.mean) <= 5 * d.std / math.sqrt(N)
    assert abs(x.std(ddof=1) - d.std) <= 5 * d.std * math.sqrt((ek + 2) / (4 * N))
    # the whole law, not just two moments: KS test against scipy's cdf (fixed seed)
    assert stats.kstest(x[:20_000], d.to_scipy().cdf).pvalue > 1e-4


def test_sample_shape_tuple():
    x = Uniform(0.0, 1.0).sample(np.random.default_rng(1), (3, 4))
    assert x.shape == (3, 4)


def test_arcsine_is_sine_of_uniform_phase():
    # the law of a*sin(2*pi*U) in the seed's eq. (3)
    a = 2.7e-6
    d = Arcsine.from_amplitude(a)
    assert d.std == pytest.approx(a / math.sqrt(2), rel=1e-15)
    assert d.low == -a and d.high == a
    u = np.random.default_rng(3).uniform(-0.5, 0.5, 20_000)
    assert stats.ks_2samp(a * np.sin(2 * np.pi * u), d.sample(np.random.default_rng(4), 20_000)).pvalue > 1e-4


def test_uniform_from_std():
    d = Uniform.from_std(0.2e-6)
    assert d.std == pytest.approx(0.2e-6, rel=1e-14)
    assert d.high == pytest.approx(math.sqrt(3) * 0.2e-6)


def test_curvilinear_trapezoidal_moments_pdf_and_samples():
    d = CurvilinearTrapezoidal(low=-1.0, high=1.0, d=0.4)
    # closed form of JCGM 101 §6.4.3.3: variance (b-a)^2/12 + d^2/9
    assert d.std == pytest.approx(math.sqrt(4 / 12 + 0.16 / 9), rel=1e-15)
    # pdf integrates to 1 and its second moment is the closed-form variance (independent check)
    pdf = lambda t: float(d.pdf(t))  # noqa: E731
    pts = [-1.4, -0.6, 0.6, 1.4]
    assert integrate.quad(pdf, -1.5, 1.5, points=pts, limit=200)[0] == pytest.approx(1.0, abs=1e-8)
    var = integrate.quad(lambda t: t * t * pdf(t), -1.5, 1.5, points=pts, limit=200)[0]
    assert var == pytest.approx(d.variance, rel=1e-7)
    rng = np.random.default_rng(11)
    x = d.sample(rng, N)
    assert x.min() >= -1.4 and x.max() <= 1.4
    assert abs(x.mean()) <= 5 * d.std / math.sqrt(N)
    # kurtosis of this law is between rectangular and triangular; excess <= -0.6 -> (ek+2) <= 1.4
    assert abs(x.std(ddof=1) - d.std) <= 5 * d.std * math.sqrt(1.4 / (4 * N))
    # KS against the numerically integrated closed-form cdf
    grid = np.linspace(-1.4, 1.4, 4001)
    cdf = integrate.cumulative_trapezoid(d.pdf(grid), grid, initial=0.0)
    cdf /= cdf[-1]
    assert stats.kstest(x[:20_000], lambda t: np.interp(t, grid, cdf)).pvalue > 1e-4


def test_curvilinear_trapezoidal_d0_is_rectangular():
    d = CurvilinearTrapezoidal(low=0.0, high=2.0, d=0.0)
    assert d.std == pytest.approx(Uniform(0.0, 2.0).std, rel=1e-15)


def test_student_t_moments_edge_cases():
    assert StudentT(df=2, loc=1.0, scale=1.0).std == math.inf
    assert math.isnan(StudentT(df=1, loc=1.0).mean)
    assert StudentT(df=1, loc=1.0).centre == 1.0


def test_cauchy():
    d = Cauchy(loc=1e-6, scale=2e-7)
    assert d.std == math.inf and math.isnan(d.mean) and d.centre == 1e-6
    x = d.sample(np.random.default_rng(5), 40_001)
    # the sample median of a Cauchy has standard error pi*scale/(2 sqrt(n))
    assert abs(np.median(x) - d.loc) <= 5 * math.pi * d.scale / (2 * math.sqrt(x.size))
    assert stats.kstest(x[:20_000], d.to_scipy().cdf).pvalue > 1e-4


def test_constant():
    d = Constant(3.0)
    assert d.mean == 3.0 and d.std == 0.0
    assert np.all(d.sample(np.random.default_rng(0), 5) == 3.0)
    with pytest.raises(MultilatError):
        d.to_scipy()


def test_sampling_reproducible_from_int_seed():
    d = Normal(0.0, 1.0)
    assert np.array_equal(d.sample(7, 10), d.sample(7, 10))


@pytest.mark.parametrize(
    "factory, name",
    [
        (lambda: Normal(mean=0.0, std=-1.0), "std"),
        (lambda: Normal(mean=float("nan"), std=1.0), "mean"),
        (lambda: Uniform(low=1.0, high=1.0), "high"),
        (lambda: Uniform.from_halfwidth(-1.0), "half_width"),
        (lambda: Arcsine(low=2.0, high=1.0), "high"),
        (lambda: Triangular(low=0.0, mode=2.0, high=1.0), "mode"),
        (lambda: Trapezoidal(low=0.0, high=1.0, beta=1.5), "beta"),
        (lambda: CurvilinearTrapezoidal(low=0.0, high=1.0, d=0.6), "d"),
        (lambda: StudentT(df=0.0), "df"),
        (lambda: Cauchy(scale=0.0), "scale"),
        (lambda: Constant(float("inf")), "value"),
        (lambda: Normal(mean="abc"), "mean"),
    ],
)
def test_bad_parameters_raise_naming_the_parameter(factory, name):
    with pytest.raises(MultilatError, match=name):
        factory()


def test_frozen():
    d = Normal(0.0, 1.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.std = 2.0  # type: ignore[misc]


def test_multivariate_normal_covariance_and_errors():
    cov = np.array([[4.0, 1.2, 0.0], [1.2, 1.0, -0.3], [0.0, -0.3, 0.25]])
    d = MultivariateNormal(mean=[1.0, 2.0, 3.0], cov=cov)
    assert np.allclose(d.std, [2.0, 1.0, 0.5])
    x = d.sample(np.random.default_rng(3), 100_000)
    assert x.shape == (100_000, 3)
    # SE of a sample covariance element: sqrt((s_ii s_jj + s_ij^2) / n)
    se = np.sqrt((np.outer(np.diag(cov), np.diag(cov)) + cov**2) / x.shape[0])
    assert np.all(np.abs(np.cov(x.T) - cov) <= 5 * se)
    assert np.all(np.abs(x.mean(axis=0) - d.mean) <= 5 * d.std / math.sqrt(x.shape[0]))
    singular = MultivariateNormal(mean=[0.0, 0.0], cov=[[1.0, 1.0], [1.0, 1.0]])
    y = singular.sample(np.random.default_rng(1), 1000)
    assert np.allclose(y[:, 0], y[:, 1])
    with pytest.raises(MultilatError, match="shape"):
        MultivariateNormal(mean=[0.0, 0.0], cov=np.eye(3))
    with pytest.raises(MultilatError, match="semi-definite"):
        MultivariateNormal(mean=[0.0, 0.0], cov=[[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(MultilatError, match="symmetric"):
        MultivariateNormal(mean=[0.0, 0.0], cov=[[1.0, 0.5], [0.0, 1.0]])


def test_numba_normals_identical_to_numpy(monkeypatch):
    pytest.importorskip("numba")
    import os

    import multilat.fast_normal as dist

    if os.environ.get("MULTILAT_NO_NUMBA"):
        pytest.skip("numba path disabled by MULTILAT_NO_NUMBA")

    monkeypatch.setattr(dist, "NUMBA_AFTER", 0)
    for bit_generator in (np.random.SFC64, np.random.PCG64):
        g1, g2 = np.random.Generator(bit_generator(11)), np.random.Generator(bit_generator(11))
        fast = dist._fast_std_normal(g1, (5000, 3))
        assert dist._NUMBA_NORMAL not in (None, False)  # the numba path really ran
        assert np.array_equal(fast, g2.standard_normal((5000, 3)))
        assert np.array_equal(g1.random(4), g2.random(4))  # and left the same generator state
