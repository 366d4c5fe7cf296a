"""Which error source sets the coordinate uncertainty: one-source-at-a-time direct propagation.

Each group of sources is switched on alone (every other set to zero through the config) and propagated
with :func:`multilat.lbb.simulate.run_direct`. The groups act on the edge lengths almost linearly and
independently, so their coordinate variances add up to the total (tested).

Groups: ``interferometer`` (DMI error of every reading, including the initialization's), ``unsensed
thermal`` (§3.1.6), ``base-edge drift`` (§4.3), ``fixture offset`` (eq. 6), ``mechanics`` (axis motion,
bearing compliance, cosine misalignment). The sag's randomness (the middle tube's free position) stays
in every group; it acts at second order (nm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.lbb.config import LBBConfig
from multilat.lbb.simulate import run_direct
from multilat.montecarlo import resolve_seed

__all__ = ["GROUPS", "Contributions", "contributions", "only"]

GROUPS = ("interferometer", "unsensed thermal", "base-edge drift", "fixture offset", "mechanics")


def only(cfg: LBBConfig, group: str) -> LBBConfig:
    """A copy of ``cfg`` with every error group but ``group`` switched off."""
    if group not in GROUPS:
        raise MultilatError(f"unknown group {group!r}; groups: {', '.join(GROUPS)}")
    e = cfg.errors.model_dump()
    off = {
        "interferometer": {"interferometer_std_m": 0.0},
        "unsensed thermal": {"unsensed_temperature_bound_c": 0.0},
        "mechanics": {"middle_angle_bound_rad": 0.0, "middle_straightness_bound_m": 0.0,
                      "inner_angle_bound_rad": 0.0, "inner_straightness_bound_m": 0.0,
                      "bearing_compliance_rad": 0.0, "cosine_misalignment_std_rad": 0.0},
    }
    ini = cfg.initialization.model_dump()
    base = cfg.base.model_dump()
    for g, keys in off.items():
        if g != group:
            e.update(keys)
    if group != "fixture offset":
        ini["fixture_offset_std_m"] = 0.0
    if group != "base-edge drift":
        base["thermal_bound_c"] = 0.0
    return cfg.replace(errors=e, initialization=ini, base=base)


@dataclass(frozen=True)
class Contributions:
    """Coordinate std (m) per group, shape (3,) each, and the total with every group on."""

    point_m: np.ndarray
    std_by_group_m: dict
    total_std_m: np.ndarray
    trials: int

    @property
    def root_sum_square_m(self) -> np.ndarray:
        """sqrt of the sum of the group variances, (3,): equals the total when the groups add."""
        return np.sqrt(np.sum([s**2 for s in self.std_by_group_m.values()], axis=0))


def contributions(cfg: LBBConfig, point_m, *, trials: int = 4000, rng=None) -> Contributions:
    """Coordinate std of ``point_m`` (3,) with each group alone and with all of them (direct method)."""
    root = resolve_seed(rng)
    seeds = root.spawn(len(GROUPS) + 1)
    pt = np.asarray(point_m, dtype=float).reshape(1, 3)
    by = {g: run_direct(only(cfg, g), pt, trials=trials, rng=s).std_m[0] for g, s in zip(GROUPS, seeds)}
    total = run_direct(cfg, pt, trials=trials, rng=seeds[-1]).std_m[0]
    return Contributions(pt[0], by, total, trials)
