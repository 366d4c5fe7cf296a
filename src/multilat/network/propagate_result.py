"""The result of :func:`multilat.network.propagate.propagate`: Monte Carlo distributions of the
adjusted parameters beside the linear covariance, with its JSON and summary forms."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from multilat.network.statistics import CHI2_3_95

if TYPE_CHECKING:
    from multilat.network.propagate import Problem

__all__ = ["PropagationResult", "chi2_3_95"]

#: chi-square quantile with 3 degrees of freedom at 0.95 (JCGM 102 ellipsoid scale): statistics.CHI2_3_95
chi2_3_95 = CHI2_3_95


@dataclass(frozen=True)
class PropagationResult:
    """Result of :func:`propagate`. Deviations are relative to the nominal values; metres.

    Attributes
    ----------
    problem : Problem
    labels : tuple of str
        Parameter labels in the :func:`batched.flatten` layout (``"A.x"``, ``"A.offset"``, ``"T1.z"``),
        then the interpoint distances ``"T1-T2"``.
    nominal : ndarray (k,)
        Nominal values of those quantities.
    mc_mean, mc_std : ndarray (k,)
        Monte Carlo estimate and standard uncertainty.
    mc_std_se : ndarray (k,)
        Monte Carlo standard error of ``mc_std``: ``mc_std * sqrt((kurtosis - 1) / (4 n))``
        (``sqrt(1 / (2(n-1)))`` relative for a gaussian output).
    lin_std : ndarray (k,)
        First-order standard uncertainty from the adjustment's covariance (sandwich with the actual
        standard deviation of the input errors).
    interval_symmetric, interval_shortest : ndarray (k, 2)
        95 % (``coverage``) coverage intervals.
    point_ids : tuple of str
    point_cov_mc, point_cov_lin : ndarray (P, 3, 3)
        Monte Carlo and linear covariances of each point (datum-dependent).
    ellipsoid_coverage_mc : ndarray (P,)
        Fraction of trials inside the 95 % ellipsoid built from the MC covariance (JCGM 102); for a
        point with datum-fixed coordinates, the ellipsoid in the free coordinates (chi2 with their
        number of degrees of freedom); NaN for a fixed point.
    ellipsoid_coverage_lin : ndarray (P,)
        Fraction of trials inside the 95 % ellipsoid of the linear covariance.
    trials : int
        Trials kept (converged).
    n_failed : int
        Trials dropped because the solver did not converge.
    sigma0_mean : float
        Mean a-posteriori sigma0 over the trials.
    sigma0_rms : float
        Root mean square of the trials' sigma0. The trials' distances are the nominal ones plus the
        drawn errors, and the residuals are linear in the distances, so each trial's residuals are
        the nominal residuals plus those of the errors: ``E[sigma0^2] = sigma0_nominal^2 + s_e^2``
        with ``s_e^2`` the errors' own contribution (1 for gaussian errors with the weights' sigma).
        For measured observations the trials' sigma0 is therefore larger than the nominal one.
    noise : str
    seed_entropy : int
    adaptive : dict or None
        Adaptive runs: ``{"converged": bool, "batches": int, "batch_trials": int, "tolerance_m_min": float,
        "n_fixed_by_datum": int}`` (:class:`multilat.montecarlo.AdaptiveRule`).
    elapsed_s : float
    input_std_m : ndarray (m,)
        Standard deviation of each distance's input error used by the linear propagation: the
        gaussian ``sigma_m``, or for ``noise="model"`` the empirical std of all errors drawn.
    input_std_ratio : float
        Mean of (empirical input std / the distance model's :func:`budget.distance_std_m`) — how well
        the distance model's stated standard uncertainty matches its own samples (1 for gaussian).
    n_retried : int
        Trials the frozen-matrix iteration did not converge and full Gauss-Newton re-solved.
    samples : ndarray (trials, k) float32 or None
        Deviations from nominal (kept for figures).
    """

    problem: Problem
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
    ellipsoid_coverage_mc: np.ndarray
    ellipsoid_coverage_lin: np.ndarray
    trials: int
    n_failed: int
    sigma0_mean: float
    noise: str
    seed_entropy: int
    adaptive: dict | None
    elapsed_s: float
    input_std_m: np.ndarray = field(default=None, repr=False)
    input_std_ratio: float = 1.0
    n_retried: int = 0
    samples: np.ndarray | None = field(default=None, repr=False)
    sigma0_rms: float = float("nan")

    @property
    def sigma0_nominal(self) -> float:
        """sigma0 of the nominal solution (``problem.sigma0_nominal``)."""
        return float(self.problem.sigma0_nominal)

    @property
    def sigma0_noise_only(self) -> float:
        """``sqrt(sigma0_rms^2 - sigma0_nominal^2)``: the drawn errors' own contribution to sigma0
        (about 1 for gaussian errors drawn with the weights' sigma; NaN if negative)."""
        v = self.sigma0_rms**2 - self.sigma0_nominal**2
        return float(np.sqrt(v)) if v >= 0 else float("nan")

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
        """Validation rows: dicts with label, nominal, mean/std/intervals (MC), lin std, ratio, agrees."""
        out = []
        for k, lab in enumerate(self.labels):
            if kind == "distance" and "-" not in lab or kind == "parameter" and "-" in lab:
                continue
            out.append({
                "label": lab,
                "nominal_m": float(self.nominal[k]),
                "mean_mc_m": float(self.mc_mean[k]),
                "std_mc_m": float(self.mc_std[k]),
                "std_mc_se_m": float(self.mc_std_se[k]),
                "std_lin_m": float(self.lin_std[k]),
                "ratio": None if self.fixed[k] else float(self.std_ratio[k]),
                "agrees": bool(self.agrees[k]),
                "interval_symmetric_m": [float(v) for v in self.interval_symmetric[k]],
                "interval_shortest_m": [float(v) for v in self.interval_shortest[k]],
            })
        return out

    def to_dict(self) -> dict:
        """Plain-JSON summary (no samples)."""
        n_par = self.problem.network.n_params
        dist_rows = []
        for k, (a, b) in enumerate(self.problem.pairs):
            r = self.rows()[n_par + k]
            ref = self.problem.reference_m[k]
            r.update(a=a, b=b, reference_m=None if np.isnan(ref) else float(ref))
            dist_rows.append(r)
        pts = []
        for q, pid in enumerate(self.point_ids):
            pts.append({"id": pid, "cov_mc_m2": self.point_cov_mc[q].tolist(),
                        "cov_lin_m2": self.point_cov_lin[q].tolist(),
                        "semi_axes_95_m": _semi_axes(self.point_cov_mc[q]).tolist(),
                        "ellipsoid_coverage_mc": float(self.ellipsoid_coverage_mc[q]),
                        "ellipsoid_coverage_lin": float(self.ellipsoid_coverage_lin[q])})
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
            "parameters": self.rows()[:n_par],
            "distances": dist_rows,
            "points": pts,
            "summary": self.summary(),
        }

    def summary(self) -> dict:
        """Headline numbers: worst std ratio, how many quantities agree with the linear covariance."""
        r = self.std_ratio[~self.fixed]
        cm = self.ellipsoid_coverage_mc[np.isfinite(self.ellipsoid_coverage_mc)]
        cl = self.ellipsoid_coverage_lin[np.isfinite(self.ellipsoid_coverage_lin)]
        return {"n_quantities": len(self.labels), "n_fixed_by_datum": int(self.fixed.sum()),
                "n_agree": int(self.agrees.sum()),
                "ratio_min": float(r.min()) if r.size else None,
                "ratio_max": float(r.max()) if r.size else None,
                "ellipsoid_coverage_mc_min": float(cm.min()) if cm.size else None,
                "ellipsoid_coverage_mc_max": float(cm.max()) if cm.size else None,
                "ellipsoid_coverage_lin_min": float(cl.min()) if cl.size else None,
                "ellipsoid_coverage_lin_max": float(cl.max()) if cl.size else None}


def _semi_axes(cov):
    """95 % ellipsoid semi-axes (sqrt(chi2_3 * eigenvalues)), descending, metres."""
    ev = np.clip(np.linalg.eigvalsh(cov), 0, None)[::-1]
    return np.sqrt(chi2_3_95 * ev)
