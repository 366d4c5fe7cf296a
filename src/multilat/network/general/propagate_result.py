"""The result of :func:`.propagate.propagate`: per free parameter and interpoint distance the Monte
Carlo summaries beside the adjustment's linear ones, per point the covariances, and the JSON document
(``schema`` ``multilat.propagate-general/1``, keys in ``docs/general-network.md``)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from multilat.errors import MultilatError
from multilat.montecarlo import summarize

__all__ = ["GeneralPropagation", "SCHEMA", "default_pairs", "summarise"]

#: JSON schema stamp of :meth:`GeneralPropagation.to_dict`.
SCHEMA = "multilat.propagate-general/1"


@dataclass(frozen=True, eq=False)
class GeneralPropagation:
    """Result of :func:`.propagate.propagate`; deviations from the adjusted values, SI units (m, rad, 1).

    labels : free parameter names (``x:P``, ``offset:I``, ...) then the pairs ``"A-B"``;  n_params : how many parameters
    units : "m", "rad" or "1" per label;  nominal : (k,) adjusted values
    mc_mean, mc_std : (k,) Monte Carlo estimate (mean deviation added to the nominal) and standard deviation
    mc_std_se : (k,) its Monte Carlo standard error ``mc_std sqrt((kurtosis - 1) / (4 N))``
        (``sqrt(1 / (2 (N - 1)))`` relative for a gaussian output)
    lin_std : (k,) the adjustment's linear standard deviation (``Q``, σ0 a priori = 1)
    interval_symmetric, interval_shortest : (k, 2) 95 % coverage intervals (values, not deviations)
    point_ids : points with a free coordinate;  point_cov_mc, point_cov_lin : (P, 3, 3) m²
    trials : kept;  n_failed : dropped (not converged);  n_full_gauss_newton : re-solved by full Gauss-Newton
    chord_steps_mean : mean chord steps per trial;  sigma0_mean, sigma0_rms : of the trials (dof of the adjustment)
    seed_entropy : root entropy;  elapsed_s : wall time;  samples : (N, k) float32 deviations or None
    """

    labels: tuple
    units: tuple
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
    n_full_gauss_newton: int
    chord_steps_mean: float
    sigma0_mean: float
    sigma0_rms: float
    dof: int
    seed_entropy: int
    elapsed_s: float
    n_params: int
    samples: np.ndarray | None = field(default=None, repr=False)

    @property
    def agrees(self) -> np.ndarray:
        """|MC std - linear std| <= 3 MC standard errors, per quantity (held by a datum: True)."""
        return np.abs(self.mc_std - self.lin_std) <= 3 * self.mc_std_se + 1e-15

    def to_dict(self) -> dict:
        """The JSON document (``schema`` :data:`SCHEMA`; keys in ``docs/general-network.md``)."""
        def rows(sl):
            return [{"label": self.labels[i], "unit": self.units[i], "nominal": float(self.nominal[i]),
                     "mean_mc": float(self.mc_mean[i]), "std_mc": float(self.mc_std[i]),
                     "std_mc_se": float(self.mc_std_se[i]), "std_lin": float(self.lin_std[i]),
                     "ratio": float(self.mc_std[i] / self.lin_std[i]) if self.lin_std[i] > 0 else None,
                     "agrees": bool(self.agrees[i]),
                     "interval_symmetric": [float(v) for v in self.interval_symmetric[i]],
                     "interval_shortest": [float(v) for v in self.interval_shortest[i]]}
                    for i in range(*sl.indices(len(self.labels)))]
        n_par = self.n_params
        ratio = self.mc_std / np.where(self.lin_std > 0, self.lin_std, np.nan)
        return {"schema": SCHEMA, "model": "general", "trials": int(self.trials), "n_failed": int(self.n_failed),
                "n_full_gauss_newton": int(self.n_full_gauss_newton), "chord_steps_mean": float(self.chord_steps_mean),
                "sigma0_mean": float(self.sigma0_mean), "sigma0_rms": float(self.sigma0_rms), "dof": int(self.dof),
                "seed": int(self.seed_entropy), "elapsed_s": float(self.elapsed_s),
                "parameters": rows(slice(0, n_par)), "distances": rows(slice(n_par, None)),
                "points": {p: {"cov_mc_m2": self.point_cov_mc[i].tolist(), "cov_lin_m2": self.point_cov_lin[i].tolist(),
                               "std_mc_m": np.sqrt(np.diag(self.point_cov_mc[i])).tolist(),
                               "std_lin_m": np.sqrt(np.diag(self.point_cov_lin[i])).tolist()}
                           for i, p in enumerate(self.point_ids)},
                "summary": {"n_quantities": len(self.labels), "n_agree": int(self.agrees.sum()),
                            "ratio_min": float(np.nanmin(ratio)) if np.isfinite(ratio).any() else None,
                            "ratio_max": float(np.nanmax(ratio)) if np.isfinite(ratio).any() else None}}


def _unit(name: str) -> str:
    kind = name.split(":", 1)[0]
    return "m" if kind in ("x", "y", "z", "offset") else "1" if kind == "scale" else "rad"


def default_pairs(system) -> np.ndarray:
    """Interpoint distances to report: every pair of points with a free coordinate when there are at
    most 20 of them, consecutive pairs otherwise (:func:`multilat.network.propagate._default_pairs`)."""
    from multilat.network.propagate import _default_pairs

    pts = system.network.points
    free = [i for i in range(pts.n) if system.layout.free[system.layout.point_cols[i]].any()]
    return np.array([(a, b) for a, b in _default_pairs(free)], int).reshape(-1, 2)


def _linear(frozen, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear std of the outputs and the full-layout cofactor of the points (P, 3, 3)."""
    n = frozen.system.layout.n
    qf = np.zeros((n, n))
    qf[np.ix_(frozen.free, frozen.free)] = frozen.q
    pc = frozen.system.layout.point_cols
    std = [np.sqrt(np.clip(np.diag(frozen.q), 0, None))]
    if len(pairs):
        a, b = pc[pairs[:, 0]], pc[pairs[:, 1]]
        u = frozen.x_hat[b] - frozen.x_hat[a]
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        g = np.zeros((len(pairs), n))
        np.put_along_axis(g, b, u, 1)
        np.put_along_axis(g, a, -u, 1)
        std.append(np.sqrt(np.clip(np.einsum("qi,ij,qj->q", g, qf, g), 0, None)))
    return np.concatenate(std), qf[pc[:, :, None], pc[:, None, :]]


def summarise(frozen, pairs, blocks, seed_entropy, t0, keep_samples) -> GeneralPropagation:
    """The result of a run from its blocks (:func:`.propagate._solve_block`), in block order."""
    from multilat.network.propagate_summary import _kurtosis

    dev = np.concatenate([b["dev"] for b in blocks])
    if dev.shape[0] < 2:
        raise MultilatError(f"only {dev.shape[0]} trials converged: the network is too weak for a Monte Carlo "
                            "from its adjusted solution")
    lay = frozen.system.layout
    names = tuple(np.array(lay.names)[frozen.free]) + tuple(
        f"{frozen.system.network.points.ids[a]}-{frozen.system.network.points.ids[b]}" for a, b in pairs)
    pc = lay.point_cols
    nominal = np.concatenate([frozen.x_hat[frozen.free],
                              np.linalg.norm(frozen.x_hat[pc[pairs[:, 1]]] - frozen.x_hat[pc[pairs[:, 0]]], axis=1)])
    y = dev.astype(float)
    mc = summarize(y)
    mean = np.asarray(mc.estimate, float)
    std = np.asarray(mc.std, float)
    se = std * np.sqrt(np.clip(_kurtosis(y, mean) - 1.0, 0, None) / (4 * len(y)))
    lin, qp = _linear(frozen, pairs)
    red = lay.reduced
    pts = [i for i in range(len(pc)) if (red[pc[i]] >= 0).any()]
    cov_mc = np.zeros((len(pts), 3, 3))
    for k, i in enumerate(pts):
        c = red[pc[i]]
        have = c >= 0
        sub = y[:, c[have]]
        cov_mc[k][np.ix_(have, have)] = np.atleast_2d(np.cov(sub, rowvar=False))
    vtpv = np.concatenate([b["vtpv"] for b in blocks])
    s0 = np.sqrt(vtpv / frozen.dof) if frozen.dof > 0 else np.full(len(vtpv), np.nan)
    n_all = sum(b["n"] for b in blocks)
    return GeneralPropagation(
        labels=names, units=tuple(_unit(n) if ":" in n else "m" for n in names), nominal=nominal,
        mc_mean=nominal + mean, mc_std=std, mc_std_se=se, lin_std=lin,
        interval_symmetric=nominal[:, None] + np.asarray(mc.interval_symmetric),
        interval_shortest=nominal[:, None] + np.asarray(mc.interval_shortest),
        point_ids=tuple(frozen.system.network.points.ids[i] for i in pts), point_cov_mc=cov_mc,
        point_cov_lin=qp[pts], trials=len(y), n_failed=sum(b["n_failed"] for b in blocks),
        n_full_gauss_newton=sum(b["n_full_gauss_newton"] for b in blocks),
        chord_steps_mean=sum(b["iterations"] for b in blocks) / max(n_all, 1),
        sigma0_mean=float(np.mean(s0)), sigma0_rms=float(np.sqrt(np.mean(s0 ** 2))), dof=frozen.dof,
        seed_entropy=int(seed_entropy), elapsed_s=time.perf_counter() - t0, n_params=len(frozen.free),
        samples=dev if keep_samples else None)
