"""``tests/test_weak_targets.py``'s network with its weak target P403, for the tests of the weak-point
rule and of the general layer's approximate chain (``test_weak_rule.py``, ``test_coplanar_general.py``):
6 stations, ``n_targets`` targets seen by all, and P403 seen by stations 1, 2, 3 only, at their
centroid lifted ``lift_m`` along their plane's normal (0: its lines of sight exactly coplanar).
``angles``: station 1 is a tracker reading azimuth and elevation (σ 1 arcsecond) of every target it
sees, P403 too."""

from __future__ import annotations

import numpy as np

from multilat.network.model.angles import predicted_angles
from multilat.network.model.data import Observations
from multilat.network.synthetic.generator import synthetic_network

SIGMA = 5e-6
SIGMA_ANGLE = 5e-6          # rad, about 1 arcsecond: a laser tracker's angle encoders
ON = (1, 2, 3)              # the stations that see P403


def p403_network(angles: bool, *, lift_m: float = 0.0, n_targets: int = 40, truth: bool = False):
    """The observations; with ``truth`` also the true stations (6, 3) and P403 (3,)."""
    tr = synthetic_network(1, population="shell", n_stations=6, n_targets=n_targets, sigma_m=SIGMA)
    o, H = tr.obs, tr.station_xyz_m
    P = H[list(ON)].mean(axis=0)
    if lift_m:
        n = np.cross(H[2] - H[1], H[3] - H[1])
        P = P + lift_m * n / np.linalg.norm(n)
    rng = np.random.default_rng(2)
    rho = np.linalg.norm(H[list(ON)] - P, axis=1) + tr.offset_m[list(ON)] + rng.normal(0, SIGMA, 3)
    si, ti = np.r_[o.station_index, ON], np.r_[o.target_index, [o.n_targets] * 3]
    kw = {}
    if angles:
        az, el = predicted_angles(H, np.zeros((len(H), 3)), np.vstack([tr.target_xyz_m, P]), si, ti)
        tracker = si == 1
        noise = rng.normal(0, SIGMA_ANGLE, (2, si.size))
        kw = dict(azimuth_rad=np.where(tracker, az + noise[0], np.nan),
                  elevation_rad=np.where(tracker, el + noise[1], np.nan),
                  sigma_azimuth_rad=np.where(tracker, SIGMA_ANGLE, np.nan),
                  sigma_elevation_rad=np.where(tracker, SIGMA_ANGLE, np.nan))
    obs = Observations(o.station_ids, list(o.target_ids) + ["P403"], si, ti,
                       np.r_[o.distance_m, rho], np.r_[o.sigma_m, [SIGMA] * 3], **kw)
    return (obs, H, P) if truth else obs
