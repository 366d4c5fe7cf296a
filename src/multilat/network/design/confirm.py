"""Monte Carlo confirmation of a design: the layout handed to :func:`multilat.network.montecarlo.propagate.propagate`.

The design's pre-analysis is linear (first order, any distance-error distribution with the given
standard deviations). :func:`simulate_design` builds the propagate problem of the layout's exact
distances (:func:`~multilat.network.montecarlo.propagate.problem_from_truth`, same observations, weights and
datum), draws the distance errors (``gaussian`` with the design's sigmas, or ``model``: the
instrument's non-gaussian distance model of :mod:`multilat.budget`), re-adjusts every trial and
compares the Monte Carlo standard uncertainty of every target coordinate with the predicted one, in
units of its Monte Carlo standard error (``z``), and the largest 95 % semi-axes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust import statistics as st
from multilat.network.design.backends import u95_max_m

__all__ = ["DesignSimulation", "simulate_design"]


@dataclass(frozen=True, eq=False)
class DesignSimulation:
    """Result of :func:`simulate_design` (metres; target order of the layout).

    noise : str ; trials : int (kept) ; n_failed : int
    predicted_std_m, mc_std_m, mc_std_se_m, z : ndarray (t, 3)  per coordinate; ``z = (mc - pred) / se``
    predicted_u95_max_m, mc_u95_max_m : ndarray (t,)  largest 95 % semi-axis, predicted and from the MC
        covariance
    ellipsoid_coverage_pred : ndarray (t,)  fraction of trials inside the predicted 95 % ellipsoid
        (the linear one; 0.95 expected for gaussian errors)
    lin_std_m : ndarray (t, 3)  propagate's linear std with the empirical std of the errors drawn
        (for ``model`` noise it separates the distance model's own std mismatch from nonlinearity)
    input_std_ratio : float  empirical std of the drawn errors / the model's stated std (1: gaussian)
    result : PropagationResult  the whole propagate result
    """

    noise: str
    trials: int
    n_failed: int
    target_ids: tuple
    predicted_std_m: np.ndarray
    mc_std_m: np.ndarray
    mc_std_se_m: np.ndarray
    z: np.ndarray
    predicted_u95_max_m: np.ndarray
    mc_u95_max_m: np.ndarray
    ellipsoid_coverage_pred: np.ndarray
    lin_std_m: np.ndarray
    input_std_ratio: float
    result: object

    def summary(self) -> dict:
        return {"noise": self.noise, "trials": self.trials, "n_failed": self.n_failed,
                "z_abs_max": float(np.abs(self.z).max()), "z_mean": float(self.z.mean()),
                "ratio_mean": float((self.mc_std_m / self.predicted_std_m).mean()),
                "u95_max_lin_m": float(self.predicted_u95_max_m.max()),
                "u95_max_mc_m": float(self.mc_u95_max_m.max()),
                "ellipsoid_coverage_mean": float(np.mean(self.ellipsoid_coverage_pred)),
                "input_std_ratio": self.input_std_ratio,
                "z_drawn_abs_max": float(np.abs((self.mc_std_m - self.lin_std_m)
                                                                   / self.mc_std_se_m).max())}


def simulate_design(pa, *, trials: int = 4000, rng=None, noise: str = "gaussian", instrument=None,
                    chunk_size: int = 2000, map=None) -> DesignSimulation:
    """Propagate a :class:`~multilat.network.design.preanalysis.PreAnalysis`'s layout by Monte Carlo.

    Parameters
    ----------
    pa : PreAnalysis  (offsets estimated; free or 321 datum)
    trials : int ; rng : seed or Generator
    noise : "gaussian" (the design's sigmas) or "model" (the instrument's distance model; the
        design's sigmas should come from the same instrument for the comparison to mean anything)
    instrument : Instrument or preset, for ``noise="model"``
    """
    from multilat.network.model.datum import frame_321
    from multilat.network.montecarlo.propagate import problem_from_truth, propagate

    if not pa.offsets:
        raise MultilatError("simulate: the Monte Carlo estimates the offsets; design with offsets = true")
    if noise == "model" and instrument is None:
        raise MultilatError("simulate: noise 'model' needs an instrument ([instrument] preset or file)")
    lay = pa.layout
    s = lay.n_stations
    prob = problem_from_truth(lay.station_ids, lay.target_ids, pa.station_index, pa.target_index,
                              pa.sigma_m, lay.station_xyz_m, np.zeros(s), lay.target_xyz_m,
                              datum=pa.datum, pairs=[], instrument=instrument)
    res = propagate(prob, trials=trials, rng=rng, noise=noise, instrument=instrument or "seed2020",
                    chunk_size=chunk_size, keep_samples=True, map=map)
    C = pa.target_cov_m2
    if pa.datum.kind == "321":         # propagate (as adjust) reports in the frame of the three points
        from multilat.network.model.datum import apply_rigid
        from multilat.network.design.preanalysis import Layout, preanalyse

        xyz = dict(zip(lay.station_ids + lay.target_ids, np.vstack([lay.station_xyz_m, lay.target_xyz_m])))
        R, t0 = frame_321(*(xyz[p] for p in pa.datum.points))
        rot = Layout(lay.station_ids, apply_rigid(R, t0, lay.station_xyz_m), lay.target_ids,
                     apply_rigid(R, t0, lay.target_xyz_m), lay.visible)
        C = preanalyse(rot, pa.sigma_m, offsets=True, datum=pa.datum).target_cov_m2
    lab = {x: k for k, x in enumerate(res.labels)}
    rows = np.array([[lab[f"{t}.{c}"] for c in "xyz"] for t in lay.target_ids])
    pred = np.sqrt(np.clip(np.diagonal(C, axis1=1, axis2=2), 0, None))
    mc, se = res.mc_std[rows], res.mc_std_se[rows]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(se > 0, (mc - pred) / se, 0.0)
    pid = {p: k for k, p in enumerate(res.point_ids)}
    Cmc = np.stack([res.point_cov_mc[pid[t]] for t in lay.target_ids])
    u_mc, u_pred = u95_max_m(Cmc), u95_max_m(C)
    # coverage of the predicted ellipsoid: trials whose target deviation has d^T C^-1 d <= chi2(3)
    samples = res.samples                           # (n, k) float32 deviations
    cov_frac = np.full(lay.n_targets, np.nan)
    if samples is not None:
        for j in range(lay.n_targets):
            dv = np.asarray(samples[:, rows[j]], float)
            try:
                m2 = np.einsum("ni,ij,nj->n", dv, np.linalg.inv(C[j]), dv)
            except np.linalg.LinAlgError:
                continue
            cov_frac[j] = float(np.mean(m2 <= st.CHI2_3_95))
    return DesignSimulation(noise, int(res.trials), int(res.n_failed), lay.target_ids, pred, mc, se, z,
                            u_pred, u_mc, cov_frac, res.lin_std[rows], float(res.input_std_ratio), res)
