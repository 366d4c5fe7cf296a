"""Weighted distance cost vs the paper's eq. (6): Gauss-Markov says the weighted cost is never
worse; the first-order (sandwich) uncertainty of eq. (6) is checked by Monte Carlo."""

import numpy as np
from scipy import stats

from multilat.network.synthetic import configs
from multilat.network.adjust.distance.costs import compare_costs_linear, compare_costs_mc


def _refs(cfg):
    ids = list(cfg.target_ids)
    rl = cfg.reference_lengths
    return [(ids.index(a), ids.index(b)) for a, b in zip(rl.target_a, rl.target_b)]


def test_weighted_distance_cost_is_never_worse_than_eq6():
    for cfg in (configs.small_volume(), configs.large_volume()):
        c = compare_costs_linear(cfg.station_xyz_m, cfg.target_xyz_m, cfg.offset_m, 4.7e-6)
        # BLUE: the variance of any linear function is not larger (1e-9 relative: rounding)
        assert np.all(c.u_pairs_distance <= c.u_pairs_squared * (1 + 1e-9))
        assert np.all(c.u_offsets_distance <= c.u_offsets_squared * (1 + 1e-9))
    # and the difference matters where distances spread (0.34-11.54 m): > 5 % on the RMS
    big = compare_costs_linear(cfg.station_xyz_m, cfg.target_xyz_m, cfg.offset_m, 4.7e-6)
    ratio = np.sqrt(np.mean(big.u_pairs_squared ** 2) / np.mean(big.u_pairs_distance ** 2))
    assert ratio > 1.05


def test_linear_uncertainties_match_monte_carlo():
    cfg = configs.large_volume()
    pairs = _refs(cfg)
    lin = compare_costs_linear(cfg.station_xyz_m, cfg.target_xyz_m, cfg.offset_m, 4.7e-6, pairs=pairs)
    n = 60
    rms_p, rms_o = compare_costs_mc(cfg.station_xyz_m, cfg.target_xyz_m, cfg.offset_m, 4.7e-6,
                                    trials=n, rng=7, pairs=pairs)
    # n * (rms / u)^2 ~ chi2(n) for each quantity (gaussian, linear regime); two-sided at 0.1 %
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], n)
    for rms, u in ((rms_p[0], lin.u_pairs_distance), (rms_p[1], lin.u_pairs_squared),
                   (rms_o[0], lin.u_offsets_distance), (rms_o[1], lin.u_offsets_squared)):
        q = n * (rms / u) ** 2
        assert np.all((lo < q) & (q < hi)), q
