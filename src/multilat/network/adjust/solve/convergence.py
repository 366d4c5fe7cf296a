"""The convergence record every network solver returns, and the one stopping rule they share.

A step is measured in units of the observations' a-priori standard uncertainty. The distance path:
the largest change of a length parameter (station or target coordinate, offset; a scale times the
largest distance) divided by the smallest ``sigma_m``. The general layer, whose parameters are
lengths, angles and scales: the largest change of a modelled observation it predicts, in units of
that observation's sigma (``max |J_w dx|``, the whitened Jacobian times the step). Gauss-Newton contracts quickly near a small-residual minimum; once the
step is a tiny fraction of sigma it is rounding noise amplified by the condition number, and chasing
it further changes nothing. The rule:

* stop, converged, when the step falls below ``STEP_TOL_SIGMA`` (1e-9 sigma: for sigma = 5 µm that is
  5e-15 m, the float64 resolution of coordinates of a few metres), or
* when the step is already below ``FLOOR_SIGMA`` (1e-4 sigma) and no longer shrinks by at least a
  factor 2: the iterates have reached the rounding floor of the minimum (converged), or
* not converged: the iteration limit, or Levenberg-Marquardt damping that cannot decrease the cost.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Convergence", "STEP_TOL_SIGMA", "FLOOR_SIGMA"]

STEP_TOL_SIGMA = 1e-9
FLOOR_SIGMA = 1e-4


@dataclass(frozen=True)
class Convergence:
    """How a solver ended.

    Attributes
    ----------
    converged : bool
    iterations : int
        Gauss-Newton iterations (each with one normal-equation assembly).
    last_step_sigma : float
        Length of the last step in units of sigma (module docstring: the distance path's largest
        parameter change over the smallest a-priori sigma; the general layer's ``max |J_w dx|``).
    reason : str
        One phrase: ``"step below 1e-09 sigma"``, ``"rounding floor"``, ``"iteration limit"``,
        ``"no decrease of the cost"``.
    """

    converged: bool
    iterations: int
    last_step_sigma: float
    reason: str

    def to_json(self) -> dict:
        return {"converged": self.converged, "iterations": self.iterations,
                "last_step_sigma": self.last_step_sigma, "reason": self.reason}


def step_verdict(step_sigma: float, prev_step_sigma: float) -> str | None:
    """The stopping rule: a reason to stop as converged after a step of ``step_sigma`` (the previous
    one ``prev_step_sigma``), or None to go on."""
    if step_sigma < STEP_TOL_SIGMA:
        return f"step below {STEP_TOL_SIGMA:g} sigma"
    if step_sigma < FLOOR_SIGMA and step_sigma > 0.5 * prev_step_sigma:
        return "rounding floor"
    return None
