"""Data snooping of angle observations (issue 15 item 3: w-tests per observation type, and the
rejection that follows them).

Independent values: the planted blunder itself (which angle, how large), and a second adjustment of
the same data with that angle left out by hand (``σ = NaN``, no snooping), whose coordinates the
snooped adjustment must equal (1e-9 m: the same least-squares problem). False alarms: on clean
networks the angles rejected stay within the Poisson bound of the w-tests' α0.
"""

import json

import numpy as np
import pytest

from multilat.cli import main
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.io.files import write_observations

from angle_networks import SIG_ANGLE, mixed_with_angles


def _blunder(obs, k, kind, size):
    import dataclasses

    name = "azimuth_rad" if kind == "azimuth" else "elevation_rad"
    v = getattr(obs, name).copy()
    v[k] += size
    return dataclasses.replace(obs, **{name: v})


def _left_out(obs, k, kind):
    name = "sigma_azimuth_rad" if kind == "azimuth" else "sigma_elevation_rad"
    s = getattr(obs, name).copy()
    s[k] = np.nan
    sa, se = (s, obs.sigma_elevation_rad) if kind == "azimuth" else (obs.sigma_azimuth_rad, s)
    return obs.with_angle_sigma(sa, se)


@pytest.mark.parametrize("kind, which", [("azimuth", 4), ("elevation", 11)])
def test_a_planted_angle_blunder_is_rejected_and_the_rest_equals_the_adjustment_without_it(kind, which):
    net, obs, _ = mixed_with_angles(seed=3)
    k = int(np.flatnonzero(np.isfinite(obs.sigma_azimuth_rad))[which])
    bad = _blunder(obs, k, kind, 20 * SIG_ANGLE)
    res = adjust(bad, initial=net)
    assert [(a["station"], a["target"], a["kind"]) for a in res.angle_outliers] == [
        (obs.station_ids[obs.station_index[k]], obs.target_ids[obs.target_index[k]], kind)]
    a = res.angle_outliers[0]
    assert a["w"] > a["critical"] and a["step"] == 1 and a["test"] == "w"
    assert abs(a["residual_rad"] - 20 * SIG_ANGLE) < 4 * SIG_ANGLE      # the blunder, seen against the rest
    assert not res.outliers                                               # its row's distance is kept
    step = res.tests["steps"][0]                                         # adjust/3: the row by index and kind
    assert (step["index"], step["kind"]) == (k, kind) and a["index"] == k
    ref = adjust(_left_out(bad, k, kind), initial=net, snooping=False)
    assert res.dof == ref.dof and res.sigma0 == pytest.approx(ref.sigma0, rel=1e-9)
    np.testing.assert_allclose(res.target_xyz_m, ref.target_xyz_m, atol=1e-9)
    assert len(res.angles) == len(ref.angles)


def test_a_station_at_its_fewest_angles_has_no_redundancy_there_and_nothing_is_rejected():
    """S2 reads an azimuth and an elevation of one target and an azimuth of another: 3 angles to 2
    targets, the fewest its 3 orientation angles need. The orientation absorbs any error there
    (redundancy 0, w 0, MDB infinite), so a 50σ blunder is not seen and not rejected — the reliability
    report names the risk instead; one angle fewer is refused as unsolvable."""
    net, obs, _ = mixed_with_angles(seed=3)
    s2 = np.flatnonzero(obs.station_index == 1)
    sa = obs.sigma_azimuth_rad.copy()
    se = obs.sigma_elevation_rad.copy()
    sa[s2[2:]] = np.nan
    se[s2[1:]] = np.nan
    res = adjust(_blunder(obs.with_angle_sigma(sa, se), int(s2[0]), "azimuth", 50 * SIG_ANGLE), initial=net)
    assert not res.angle_outliers
    s2_angles = [a for a in res.angles if a["station"] == "S2"]
    assert len(s2_angles) == 3
    assert max(a["redundancy"] for a in s2_angles) < 1e-9 and all(a["mdb_rad"] == np.inf for a in s2_angles)
    se2 = se.copy()
    sa2 = sa.copy()
    sa2[s2[1]] = np.nan                        # 2 angles to one target: the roll about its line of sight is free
    from multilat.errors import MultilatError
    with pytest.raises(MultilatError, match="station 'S2' has 2 angle observation.* to 1 target.*needs at least 3, to 2"):
        adjust(obs.with_angle_sigma(sa2, se2), initial=net)


def test_angles_are_rarely_rejected_on_clean_networks():
    """10 clean mixed networks (520 angles): rejected angles <= the Poisson 99.9 % bound of α0 · n
    (α0 = 0.001: expected 0.5, bound 4)."""
    n_rej, n_ang = 0, 0
    for seed in range(20, 30):
        net, obs, _ = mixed_with_angles(seed=seed)
        res = adjust(obs, initial=net)
        n_rej += len(res.angle_outliers)
        n_ang += 2 * int(np.isfinite(obs.sigma_azimuth_rad).sum())
    assert n_ang == 520
    assert n_rej <= 4


def test_cli_reports_rejected_angles(tmp_path, capsys):
    net, obs, _ = mixed_with_angles(seed=3)
    k = int(np.flatnonzero(np.isfinite(obs.sigma_azimuth_rad))[4])
    p = tmp_path / "bad.csv"
    write_observations(p, _blunder(obs, k, "azimuth", 20 * SIG_ANGLE))
    assert main(["adjust", str(p), "--json", "--observations"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [(a["station"], a["target"], a["kind"]) for a in doc["angle_outliers"]] == [("S1", "T5", "azimuth")]
    # adjust/3: the angle's row of the observations table, named the same way by its snooping step
    a = doc["angle_outliers"][0]
    row = doc["observations"][a["index"]]
    assert a["index"] == k and (row["index"], row["station"], row["target"]) == (k, "S1", "T5")
    assert [(s["index"], s["kind"]) for s in doc["tests"]["steps"] if s["action"] == "rejected"] == [(k, "azimuth")]
    assert main(["adjust", str(p)]) == 0
    out = capsys.readouterr().out
    assert "rejected angles, in order:" in out and "S1->T5 azimuth: w = +" in out
