"""The package's one generator of networks, :func:`multilat.network.synthetic.generator.synthetic_network`
(issue 27 item 4): the draws of the three generators it replaces kept bit for bit, and its options
checked against what they promise (sizes, coverage, gap rate, blunders, seeding)."""

from __future__ import annotations

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.synthetic.generator import POPULATIONS, synthetic_network


def _fingerprint(n):
    si, ti, d = n.station_index, n.target_index, n.distance_m
    return (len(n.station_xyz_m), len(n.target_xyz_m), len(si), int(np.sum(si * (np.arange(len(si)) % 97))),
            int(np.sum(ti * (np.arange(len(ti)) % 89))), float(d.sum()), float(d[-1]), float(n.station_xyz_m.sum()),
            float(n.target_xyz_m.sum()), float(n.offset_m.sum()))


#: fingerprints of networks drawn by the three generators this module replaced (generator.random_network,
#: simulate.random_network, large.synthetic_network, and generator.sequential_network / mixed_network),
#: measured at f64db4c with the old functions, and by the tests' own tests/network_truth.random_network
#: (measured at c3e65ec); the integers pin the observed pairs, the sums the draws
OLD = [
    (dict(rng=np.random.default_rng([2024, 0])),
     (5, 45, 222, 20796, 227287, 383.85801005350095, 1.3359041101079232, 0.7349663150903702, 6.0867057309533115,
      -0.002020468433550045)),
    (dict(rng=np.random.default_rng([2024, 1])),
     (10, 16, 145, 26965, 42703, 258.24545493865423, 2.05557249215669, 14.845803997473437, 5.754134672475522,
      0.0027712662665857774)),
    (dict(rng=10, n_stations=8, n_targets=(40, 40), gap_fraction=0.15, min_stations_per_target=3,
          station_layout="ring"),
     (8, 40, 267, 44858, 238426, 2591.923690468762, 12.822947436055163, 15.582885611009182, 126.53946495710642,
      0.005104205514121899)),
    (dict(rng=np.random.default_rng(0), population="well-conditioned"),
     (8, 23, 156, 24195, 68077, 278.75033789690804, 2.222872432952757, -0.6082446906872854, 9.672454460634599,
      0.021661361779473694)),
    (dict(rng=np.random.default_rng(1000), population="well-conditioned", n_stations=(8, 12),
          n_targets=(50, 200), gap_fraction=0.3),
     (10, 107, 770, 170255, 1822537, 1352.9219589328604, 2.268309169298722, 2.2296272825917924,
      -3.3352579152321375, -0.009329046542122061)),
    (dict(rng=9, population="rings", n_stations=8, n_targets=300, per_target=6, size_m=6.0),
     (8, 300, 1800, 297657, 11830806, 7514.167579028328, 1.6233915992564458, 7.1999999999999975,
      225.84665358482448, 0.019478346743551006)),
    (dict(rng=10, population="rings", n_stations=5, n_targets=40, per_target=4),
     (5, 40, 160, 14235, 139834, 2191.170684928943, 10.982668670938637, 11.999999999999996, 75.97999007226,
      0.0015421514450123823)),
    (dict(rng=2026, population="sequential"),
     (8, 16, 110, 20434, 29948, 325.5360074934946, 3.2583802928791754, 8.826803655301944, 3.1836676306836598,
      0.006823682191113846)),
    (dict(rng=2028, population="mixed"),
     (6, 14, 84, 12145, 24024, 214.72390190264338, 1.8277600383282, 27.53130681318424, 57.70729976734133,
      -0.001034348376610306)),
    # the tests' own generator it replaced (tests/network_truth.random_network, measured at c3e65ec)
    (dict(rng=7, population="shell", n_stations=6, n_targets=25, gap_fraction=0.2),
     (6, 25, 120, 12176, 56164, 257.8563984341612, 2.120616997897538, -1.205180614477881, -2.5972874113217266,
      -0.0034187577796137222)),
    (dict(rng=1, population="shell", n_stations=8, n_targets=40, gap_fraction=0.15),
     (8, 40, 268, 42355, 259293, 558.9521085753827, 1.9988786967819445, 4.2520859333592655, 2.3149436889001502,
      -0.003042313235883107)),
]


@pytest.mark.parametrize("kw, old", OLD, ids=[f"{k.get('population', 'field')}-{i}" for i, (k, _) in enumerate(OLD)])
def test_the_old_generators_draws_are_kept(kw, old):
    """Integers exact; sums to 1e-13 relative (a libm may round a cos or a sqrt differently by an ulp;
    a changed draw order moves them by 1e-1 or more)."""
    kw = dict(kw)
    new = _fingerprint(synthetic_network(kw.pop("rng"), **kw))
    assert new[:5] == old[:5]
    np.testing.assert_allclose(new[5:], old[5:], rtol=1e-13, atol=1e-16)


def test_old_extras_kept():
    seq = synthetic_network(2026, population="sequential")
    assert seq.obs.station_heads == ("T1", "T2") * 4 and seq.obs.target_ids[0] == "P1"
    mix = synthetic_network(2028, population="mixed")
    np.testing.assert_allclose([np.nansum(mix.obs.azimuth_rad), mix.orientation_rad.sum()],
                               [23.808603371959993, 0.9047642594027996], rtol=1e-13)
    lev = synthetic_network(2028, population="mixed", levelled=True)
    assert lev.obs.levelled == ("AT1", "AT2") and np.all(lev.orientation_rad[:, :2] == 0)
    np.testing.assert_array_equal(lev.orientation_rad[:, 2], mix.orientation_rad[:, 2])   # same draws


@pytest.mark.parametrize("population", list(POPULATIONS))
def test_distances_are_the_truth_plus_noise(population):
    """Every row against the truth it claims: ``|d - |H - T| - o| < 5.5 σ`` (gaussian noise; 5.5 σ has
    probability 4e-8 per row), ids and sizes consistent, ``obs`` the same arrays."""
    net = synthetic_network(np.random.default_rng([27, 4]), population=population,
                            **({"n_targets": 500} if population == "rings" else {}))
    o = net.obs
    for a in ("station_index", "target_index", "distance_m", "sigma_m"):
        np.testing.assert_array_equal(getattr(o, a), getattr(net, a))
    assert len(o.station_ids) == len(net.station_xyz_m) == len(net.offset_m)
    assert len(o.target_ids) == len(net.target_xyz_m)
    rho = np.linalg.norm(net.station_xyz_m[net.station_index] - net.target_xyz_m[net.target_index], axis=1)
    z = (net.distance_m - rho - net.offset_m[net.station_index]) / net.sigma_m
    assert np.abs(z).max() < 5.5 and 0.7 < z.std() < 1.3


def test_sizes_and_coverage_are_exact():
    f = synthetic_network(1, n_stations=7, n_targets=(33, 33), min_stations_per_target=5)
    seen = np.zeros((7, 33), int)
    np.add.at(seen, (f.station_index, f.target_index), 1)
    assert seen.max() == 1 and seen.sum(0).min() >= 5 and seen.sum(1).min() >= 5
    r = synthetic_network(2, population="rings", n_stations=12, n_targets=1000, per_target=5)
    assert r.distance_m.size == 5000
    st = r.station_index.reshape(1000, 5)
    assert np.all(np.diff(st, axis=1) > 0)                    # distinct stations, sorted
    assert np.all((st % 2 == 0).sum(1) == 2) and np.all(np.bincount(r.target_index) == 5)   # 2 low, 3 high
    assert r.gap_fraction == 1 - 5 / 12
    s = synthetic_network(3, population="sequential", heads=("A", "B", "C"), n_stations=9, n_targets=20)
    assert s.obs.station_heads == ("A", "B", "C") * 3
    np.testing.assert_array_equal(s.offset_m[:3], s.offset_m[3:6])          # one offset per head


@pytest.mark.parametrize("population, kw, p", [
    ("field", {"n_stations": 10, "n_targets": 300, "gap_fraction": 0.2}, 0.2),
    ("well-conditioned", {"n_stations": 12, "n_targets": 60, "gap_fraction": 0.3}, 0.3),
    ("sequential", {"n_stations": 10, "n_targets": 300, "gap_fraction": 0.25}, 0.25),
])
def test_gap_rate_within_the_binomial_bound(population, kw, p):
    """The observed fraction of unobserved pairs is within 4.5 binomial standard deviations of ``p``
    (probability 7e-6 of failing by chance; the rejection of masks leaving a target under-seen biases it by
    far less: P(Bin(10, 0.8) < 4) = 9e-4 per target)."""
    net = synthetic_network(np.random.default_rng([27, 9]), population=population, **kw)
    n = len(net.station_xyz_m) * len(net.target_xyz_m)
    missing = 1 - net.distance_m.size / n
    assert abs(missing - p) < 4.5 * np.sqrt(p * (1 - p) / n), (missing, p)


@pytest.mark.parametrize("population", list(POPULATIONS))
def test_blunders_exact_and_nothing_else_moves(population):
    kw = {"n_targets": 200} if population == "rings" else {}
    clean = synthetic_network(np.random.default_rng(5), population=population, **kw)
    bad = synthetic_network(np.random.default_rng(5), population=population, blunders=6, blunder_m=2e-3, **kw)
    assert bad.blunder_index.size == 6 == np.unique(bad.blunder_index).size and bad.blunder_m == 2e-3
    diff = bad.obs.distance_m - clean.obs.distance_m
    assert set(np.flatnonzero(diff)) == set(bad.blunder_index)
    np.testing.assert_allclose(np.abs(diff[bad.blunder_index]), 2e-3, rtol=1e-9)
    for a in ("station_xyz_m", "target_xyz_m", "offset_m", "station_index", "target_index"):
        np.testing.assert_array_equal(getattr(bad, a), getattr(clean, a))


def test_same_seed_same_network_and_the_split_does_not_matter():
    """A network depends on its seed only: drawn again, or as child ``k`` of a ``SeedSequence`` alone or
    among all children in any order, it is the same bit for bit; another seed gives another network."""
    a, b = (synthetic_network(np.random.default_rng(11), population="rings", n_targets=300) for _ in range(2))
    for x in ("station_index", "target_index", "distance_m", "target_xyz_m", "offset_m"):
        np.testing.assert_array_equal(getattr(a, x), getattr(b, x))
    kids = np.random.SeedSequence(27).spawn(6)
    all_ = [synthetic_network(k) for k in kids]
    rev = [synthetic_network(k) for k in reversed(np.random.SeedSequence(27).spawn(6))][::-1]
    alone = synthetic_network(np.random.SeedSequence(27).spawn(6)[4])
    for n, m in zip(all_, rev):
        np.testing.assert_array_equal(n.distance_m, m.distance_m)
    np.testing.assert_array_equal(alone.distance_m, all_[4].distance_m)
    c = synthetic_network(np.random.default_rng(12), population="rings", n_targets=300)
    assert not np.array_equal(a.distance_m, c.distance_m)


@pytest.mark.parametrize("kw, msg", [
    ({"population": "dome"}, "population must be one of"),
    ({"per_target": 4}, "population 'field' takes no option 'per_target'"),
    ({"population": "rings", "gap_fraction": 0.2}, "population 'rings' takes no option 'gap_fraction'"),
    ({"station_layout": "dome"}, "station_layout must be one of"),
    ({"population": "rings", "n_stations": 5, "per_target": 6}, "per_target must be in 3..n_stations"),
    ({"blunders": 10**6}, "blunders must be in 0.."),
    ({"blunders": 2, "blunder_m": 0.0}, "blunder_m must be > 0"),
    ({"gap_fraction": (0.5, 1.0)}, "gap_fraction must be below 1"),
    ({"population": "shell", "n_stations": 3}, "shell needs >= 4 stations"),
    ({"population": "shell", "offset_max_m": 1e-3}, "population 'shell' takes no option 'offset_max_m'"),
])
def test_bad_options_are_refused(kw, msg):
    with pytest.raises(MultilatError, match=msg.replace("(", r"\(").replace(".", r"\.")):
        synthetic_network(1, **kw)
