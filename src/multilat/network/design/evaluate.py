"""One interface for evaluating a layout: ``evaluate_layout(design, backend) -> Prediction``, with the
design's evaluators as back ends behind it (as Gama's adjustment algorithms sit behind ``AdjBase``).

* ``general`` (the default): the general network layer's pre-analysis
  (:func:`multilat.network.design.general_preanalysis.predict`): any kinds (distances, angles, tracker
  angles, vectors, levelling, control), the adjustment's own system, datum and statistics.
* ``distance``: the distance-only pre-analysis :func:`.preanalysis.preanalyse` (dense or blocked), an
  adapter: the whole distance-only layout, stations and targets, redundancy and MDBs.
* ``fast``: the search's evaluator (the ``fast`` back end of :mod:`.backends`, the Schur complement in
  heads x targets arrays), an adapter: the targets' covariances only.

A :class:`Design` holds the designed general network (planned coordinates, σ) and, when it is a
distance-only layout (:func:`design_from_layout`), that layout too, so the distance-only back ends can
take it; they refuse any other design in one line. The back ends agree to 1e-9 on distance-only
layouts (``tests/test_general_preanalysis.py``); the datum ``free`` (inner constraints over every
point) and ``free:P,..`` (over the listed points) are the general layer's datum points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust import statistics as st
from multilat.network.model.datum import parse_datum
from multilat.network.design.preanalysis import Layout, SigmaModel, preanalyse
from multilat.network.model.observations import Block, Network
from multilat.network.model.points import FREE, PointSet
from multilat.network.model.distance import range_m
from multilat.network.adjust.distance.reliability import MDB_LIMIT_SIGMA, R_MIN

__all__ = ["Design", "Prediction", "design_from_layout", "evaluate_layout", "BACKENDS"]


@dataclass(frozen=True, eq=False)
class Design:
    """network : the designed general network (planned coordinates; values are replaced by the model)
    datum : the general layer's datum (``auto``: the points flagged ``constrained``, else the fixed ones)
    layout, sigma_m, offsets, distance_datum : the distance-only form (None when the design is not one):
        the layout, σ per observation in :meth:`~.preanalysis.Layout.pairs` order, whether each head's
        additive constant is estimated, and the datum text of the distance-only evaluators
    alpha, power : of the MDBs
    """

    network: Network
    datum: str = "auto"
    layout: Layout | None = None
    sigma_m: np.ndarray | None = None
    offsets: bool = True
    distance_datum: str = "free"
    alpha: float = 0.001
    power: float = 0.80


@dataclass(frozen=True, eq=False)
class Prediction:
    """backend : its name;  ids : the predicted points;  cov_m2 : (n, 3, 3) their covariance (σ0 a priori)
    semi_axes_95_m : (n, 3) ascending, axes_95 : (n, 3, 3) the 95 % ellipsoids
    redundancy, mdb, weak : (R,) per observation row (None when the back end does not give them)
    undetermined : the points left out and why (dicts {id, reason, n_obs, ...})
    detail : the back end's own result (:class:`~multilat.network.design.general_preanalysis.GeneralPrediction`,
        :class:`~.preanalysis.PreAnalysis`, or None)
    """

    backend: str
    ids: tuple
    cov_m2: np.ndarray
    semi_axes_95_m: np.ndarray
    axes_95: np.ndarray
    redundancy: np.ndarray | None
    mdb: np.ndarray | None
    weak: np.ndarray | None
    undetermined: tuple
    detail: object = None

    def point_cov_m2(self, pid: str) -> np.ndarray:
        try:
            return self.cov_m2[self.ids.index(pid)]
        except ValueError:
            raise MultilatError(f"point {pid!r} is not predicted by the {self.backend} back end") from None


def design_from_layout(layout: Layout, sigma, *, offsets: bool = True, datum: str = "free", alpha: float = 0.001,
                       power: float = 0.80) -> Design:
    """The distance-only layout as a designed general network: every station and target a free point,
    one slope distance per visible pair (station-major, :meth:`~.preanalysis.Layout.pairs`), each
    station its own instrument (additive constant estimated when ``offsets``), σ from ``sigma``
    (:class:`~.preanalysis.SigmaModel`, metres, or (m,)); datum ``free`` or ``free:P,..``."""
    dat = parse_datum(datum)
    if dat.kind != "free":
        raise MultilatError(f"datum {datum!r}: the general back end takes free or free:P,.. (inner constraints); "
                            "a 321 or control datum is the distance-only evaluators' S-transform")
    si, ti = layout.pairs()
    s = layout.n_stations
    d = range_m(layout.station_xyz_m[si] - layout.target_xyz_m[ti])
    sig = sigma(d, si, layout.station_ids) if isinstance(sigma, SigmaModel) else \
        np.broadcast_to(np.asarray(sigma, float), d.shape).copy()
    ids = layout.station_ids + layout.target_ids
    constrained = np.ones(len(ids), bool) if dat.points is None else np.isin(ids, dat.points)
    if dat.points is not None and constrained.sum() != len(set(dat.points)):
        raise MultilatError(f"datum {datum!r}: unknown point {next(p for p in dat.points if p not in ids)!r}")
    pts = PointSet.build(ids, np.vstack([layout.station_xyz_m, layout.target_xyz_m]), status=np.full(len(ids), FREE),
                         constrained=constrained)
    block = Block("slope_distance", np.zeros(len(si)), sig, None, {"from": si, "to": ti + s, "instrument": si},
                  labels=tuple(f"{ids[a]}-{ids[b + s]}" for a, b in zip(si, ti)),
                  names={"instrument": layout.station_ids}, options={"estimate_offset": bool(offsets)})
    return Design(Network(pts, (block,)), "auto", layout, sig, bool(offsets), str(datum), alpha, power)


def _ellipsoids(backend, ids, cov, **rows) -> Prediction:
    semi, axes = st.confidence_ellipsoid(cov, level=0.95)
    return Prediction(backend, tuple(ids), cov, semi, axes, **rows)


def _general(design: Design) -> Prediction:
    from multilat.network.design.general_preanalysis import predict

    g = predict(design.network, datum=design.datum, alpha=design.alpha, power=design.power)
    s = g.stats
    return Prediction("general", tuple(g.result.ids), s.cov_m2, s.semi_axes_95_m, s.axes_95, s.redundancy, s.mdb,
                      g.weak, g.undetermined, g)


def _distance_layout(design: Design, backend: str) -> Layout:
    if design.layout is None:
        raise MultilatError(f"the {backend} back end evaluates distance-only layouts (design_from_layout); "
                            "use the general back end for this design")
    return design.layout


def _distance(design: Design) -> Prediction:
    lay = _distance_layout(design, "distance")
    pa = preanalyse(lay, design.sigma_m, offsets=design.offsets, datum=design.distance_datum, alpha=design.alpha,
                    power=design.power)
    weak = (pa.redundancy < R_MIN) | ~(pa.mdb_m / pa.sigma_m <= MDB_LIMIT_SIGMA)
    return _ellipsoids("distance", lay.station_ids + lay.target_ids,
                       np.concatenate([pa.station_cov_m2, pa.target_cov_m2]), redundancy=pa.redundancy,
                       mdb=pa.mdb_m, weak=weak, undetermined=(), detail=pa)


def _fast(design: Design) -> Prediction:
    from multilat.network.design.backends import make_backend

    lay = _distance_layout(design, "fast")
    cov = make_backend("fast", lay, design.sigma_m, offsets=design.offsets,
                       datum=design.distance_datum).target_cov_m2()
    return _ellipsoids("fast", lay.target_ids, cov, redundancy=None, mdb=None, weak=None, undetermined=())


#: the back ends: name -> evaluator (Design -> Prediction)
BACKENDS = {"general": _general, "distance": _distance, "fast": _fast}


def evaluate_layout(design: Design, backend: str = "general") -> Prediction:
    """The predicted uncertainty of ``design`` by ``backend`` (:data:`BACKENDS`)."""
    try:
        fn = BACKENDS[backend]
    except KeyError:
        raise MultilatError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}") from None
    return fn(design)
