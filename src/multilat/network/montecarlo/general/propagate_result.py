"""The result of :func:`.propagate.propagate` from its blocks of trials: per free parameter and
interpoint distance the Monte Carlo summaries beside the adjustment's linear ones, per point the
covariances. The record and its JSON document (``schema`` ``multilat.propagate-general/2``, keys in
``docs/general-network.md``) are the Monte Carlo's one :class:`~multilat.network.montecarlo.propagate_result.PropagationResult`,
its general fields (``units``, ``n_params``, ``dof``, ``chord_steps_mean``) set."""

from __future__ import annotations

import time

import numpy as np

from multilat.errors import MultilatError
from multilat.montecarlo import summarize
from multilat.network.montecarlo.propagate_result import GENERAL_SCHEMA, PropagationResult

__all__ = ["GeneralPropagation", "SCHEMA", "default_pairs", "summarise"]

#: JSON schema stamp of the general layer's document (:data:`multilat.network.montecarlo.propagate_result.GENERAL_SCHEMA`).
SCHEMA = GENERAL_SCHEMA
#: The general layer's result is the Monte Carlo's one record (its general fields set).
GeneralPropagation = PropagationResult


def _unit(name: str) -> str:
    kind = name.split(":", 1)[0]
    return "m" if kind in ("x", "y", "z", "offset") else "1" if kind == "scale" else "rad"


def default_pairs(system) -> np.ndarray:
    """Interpoint distances to report: every pair of points with a free coordinate when there are at
    most 20 of them, consecutive pairs otherwise (:func:`multilat.network.montecarlo.propagate._default_pairs`)."""
    from multilat.network.montecarlo.propagate import _default_pairs

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


def summarise(frozen, pairs, blocks, seed_entropy, t0, keep_samples, noise="gaussian", q=None,
              linear=None) -> PropagationResult:
    """The result of a run from its blocks (:func:`.propagate._solve_block`), in block order; ``q`` the
    linear covariance of the free parameters for the drawn inputs (default the cofactor ``Q``), or
    ``linear`` (std of the outputs, point covariances (P, 3, 3)) when ``Q`` is kept in blocks
    (:func:`.propagate_blocks.linear`)."""
    # column-major, as the distance path keeps them: each point's or block's columns gathered at once
    dev = np.empty((sum(len(b["dev"]) for b in blocks), blocks[0]["dev"].shape[1]), np.float32, order="F")
    np.concatenate([b["dev"] for b in blocks], out=dev)
    n = dev.shape[0]
    if n < 2:
        raise MultilatError(f"only {n} trials converged: the network is too weak for a Monte Carlo "
                            "from its adjusted solution")
    lay = frozen.system.layout
    names = tuple(np.array(lay.names)[frozen.free]) + tuple(
        f"{frozen.system.network.points.ids[a]}-{frozen.system.network.points.ids[b]}" for a, b in pairs)
    pc = lay.point_cols
    nominal = np.concatenate([frozen.x_hat[frozen.free],
                              np.linalg.norm(frozen.x_hat[pc[pairs[:, 1]]] - frozen.x_hat[pc[pairs[:, 0]]], axis=1)])
    mean, std, iv_sym, iv_short, kurt, cov_mc, pts = _statistics(dev, pc, lay.reduced)
    se = std * np.sqrt(np.clip(kurt - 1.0, 0, None) / (4 * n))
    lin, qp = _linear(frozen, pairs, frozen.q if q is None else q) if linear is None else linear
    vtpv = np.concatenate([b["vtpv"] for b in blocks])
    s0 = np.sqrt(vtpv / frozen.dof) if frozen.dof > 0 else np.full(len(vtpv), np.nan)
    n_all = sum(b["n"] for b in blocks)
    return PropagationResult(
        labels=names, units=tuple(_unit(nm) if ":" in nm else "m" for nm in names), nominal=nominal,
        mc_mean=nominal + mean, mc_std=std, mc_std_se=se, lin_std=lin,
        interval_symmetric=nominal[:, None] + iv_sym, interval_shortest=nominal[:, None] + iv_short,
        point_ids=tuple(frozen.system.network.points.ids[i] for i in pts), point_cov_mc=cov_mc,
        point_cov_lin=qp[pts], trials=n, n_failed=sum(b["n_failed"] for b in blocks),
        n_retried=sum(b["n_retried"] for b in blocks), noise=noise,
        chord_steps_mean=sum(b["iterations"] for b in blocks) / max(n_all, 1),
        sigma0_mean=float(np.mean(s0)), sigma0_rms=float(np.sqrt(np.mean(s0 ** 2))), dof=frozen.dof,
        seed_entropy=int(seed_entropy), elapsed_s=time.perf_counter() - t0, n_params=len(frozen.free),
        samples=dev if keep_samples else None)


def _statistics(dev: np.ndarray, pc: np.ndarray, red: np.ndarray):
    """The engine's :func:`summarize` and the kurtosis of every column of the float32 deviations ``dev``
    (N, k) in float64, as the distance path summarises (:func:`multilat.network.montecarlo.propagate_summary.summarise`):
    each point with a free coordinate (``pc`` its full columns, ``red`` full -> free column) its own
    columns at once, whose summary gives its MC 3 x 3 covariance too; the other columns eight at a
    time. Independent tasks in two threads from 50 000 trials
    (:func:`~multilat.network.montecarlo.propagate_summary._in_two_threads`),
    no (N, k) float64 copy. Returns mean, std, the two intervals (k, 2) (deviations), kurtosis, the
    covariances (P, 3, 3) and the point indices P."""
    from multilat.network.montecarlo.propagate_summary import _in_two_threads, _kurtosis

    k = dev.shape[1]
    mean, std, kurt = np.empty(k), np.empty(k), np.empty(k)
    iv_sym, iv_short = np.empty((k, 2)), np.empty((k, 2))
    pts = [i for i in range(len(pc)) if (red[pc[i]] >= 0).any()]
    cov_mc = np.zeros((len(pts), 3, 3))

    def put(cols):
        y = dev[:, cols].astype(np.float64)
        r = summarize(y)
        mean[cols], std[cols] = r.estimate, r.std
        iv_sym[cols], iv_short[cols] = r.interval_symmetric, r.interval_shortest
        kurt[cols] = _kurtosis(y, mean[cols])
        return r

    def point(j, i):
        c = red[pc[i]]
        have = c >= 0
        r = put(c[have])
        cov_mc[j][np.ix_(have, have)] = r.cov

    in_point = np.zeros(k, bool)
    for i in pts:
        c = red[pc[i]]
        in_point[c[c >= 0]] = True
    rest = np.flatnonzero(~in_point)
    _in_two_threads([lambda j=j, i=i: point(j, i) for j, i in enumerate(pts)]
                    + [lambda c=rest[c0:c0 + 8]: put(c) for c0 in range(0, len(rest), 8)], len(dev))
    return mean, std, iv_sym, iv_short, kurt, cov_mc, pts
