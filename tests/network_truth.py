"""Helpers around the package's one network generator, for the network tests (not a test module).

Networks are drawn by :func:`multilat.network.synthetic.generator.synthetic_network` (issue 27, "one
generator"); this module only adds what a test needs on top of a drawn network: its exact
(noise-free) observations and initial values near the truth in another frame."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from multilat.network.adjust.distance.adjust import Start
from multilat.network.model.distance import predicted_distance_m


def noise_free(net):
    """``net.obs`` with the exact distances ``|H - T| + offset`` of the truth (σ column unchanged)."""
    o = net.obs
    d = predicted_distance_m(net.station_xyz_m, net.target_xyz_m, net.offset_m, np.zeros(o.n_stations),
                             o.station_index, o.target_index)
    return o.with_distances(d)


def perturbed_start(net, rng, scale_m=5e-3) -> Start:
    """Initial values near the truth of ``net`` (a :class:`SyntheticNetwork`), in a rotated and
    shifted frame, each coordinate moved by N(0, ``scale_m``); offsets zero."""
    rng = np.random.default_rng(rng)
    R = Rotation.from_rotvec(rng.normal(size=3) * 0.5).as_matrix()
    tvec = rng.normal(size=3)
    sx = net.station_xyz_m @ R.T + tvec + rng.normal(0, scale_m, net.station_xyz_m.shape)
    tx = net.target_xyz_m @ R.T + tvec + rng.normal(0, scale_m, net.target_xyz_m.shape)
    return Start(sx, tx, np.zeros(net.offset_m.size))
