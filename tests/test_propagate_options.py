"""``propagate`` takes the model ``adjust`` takes (issue 28): held offsets, chosen interpoint distances,
and by default errors drawn with the σ the file gives — the distance model only with an instrument
named.

Statistics of the comparisons: from N independent trials, the relative standard error of a sample
variance of a gaussian quantity is sqrt(2 / (N - 1)) (of a standard deviation half that). Each
variance is compared with its reference as z = (var_MC / var_ref - 1) / sqrt(2 / (N - 1)); over the
56 quantities of the network the largest |z| stays below 4.5 by chance with probability > 0.999
(two-sided normal tail 6.8e-6 each). The references are independent of the Monte Carlo: the
covariance of ``adjust`` (normal equations of the Gauss-Newton adjustment) and the file's σ column
read with the csv module.
"""

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.montecarlo import propagate as pr
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.io.files import read_observations
from multilat.network.adjust.distance.options import NetworkOptions

EX = Path(__file__).resolve().parents[1] / "examples" / "network"
OBS = EX / "small_volume_obs.csv"
N = 4000
SE_VAR = np.sqrt(2 / (N - 1))
Z_MAX = 4.5
HELD = {"A": 1234e-6, "B": -871e-6}
PAIRS = (("1", "2"), ("3", "A"), ("5", "14"), ("B", "C"))


def _z(var_mc, var_ref):
    return (np.asarray(var_mc) / np.asarray(var_ref) - 1.0) / SE_VAR


@pytest.fixture(scope="module")
def held_run():
    obs = read_observations(OBS)
    opts = NetworkOptions.of(offsets_m=HELD)
    adj = adjust(obs, opts, snooping=False)
    prob = pr.problem_from_observations(obs, opts, pairs=PAIRS)
    res = pr.propagate(prob, trials=N, rng=11, noise="gaussian", keep_samples=True)
    return adj, prob, res


def _mc_var(res, label):
    k = res.labels.index(label)
    return float(np.var(res.samples[:, k].astype(float), ddof=1))


def test_held_offsets_propagate_to_the_covariance_of_adjust(held_run):
    """Every coordinate's and free offset's Monte Carlo variance equals the variance of ``adjust`` with
    the same held offsets, within its standard error; the held offsets do not move in any trial."""
    adj, prob, res = held_run
    assert res.trials == N and res.n_failed == 0
    z = []
    for i, sid in enumerate(adj.station_ids):
        off = res.samples[:, res.labels.index(f"{sid}.offset")]
        if sid in HELD:
            assert not adj.offset_estimated[i] and np.all(off == 0.0)
        else:
            z.append(_z(_mc_var(res, f"{sid}.offset"), adj.offset_std_m[i] ** 2))
    for pid in adj.station_ids + adj.target_ids:
        c = adj.points_covariance([pid])
        for a, axis in enumerate("xyz"):
            if c[a, a] > 1e-18:
                z.append(_z(_mc_var(res, f"{pid}.{axis}"), c[a, a]))
    z = np.array(z)
    assert len(z) == 3 * 18 + 2 and np.max(np.abs(z)) < Z_MAX, np.max(np.abs(z))   # 18 points, 2 free offsets


def test_the_comparison_can_fail(held_run):
    """The same trials against the adjustment with every offset estimated: far outside (the test above
    sees which model was propagated)."""
    adj, prob, res = held_run
    free = adjust(read_observations(OBS), snooping=False)
    i = free.station_ids.index("C")
    assert abs(_z(_mc_var(res, "C.offset"), free.offset_std_m[i] ** 2)) > 20


def test_chosen_pairs_are_the_adjusted_distances_with_their_u(held_run):
    adj, prob, res = held_run
    doc = res.to_dict()
    assert [(d["a"], d["b"]) for d in doc["distances"]] == list(PAIRS)
    k0 = prob.network.n_params
    for q, (a, b) in enumerate(PAIRS):
        ref = adj.interpoint_distance(a, b)
        assert doc["distances"][q]["nominal_m"] == pytest.approx(ref.length_m, abs=1e-12)
        var = float(np.var(res.samples[:, k0 + q].astype(float), ddof=1))
        assert abs(_z(var, ref.u_m ** 2)) < Z_MAX, (a, b, var, ref.u_m ** 2)


def test_cli_fix_offsets_and_pairs(capsys, tmp_path):
    pf = tmp_path / "pairs.csv"
    pf.write_text("# two pairs\npoint_a,point_b\n1,2\n3,A\n")
    assert main(["propagate", str(OBS), "--trials", "2000", "--fix-offsets-um", "A=1234,B=-871",
                 "--pairs", str(pf), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    rows = {r["label"]: r for r in doc["parameters"]}
    assert rows["A.offset"]["nominal_m"] == 1234 * 1e-6 and rows["A.offset"]["std_mc_m"] == 0.0
    assert rows["C.offset"]["std_mc_m"] > 0
    assert [d["label"] for d in doc["distances"]] == ["1-2", "3-A"]
    assert main(["propagate", str(OBS), "--trials", "2000", "--pairs", "1-2,3-A", "--fix-offsets-um",
                 "A=1234,B=-871", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["distances"] == doc["distances"]   # same seed, same pairs


@pytest.mark.parametrize("pairs, message", [
    ("1-99", "--pairs: unknown point id '99'"),
    ("1_2", "--pairs: expected P1-P2"),
    ("1-2,1-2", "--pairs: pair 1-2 given twice"),
    ("1-1", "--pairs: distance from '1' to itself"),
    ("missing.csv", "--pairs: missing.csv: no such file"),
])
def test_bad_pairs_one_line(capsys, pairs, message):
    assert main(["propagate", str(OBS), "--trials", "100", "--pairs", pairs]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


# ------------------------------------------------------------------------------------------ noise
SIGMA_BY_STATION = {"A": 2e-6, "B": 5e-6, "C": 9e-6, "D": 15e-6}


def _file_with_own_sigma(tmp_path) -> tuple[Path, np.ndarray]:
    """The example with σ of 2, 5, 9 and 15 µm by station (not the distance model's); its σ column."""
    p = tmp_path / "own_sigma.csv"
    sig = []
    with open(OBS, newline="") as f, open(p, "w", newline="") as g:
        w = csv.writer(g)
        rows = [r for r in csv.reader(f) if r and not r[0].startswith("#")]
        w.writerow(rows[0])
        k = rows[0].index("sigma_m")
        for r in rows[1:]:
            r[k] = repr(SIGMA_BY_STATION[r[0]])
            sig.append(SIGMA_BY_STATION[r[0]])
            w.writerow(r)
    return p, np.array(sig)


@pytest.fixture
def drawn(monkeypatch):
    """Every block of distance errors the trials draw."""
    seen = []
    orig = pr._draw_errors

    def spy(spec, n, rng):
        e = orig(spec, n, rng)
        seen.append(e.copy())
        return e

    monkeypatch.setattr(pr, "_draw_errors", spy)
    return seen


def test_without_instrument_the_files_sigma_are_drawn(capsys, tmp_path, drawn):
    path, sigma_file = _file_with_own_sigma(tmp_path)
    assert main(["propagate", str(path), "--trials", str(N), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["noise"] == "gaussian" and doc["noise_source"]["kind"] == "gaussian"
    assert doc["sigma_source"]["kind"] == "file column"
    e = np.concatenate(drawn)
    assert e.shape == (N, sigma_file.size)
    z = _z(np.var(e, axis=0, ddof=1), sigma_file ** 2)
    assert np.max(np.abs(z)) < Z_MAX, np.max(np.abs(z))


def test_with_instrument_the_distance_model_is_drawn(capsys, tmp_path, drawn):
    """Naming the instrument draws its distance model: then the file's σ are not what is drawn (the
    per-row check above would fail), and the JSON says which instrument."""
    path, sigma_file = _file_with_own_sigma(tmp_path)
    assert main(["propagate", str(path), "--trials", "2000", "--instrument", "seed2020", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["noise"] == "model" and doc["noise_source"] == {"kind": "distance model", "instrument": "seed2020"}
    e = np.concatenate(drawn)
    z = _z(np.var(e, axis=0, ddof=1), sigma_file ** 2)
    assert np.max(np.abs(z)) > 20


def test_no_quiet_default_instrument(capsys, tmp_path):
    """--noise model needs --instrument; a file without σ needs --sigma-um or --instrument: one line
    naming the options, nothing written."""
    out = tmp_path / "o"
    assert main(["propagate", str(OBS), "--trials", "100", "--noise", "model", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--noise model" in err[0] and "--instrument" in err[0]
    bare = tmp_path / "bare.csv"
    bare.write_text("station,target,distance_m\n" + "".join(
        f"{s},{t},{1.0 + 0.1 * i + 0.03 * j}\n" for i, s in enumerate("ABCD") for j, t in enumerate("12345")))
    assert main(["propagate", str(bare), "--trials", "100", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no sigma_m column" in err[0] and "--sigma-um" in err[0] and "--instrument" in err[0]
    assert not out.exists()
    with pytest.raises(MultilatError, match="noise model draws from an instrument"):
        pr.propagate(pr.problem_from_observations(read_observations(OBS)), trials=10, noise="model")


def test_python_default_follows_the_instrument():
    prob = pr.problem_from_observations(read_observations(OBS))
    assert pr.propagate(prob, trials=1000, rng=1).noise == "gaussian"
    assert pr.propagate(prob, trials=1000, rng=1, instrument="seed2020").noise == "model"


def test_options_that_do_not_apply_are_refused():
    obs = read_observations(OBS)
    with pytest.raises(MultilatError, match="alpha does not apply to a propagation"):
        pr.problem_from_observations(obs, NetworkOptions.of(alpha=0.01))
    with pytest.raises(MultilatError, match="cost does not apply"):
        pr.problem_from_observations(obs, cost="squared")
