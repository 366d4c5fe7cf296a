"""Laser trackers in instrument files (issue 15 item 2, distances): ``[trackers.NAME]`` in the maker's
MPE form beside the heads; a tracker's distances get σ = std_per_mpe × (a + b L) (closed form checked
here), the heads' distances keep the distance model, the σ source names both, and what has no model
(the tracker's error draws for ``--noise model``) is refused in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from multilat import budget
from multilat.cli import main
from multilat.errors import MultilatError
from multilat.instrument import load_instrument
from multilat.network.io.files import read_observations
from multilat.network.synthetic.generator import synthetic_network

INST = Path(__file__).resolve().parents[1] / "examples" / "instruments" / "heads_and_trackers.toml"


def _mixed_file(tmp_path):
    """A random network whose stations S1, S2 are called AT1, AT2 (trackers), the others heads H3..;
    no sigma_m column: σ from the instrument."""
    net = synthetic_network(np.random.default_rng([15, 40]), n_stations=(6, 6), n_targets=(14, 14))
    o = net.obs
    names = ["AT1", "AT2"] + [f"H{i + 1}" for i in range(2, o.n_stations)]
    p = tmp_path / "mixed.csv"
    p.write_text("station,target,distance_m\n" + "".join(
        f"{names[i]},{o.target_ids[j]},{float(d)!r}\n" for i, j, d in zip(o.station_index, o.target_index, o.distance_m)))
    return p, names


def test_tracker_sigma_is_the_mpe_closed_form(tmp_path):
    p, names = _mixed_file(tmp_path)
    inst = load_instrument(INST)
    src: dict = {}
    obs = read_observations(p, instrument=inst, sigma_source=src)
    st = np.array(obs.station_ids)[obs.station_index]
    for t in ("AT1", "AT2"):
        sel = st == t
        L = obs.distance_m[sel]
        np.testing.assert_allclose(obs.sigma_m[sel], 0.5 * (10.0 + 0.3 * L) * 1e-6, rtol=1e-15)
    sel = st == "H3"
    np.testing.assert_array_equal(obs.sigma_m[sel], budget.distance_std_m(inst, obs.distance_m[sel], head="H3"))
    assert src["trackers"]["AT1"]["tracker"] == "AT1" and "AT1" not in src["heads"]
    assert src["heads"]["H3"] == "H3"
    # angles: the transverse MPE over the range, per the same specification
    spec = inst.trackers["AT1"].spec()
    np.testing.assert_allclose(spec.angle_sigma_rad(5.0), 0.5 * (15.0 + 6.0 * 5.0) * 1e-6 / 5.0)
    assert not inst.trackers["AT1"].levelled and not inst.trackers["AT2"].levelled


def test_cli_adjust_with_trackers_and_heads(tmp_path, capsys):
    p, _ = _mixed_file(tmp_path)
    assert main(["adjust", str(p), "--instrument", str(INST), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc["sigma_source"]["trackers"]) == {"AT1", "AT2"}
    assert main(["adjust", str(p), "--instrument", str(INST)]) == 0
    out = capsys.readouterr().out
    assert "tracker AT1 MPE" in out
    # the Monte Carlo: gaussian with the trackers' σ runs; the distance model is refused in one line
    assert main(["propagate", str(p), "--instrument", str(INST), "--noise", "gaussian", "--trials", "500",
                 "--json"]) == 0
    capsys.readouterr()
    assert main(["propagate", str(p), "--instrument", str(INST), "--trials", "500"]) == 2
    err = capsys.readouterr().err
    assert "laser tracker 'AT1'" in err and err.count("\n") == 1


@pytest.mark.parametrize("edit,match", [
    ("adm_a_um = 10.0", "adm_a_um = -1.0"),
    ("std_per_mpe = 0.5\nlevelled = false", "std_per_mpe = 2.0\nlevelled = false"),
])
def test_bad_tracker_spec_is_one_line(tmp_path, capsys, edit, match):
    text = INST.read_text().replace(edit, match, 1)
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(MultilatError) as e:
        load_instrument(f)
    msg = str(e.value)
    assert "trackers" in msg and "AT1" in msg and "\n" not in msg


def test_tracker_named_like_a_head_is_refused(tmp_path):
    text = INST.read_text().replace("[trackers.AT2]", "[heads.AT1]\na_limit_m = 1e-4\nc_limit_m = 1e-4\n"
                                    "alpha_deg = [0, 0.1]\ngamma_deg = [0, 0.1]\ntoh_m = 0\ntoh_std_m = 1e-6\n\n"
                                    "[trackers.AT2]")
    f = tmp_path / "clash.toml"
    f.write_text(text)
    with pytest.raises(MultilatError, match="'AT1' is also a head"):
        load_instrument(f)


def test_tracker_angles_get_their_sigma_from_the_specification(tmp_path):
    """The mixed example without its σ columns, read with the instrument: the trackers' angles become
    observations with σ = std_per_mpe · (a + b L) / L (closed form), equal to the shipped columns
    (written from the same specification at the true range); the heads' rows have no angles."""
    ex = Path(__file__).resolve().parents[1] / "examples" / "network" / "mixed" / "obs.csv"
    lines = ex.read_text().splitlines()
    hdr = lines[0].split(",")
    keep = [i for i, c in enumerate(hdr) if c not in ("sigma_azimuth_rad", "sigma_elevation_rad")]
    p = tmp_path / "no_sigma.csv"
    p.write_text("\n".join(",".join(r.split(",")[i] for i in keep) for r in lines) + "\n")
    src: dict = {}
    obs = read_observations(p, instrument=load_instrument(INST), sigma_source=src)
    ref = read_observations(ex)
    tr = np.isfinite(ref.sigma_azimuth_rad)
    L = obs.distance_m[tr]
    np.testing.assert_allclose(obs.sigma_azimuth_rad[tr], 0.5 * (15.0 + 6.0 * L) * 1e-6 / L, rtol=1e-15)
    # the generator took the true range, the reader the measured distance (µm apart over metres)
    np.testing.assert_allclose(obs.sigma_elevation_rad[tr], ref.sigma_elevation_rad[tr], rtol=1e-5)
    assert np.all(np.isnan(obs.sigma_azimuth_rad[~tr])) and "angles" in src
    # without the instrument: the angles stay initial values only
    assert read_observations(p).sigma_azimuth_rad is None
