"""The result of a Monte Carlo propagation, one record for both paths (the distance path's
:func:`multilat.network.montecarlo.propagate.propagate` and the general layer's
:func:`multilat.network.montecarlo.general.propagate.propagate`): Monte Carlo distributions of the adjusted
parameters beside the linear covariance, with its JSON and summary forms."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from multilat.network.adjust.statistics import CHI2_3_95
from multilat.vocabulary import schema_id

if TYPE_CHECKING:
    from multilat.network.montecarlo.propagate import Problem

__all__ = ["GENERAL_SCHEMA", "PropagationResult", "chi2_3_95"]

#: JSON schema stamp of the general layer's document (:meth:`PropagationResult.to_dict`).
GENERAL_SCHEMA = schema_id("propagate-general")

#: chi-square quantile with 3 degrees of freedom at 0.95 (JCGM 102 ellipsoid scale): statistics.CHI2_3_95
chi2_3_95 = CHI2_3_95


@dataclass(frozen=True, eq=False, kw_only=True)
class PropagationResult:
    """Result of a Monte Carlo propagation, the distance path's (:func:`multilat.network.montecarlo.propagate.propagate`,
    ``problem`` set) or the general layer's (:func:`multilat.network.montecarlo.general.propagate.propagate`,
    ``problem`` None, ``units`` set). Deviations are relative to the nominal values; SI units.

    Attributes (both paths)
    -----------------------
    labels : tuple of str
        Parameter labels, then the interpoint distances ``"T1-T2"``: the distance path's
        :func:`batched.flatten` layout (``"A.x"``, ``"A.offset"``, ``"T1.z"``), the general layer's
        free parameters (``"x:P"``, ``"offset:I"``, ``"omega:U"``).
    nominal : ndarray (k,)
        Nominal values of those quantities (the general layer: the adjusted ones).
    mc_mean, mc_std : ndarray (k,)
        Monte Carlo estimate and standard uncertainty.
    mc_std_se : ndarray (k,)
        Monte Carlo standard error of ``mc_std``: ``mc_std * sqrt((kurtosis - 1) / (4 n))``
        (``sqrt(1 / (2(n-1)))`` relative for a gaussian output).
    lin_std : ndarray (k,)
        First-order standard uncertainty from the adjustment's covariance (the distance path: sandwich
        with the actual standard deviation of the input errors; the general layer: its ``Q``, σ0 a priori 1).
    interval_symmetric, interval_shortest : ndarray (k, 2)
        95 % coverage intervals (values, not deviations).
    point_ids : tuple of str
    point_cov_mc, point_cov_lin : ndarray (P, 3, 3)
        Monte Carlo and linear covariances of each point (datum-dependent; m²).
    trials : int
        Trials kept (converged).
    n_failed : int
        Trials dropped because the solver did not converge.
    n_retried : int
        Trials the frozen-matrix iteration did not converge (or, general layer, whose chord step did
        not contract) and full Gauss-Newton re-solved.
    sigma0_mean, sigma0_rms : float
        Mean and root mean square of the trials' a-posteriori sigma0.
    noise : str
        How the inputs were drawn (``gaussian``, ``model``).
    seed_entropy : int
    elapsed_s : float
    samples : ndarray (trials, k) float32 or None
        Deviations from nominal (kept for figures).

    Distance path (None on the general layer)
    -----------------------------------------
    problem : Problem
    ellipsoid_coverage_mc : ndarray (P,)
        Fraction of trials inside the 95 % ellipsoid built from the MC covariance (JCGM 102); for a
        point with datum-fixed coordinates, the ellipsoid in the free coordinates (chi2 with their
        number of degrees of freedom); NaN for a fixed point.
    ellipsoid_coverage_lin : ndarray (P,)
        Fraction of trials inside the 95 % ellipsoid of the linear covariance.
    adaptive : dict or None
        Adaptive runs: ``{"converged": bool, "batches": int, "batch_trials": int, "tolerance_m_min": float,
        "n_fixed_by_datum": int}`` (:class:`multilat.montecarlo.AdaptiveRule`).
    input_std_m : ndarray (m,)
        Standard deviation of each distance's input error used by the linear propagation: the
        gaussian ``sigma_m``, or for ``noise="model"`` the empirical std of all errors drawn.
    input_std_ratio : float
        Mean of (empirical input std / the distance model's :func:`budget.distance_std_m`) — how well
        the distance model's stated standard uncertainty matches its own samples (1 for gaussian).
    The trials' sigma0: their distances are the nominal ones plus the drawn errors, and the residuals
    are linear in the distances, so each trial's residuals are the nominal residuals plus those of the
    errors: ``E[sigma0^2] = sigma0_nominal^2 + s_e^2`` with ``s_e^2`` the errors' own contribution (1
    for gaussian errors with the weights' sigma). For measured observations the trials' sigma0 is
    therefore larger than the nominal one.

    General layer (None on the distance path)
    -----------------------------------------
    units : tuple of str
        ``"m"``, ``"rad"`` or ``"1"`` per label.
    n_params : int
        How many of the labels are parameters (the rest are distances).
    dof : int
        Degrees of freedom of the adjustment (of the trials' sigma0).
    chord_steps_mean : float
        Mean chord steps per trial.
    """

    labels: tuple
    nominal: np.ndarray
    mc_mean: np.ndarray
    mc_std: np.ndarray
    mc_std_se: np.ndarray
    lin_std: np.ndarray
    interval_symmetric: np.ndarray
    interval_shortest: np.ndarray
    point_ids: tuple
    point_cov_mc: np.ndarray
    point_cov_lin: np.ndarray
    trials: int
    n_failed: int
    sigma0_mean: float
    seed_entropy: int
    elapsed_s: float
    n_retried: int = 0
    sigma0_rms: float = float("nan")
    noise: str = "gaussian"
    samples: np.ndarray | None = field(default=None, repr=False)
    # the distance path
    problem: Problem | None = None
    ellipsoid_coverage_mc: np.ndarray | None = None
    ellipsoid_coverage_lin: np.ndarray | None = None
    adaptive: dict | None = None
    input_std_m: np.ndarray | None = field(default=None, repr=False)
    input_std_ratio: float = 1.0
    # the general layer
    units: tuple | None = None
    n_params: int | None = None
    dof: int | None = None
    chord_steps_mean: float | None = None

    @property
    def sigma0_nominal(self) -> float:
        """sigma0 of the nominal solution (``problem.sigma0_nominal``; NaN on the general layer, whose
        trials are drawn about the adjusted observations)."""
        return float(self.problem.sigma0_nominal) if self.problem is not None else float("nan")

    @property
    def sigma0_noise_only(self) -> float:
        """``sqrt(sigma0_rms^2 - sigma0_nominal^2)``: the drawn errors' own contribution to sigma0
        (about 1 for gaussian errors drawn with the weights' sigma; NaN if negative)."""
        v = self.sigma0_rms**2 - self.sigma0_nominal**2
        return float(np.sqrt(v)) if v >= 0 else float("nan")

    @property
    def n_parameters(self) -> int:
        """How many of :attr:`labels` are parameters (the rest are interpoint distances)."""
        return int(self.n_params if self.problem is None else self.problem.network.n_params)

    @property
    def fixed(self) -> np.ndarray:
        """Quantities held by the datum (linear std below 1e-9 of the largest): no ratio for them."""
        return self.lin_std <= 1e-9 * np.max(self.lin_std)

    @property
    def std_ratio(self) -> np.ndarray:
        """MC standard deviation over linear standard deviation (NaN for datum-fixed quantities)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.fixed, np.nan, self.mc_std / self.lin_std)

    @property
    def agrees(self) -> np.ndarray:
        """|mc_std - lin_std| within 3 MC standard errors (bool per quantity; True where both ~0)."""
        tiny = self.fixed & (self.mc_std <= 1e-9 * np.max(self.mc_std))
        return tiny | (np.abs(self.mc_std - self.lin_std) <= 3.0 * self.mc_std_se)

    def rows(self, kind: str | None = None):
        """Validation rows (``kind``: ``parameter``, ``distance`` or both): dicts with label, nominal,
        mean/std/intervals (MC), lin std, ratio, agrees. The distance path's keys carry their unit
        (``std_mc_m``: all its quantities are metres); the general layer's rows name it in ``unit``
        (``m``, ``rad`` or ``1``) and their keys carry none."""
        n_par = self.n_parameters
        sfx = "_m" if self.units is None else ""
        out = []
        for k, lab in enumerate(self.labels):
            if kind == "distance" and k < n_par or kind == "parameter" and k >= n_par:
                continue
            unit = {} if self.units is None else {"unit": self.units[k]}
            out.append({
                "label": lab, **unit,
                "nominal" + sfx: float(self.nominal[k]),
                "mean_mc" + sfx: float(self.mc_mean[k]),
                "std_mc" + sfx: float(self.mc_std[k]),
                "std_mc_se" + sfx: float(self.mc_std_se[k]),
                "std_lin" + sfx: float(self.lin_std[k]),
                "ratio": None if self.fixed[k] else float(self.std_ratio[k]),
                "agrees": bool(self.agrees[k]),
                "interval_symmetric" + sfx: [float(v) for v in self.interval_symmetric[k]],
                "interval_shortest" + sfx: [float(v) for v in self.interval_shortest[k]],
            })
        return out

    def to_dict(self) -> dict:
        """Plain-JSON summary (no samples): the distance path's ``propagate`` document, or the general
        layer's (``schema`` :data:`GENERAL_SCHEMA`, keys in ``docs/general-network.md``)."""
        if self.problem is None:
            return self._general_dict()
        n_par = self.n_parameters
        rows = self.rows()
        dist_rows = []
        for k, (a, b) in enumerate(self.problem.pairs):
            r = rows[n_par + k]
            ref = self.problem.reference_m[k]
            r.update(a=a, b=b, reference_m=None if np.isnan(ref) else float(ref))
            dist_rows.append(r)
        pts = {}                    # an id map (schema /2), as adjust's targets and the general path's points
        for q, pid in enumerate(self.point_ids):
            pts[pid] = {"cov_mc_m2": self.point_cov_mc[q].tolist(),
                        "cov_lin_m2": self.point_cov_lin[q].tolist(),
                        "semi_axes_95_m": _semi_axes(self.point_cov_mc[q]).tolist(),
                        "ellipsoid_coverage_mc": float(self.ellipsoid_coverage_mc[q]),
                        "ellipsoid_coverage_lin": float(self.ellipsoid_coverage_lin[q])}
        return {
            "source": self.problem.source,
            "trials": self.trials,
            "n_failed": self.n_failed,
            "n_retried": self.n_retried,
            "noise": self.noise,
            "solver": getattr(self.problem.network, "solver_name", "batched"),
            "seed": self.seed_entropy,
            "coverage": 0.95,
            "sigma0_mean": self.sigma0_mean,
            "sigma0_rms": self.sigma0_rms,
            "sigma0_nominal": self.sigma0_nominal,
            "sigma0_noise_only": self.sigma0_noise_only,
            "input_std_ratio": self.input_std_ratio,
            "elapsed_s": self.elapsed_s,
            "adaptive": self.adaptive,
            "parameters": rows[:n_par],
            "distances": dist_rows,
            "points": pts,
            "summary": self.summary(),
        }

    def _general_dict(self) -> dict:
        """The general layer's document: points as an id map, the chord steps and dof of its solver."""
        rows = self.rows()
        n_par = self.n_parameters
        return {"schema": GENERAL_SCHEMA, "model": "general", "trials": int(self.trials),
                "n_failed": int(self.n_failed), "n_retried": int(self.n_retried), "chord_steps_mean": float(self.chord_steps_mean),
                "noise": self.noise, "sigma0_mean": float(self.sigma0_mean), "sigma0_rms": float(self.sigma0_rms),
                "dof": int(self.dof), "seed": int(self.seed_entropy), "elapsed_s": float(self.elapsed_s),
                "parameters": rows[:n_par], "distances": rows[n_par:],
                "points": {p: {"cov_mc_m2": self.point_cov_mc[i].tolist(), "cov_lin_m2": self.point_cov_lin[i].tolist(),
                               "std_mc_m": np.sqrt(np.diag(self.point_cov_mc[i])).tolist(),
                               "std_lin_m": np.sqrt(np.diag(self.point_cov_lin[i])).tolist()}
                           for i, p in enumerate(self.point_ids)},
                "summary": self.summary()}

    def summary(self) -> dict:
        """Headline numbers: worst std ratio, how many quantities agree with the linear covariance
        (the distance path adds the datum-held count and the ellipsoid coverages)."""
        r = self.std_ratio[~self.fixed]
        out = {"n_quantities": len(self.labels), "n_agree": int(self.agrees.sum()),
               "ratio_min": float(r.min()) if r.size else None,
               "ratio_max": float(r.max()) if r.size else None}
        if self.problem is None:
            return out
        cm = self.ellipsoid_coverage_mc[np.isfinite(self.ellipsoid_coverage_mc)]
        cl = self.ellipsoid_coverage_lin[np.isfinite(self.ellipsoid_coverage_lin)]
        return {"n_quantities": out["n_quantities"], "n_fixed_by_datum": int(self.fixed.sum()), **out,
                "ellipsoid_coverage_mc_min": float(cm.min()) if cm.size else None,
                "ellipsoid_coverage_mc_max": float(cm.max()) if cm.size else None,
                "ellipsoid_coverage_lin_min": float(cl.min()) if cl.size else None,
                "ellipsoid_coverage_lin_max": float(cl.max()) if cl.size else None}


def _semi_axes(cov):
    """95 % ellipsoid semi-axes (sqrt(chi2_3 * eigenvalues)), descending, metres."""
    ev = np.clip(np.linalg.eigvalsh(cov), 0, None)[::-1]
    return np.sqrt(chi2_3_95 * ev)
