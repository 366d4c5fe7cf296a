"""First-order GUM propagation with numerical sensitivities (JCGM 100 §5.1) and its validation against a
Monte Carlo result (JCGM 101 §8).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from multilat.errors import MultilatError
from multilat.montecarlo.adaptive import numerical_tolerance
from multilat.montecarlo.checks import _check_coverage, _check_int, _validate_inputs
from multilat.montecarlo.result import MCResult


@dataclass(frozen=True, eq=False)
class GUMResult:
    """First-order (GUM, JCGM 100 §5.1) propagation.

    Attributes
    ----------
    estimate : float or ndarray (k,)
        Model at the input expectations.
    std : float or ndarray (k,)
        Combined standard uncertainty ``sqrt(sum (c_i u_i)^2)`` (independent inputs).
    sensitivities : dict name -> float or ndarray (k,)
        Partial derivatives c_i (central differences with step ``1e-3 u_i``).
    contributions : dict name -> float or ndarray (k,)
        ``|c_i| u_i``, in the output unit.
    coverage : float
    coverage_factor : float
        ``k_p`` of a normal distribution for ``coverage`` (e.g. 1.96 for 95 %).
    interval : ndarray (2,) or (k, 2)
        ``estimate -/+ k_p std``.
    cov : ndarray (k, k) or None
        ``J diag(u^2) J^T`` for vector outputs.
    """

    estimate: Any
    std: Any
    sensitivities: dict
    contributions: dict
    coverage: float
    coverage_factor: float
    interval: np.ndarray
    cov: np.ndarray | None = None


def gum_linear(model, inputs: Mapping[str, Any], *, coverage: float = 0.95, rel_step: float = 1e-3) -> GUMResult:
    """Law of propagation of uncertainty to first order, with numerical sensitivities.

    Inputs need ``mean`` and ``std`` (finite); they are treated as independent. The model is
    evaluated once, vectorised, at the expectations and at ``x_i +/- rel_step * u_i``.
    """
    from scipy import stats

    inp = _validate_inputs(inputs)
    _check_coverage(coverage)
    names = [nm for nm, _ in inp]
    mu = np.empty(len(inp))
    u = np.empty(len(inp))
    for i, (nm, d) in enumerate(inp):
        m, s = getattr(d, "mean", None), getattr(d, "std", None)
        if m is not None and np.ndim(m) != 0:
            raise MultilatError(f"input {nm!r} is a vector: gum_linear supports scalar inputs only")
        if m is None or s is None or not (math.isfinite(m) and math.isfinite(s)):
            raise MultilatError(f"input {nm!r} has no finite mean and std: the GUM framework does not apply")
        mu[i], u[i] = m, s
    nin = len(inp)
    x = np.repeat(mu[None, :], 2 * nin + 1, axis=0)
    h = rel_step * u
    for i in range(nin):
        x[1 + 2 * i, i] += h[i]
        x[2 + 2 * i, i] -= h[i]
    y = np.asarray(model(**{nm: x[:, i].copy() for i, nm in enumerate(names)}), dtype=float)
    if y.ndim not in (1, 2) or y.shape[0] != 2 * nin + 1:
        raise MultilatError(f"model must return shape (n,) or (n, k), got {y.shape}")
    y2 = y.reshape(y.shape[0], -1)
    if not np.all(np.isfinite(y2)):
        raise MultilatError("model returned non-finite values near the input expectations")
    J = np.zeros((y2.shape[1], nin))
    for i in range(nin):
        if h[i] > 0:
            J[:, i] = (y2[1 + 2 * i] - y2[2 + 2 * i]) / (2 * h[i])
    est = y2[0]
    contrib = np.abs(J) * u[None, :]
    cov = (J * u**2) @ J.T
    std = np.sqrt(np.diag(cov))
    kp = float(stats.norm.ppf(0.5 * (1 + coverage)))
    interval = np.stack([est - kp * std, est + kp * std], axis=-1)
    if y.ndim == 1:
        return GUMResult(float(est[0]), float(std[0]), {nm: float(J[0, i]) for i, nm in enumerate(names)},
                         {nm: float(contrib[0, i]) for i, nm in enumerate(names)}, float(coverage), kp, interval[0])
    return GUMResult(est, std, {nm: J[:, i].copy() for i, nm in enumerate(names)},
                     {nm: contrib[:, i].copy() for i, nm in enumerate(names)}, float(coverage), kp, interval, cov)


@dataclass(frozen=True, eq=False)
class GUMValidation:
    """JCGM 101 §8.2: d_low, d_high against the numerical tolerance delta; ``valid`` if both <= delta."""

    d_low: Any
    d_high: Any
    tolerance: Any
    valid: bool


def validate_gum(mc: MCResult, gum: GUMResult, ndigits: int = 2, *, interval: str = "symmetric") -> GUMValidation:
    """Compare the GUM interval with the Monte Carlo one (JCGM 101 §8).

    ``d_low = |y - U_p - y_low|``, ``d_high = |y + U_p - y_high|`` with the GUM estimate y, the GUM
    expanded uncertainty U_p and the Monte Carlo interval (``interval``: "symmetric" or
    "shortest"); the GUM framework is validated when both are within the numerical tolerance delta
    of u(y) (``ndigits`` significant digits).
    """
    if interval not in ("symmetric", "shortest"):
        raise MultilatError(f"interval must be 'symmetric' or 'shortest', got {interval!r}")
    ndigits = _check_int("ndigits", ndigits, 1)
    iv = np.asarray(mc.interval_symmetric if interval == "symmetric" else mc.interval_shortest)
    giv = np.asarray(gum.interval)
    if iv.shape != giv.shape:
        raise MultilatError(f"Monte Carlo and GUM results have different shapes: {iv.shape} vs {giv.shape}")
    if abs(mc.coverage - gum.coverage) > 1e-12:
        raise MultilatError(f"coverage differs: MC {mc.coverage} vs GUM {gum.coverage}")
    d_low = np.abs(giv[..., 0] - iv[..., 0])
    d_high = np.abs(giv[..., 1] - iv[..., 1])
    tol = np.vectorize(lambda s: numerical_tolerance(s, ndigits))(np.asarray(gum.std, dtype=float))
    valid = bool(np.all(d_low <= tol) and np.all(d_high <= tol))
    if np.ndim(d_low) == 0:
        return GUMValidation(float(d_low), float(d_high), float(tol), valid)
    return GUMValidation(d_low, d_high, tol, valid)
