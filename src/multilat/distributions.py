"""Probability distributions for input quantities (JCGM 101:2008, clause 6).

Each distribution is a frozen dataclass with validated parameters (SI values), the closed-form
expectation :attr:`mean` and standard uncertainty :attr:`std`, a fast :meth:`sample` and, where
scipy has the distribution, :meth:`to_scipy` (a frozen ``scipy.stats`` object used by the tests as
the independent reference).

Example
-------
>>> import numpy as np
>>> from multilat.distributions import Arcsine, Normal, Uniform
>>> crosstalk = Arcsine.from_amplitude(2.7e-6)          # cyclic error, amplitude 2.7 um
>>> round(crosstalk.std * 1e6, 2)                       # a / sqrt(2)
1.91
>>> round(Uniform.from_std(0.2e-6).high * 1e6, 4)       # half-width sqrt(3) u, in um
0.3464
>>> x = Normal(mean=0.0, std=0.8e-6).sample(np.random.default_rng(1), 1000)
>>> x.shape
(1000,)

Sampling conventions: ``sample(rng, size)`` takes a :class:`numpy.random.Generator` (an int seed or
None is resolved with :func:`numpy.random.default_rng`) and returns float64 samples of shape
``size``. The draws use the generator's fast primitives (normal, uniform, triangular, standard t,
standard Cauchy; large normal draws go through numba's bit-identical implementation of
``Generator.standard_normal`` when numba is installed, see :mod:`multilat.fast_normal`); the arcsine law is drawn as ``c + w sin(U)`` with ``U`` uniform on [-pi, pi)
(computed through the half-angle tangent, which numpy vectorises), exact and faster than an
inverse-cdf transform.

Cauchy (and Student t with ``df <= 1``) has no expectation: its :attr:`mean` is ``nan`` and
:attr:`std` is ``inf``; :attr:`centre` (the median) is defined for every distribution and is what
budget-style "hold at its best estimate" computations use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from multilat.errors import MultilatError
from multilat.fast_normal import _fast_std_normal

__all__ = [
    "Distribution",
    "SupportsSample",
    "Normal",
    "Uniform",
    "Arcsine",
    "Triangular",
    "Trapezoidal",
    "CurvilinearTrapezoidal",
    "StudentT",
    "Cauchy",
    "Constant",
    "MultivariateNormal",
]


def _rng(rng) -> np.random.Generator:
    if isinstance(rng, np.random.Generator):
        return rng
    return np.random.default_rng(rng)


def _finite(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise MultilatError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(v):
        raise MultilatError(f"{name} must be finite, got {value!r}")
    return v


@runtime_checkable
class SupportsSample(Protocol):
    """Anything :func:`multilat.montecarlo.run_mc` accepts as an input: ``sample(rng, size)``."""

    def sample(self, rng, size) -> np.ndarray: ...


class Distribution:
    """Base class: ``mean``, ``std``, ``variance``, ``centre``, ``sample(rng, size)``, ``to_scipy()``.

    Subclasses are frozen dataclasses; their parameters are validated in ``__post_init__`` and raise
    :class:`~multilat.errors.MultilatError` naming the parameter.
    """

    @property
    def mean(self) -> float:  # pragma: no cover - overridden
        raise NotImplementedError

    @property
    def std(self) -> float:  # pragma: no cover - overridden
        raise NotImplementedError

    @property
    def variance(self) -> float:
        """Variance ``std**2`` (``inf`` when the standard deviation does not exist)."""
        return self.std**2

    @property
    def centre(self) -> float:
        """The median (equal to the expectation for the symmetric laws here)."""
        return self.mean

    def sample(self, rng, size) -> np.ndarray:  # pragma: no cover - overridden
        raise NotImplementedError

    def to_scipy(self):
        """The equivalent frozen ``scipy.stats`` distribution (raises if scipy has none)."""
        raise MultilatError(f"{type(self).__name__} has no scipy.stats equivalent")


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Normal(Distribution):
    """Gaussian N(mean, std**2) (JCGM 101 §6.4.7).

    Parameters
    ----------
    mean : float
        Expectation (SI unit of the quantity).
    std : float
        Standard deviation, ``>= 0``.
    """

    mean: float = 0.0
    std: float = 1.0

    def __post_init__(self):
        object.__setattr__(self, "mean", _finite("mean", self.mean))
        object.__setattr__(self, "std", _finite("std", self.std))
        if self.std < 0:
            raise MultilatError(f"std must be >= 0, got {self.std!r}")

    def sample(self, rng, size) -> np.ndarray:
        x = _fast_std_normal(_rng(rng), size)
        if self.std != 1.0:
            x *= self.std
        if self.mean != 0.0:
            x += self.mean
        return x

    def to_scipy(self):
        from scipy import stats

        return stats.norm(loc=self.mean, scale=self.std)


@dataclass(frozen=True)
class Uniform(Distribution):
    """Rectangular distribution on [low, high] (JCGM 101 §6.4.2); std = (high - low) / sqrt(12)."""

    low: float = -1.0
    high: float = 1.0

    def __post_init__(self):
        object.__setattr__(self, "low", _finite("low", self.low))
        object.__setattr__(self, "high", _finite("high", self.high))
        if not self.high > self.low:
            raise MultilatError(f"high must be > low, got low={self.low!r}, high={self.high!r}")

    @classmethod
    def from_halfwidth(cls, half_width: float, centre: float = 0.0) -> "Uniform":
        """Uniform on [centre - half_width, centre + half_width]."""
        hw = _finite("half_width", half_width)
        if hw <= 0:
            raise MultilatError(f"half_width must be > 0, got {half_width!r}")
        return cls(centre - hw, centre + hw)

    @classmethod
    def from_std(cls, std: float, centre: float = 0.0) -> "Uniform":
        """Uniform with standard deviation ``std`` (half-width ``sqrt(3) std``)."""
        return cls.from_halfwidth(math.sqrt(3.0) * _finite("std", std), centre)

    @property
    def mean(self) -> float:
        return 0.5 * (self.low + self.high)

    @property
    def std(self) -> float:
        return (self.high - self.low) / math.sqrt(12.0)

    def sample(self, rng, size) -> np.ndarray:
        x = _rng(rng).random(size)  # low + (high - low) U, in place: faster than Generator.uniform
        x *= self.high - self.low
        x += self.low
        return x

    def to_scipy(self):
        from scipy import stats

        return stats.uniform(loc=self.low, scale=self.high - self.low)


@dataclass(frozen=True)
class Arcsine(Distribution):
    """Arcsine (U-shaped) distribution on [low, high] (JCGM 101 §6.4.6).

    The law of ``c + w sin(phi)`` with ``phi`` uniform: a cyclic error of amplitude ``w`` at an
    unknown phase. Expectation ``c = (low + high) / 2``, std ``w / sqrt(2)``.
    """

    low: float = -1.0
    high: float = 1.0

    def __post_init__(self):
        object.__setattr__(self, "low", _finite("low", self.low))
        object.__setattr__(self, "high", _finite("high", self.high))
        if not self.high > self.low:
            raise MultilatError(f"high must be > low, got low={self.low!r}, high={self.high!r}")

    @classmethod
    def from_amplitude(cls, amplitude: float, centre: float = 0.0) -> "Arcsine":
        """Arcsine law of ``centre + amplitude * sin(phi)``."""
        a = _finite("amplitude", amplitude)
        if a <= 0:
            raise MultilatError(f"amplitude must be > 0, got {amplitude!r}")
        return cls(centre - a, centre + a)

    @property
    def mean(self) -> float:
        return 0.5 * (self.low + self.high)

    @property
    def std(self) -> float:
        return 0.5 * (self.high - self.low) / math.sqrt(2.0)

    def sample(self, rng, size) -> np.ndarray:
        # sin(phi), phi ~ U(-pi, pi), computed as 2t / (1 + t^2) with t = tan(phi / 2): numpy's
        # float64 tan is SIMD-vectorised, its sin is not (about twice as fast overall, same law).
        t = _rng(rng).random(size)
        t -= 0.5
        t *= math.pi
        np.tan(t, out=t)
        d = t * t
        d += 1.0
        t *= self.high - self.low  # 2 * half-width
        t /= d
        t += self.mean
        return t

    def to_scipy(self):
        from scipy import stats

        return stats.arcsine(loc=self.low, scale=self.high - self.low)


@dataclass(frozen=True)
class Triangular(Distribution):
    """Triangular distribution on [low, high] with its peak at ``mode`` (JCGM 101 §6.4.5 is the
    symmetric case). Mean ``(low + mode + high) / 3``; variance
    ``(low² + mode² + high² - low·mode - low·high - mode·high) / 18``."""

    low: float = -1.0
    mode: float = 0.0
    high: float = 1.0

    def __post_init__(self):
        for n in ("low", "mode", "high"):
            object.__setattr__(self, n, _finite(n, getattr(self, n)))
        if not self.high > self.low:
            raise MultilatError(f"high must be > low, got low={self.low!r}, high={self.high!r}")
        if not self.low <= self.mode <= self.high:
            raise MultilatError(f"mode must lie in [low, high], got mode={self.mode!r}")

    @classmethod
    def symmetric(cls, half_width: float, centre: float = 0.0) -> "Triangular":
        """Isosceles triangle on [centre - half_width, centre + half_width]."""
        hw = _finite("half_width", half_width)
        if hw <= 0:
            raise MultilatError(f"half_width must be > 0, got {half_width!r}")
        return cls(centre - hw, centre, centre + hw)

    @property
    def mean(self) -> float:
        return (self.low + self.mode + self.high) / 3.0

    @property
    def std(self) -> float:
        a, c, b = self.low, self.mode, self.high
        # shift-invariant form, numerically safe for a far-off-zero support
        a0, c0, b0 = 0.0, c - a, b - a
        return math.sqrt((a0 * a0 + c0 * c0 + b0 * b0 - a0 * c0 - a0 * b0 - c0 * b0) / 18.0)

    def sample(self, rng, size) -> np.ndarray:
        return _rng(rng).triangular(self.low, self.mode, self.high, size)

    def to_scipy(self):
        from scipy import stats

        w = self.high - self.low
        return stats.triang(c=(self.mode - self.low) / w, loc=self.low, scale=w)


@dataclass(frozen=True)
class Trapezoidal(Distribution):
    """Symmetric trapezoidal distribution (JCGM 101 §6.4.4).

    Support [low, high]; ``beta`` in [0, 1] is the ratio of the top width to the base width
    (``beta = 0``: triangular, ``beta = 1``: rectangular). Variance ``(high - low)² (1 + beta²) / 24``.
    Sampled as ``low + (high - low)/2 [(1 + beta) r1 + (1 - beta) r2]`` with r1, r2 ~ U(0, 1).
    """

    low: float = -1.0
    high: float = 1.0
    beta: float = 0.5

    def __post_init__(self):
        for n in ("low", "high", "beta"):
            object.__setattr__(self, n, _finite(n, getattr(self, n)))
        if not self.high > self.low:
            raise MultilatError(f"high must be > low, got low={self.low!r}, high={self.high!r}")
        if not 0.0 <= self.beta <= 1.0:
            raise MultilatError(f"beta must lie in [0, 1], got {self.beta!r}")

    @property
    def mean(self) -> float:
        return 0.5 * (self.low + self.high)

    @property
    def std(self) -> float:
        return (self.high - self.low) * math.sqrt((1.0 + self.beta**2) / 24.0)

    def sample(self, rng, size) -> np.ndarray:
        g = _rng(rng)
        half = 0.5 * (self.high - self.low)
        x = g.random(size)
        x *= half * (1.0 + self.beta)
        r2 = g.random(size)
        r2 *= half * (1.0 - self.beta)
        x += r2
        x += self.low
        return x

    def to_scipy(self):
        from scipy import stats

        return stats.trapezoid(
            c=(1.0 - self.beta) / 2.0, d=(1.0 + self.beta) / 2.0, loc=self.low, scale=self.high - self.low
        )


@dataclass(frozen=True)
class CurvilinearTrapezoidal(Distribution):
    """Rectangular distribution with inexactly known limits (JCGM 101 §6.4.3).

    The nominal limits ``low``, ``high`` are each known only to within ``±d`` (the midpoint is fixed):
    the half-width is ``w - delta`` with ``delta ~ U(-d, d)``, ``w = (high - low) / 2``, ``0 <= d <= w``.
    Expectation ``(low + high) / 2``, variance ``(high - low)² / 12 + d² / 9``. Sampled as in JCGM 101
    §6.4.3.4: ``a_s = (low - d) + 2 d r1``, ``b_s = (low + high) - a_s``, ``x = a_s + (b_s - a_s) r2``.
    scipy has no equivalent; :meth:`pdf` gives the closed-form density of §6.4.3.2.
    """

    low: float = -1.0
    high: float = 1.0
    d: float = 0.1

    def __post_init__(self):
        for n in ("low", "high", "d"):
            object.__setattr__(self, n, _finite(n, getattr(self, n)))
        if not self.high > self.low:
            raise MultilatError(f"high must be > low, got low={self.low!r}, high={self.high!r}")
        if not 0.0 <= self.d <= 0.5 * (self.high - self.low):
            raise MultilatError(f"d must lie in [0, (high - low)/2], got {self.d!r}")

    @property
    def mean(self) -> float:
        return 0.5 * (self.low + self.high)

    @property
    def std(self) -> float:
        return math.sqrt((self.high - self.low) ** 2 / 12.0 + self.d**2 / 9.0)

    def pdf(self, x) -> np.ndarray:
        """Closed-form density (JCGM 101 eq. 3): ``ln((w+d)/(w-d)) / (4d)`` on the flat top,
        ``ln((w+d)/|x - c|) / (4d)`` on the curved flanks, 0 outside ``[c - w - d, c + w + d]``."""
        x = np.asarray(x, dtype=float)
        c, w, d = self.mean, 0.5 * (self.high - self.low), self.d
        if d == 0.0:
            return np.where(np.abs(x - c) <= w, 0.5 / w, 0.0)
        t = np.abs(x - c)
        out = np.zeros_like(t)
        flat = t <= w - d
        flank = (t > w - d) & (t <= w + d)
        if w > d:
            out[flat] = np.log((w + d) / (w - d)) / (4 * d)
        with np.errstate(divide="ignore"):
            out[flank] = np.log((w + d) / t[flank]) / (4 * d)
        return out

    def sample(self, rng, size) -> np.ndarray:
        g = _rng(rng)
        a_s = g.random(size)
        a_s *= 2.0 * self.d
        a_s += self.low - self.d
        x = g.random(size)
        x *= (self.low + self.high) - 2.0 * a_s  # b_s - a_s
        x += a_s
        return x


@dataclass(frozen=True)
class StudentT(Distribution):
    """Scaled and shifted Student t: ``loc + scale * T_df`` (JCGM 101 §6.4.9).

    For ``n`` repeated indications with mean ``xbar`` and standard deviation ``s``:
    ``StudentT(df=n - 1, loc=xbar, scale=s / sqrt(n))``. Mean ``loc`` (``nan`` if ``df <= 1``);
    std ``scale * sqrt(df / (df - 2))`` (``inf`` if ``df <= 2``).
    """

    df: float = 3.0
    loc: float = 0.0
    scale: float = 1.0

    def __post_init__(self):
        for n in ("df", "loc", "scale"):
            object.__setattr__(self, n, _finite(n, getattr(self, n)))
        if self.df <= 0:
            raise MultilatError(f"df must be > 0, got {self.df!r}")
        if self.scale < 0:
            raise MultilatError(f"scale must be >= 0, got {self.scale!r}")

    @property
    def mean(self) -> float:
        return self.loc if self.df > 1 else math.nan

    @property
    def std(self) -> float:
        return self.scale * math.sqrt(self.df / (self.df - 2.0)) if self.df > 2 else math.inf

    @property
    def centre(self) -> float:
        return self.loc

    def sample(self, rng, size) -> np.ndarray:
        x = _rng(rng).standard_t(self.df, size)
        x *= self.scale
        x += self.loc
        return x

    def to_scipy(self):
        from scipy import stats

        return stats.t(df=self.df, loc=self.loc, scale=self.scale)


@dataclass(frozen=True)
class Cauchy(Distribution):
    """Cauchy (Lorentz) distribution, location ``loc``, half width at half maximum ``scale``.

    No expectation and no variance: ``mean`` is ``nan``, ``std`` is ``inf``; ``centre`` is ``loc``.
    """

    loc: float = 0.0
    scale: float = 1.0

    def __post_init__(self):
        object.__setattr__(self, "loc", _finite("loc", self.loc))
        object.__setattr__(self, "scale", _finite("scale", self.scale))
        if self.scale <= 0:
            raise MultilatError(f"scale must be > 0, got {self.scale!r}")

    @property
    def mean(self) -> float:
        return math.nan

    @property
    def std(self) -> float:
        return math.inf

    @property
    def centre(self) -> float:
        return self.loc

    def sample(self, rng, size) -> np.ndarray:
        x = _rng(rng).standard_cauchy(size)
        x *= self.scale
        x += self.loc
        return x

    def to_scipy(self):
        from scipy import stats

        return stats.cauchy(loc=self.loc, scale=self.scale)


@dataclass(frozen=True)
class Constant(Distribution):
    """A quantity known exactly (std 0); ``sample`` returns ``value`` repeated."""

    value: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "value", _finite("value", self.value))

    @property
    def mean(self) -> float:
        return self.value

    @property
    def std(self) -> float:
        return 0.0

    def sample(self, rng, size) -> np.ndarray:
        return np.full(size, self.value, dtype=float)


@dataclass(frozen=True, eq=False)
class MultivariateNormal(Distribution):
    """Correlated Gaussian vector N(mean, cov) (JCGM 101 §6.4.8); ``sample`` returns ``(n, d)``.

    Parameters
    ----------
    mean : array_like, shape (d,)
    cov : array_like, shape (d, d)
        Symmetric positive semi-definite covariance matrix (checked; a tiny negative eigenvalue
        from rounding, above ``-1e-12 * max eigenvalue``, is accepted).

    ``mean`` and ``std`` are arrays of shape (d,). In :func:`multilat.montecarlo.run_mc` the model
    receives the ``(n, d)`` draws under this input's name.
    """

    mean: np.ndarray = None  # type: ignore[assignment]
    cov: np.ndarray = None  # type: ignore[assignment]

    def __post_init__(self):
        try:
            m = np.array(self.mean, dtype=float).reshape(-1)
            c = np.array(self.cov, dtype=float)
        except (TypeError, ValueError):
            raise MultilatError("mean and cov must be numeric arrays") from None
        d = m.size
        if d == 0 or c.shape != (d, d):
            raise MultilatError(f"cov must have shape ({d}, {d}) for a mean of length {d}, got {c.shape}")
        if not (np.all(np.isfinite(m)) and np.all(np.isfinite(c))):
            raise MultilatError("mean and cov must be finite")
        if not np.allclose(c, c.T, rtol=1e-12, atol=0.0):
            raise MultilatError("cov must be symmetric")
        w, v = np.linalg.eigh(c)
        if w.min() < -1e-12 * max(w.max(), 0.0):
            raise MultilatError(f"cov must be positive semi-definite (smallest eigenvalue {w.min():.3g})")
        # factor L with L L^T = cov that also works for singular covariances
        factor = v * np.sqrt(np.clip(w, 0.0, None))
        m.setflags(write=False)
        c.setflags(write=False)
        factor.setflags(write=False)
        object.__setattr__(self, "mean", m)
        object.__setattr__(self, "cov", c)
        object.__setattr__(self, "_factor", factor)

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))

    @property
    def centre(self) -> np.ndarray:
        return self.mean

    def sample(self, rng, size) -> np.ndarray:
        n = int(size) if np.ndim(size) == 0 else int(np.prod(size))
        z = _fast_std_normal(_rng(rng), (n, self.mean.size))
        x = z @ self._factor.T
        x += self.mean
        return x if np.ndim(size) == 0 else x.reshape(tuple(size) + (self.mean.size,))

    def to_scipy(self):
        from scipy import stats

        return stats.multivariate_normal(mean=self.mean, cov=self.cov, allow_singular=True)
