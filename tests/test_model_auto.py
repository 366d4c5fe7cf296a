"""``multilat adjust`` without ``--model`` (``auto``): the distance-only path, and the general layer for
a network its counting rules refuse — said in one warning and the JSON's notes, never silently; an
option the general layer cannot honour keeps the refusal (with the hint); the dense general back
end refuses, in one line, a network larger than it takes (never a silent hour of SVDs)."""

import json

import numpy as np
import pytest

from multilat.cli.app import main
from multilat.errors import MultilatError

EX = "examples/general/two_trackers_csv/obs.csv"


class _Ran:
    def __init__(self, capsys, args):
        self.exit_code = main(["adjust", *map(str, args)])
        out = capsys.readouterr()
        self.stdout, self.output = out.out, out.out + out.err


@pytest.fixture
def _adjust(capsys):
    return lambda *args: _Ran(capsys, args)


def test_auto_adjusts_two_trackers_by_the_general_model_and_says_so(_adjust):
    r = _adjust(EX, "--levelled", "T1,T2", "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["model"] == "general" and doc["dof"] == 39
    assert "needs at least 3 stations" in doc["notes"][0]
    gen = json.loads(_adjust(EX, "--levelled", "T1,T2", "--json", "--model", "general").stdout)
    assert doc["sigma0"] == gen["sigma0"] and doc["points"] == gen["points"]


def test_multilateration_alone_still_refuses_with_the_hint(_adjust):
    r = _adjust(EX, "--levelled", "T1,T2", "--model", "multilateration")
    assert r.exit_code == 2
    assert "needs at least 3 stations" in r.output and "--model general adjusts" in r.output


def test_an_option_the_general_layer_lacks_keeps_the_refusal(_adjust, tmp_path):
    r = _adjust(EX, "--levelled", "T1,T2", "--mdb-limit-sigma", "8", "--out", tmp_path / "res")
    assert r.exit_code == 2
    assert "needs at least 3 stations" in r.output and "--mdb-limit-sigma not available there" in r.output
    assert not (tmp_path / "res").exists()


def test_auto_fallback_writes_the_general_report(_adjust, tmp_path):
    """--report on the general layer (refused there before): the general report, its numbers the
    JSON's (tests/test_general_report.py checks them cell by cell)."""
    r = _adjust(EX, "--levelled", "T1,T2", "--report", tmp_path / "rep.html", "--json")
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["model"] == "general"
    page = (tmp_path / "rep.html").read_text("utf-8")
    assert "General network adjustment" in page and 'id="verdicts"' in page and 'id="parameters"' in page


def test_an_accepted_network_stays_on_the_distance_path(_adjust):
    r = _adjust("examples/network/small_volume_obs.csv", "--json")
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["schema"].startswith("multilat.adjust/")


def test_dense_general_back_end_refuses_a_network_larger_than_it_takes(monkeypatch):
    """The bound is checked before approximate coordinates or any SVD: one line naming the sizes."""
    import importlib

    gadjust = importlib.import_module("multilat.network.adjust.general.adjust")   # the module, not the function
    from multilat.network.adjust.general import read_gama_input
    from multilat.network.adjust.general.run import adjust_network

    net = read_gama_input("tests/data/gama3d/two_trackers.xml")
    n_free = gadjust.System(net).n_free
    monkeypatch.setattr(gadjust, "MAX_DENSE_UNKNOWNS", n_free - 1)
    with pytest.raises(MultilatError, match=rf"at most {n_free - 1} unknowns; this network has {n_free} "):
        adjust_network(net)
    monkeypatch.setattr(gadjust, "MAX_DENSE_UNKNOWNS", n_free)
    assert adjust_network(net).result.dof > 0


@pytest.mark.parametrize("n_rows", [28, 10])
def test_null_space_economy_svd_equals_the_full_one(n_rows):
    """The economy SVD (no (R, R) U) gives the same null space as the full one: a free distance
    network's null space (defect 6 with all 28 pairs; 24 - 10 = 14 with 10 rows, fewer rows than
    unknowns) and the projector onto it."""
    from multilat.network.model.determinability import null_space

    rng = np.random.default_rng(3)
    pts = rng.uniform(-5, 5, (8, 3))
    pairs = [(i, j) for i in range(8) for j in range(i + 1, 8)][:n_rows]
    jw = np.zeros((len(pairs), 24))
    for k, (i, j) in enumerate(pairs):
        u = (pts[j] - pts[i]) / np.linalg.norm(pts[j] - pts[i])
        jw[k, 3 * i:3 * i + 3], jw[k, 3 * j:3 * j + 3] = -u, u
    g, _ = null_space(jw)
    assert g.shape[1] == (6 if n_rows == 28 else 14)
    _, s, vt = np.linalg.svd(jw)                   # independent: numpy's full SVD, unscaled columns
    ref = vt[np.r_[s, np.zeros(24 - len(s))] < 1e-9 * s.max()].T
    proj = lambda b: b @ np.linalg.pinv(b)          # noqa: E731
    np.testing.assert_allclose(proj(g), proj(ref), atol=1e-9)


def test_network_directory_honours_no_snooping(_adjust):
    """``multilat adjust DIR --no-snooping`` (multilat's files): the option was dropped on the way to
    the adjustment (snooping ran, the JSON said ``snooping: true``)."""
    r = _adjust("examples/general/station_control_files", "--json", "--no-snooping")
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["snooping"] is False
