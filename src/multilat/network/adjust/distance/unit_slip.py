"""The unit slip: distances or their a-priori σ written in another unit than the column says.

A network whose distances are all in mm while ``sigma_m`` stays in metres is a valid network 1000
times larger, measured 1000 times less precisely than stated: it adjusts, but every residual is
~1000 σ. σ written in µm into ``sigma_m`` (4.06 for 4.06e-6) makes every residual ~10^-6 σ: σ0 =
0.000, a global test that passes (it looks upwards only) and ellipsoids 10^6 times too large. Neither
is a result; :func:`check_unit_slip` stops the adjustment with one line naming the column and the
likely unit, before the statistics are built (issue 25, cases 1 and 2).

Rule (with the a-priori variance factor known; ``--variance-factor unknown`` estimates σ0 and is
the way to accept σ that are right only up to a common factor)
---------------------------------------------------------------------------------------------------
With ``σ0 = sqrt(vᵀPv / dof)`` of the best solution (after the minimum search):

* **too large**: ``σ0 >= SLIP_FACTOR`` (100) and the χ² upper-tail probability of ``vᵀPv`` is below
  ``P_MIN`` (10^-9, the minimum search's threshold), and the misfit is spread over the network like
  scaled noise: the robust scale of the normalised residuals ``s_r = 1.4826 median |w_k|`` (over the
  observations with redundancy ``r_k >= R_MIN``) is also ``>= SLIP_FACTOR`` and ``s_r / σ0 >=
  SPREAD_MIN`` (0.7). Scaled noise has ``s_r / σ0`` near 1 (measured 0.91-1.67 on distances in mm,
  4-8 stations); gross errors smear into the other residuals but leave it lower (0.38-0.61 for 1 to 16
  blunders of 5-30 mm at σ 5 µm, σ0 97-620): they are data snooping's work, and a wrong minimum
  (issue 10: σ0 4.6-7.9) is far below the factor. The check runs on the best solution after the
  minimum search and before data snooping (and before the search when the initial values' restarts
  found the same minimum twice: :mod:`multilat.network.adjust.approximate.initial`).
* **too small**: ``σ0 <= 1 / SLIP_FACTOR`` and the χ² *lower*-tail probability is below ``P_MIN``
  (with dof = 4, σ0 = 0.01 has probability 2e-8: not enough; σ0 = 0.001, 2e-12, is). No gross
  error makes residuals smaller: σ too large is the only cause left. Except noise-free data
  (simulations): residuals at the numerical floor, RMS below ``NOISE_FREE_REL`` (1e-10) times the
  median distance (no instrument measures to 1e-10 of the distance; float64 rounding leaves ~1e-15)
  are not judged.

The factor ``σ0`` (or ``1/σ0``) is named with the nearest unit within half a decade: 10^2 cm, 10^3
mm, 10^6 µm, 10^9 nm; otherwise the factor alone.
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust.distance.fit_state import Fit

__all__ = ["SLIP_FACTOR", "R_MIN", "SPREAD_MIN", "NOISE_FREE_REL", "UnitSlipError", "noise_free", "check_unit_slip", "likely_unit", "slip_message"]

#: σ0 at or beyond this factor from 1 (either way) is a unit slip, not a statistic (see the rule above)
SLIP_FACTOR = 100.0
#: observations with a redundancy number below this are left out of the robust scale (their w is noise)
R_MIN = 0.01
#: least ratio of the robust scale to σ0 for "spread like scaled noise" (gross errors: <= 0.61 measured)
SPREAD_MIN = 0.7
#: RMS residual below this fraction of the median distance: noise-free (simulated) data, not judged
NOISE_FREE_REL = 1e-10

_UNITS = ((1e2, "cm"), (1e3, "mm"), (1e6, "µm"), (1e9, "nm"))


def noise_free(obs, residuals_m) -> bool:
    """Residuals at the numerical floor: RMS below :data:`NOISE_FREE_REL` times the median distance
    (simulated, error-free data). Neither the unit-slip stop nor the σ0 plausibility check
    (:func:`multilat.network.adjust.statistics.sigma0_check`) judges such a fit."""
    v = np.asarray(residuals_m, float)
    return bool(v.size) and float(np.sqrt(np.mean(v ** 2))) < NOISE_FREE_REL * float(np.median(obs.distance_m))


def _times(k: float) -> str:
    """A factor for the message: 1200, 8.3e+05."""
    return f"{k:.0f}" if k < 1e4 else f"{k:.2g}"


class UnitSlipError(MultilatError):
    """A unit slip: ``source`` is the input at fault, ``"observations"`` or ``"points"`` (the CLI
    puts that file's name in front of the message)."""

    def __init__(self, message: str, *, source: str = "observations"):
        super().__init__(message)
        self.source = source


def likely_unit(factor: float) -> tuple[float, str] | None:
    """``(10^k, unit)`` of the unit whose factor to metres is within half a decade of ``factor``
    (1e2 cm, 1e3 mm, 1e6 µm, 1e9 nm), or None."""
    if not (np.isfinite(factor) and factor > 0):
        return None
    lf = np.log10(factor)
    f, name = min(_UNITS, key=lambda u: abs(np.log10(u[0]) - lf))
    return (f, name) if abs(np.log10(f) - lf) <= 0.5 else None


def _sigma_name(sigma_source: dict | None) -> tuple[str, str]:
    """(what the σ are called, the unit they are read in) from the σ record of the adjustment."""
    src = sigma_source or {}
    kind = src.get("kind")
    if kind == "--sigma-um":
        return "--sigma-um", "µm"
    if kind in ("distance model", "raw readings"):
        return f"the distance model of instrument {src.get('instrument', '?')!r}", "metres"
    if kind == "file column" or not src:
        return "sigma_m", "metres"
    return str(kind), "metres"


def slip_message(sigma0: float, dof: int, sigma_m: float, sigma_source: dict | None = None) -> str:
    """The one line for a unit slip with ``σ0`` on ``dof`` (``sigma_m``: the median a-priori σ)."""
    sig, sig_unit = _sigma_name(sigma_source)
    accept = "give --variance-factor unknown if these σ are right up to a common factor"
    if sigma0 >= 1.0:
        unit = likely_unit(sigma0)
        k = _times(unit[0] if unit else sigma0)
        guess = (f"distance_m in {unit[1]} while {sig} is in {sig_unit} (or {sig} {k}x too small)?"
                 if unit else f"distances {k}x too large, or {sig} {k}x too small?")
        return (f"the residuals are ~{_times(sigma0)}x sigma (sigma0 {sigma0:.3g} on {dof} dof, spread over "
                f"the network, not a gross error): {guess} {accept}")
    inv = 1.0 / sigma0
    unit = likely_unit(inv)
    if unit and sig == "sigma_m":
        guess = f"sigma_m written in {unit[1]} ({sigma_m:.3g} where {sigma_m / unit[0]:.3g} m is meant)?"
    elif unit:
        guess = f"{sig} {_times(unit[0])}x too large (a value in {unit[1]} where {sig_unit} are read)?"
    else:
        guess = f"{sig} ~{_times(inv)}x too large?"
    return (f"the residuals are ~{_times(inv)}x smaller than sigma (sigma0 {sigma0:.3g} on {dof} dof): "
            f"{guess} {accept}")


def check_unit_slip(obs, core: Fit, sigma_source: dict | None = None) -> None:
    """Raise :class:`UnitSlipError` when the adjustment ``core`` (``vtpv``, ``dof``, ``residual_w``,
    ``redundancy``; a partial one is not judged) shows a unit slip by the module's rule."""
    from scipy.special import chdtr, chdtrc

    from multilat.network.adjust.approximate.search import P_MIN

    if core.partial or core.redundancy is None:
        return
    dof, vtpv = int(core.dof), float(core.vtpv)
    if dof < 1 or not np.isfinite(vtpv):
        return
    s0 = float(np.sqrt(vtpv / dof))
    if s0 >= SLIP_FACTOR:
        if not chdtrc(dof, vtpv) < P_MIN:
            return
        red = np.asarray(core.redundancy, float)
        v = np.asarray(core.residual_w, float)[: red.size]
        ok = red >= R_MIN
        if not ok.any():
            return
        robust = 1.4826 * float(np.median(np.abs(v[ok]) / np.sqrt(red[ok])))
        if robust < SLIP_FACTOR or robust < SPREAD_MIN * s0:
            return
    elif s0 <= 1.0 / SLIP_FACTOR:
        if not chdtr(dof, vtpv) < P_MIN:
            return
        n = obs.n_obs
        if noise_free(obs, np.asarray(core.residual_w, float)[:n] * np.asarray(obs.sigma_m, float)[:n]):
            return
    else:
        return
    raise UnitSlipError(slip_message(s0, dof, float(np.median(obs.sigma_m)), sigma_source))
