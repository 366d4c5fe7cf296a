"""Pre-analysis of a designed general network: what :func:`~.adjust.adjust` would report for
error-free observations, from the planned coordinates alone.

A design is a :class:`~.observations.Network` whose points carry their *planned* coordinates and
whose blocks carry the σ (or covariances) of the observations to be made; their values are not
measurements (a placeholder, e.g. zeros, or the values of a file being re-planned). The values are
replaced by the kinds' own model at the planned coordinates (:func:`planned`), so the residuals are
zero and the adjustment of that network stops at the plan after one step: its cofactor matrix ``Q``
(σ0 a priori = 1), its redundancy numbers and MDBs are the prediction. Nothing is retyped: the
:class:`~.adjust.System` (every kind's model and Jacobian, the whiteners), the datum of
:mod:`.determinability` (inner constraints on the datum points, or the fixed points alone), and the
statistics of :mod:`.quality` (95 % ellipsoids, redundancy numbers, MDBs, external reliability) are
those of ``multilat adjust``.

Undetermined points are named, never refused: a point the observations and the datum leave
undetermined is left out with every row that references it (:func:`.run.adjust_network`'s rule and
reasons), and the rest is predicted; :attr:`GeneralPrediction.undetermined` lists them.

Weak rows: redundancy below :data:`multilat.network.adjust.distance.reliability.R_MIN` or MDB above
:data:`~multilat.network.adjust.distance.reliability.MDB_LIMIT_SIGMA` σ (the adjustment's thresholds).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model import kinds as kinds_registry
from multilat.network.adjust.general.adjust import AdjustOptions, GeneralResult, System, UndeterminedError, _result
from multilat.network.model.observations import Block, Network
from multilat.network.adjust.general.quality import POWER, GeneralStatistics, statistics
from multilat.network.adjust.general.run import MAX_ROUNDS, leave_out, undetermined_reason
from multilat.network.adjust.distance.reliability import MDB_LIMIT_SIGMA, R_MIN

__all__ = ["GeneralPrediction", "planned", "predict"]


@dataclass(frozen=True, eq=False)
class GeneralPrediction:
    """network : the predicted network (planned values; undetermined points left out)
    system : its :class:`~.adjust.System`;  result : the adjustment at the plan (``cofactor`` = Q)
    stats : :class:`~.quality.GeneralStatistics` (known variance factor: a-priori covariances)
    weak : (R,) bool  rows with r < ``r_min`` or MDB > ``mdb_limit_sigma`` σ
    undetermined : tuple of dicts {id, kind, reason, n_obs, round} (as :attr:`.run.NetworkAdjustment.excluded`)
    r_min, mdb_limit_sigma : the thresholds of ``weak``
    """

    network: Network
    system: System
    result: GeneralResult
    stats: GeneralStatistics
    weak: np.ndarray
    undetermined: tuple
    r_min: float
    mdb_limit_sigma: float


def planned(network: Network) -> Network:
    """``network`` with every block's values replaced by the kinds' model at the planned coordinates
    (error-free observations). Every point needs planned coordinates (a one-line error names the
    first without)."""
    pts = network.points
    bad = np.argwhere(~np.isfinite(pts.xyz_m))
    if bad.size:
        raise MultilatError(f"point {pts.ids[int(bad[0][0])]!r} has no planned coordinates (a design gives "
                            "every point's coordinates)")
    system = System(network)
    x = system.layout.initial()
    blocks = []
    for b, cols in zip(network.blocks, system.cols):       # the weighted-coordinate block is the points'
        computed, _, _ = kinds_registry.kind(b.kind).evaluate(b, system.layout, cols, x, jacobian=False)
        blocks.append(Block(b.kind, np.asarray(computed, float).copy(), b.sigma, b.cov, b.index, b.data, b.labels,
                            b.names, b.options))
    return Network(pts, tuple(blocks), network.notes)


def predict(network: Network, *, datum: str = "auto", alpha: float = 0.001, power: float = POWER,
            r_min: float = R_MIN, mdb_limit_sigma: float = MDB_LIMIT_SIGMA, strict: bool = False,
            external: bool = True) -> GeneralPrediction:
    """The pre-analysis of the designed ``network`` (module docstring). ``datum`` as
    :class:`~.adjust.AdjustOptions`; ``alpha``, ``power`` of the MDBs (the adjustment's defaults);
    ``strict``: an undetermined point is an error (:class:`~.adjust.UndeterminedError`) instead of
    being left out and named."""
    options = AdjustOptions(datum=datum)
    net, excluded = planned(network), []
    for rnd in range(1, MAX_ROUNDS + 1):
        system = System(net)
        x = system.layout.initial()
        mask = system.datum_mask(options.datum)
        try:
            result = _result(system, x, mask, ())       # the adjustment's result at the plan: residuals 0
        except UndeterminedError as e:
            if strict or not e.points:
                raise
            net = leave_out(net, {p: undetermined_reason(c) for p, c in e.points.items()}, rnd, excluded, error=e)
            continue
        stats = statistics(system, result, alpha=alpha, power=power, variance_factor="known", external=external)
        weak = (stats.redundancy < r_min) | ~(stats.mdb_sigma <= mdb_limit_sigma)
        return GeneralPrediction(net, system, result, stats, weak, tuple(excluded), float(r_min),
                                 float(mdb_limit_sigma))
    raise MultilatError(f"still undetermined points after {MAX_ROUNDS} rounds of leaving them out "
                        f"({', '.join(e['id'] for e in excluded[:5])})")
