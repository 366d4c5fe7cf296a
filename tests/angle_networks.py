"""A random mixed network for the angle tests: six stations, fifteen targets, distances from all and
azimuths and elevations at 20 µrad from two tracker stations with random orientations."""

import numpy as np

from multilat.network.model.angles import predicted_angles
from multilat.network.model.data import Observations
from multilat.network.synthetic.generator import synthetic_network

SIG_ANGLE = 20e-6


def mixed_with_angles(seed=3, noise=True, trackers=(0, 1)):
    """(network truth, observations, true orientations (s, 3)); ``noise=False``: exact data."""
    net = synthetic_network(np.random.default_rng([15, seed]), n_stations=(6, 6), n_targets=(15, 15))
    o = net.obs
    rng = np.random.default_rng(seed)
    ori = rng.uniform(-0.2, 0.2, (o.n_stations, 3))
    ori[:, 2] = rng.uniform(-3, 3, o.n_stations)
    az, el = predicted_angles(net.station_xyz_m, ori, net.target_xyz_m, o.station_index, o.target_index)
    tr = np.isin(o.station_index, trackers)
    s = np.where(tr, SIG_ANGLE, np.nan)
    d = o.distance_m
    if noise:
        az = az + rng.normal(0, SIG_ANGLE, az.size)
        el = el + rng.normal(0, SIG_ANGLE, el.size)
    else:
        d = d - (d - np.linalg.norm(net.station_xyz_m[o.station_index] - net.target_xyz_m[o.target_index], axis=1)
                 - net.offset_m[o.station_index])          # exact distances
    obs = Observations(o.station_ids, o.target_ids, o.station_index, o.target_index, d, o.sigma_m, az, el,
                       None, s, s)
    return net, obs, ori
