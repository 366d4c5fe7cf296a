"""Unit slips and bounded searches (issue 25, items 1, 2 and 8): the rule of
:mod:`multilat.network.adjust.distance.unit_slip`, the bounds of :mod:`multilat.network.adjust.approximate.bounds`, the control-scale
check, the instrument's metres keys, and the messages of the starts and the scale datum."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.adjust.approximate.bounds import Bound, reporting
from multilat.network.model.data import Observations, Points
from multilat.network.io.files import read_observations
from multilat.network.adjust.distance.unit_slip import SLIP_FACTOR, UnitSlipError, likely_unit
from multilat.network.synthetic.generator import synthetic_network
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "network" / "small_volume_obs.csv"


def _scaled(obs, *, distance=1.0, sigma=1.0):
    return Observations(obs.station_ids, obs.target_ids, obs.station_index, obs.target_index,
                        obs.distance_m * distance, obs.sigma_m * sigma)


@pytest.fixture(scope="module")
def example():
    """The example network and its adjustment (σ0 1.199 on 4 dof)."""
    obs = read_observations(EXAMPLE)
    return obs, adjust(obs, rng=0)


# ----------------------------------------------------------------------------- the rule


def test_likely_unit_is_the_nearest_within_half_a_decade():
    assert likely_unit(1199.0) == (1e3, "mm")
    assert likely_unit(8.3e5) == (1e6, "µm")        # log10 5.92: within 0.5 of 6
    assert likely_unit(150.0) == (1e2, "cm")
    assert likely_unit(30.0) is None                # 10^1.48: more than half a decade from 10^2
    assert likely_unit(1e4) is None                 # 10^4: a decade from mm and from µm
    assert likely_unit(float("nan")) is None


def test_distances_in_mm_stop_with_the_factor(example):
    """Distances x1000, σ unchanged: the same network 1000 times larger, every residual 1000 times
    its old value, so σ0 is exactly 1000 x that of the valid file (the message shows 4 digits)."""
    obs, ref = example
    with pytest.raises(UnitSlipError, match="distance_m in mm while sigma_m is in metres") as e:
        adjust(_scaled(obs, distance=1000.0), rng=0)
    assert f"~{1000 * ref.sigma0:.0f}x sigma" in str(e.value)
    assert e.value.source == "observations"


def test_sigma_in_um_stops_naming_the_column(example):
    """σ x1e6 (µm written in sigma_m): σ0 is exactly 1e-6 x that of the valid file."""
    obs, ref = example
    with pytest.raises(UnitSlipError, match="sigma_m written in µm") as e:
        adjust(_scaled(obs, sigma=1e6), rng=0)
    assert f"sigma0 {1e-6 * ref.sigma0:.3g}" in str(e.value)


def test_sigma_from_the_option_is_named(example):
    obs, _ = example
    with pytest.raises(UnitSlipError, match="--sigma-um"):
        adjust(_scaled(obs, sigma=1e6), rng=0, sigma_source={"kind": "--sigma-um", "sigma_m": 4.7})


def test_unknown_variance_factor_accepts_the_factor(example):
    """The way out the message gives: σ0 estimated, the same adjustment scaled (σ0 x 1e-6)."""
    obs, ref = example
    res = adjust(_scaled(obs, sigma=1e6), rng=0, variance_factor="unknown")
    assert res.sigma0 == pytest.approx(1e-6 * ref.sigma0, rel=1e-6)    # the same solution, σ x 1e6


def test_factor_below_the_threshold_is_not_a_slip(example):
    """σ 30 times too small (σ0 ~ 36 < SLIP_FACTOR): an ordinary failed global test, no stop."""
    obs, _ = example
    assert 30 * 1.2 < SLIP_FACTOR
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = adjust(_scaled(obs, sigma=1 / 30), rng=0, snooping=False)
    assert res.sigma0 == pytest.approx(30 * 1.199, rel=1e-3)


@pytest.mark.parametrize("blunders", [{17: 20e-3}, {17: 20e-3, 60: -15e-3, 90: 30e-3}])
def test_gross_errors_are_not_a_slip(blunders):
    """One to three blunders of 15-30 mm (3000-6000 σ) among 6 x 20 distances: σ0 388-542, above the
    factor, and their misfit smears into the other residuals (robust scale 150-300); but the robust
    scale stays below SPREAD_MIN x σ0, so no unit-slip stop: data snooping rejects them, each with
    its blunder as residual (to 50 µm: 10 σ, the blunders' own effect on the fit is below that)."""
    net = synthetic_network(3, population="shell", n_stations=6, n_targets=20)
    obs = net.obs
    d = obs.distance_m.copy()
    for k, b in blunders.items():
        d[k] += b
    bad = Observations(obs.station_ids, obs.target_ids, obs.station_index, obs.target_index, d, obs.sigma_m)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        first = adjust(bad, rng=0, snooping=False, variance_factor="unknown")
        res = adjust(bad, rng=0)
    assert first.sigma0 > SLIP_FACTOR
    got = {(o.station, o.target): o.residual_m for o in res.outliers}
    want = {(obs.station_ids[obs.station_index[k]], obs.target_ids[obs.target_index[k]]): b
            for k, b in blunders.items()}
    assert set(got) == set(want)
    for key, b in want.items():
        assert got[key] == pytest.approx(b, abs=50e-6)


# ----------------------------------------------------------------------------- bounds


class _Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def test_bound_stops_on_work_then_says_so():
    b = Bound("x", max_work=3, max_seconds=10, clock=_Clock())
    n = 0
    while not b.exhausted():
        b.spend()
        n += 1
    assert n == 3 and b.stopped_by == "work" and "work bound (3 starts)" in b.note()


def test_bound_stops_on_wall_time_and_warns():
    clock = _Clock()
    b = Bound("restarts", max_work=100, max_seconds=5, clock=clock)
    b.spend()
    assert not b.exhausted()
    clock.t += 5.0
    assert b.exhausted() and b.stopped_by == "time"
    with pytest.warns(UserWarning, match="restarts: stopped at its wall-time bound"):
        b.warn_if_timed_out()


def test_bound_takes_the_earlier_deadline():
    clock = _Clock()
    b = Bound("inner", max_work=10, max_seconds=60, deadline=103.0, clock=clock)
    assert b.deadline == 103.0


def test_levenberg_marquardt_stops_at_a_passed_deadline():
    """A deadline already passed: no iteration, the start returned as it was."""
    import time

    from multilat.network.adjust.approximate.initial_refine import levenberg_marquardt

    x0 = np.array([3.0, -1.0])
    x, conv = levenberg_marquardt(lambda x: x - 1.0, lambda x: np.eye(2), x0,
                                  deadline=time.monotonic() - 1.0)
    assert np.array_equal(x, x0) and not conv.converged and conv.reason == "wall-time bound"
    x, conv = levenberg_marquardt(lambda x: x - 1.0, lambda x: np.eye(2), x0)
    assert np.allclose(x, 1.0) and conv.converged       # without it: the minimum (x = 1)


def test_restarts_end_when_a_far_minimum_is_found_again(example):
    """Distances in mm: the blocks' minimum is ~320 RMS σ; the first random restart reaches it
    again (same RMS to 1e-6) and the restarts stop (before: all 20 ran). The minimum is the valid
    network's scaled by 1000 (RMS residual 1000 x)."""
    from multilat.network.adjust.approximate.initial import initial_values

    obs, _ = example
    good = initial_values(obs, rng=0)
    steps = []
    with reporting(steps.append):
        iv = initial_values(_scaled(obs, distance=1000.0), rng=0)
    assert iv.far_minimum_again and not good.far_minimum_again
    assert steps == ["initial values: random start 1 of 20"]
    assert iv.rms_residual_m == pytest.approx(1000 * good.rms_residual_m, rel=1e-6)


def test_minimum_search_records_its_bound(example):
    """A work bound of 2 starts: the search stops there and says so in its record.

    The first solution is the example's adjustment with σ 300 times too small: the same minimum (a
    common factor on σ does not move it), σ0 300 x 1.199 ~ 360, so the search is triggered. The
    solver hands that solution back for every start (no start improves on it): only the bound can
    end the search, after exactly 2 solves. (It used to run the full adjustment, which searched
    again inside each solve: 10 s for a test of the bound's bookkeeping.)"""
    from types import SimpleNamespace

    from multilat.network.adjust.approximate.search import find_minimum

    obs, ref = example
    bad = _scaled(obs, sigma=1 / 300)
    first = SimpleNamespace(station_xyz_m=ref.station_xyz_m, target_xyz_m=ref.target_xyz_m, offset_m=ref.offset_m,
                            sigma0=300 * ref.sigma0, dof=ref.dof)
    starts = []
    ms = find_minimum(bad, lambda s: starts.append(s) or first, first, rng=0, max_solves=2)
    assert ms.triggered and len(ms.candidates) == 2 and len(starts) == 2
    assert ms.bounded == "minimum search: stopped at its work bound (2 starts)"
    assert ms.as_dict()["bounded"] == ms.bounded


# ----------------------------------------------------------------------------- item 8


def test_control_in_mm_names_the_points(example):
    """Control coordinates x1000: the median ratio of control-derived to observed lengths is ~1000
    (offsets of ~1 mm on 0.5-1 m distances keep it within 0.3 %)."""
    obs, ref = example
    ids = list(obs.station_ids) + ["1", "2"]
    xyz = np.vstack([ref.station_xyz_m, ref.target_xyz_m[:2]]) * 1000.0
    with pytest.raises(UnitSlipError, match=r"control coordinates are ~99\dx larger.*x_m, y_m, z_m in mm") as e:
        adjust(obs, datum="control", points=Points(tuple(ids), xyz), rng=0)
    assert e.value.source == "points"


def test_control_scale_from_spacings_when_no_pair_is_given(example):
    """Control on targets only: the scale is compared with the targets' spacings from the
    distances; a control file in metres passes, in mm it is refused."""
    from multilat.network.adjust.distance.fit import check_control_scale

    obs, ref = example
    ids = ("1", "2", "3", "4")
    T = ref.target_xyz_m[:4]
    sx, tx = ref.station_xyz_m + 5.0, ref.target_xyz_m + 5.0        # another frame, same scale
    check_control_scale(obs, set(ids), Points(ids, T), sx, tx)
    with pytest.raises(UnitSlipError, match="~1e\\+03x larger|~1000x larger"):
        check_control_scale(obs, set(ids), Points(ids, T * 1000.0), sx, tx)


@pytest.mark.parametrize("path,value,key", [
    (("head_common", "beam_offset_m"), [-320, 320], "head_common.beam_offset_m"),
    (("target", "tot_m"), 11, "target.tot_m"),
    (("heads", "B", "a_limit_m"), 310, "heads.B.a_limit_m"),
    (("adm", "am_pm_m_per_db"), -0.15, "adm.am_pm_m_per_db"),
])
def test_instrument_metres_key_holding_micrometres(path, value, key):
    import tomllib
    from importlib import resources

    from multilat.instrument import parse_instrument

    data = tomllib.loads(resources.files("multilat").joinpath("presets", "seed2020.toml").read_text("utf-8"))
    node = data
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    with warnings.catch_warnings():
        warnings.simplefilter("error")                    # no numpy warning on the way
        with pytest.raises(MultilatError, match=rf"^my\.toml: {key.replace('.', '[.]')}: must lie within .*µm"):
            parse_instrument(data, source="my.toml")


def test_starts_message_when_no_target_is_seen_by_four():
    from multilat.network.adjust.approximate.starts import initial_from_distances

    net = synthetic_network(2, population="shell", n_stations=4, n_targets=12)
    o = net.obs
    keep = o.station_index != (o.target_index % 4)            # each target loses one station
    sub = o.subset(keep)
    with pytest.raises(MultilatError, match=r"4 or more stations see \(0 of 12 targets"):
        initial_from_distances(sub, 0)


def test_scale_datum_hint_uses_accepted_options(example):
    obs, _ = example
    with pytest.raises(MultilatError) as e:
        adjust(obs, scales=True, rng=0)
    msg = str(e.value)
    assert "--scales A,B" not in msg and "--scales --fixed-scale HEAD" in msg
