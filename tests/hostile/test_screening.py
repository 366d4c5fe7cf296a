"""network/io/screening.py: gross errors named as suspect rows before the adjustment."""

from __future__ import annotations

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.model.data import Observations
from multilat.network.io.files import read_observations
from multilat.network.io.screening import screen_observations, suspect_rows

from conftest import BASE


@pytest.fixture
def obs():
    return read_observations(BASE["obs.csv"])


def _with(obs, k, *, d=None, s=None):
    dist = obs.distance_m.copy()
    sig = obs.sigma_m.copy()
    if d is not None:
        dist[k] = d
    if s is not None:
        sig[k] = s
    return Observations(obs.station_ids, obs.target_ids, obs.station_index, obs.target_index, dist, sig)


def test_clean_network_passes(obs):
    assert suspect_rows(obs) == []
    screen_observations(obs)


@pytest.mark.parametrize("k,d,s,why", [
    (5, 1e300, None, "absurd"),
    (7, None, 1e-300, "below"),
    (9, None, 1e9, "absurd"),
    (11, "mm", None, "median"),
    (3, "x10", None, "median"),
])
def test_gross_error_named(obs, k, d, s, why):
    if d == "mm":
        d = obs.distance_m[k] * 1000
    elif d == "x10":
        d = obs.distance_m[k] * 10
    bad = _with(obs, k, d=d, s=s)
    rows = suspect_rows(bad)
    assert [r for r, _ in rows] == [k]
    assert why in rows[0][1]
    sid = obs.station_ids[obs.station_index[k]]
    tid = obs.target_ids[obs.target_index[k]]
    with pytest.raises(MultilatError, match=f"row {k + 1} {sid}->{tid}"):
        screen_observations(bad)


def test_a_metre_blunder_is_left_to_data_snooping(obs):
    assert suspect_rows(_with(obs, 4, d=obs.distance_m[4] + 1.0)) == []


def test_many_rows_are_counted(obs):
    d = obs.distance_m.copy()
    d[[0, 5, 10, 15, 20, 25]] *= 1000
    bad = Observations(obs.station_ids, obs.target_ids, obs.station_index, obs.target_index, d, obs.sigma_m)
    with pytest.raises(MultilatError, match=r"\(\+3 more\)"):
        screen_observations(bad)


def test_a_whole_target_in_mm(obs):
    d = obs.distance_m.copy()
    rows = np.flatnonzero(obs.target_index == 0)
    d[rows] *= 1000
    bad = Observations(obs.station_ids, obs.target_ids, obs.station_index, obs.target_index, d, obs.sigma_m)
    assert [r for r, _ in suspect_rows(bad)] == rows.tolist()


def test_file_lines_named(obs):
    bad = _with(obs, 0, d=1e300)
    with pytest.raises(MultilatError, match="obs.csv:4 A->1"):
        screen_observations(bad, source="obs.csv", line_numbers=list(range(4, 4 + obs.n_obs)))


def test_cli_names_the_row_not_the_geometry(ws):
    p = ws / "obs.csv"
    lines = p.read_text().splitlines()
    cells = lines[6].split(",")
    cells[2] = str(float(cells[2]) * 1000)          # one distance in mm among metres
    lines[6] = ",".join(cells)
    p.write_text("\n".join(lines) + "\n")
    line = ws.fails(["adjust", "{d}/obs.csv"], "obs.csv:7", "suspect")
    assert "degenerate" not in line and "condition" not in line
    ws.fails(["propagate", "{d}/obs.csv", "--trials", "100"], "obs.csv:7", "suspect")


def test_group_medians_match_numpy():
    from multilat.network.io.screening import _group_medians

    rng = np.random.default_rng(3)
    g = rng.integers(0, 7, 200)
    v = rng.random(200)
    med = _group_medians(v, g, 8)
    for t in range(7):
        assert med[t] == pytest.approx(np.median(v[g == t]))
    assert np.isnan(med[7])
