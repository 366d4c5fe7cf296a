"""Random self-calibrating networks with a known truth, for the network tests (not a test module)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.network.data import Observations


@dataclass(frozen=True)
class Truth:
    obs: Observations
    station_xyz_m: np.ndarray
    target_xyz_m: np.ndarray
    offset_m: np.ndarray
    noise_m: np.ndarray


def random_network(rng, *, n_stations=4, n_targets=20, sigma_m=5e-6, gap_fraction=0.0,
                   offset_scale_m=3e-3, size_m=2.0, noise=True) -> Truth:
    """Stations on a rough sphere shell of radius ``size_m`` (off one plane), targets uniform in a box
    inside, offsets ~ N(0, offset_scale), gaussian noise ``sigma_m``; a fraction of the observations
    dropped at random while every target keeps >= 4 stations."""
    rng = np.random.default_rng(rng)
    s, t = n_stations, n_targets
    d = rng.normal(size=(s, 3))
    d[:, 2] = np.abs(d[:, 2]) * 0.6 + 0.2 * rng.uniform(size=s)
    d /= np.linalg.norm(d, axis=1)[:, None]
    if s >= 4:   # guarantee one station well below the others
        d[0] = [0.1, 0.1, -0.9]
    H = d * size_m * rng.uniform(0.8, 1.2, size=(s, 1))
    T = rng.uniform(-0.5, 0.5, size=(t, 3)) * size_m
    off = rng.normal(0.0, offset_scale_m, size=s)
    pairs = []
    for j in range(t):
        seen = np.ones(s, bool)
        if gap_fraction > 0 and s > 4:
            drop = rng.uniform(size=s) < gap_fraction
            if s - drop.sum() < 4:
                keep = rng.choice(s, size=4, replace=False)
                drop[:] = True
                drop[keep] = False
            seen &= ~drop
        pairs += [(i, j) for i in range(s) if seen[i]]
    si = np.array([p[0] for p in pairs])
    ti = np.array([p[1] for p in pairs])
    rho = np.linalg.norm(H[si] - T[ti], axis=1)
    e = rng.normal(0.0, sigma_m, size=si.size) if noise else np.zeros(si.size)
    obs = Observations([f"S{i}" for i in range(s)], [f"T{j}" for j in range(t)], si, ti,
                       rho + off[si] + e, np.full(si.size, sigma_m))
    return Truth(obs, H, T, off, e)


def perturbed_start(truth: Truth, rng, scale_m=5e-3):
    """Initial values near the truth, in a rotated and shifted frame."""
    from multilat.network.adjust import Start

    rng = np.random.default_rng(rng)
    a = rng.normal(size=3) * 0.5
    from scipy.spatial.transform import Rotation
    R = Rotation.from_rotvec(a).as_matrix()
    tvec = rng.normal(size=3)
    sx = truth.station_xyz_m @ R.T + tvec + rng.normal(0, scale_m, truth.station_xyz_m.shape)
    tx = truth.target_xyz_m @ R.T + tvec + rng.normal(0, scale_m, truth.target_xyz_m.shape)
    return Start(sx, tx, np.zeros(truth.offset_m.size))
