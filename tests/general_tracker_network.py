"""The small volume (seed 000 §4.1: 4 stations, 14 targets) as a general network with everything the
distance-only Monte Carlo cannot take: two heads each moved over two stations (one additive constant
per head), azimuths and elevations at 20 µrad from two unlevelled set-ups, the nine published scale
bars (σ = their u_m) and three weighted control points (10 µm): the network of the general Monte
Carlo's tests and benchmark (``benchmarks/bench_general_propagate.py``)."""

import numpy as np

from multilat.network.model.angles import predicted_angles
from multilat.network.synthetic.configs import small_volume
from multilat.network.model.observations import Block, Network
from multilat.network.model.points import FREE, WEIGHTED, PointSet

SIG_DIST_M = 4.7e-6
SIG_ANGLE_RAD = 20e-6
SIG_CONTROL_M = 10e-6
CONTROL = ("1", "9", "11")
HEADS = ("H1", "H2", "H1", "H2")          # station A, B, C, D -> head
TRACKERS = (0, 3)                         # stations A and D also read angles


def tracker_network(seed: int = 5, noise: bool = True, extras: bool = True) -> Network:
    """The network (observations with noise drawn from ``seed`` unless ``noise`` is False) and the
    set-ups' true frames. ``extras=False``: the distance-only small volume of today's compiled Monte
    Carlo instead (one head per station, no angles, bars or control: a free network, adjust it with
    ``AdjustOptions(datum="free")``), the same 56 distances."""
    cfg = small_volume()
    rng = np.random.default_rng(seed)
    s, t = len(cfg.station_ids), len(cfg.target_ids)
    ids = cfg.station_ids + cfg.target_ids
    xyz = np.vstack([cfg.station_xyz_m, cfg.target_xyz_m])
    status = np.full((s + t, 3), FREE)
    sigma = np.full((s + t, 3), np.nan)
    for p in CONTROL if extras else ():
        status[ids.index(p)] = WEIGHTED
        sigma[ids.index(p)] = SIG_CONTROL_M
    heads = HEADS if extras else cfg.station_ids
    head_names = tuple(sorted(set(heads)))
    offset = dict(zip(head_names, np.linspace(-80e-6, 120e-6, len(head_names))))
    si, ti = np.repeat(np.arange(s), t), np.tile(np.arange(t), s) + s
    rho = np.linalg.norm(xyz[ti] - xyz[si], axis=1)
    d = rho + np.array([offset[heads[i]] for i in si])
    blocks = [Block("slope_distance", d, np.full(len(d), SIG_DIST_M), None,
                    {"from": si, "to": ti, "instrument": np.array([head_names.index(heads[i]) for i in si])},
                    labels=tuple(f"{ids[a]}-{ids[b]}" for a, b in zip(si, ti)),
                    names={"instrument": head_names}, options={"estimate_offset": True})]
    ori = np.array([[0.01, -0.02, 0.7], [-0.015, 0.01, -2.1]])
    if not extras:
        return _finish(blocks, ids, xyz, status, sigma, rng, noise, s + t), ori
    fr, to, setup, comp, val = [], [], [], [], []
    for u, st in enumerate(TRACKERS):
        az, el = predicted_angles(cfg.station_xyz_m[[st]], ori[[u]], cfg.target_xyz_m, np.zeros(t, int), np.arange(t))
        for c, a in ((0, az), (1, el)):
            fr += [st] * t
            to += list(range(s, s + t))
            setup += [u] * t
            comp += [c] * t
            val += list(a)
    blocks.append(Block("tracker_angles", np.array(val), np.full(len(val), SIG_ANGLE_RAD), None,
                        {"from": np.array(fr), "to": np.array(to), "setup": np.array(setup),
                         "component": np.array(comp)},
                        names={"setup": tuple(cfg.station_ids[i] for i in TRACKERS)}, options={"levelled": False}))
    refs = cfg.reference_lengths
    a = np.array([ids.index(p) for p in refs.target_a])
    b = np.array([ids.index(p) for p in refs.target_b])
    blocks.append(Block("slope_distance", np.linalg.norm(xyz[b] - xyz[a], axis=1), np.asarray(refs.u_m, float),
                        None, {"from": a, "to": b}))
    return _finish(blocks, ids, xyz, status, sigma, rng, noise, s + t), ori


def _finish(blocks, ids, xyz, status, sigma, rng, noise, n) -> Network:
    if noise:
        blocks = [Block(k.kind, k.value + rng.standard_normal(k.n_rows) * k.sigma, k.sigma, k.cov, k.index, k.data,
                        k.labels, k.names, k.options) for k in blocks]
        given = xyz + np.where(status == WEIGHTED, rng.standard_normal(xyz.shape) * SIG_CONTROL_M, 0.0)
    else:
        given = xyz
    return Network(PointSet(ids, given, status, sigma, np.zeros(n, bool)), tuple(blocks))
