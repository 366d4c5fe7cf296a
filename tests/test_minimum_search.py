"""The minimum search (issue 10, item 4): random networks from multilat.network.synthetic.generator adjusted
from distances alone reach the minimum of the solver started from the truth, or are warned."""

import functools

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.synthetic.generator import STATION_LAYOUTS, TARGET_LAYOUTS, synthetic_network
from multilat.network.adjust.approximate import search as search_module
from multilat.network.adjust.approximate.search import find_minimum, needs_search


def _net(k):
    return synthetic_network(np.random.default_rng([2024, k]))


def _datum_free_gap(a, b):
    """Largest difference of all interpoint distances and offsets (frame and mirror free), m."""
    P = np.vstack([a.station_xyz_m, a.target_xyz_m])
    Q = np.vstack([b.station_xyz_m, b.target_xyz_m])
    dp = np.linalg.norm(P[:, None] - P[None], axis=2)
    dq = np.linalg.norm(Q[:, None] - Q[None], axis=2)
    return max(np.abs(dp - dq).max(), np.abs(a.offset_m - b.offset_m).max())


def _outcome(net):
    """'reached' | 'warned' | 'refused' (MultilatError) | 'silent' (a wrong minimum, no warning),
    or None when the solver started from the truth fails itself (no reference). ``adjust`` runs the
    minimum search itself."""
    try:
        ref = adjust(net.obs, initial=net, snooping=False)
    except MultilatError:
        return None, None
    try:
        with _quiet():
            res = adjust(net.obs, snooping=False, rng=0)
    except MultilatError:
        return "refused", None
    if abs(res.sigma0 - ref.sigma0) <= 1e-6 * ref.sigma0:
        return "reached", res
    return ("warned" if any("false minimum" in w for w in res.warnings) else "silent"), res


def _quiet():
    import warnings

    cm = warnings.catch_warnings()
    cm.__enter__()
    warnings.simplefilter("ignore")

    class _Ctx:
        def __enter__(self):
            return self

        def __exit__(self, *a):
            cm.__exit__(*a)

    return _Ctx()


# ------------------------------------------------------------------------------- the generator


def test_generator_is_seeded_and_within_its_ranges():
    a, b = _net(3), _net(3)
    np.testing.assert_array_equal(a.obs.distance_m, b.obs.distance_m)
    seen_layouts = set()
    for k in range(60):
        net = _net(k)
        s, t = net.obs.n_stations, net.obs.n_targets
        assert 4 <= s <= 10 and 12 <= t <= 60 and 2.0 <= net.extent_m <= 20.0
        assert 0.0 <= net.gap_fraction <= 0.3
        per_target = np.bincount(net.obs.target_index, minlength=t)
        per_station = np.bincount(net.obs.station_index, minlength=s)
        assert per_target.min() >= 4 and per_station.min() >= 5
        assert np.abs(net.offset_m).max() <= 5e-3
        # the observations are the truth plus noise of 5 µm (independent recomputation)
        rho = np.linalg.norm(net.station_xyz_m[net.obs.station_index]
                             - net.target_xyz_m[net.obs.target_index], axis=1)
        e = net.obs.distance_m - rho - net.offset_m[net.obs.station_index]
        assert np.abs(e).max() < 6 * 5e-6
        clearance = np.linalg.norm(net.target_xyz_m[:, None] - net.station_xyz_m[None], axis=2).min()
        assert clearance >= max(0.2, 0.05 * net.extent_m) - 1e-12
        seen_layouts.add((net.station_layout, net.target_layout))
    assert {sl for sl, _ in seen_layouts} == set(STATION_LAYOUTS)
    assert {tl for _, tl in seen_layouts} == set(TARGET_LAYOUTS)


def test_generator_flat_ring_has_heads_near_one_height():
    net = synthetic_network(5, station_layout="ring", n_stations=8, extent_m=10.0)
    z = net.station_xyz_m[:, 2]
    assert np.ptp(z) <= 0.6 and abs(z.mean() - 1.5) < 0.3
    with pytest.raises(MultilatError, match="station_layout"):
        synthetic_network(5, station_layout="dome")


# ------------------------------------------------------------------------------- the search


def test_search_not_triggered_at_the_least_squares_minimum():
    net = _net(0)
    ref = adjust(net.obs, initial=net, snooping=False)
    assert not needs_search(ref, net.obs)
    ms = find_minimum(net.obs, lambda s: adjust(net.obs, initial=s, snooping=False), ref, rng=0)
    assert not ms.triggered and ms.candidates == () and ms.solution is ref and ms.warning is None


def test_search_escapes_a_wrong_minimum_of_a_flat_ring():
    """Network 87: a 7-station flat ring whose initial values put targets on the wrong side of the
    stations' plane; the first adjustment converges at sigma0 ~ 130; the search (run by adjust
    itself) reaches the minimum of the solver started from the truth (sigma0 1.047), interpoint
    distances and offsets within 1e-7 m, and the JSON block says what was tried."""
    net = _net(87)
    ref = adjust(net.obs, initial=net, snooping=False)
    res = adjust(net.obs, snooping=False, rng=0)
    search = res.initial["search"]
    assert search["search_triggered"] and search["warning"] is None
    assert search["first_cost"] > 100 * res.dof                      # sigma0 > 10 before the search
    assert abs(res.sigma0 - ref.sigma0) <= 1e-6 * ref.sigma0
    assert _datum_free_gap(res, ref) < 1e-7
    accepted = [c for c in search["tried"] if c["accepted"]]
    assert accepted and accepted[-1]["cost"] == pytest.approx(search["cost"])
    assert not any("false minimum" in w for w in res.warnings)
    # find_minimum on its own, from a solution known to be wrong: the same minimum. The wrong
    # solution is adjust's first fit from a mirrored start, its own search skipped (max_rounds=0):
    # that search tries 25 starts, finds none lower (the same sigma0 85.19457112752276, measured) and
    # was a quarter of this test's time (issue 29)
    with pytest.MonkeyPatch.context() as mp, pytest.warns(UserWarning, match="false minimum"):
        mp.setattr(search_module, "find_minimum", functools.partial(find_minimum, max_rounds=0))
        first = adjust(net.obs, snooping=False, initial=_mirrored_start(net, ref))
    assert first.sigma0 > 10 and first.initial["search"]["tried"] == []
    ms = find_minimum(net.obs, lambda s: adjust(net.obs, initial=s, snooping=False), first, rng=1)
    assert abs(ms.solution.sigma0 - ref.sigma0) <= 1e-6 * ref.sigma0


def _mirrored_start(net, ref):
    """The truth with target 0 mirrored through the best-fit plane of its stations (a wrong start)."""
    from types import SimpleNamespace

    j = 0
    h = net.station_xyz_m[net.obs.station_index[net.obs.target_index == j]]
    c = h.mean(axis=0)
    nrm = np.linalg.svd(h - c)[2][-1]
    t = net.target_xyz_m.copy()
    t[j] = t[j] - 2 * np.dot(t[j] - c, nrm) * nrm
    return SimpleNamespace(station_xyz_m=net.station_xyz_m, target_xyz_m=t, offset_m=net.offset_m)


def test_search_that_fails_warns():
    """Network 331 (5-station flat ring, 13 clustered targets): no candidate reaches the minimum;
    the result carries a warning naming a possible false minimum instead of passing as ordinary."""
    net = _net(331)
    with pytest.warns(UserWarning, match="possible false minimum"):
        res = adjust(net.obs, snooping=False, rng=0)
    assert any("false minimum" in w for w in res.warnings)
    assert res.initial["search"]["cost"] <= res.initial["search"]["first_cost"]


def test_acceptance_30_networks():
    """The first 30 networks of the 1000-network study (the slow test below): none silent or refused,
    every one reaches the minimum of the solver started from the truth."""
    counts = {}
    for k in range(30):
        out, _ = _outcome(_net(k))
        counts[out] = counts.get(out, 0) + 1
    assert counts.get("silent", 0) == 0 and counts.get("refused", 0) == 0, counts
    assert counts["reached"] >= 0.995 * (30 - counts.get(None, 0)), counts


@pytest.mark.slow
def test_acceptance_1000_networks():
    """Measured (commit of this test): see docs/network.md, "The minimum search"."""
    counts = {}
    for k in range(1000):
        out, _ = _outcome(_net(k))
        counts[out] = counts.get(out, 0) + 1
    n = 1000 - counts.get(None, 0)
    assert counts.get("silent", 0) == 0, counts
    assert counts["reached"] + counts.get("warned", 0) >= 0.995 * n, counts
