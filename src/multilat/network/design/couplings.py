"""Pre-analysis of a layout with scale bars and weighted control points (issue 11 item 1).

Scale bars (a reference length between two targets with its standard uncertainty) and control points
observed with standard uncertainties couple targets, which the fast and blocked evaluators (per-target
3 x 3 blocks) do not model. Here the pre-analysis is what the issue defines it to be: ``adjust`` run on
the layout's error-free distances, with the bars as observations of their exact lengths and the control
points at their exact coordinates (:mod:`multilat.network.model.couplings`, the dense coupled path), data
snooping off. Its covariance, redundancy numbers, MDBs and external reliability are the prediction.

The optimisation (``multilat design`` without fixed heads) does not use bars or control yet: a config
that gives them must fix the heads (``heads.fixed`` or ``--evaluate``).
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError

__all__ = ["preanalyse_coupled"]


def preanalyse_coupled(layout, sigma, *, scale_bars=(), control=None, offsets: bool = True, datum=None,
                       lengths=(), alpha: float = 0.001, power: float = 0.80):
    """:class:`~multilat.network.design.preanalysis.PreAnalysis` of ``layout`` with couplings.

    Parameters
    ----------
    layout : Layout
    sigma : SigmaModel, float (m) or ndarray (m,) in ``layout.pairs()`` order
    scale_bars : sequence of (target id, target id, u_m)  bars between two targets, standard
        uncertainty of each bar's length in metres (> 0); the length is the layout's
    control : sequence of (target id, sx_m, sy_m, sz_m), optional  targets observed as control points
        with these standard uncertainties (> 0), at the layout's coordinates
    offsets, lengths, alpha, power : as :func:`~multilat.network.design.preanalysis.preanalyse`
    datum : str, optional  default ``control`` with control points, else ``free``
    """
    from multilat.network.adjust.distance.adjust import adjust
    from multilat.network.model.data import Points, ReferenceLengths
    from multilat.network.design.backends import u95_max_m
    from multilat.network.design.preanalysis import PreAnalysis, SigmaModel, layout_observations
    from multilat.network.model.datum import parse_datum
    from multilat.network.adjust.distance.result import Start

    si, ti = layout.pairs()
    d = np.linalg.norm(layout.station_xyz_m[si] - layout.target_xyz_m[ti], axis=1)
    sig = sigma(d, si, layout.station_ids) if isinstance(sigma, SigmaModel) else \
        np.broadcast_to(np.asarray(sigma, float), d.shape).copy()
    if not np.all(np.isfinite(sig) & (sig > 0)):
        raise MultilatError("sigma must be finite and > 0")
    pos = {p: j for j, p in enumerate(layout.target_ids)}

    def target(p, what):
        if p not in pos:
            raise MultilatError(f"{what}: {p!r} is not a target of the layout")
        return pos[p]

    refs = None
    if scale_bars:
        a, b, lens, us = [], [], [], []
        for pa, pb, u in scale_bars:
            ja, jb = target(pa, "scale_bars"), target(pb, "scale_bars")
            if not (np.isfinite(u) and u > 0):
                raise MultilatError(f"scale_bars: the uncertainty of {pa}-{pb} must be > 0, got {u!r}")
            a.append(pa)
            b.append(pb)
            lens.append(float(np.linalg.norm(layout.target_xyz_m[ja] - layout.target_xyz_m[jb])))
            us.append(float(u))
        refs = ReferenceLengths(tuple(a), tuple(b), np.array(lens), np.array(us))
    points = None
    if control:
        ids, xyz, std = [], [], []
        for p, *s3 in control:
            j = target(p, "control")
            if len(s3) != 3 or not all(np.isfinite(v) and v > 0 for v in s3):
                raise MultilatError(f"control: {p!r} needs three standard uncertainties > 0, got {s3!r}")
            ids.append(p)
            xyz.append(layout.target_xyz_m[j])
            std.append(s3)
        points = Points(tuple(ids), np.array(xyz, float), np.array(std, float))
    dat = parse_datum(datum if datum is not None else ("control" if points is not None else "free"))
    obs = layout_observations(layout, sig)
    start = Start(layout.station_xyz_m, layout.target_xyz_m, np.zeros(layout.n_stations))
    fixed = None if offsets else {sid: 0.0 for sid in layout.station_ids}
    res = adjust(obs, initial=start, datum=dat, points=points, scale_bars=refs, offsets=fixed,
                 snooping=False, alpha=alpha, power=power, solver="dense")
    tcov = res.target_cov_m2
    lens_out = []
    for pa, pb in lengths:
        ip = res.interpoint_distance(pa, pb)
        lens_out.append((pa, pb, ip.length_m, ip.u_m))
    rel = res.reliability
    ext = np.full(obs.n_obs, np.inf) if rel is None else np.where(np.isfinite(rel.shift_max_m),
                                                                 rel.shift_max_m, np.inf)
    return PreAnalysis(layout=layout, station_index=si, target_index=ti, distance_m=d, sigma_m=sig, cov=None,
                       global_cov=res.covariance.global_block(), station_cov_m2=res.station_cov_m2,
                       target_cov_m2=tcov, offset_std_m=np.asarray(res.offset_std_m, float),
                       u95_max_m=u95_max_m(tcov), redundancy=res.redundancy, mdb_m=res.mdb_m, external_m=ext,
                       dof=int(res.dof), lengths=tuple(lens_out), datum=dat, offsets=offsets, alpha=alpha,
                       power=power)
