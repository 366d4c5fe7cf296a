"""The result of :func:`.propagate.propagate` from its blocks of trials: per free parameter and
interpoint distance the Monte Carlo summaries beside the adjustment's linear ones, per point the
covariances. The record and its JSON document (``schema`` ``multilat.propagate-general/1``, keys in
``docs/general-network.md``) are the Monte Carlo's one :class:`~multilat.network.propagate_result.PropagationResult`,
its general fields (``units``, ``n_params``, ``dof``, ``chord_steps_mean``) set."""

from __future__ import annotations

import time

import numpy as np

from multilat.errors import MultilatError
from multilat.montecarlo import summarize
from multilat.network.propagate_result import GENERAL_SCHEMA, PropagationResult

__all__ = ["GeneralPropagation", "SCHEMA", "default_pairs", "summarise"]

#: JSON schema stamp of the general layer's document (:data:`multilat.network.propagate_result.GENERAL_SCHEMA`).
SCHEMA = GENERAL_SCHEMA
#: The general layer's result is the Monte Carlo's one record (its general fields set).
GeneralPropagation = PropagationResult


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


def _linear(frozen, pairs: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear std of the outputs and the full-layout covariance of the points (P, 3, 3), from the free
    parameters' covariance ``q`` (``Q``, or its sandwich for the model's inputs)."""
    n = frozen.system.layout.n
    qf = np.zeros((n, n))
    qf[np.ix_(frozen.free, frozen.free)] = q
    pc = frozen.system.layout.point_cols
    std = [np.sqrt(np.clip(np.diag(q), 0, None))]
    if len(pairs):
        a, b = pc[pairs[:, 0]], pc[pairs[:, 1]]
        u = frozen.x_hat[b] - frozen.x_hat[a]
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        g = np.zeros((len(pairs), n))
        np.put_along_axis(g, b, u, 1)
        np.put_along_axis(g, a, -u, 1)
        std.append(np.sqrt(np.clip(np.einsum("qi,ij,qj->q", g, qf, g), 0, None)))
    return np.concatenate(std), qf[pc[:, :, None], pc[:, None, :]]


def summarise(frozen, pairs, blocks, seed_entropy, t0, keep_samples, noise="gaussian", q=None) -> PropagationResult:
    """The result of a run from its blocks (:func:`.propagate._solve_block`), in block order; ``q`` the
    linear covariance of the free parameters for the drawn inputs (default the cofactor ``Q``)."""
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
    lin, qp = _linear(frozen, pairs, frozen.q if q is None else q)
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
    return PropagationResult(
        labels=names, units=tuple(_unit(n) if ":" in n else "m" for n in names), nominal=nominal,
        mc_mean=nominal + mean, mc_std=std, mc_std_se=se, lin_std=lin,
        interval_symmetric=nominal[:, None] + np.asarray(mc.interval_symmetric),
        interval_shortest=nominal[:, None] + np.asarray(mc.interval_shortest),
        point_ids=tuple(frozen.system.network.points.ids[i] for i in pts), point_cov_mc=cov_mc,
        point_cov_lin=qp[pts], trials=len(y), n_failed=sum(b["n_failed"] for b in blocks),
        n_retried=sum(b["n_retried"] for b in blocks), noise=noise,
        chord_steps_mean=sum(b["iterations"] for b in blocks) / max(n_all, 1),
        sigma0_mean=float(np.mean(s0)), sigma0_rms=float(np.sqrt(np.mean(s0 ** 2))), dof=frozen.dof,
        seed_entropy=int(seed_entropy), elapsed_s=time.perf_counter() - t0, n_params=len(frozen.free),
        samples=dev if keep_samples else None)
