"""``propagate`` of what ``adjust`` accepts beyond one offset per station (issue 16 item 6): heads that
occupy several stations, scale bars (with per-head scales), weighted and hard control — the general
batched solver (:mod:`multilat.network.montecarlo.batched_coupled`).

Independent values:

* the linear covariance of the general solver, which is ``adjust``'s covariance object since issue 27
  (before, a second implementation: its own Jacobian, g-inverse and S-transformation), against the
  per-point blocks ``adjust`` reports (another code path of that object), 1e-8 relative here (the
  exact comparisons are ``tests/test_mc_linear_covariance.py``'s, 1e-13);
* the Monte Carlo standard deviations against that linear covariance within the Monte Carlo standard
  error: gaussian inputs, so the relative standard error of a standard deviation from n trials is
  ``sqrt(1/(2(n-1)))`` (kurtosis 3); the bound is 5 standard errors on the largest of ~100 correlated
  ratios (a 1-in-10^5 bound for each, so a failure is a real disagreement). The micrometre noise
  keeps the problem linear, so MC and linear must agree.
* Mutation check: the same Monte Carlo without drawing the couplings' values (bars held at their
  lengths, control at its coordinates) falls outside that bound — the test can fail.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.montecarlo import propagate as pr
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.montecarlo.batched_coupled import CoupledBatchedNetwork
from multilat.network.model.data import Points, ReferenceLengths
from multilat.network.io.files import read_observations
from multilat.network.synthetic.generator import synthetic_network

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "network" / "sequential"
TRIALS = 4000
SE = np.sqrt(1.0 / (2 * (TRIALS - 1)))


def _std_from_adjust(res, s):
    """Per-parameter std in propagate's layout from adjust's covariance."""
    st = np.sqrt(np.einsum("sii->si", res.station_cov_m2)).ravel()
    tt = np.sqrt(np.einsum("tii->ti", res.target_cov_m2)).ravel()
    return np.concatenate([st, res.offset_std_m, tt])


def _check(res, prob, *, trials=TRIALS, rel_lin=1e-8):
    assert isinstance(prob.network, CoupledBatchedNetwork)
    s = len(prob.station_ids)
    k = prob.network.n_params
    r = pr.propagate(prob, trials=trials, rng=7, noise="gaussian")
    ref = _std_from_adjust(res, s)
    var = ref > 1e-12 * ref.max()          # held by the datum (3-2-1, hard control): both ~0
    np.testing.assert_allclose(r.lin_std[:k][var], ref[var], rtol=rel_lin)
    assert np.all(r.lin_std[:k][~var] < 1e-9 * ref.max())
    ratio = r.mc_std[:k][var] / r.lin_std[:k][var]
    assert np.max(np.abs(ratio - 1.0)) < 5 * SE, (ratio.min(), ratio.max())
    assert r.n_failed == 0
    return r


def test_heads_over_several_stations_sequential_example():
    """The shipped sequential example: two heads over 8 stations, one offset per head."""
    obs = read_observations(EXAMPLE / "obs.csv")
    res = adjust(obs, snooping=False)
    prob = pr.problem_from_observations(obs, adjustment=res)
    r = _check(res, prob)
    # a head's offset is the same unknown on each of its stations: its trials are identical
    hi = obs.head_index
    s = obs.n_stations
    same = [i for i in range(1, s) if hi[i] == hi[0]]
    dev = r.samples
    assert np.array_equal(dev[:, 3 * s], dev[:, 3 * s + same[0]])
    assert r.to_dict()["solver"] == "batched-coupled"


def test_scale_bars_as_scale_datum_with_per_head_scales():
    """Scales of both heads estimated, three 2 µm scale bars as the scale datum; bars drawn per trial."""
    net = synthetic_network(np.random.default_rng([16, 2]), population="sequential")
    rng = np.random.default_rng(7)
    ids = list(net.obs.target_ids)
    pairs = [("P1", "P2"), ("P3", "P7"), ("P5", "P11")]
    L = [float(np.linalg.norm(net.target_xyz_m[ids.index(a)] - net.target_xyz_m[ids.index(b)]))
         + rng.normal(0, 2e-6) for a, b in pairs]
    bars = ReferenceLengths(tuple(a for a, _ in pairs), tuple(b for _, b in pairs), L, np.full(3, 2e-6))
    res = adjust(net.obs, initial=net, scales=True, scale_bars=bars, snooping=False)
    prob = pr.problem_from_observations(net.obs, adjustment=res, scale_bars=bars, references=bars)
    assert prob.network.n_extra == 3 and prob.network.scale_free.all()
    r = _check(res, prob)
    # the bars' lengths: MC spread of the adjusted bar vs the adjustment's u of that length
    for q, (a, b) in enumerate(pairs):
        ip = res.interpoint_distance(a, b)
        k = prob.network.n_params + q
        assert r.lin_std[k] == pytest.approx(ip.u_m, rel=1e-6)
        assert abs(r.mc_std[k] / r.lin_std[k] - 1) < 5 * SE


def test_weighted_and_hard_control():
    """Control datum: 2 hard targets, 3 weighted (20, 30, 10 µm), drawn in every trial."""
    net = synthetic_network(np.random.default_rng([2024, 8]))
    tid = net.obs.target_ids
    tj = lambda p: net.target_xyz_m[tid.index(p)]  # noqa: E731
    rng = np.random.default_rng(11)
    sd = np.array([20e-6, 30e-6, 10e-6])
    weighted = [(p, tj(p) + rng.normal(0, sd), sd) for p in tid[2:5]]
    hard = [(p, tj(p)) for p in tid[:2]]
    pts = Points(tuple(p for p, _ in hard) + tuple(p for p, _, _ in weighted),
                 np.vstack([x for _, x in hard] + [x for _, x, _ in weighted]),
                 np.vstack([np.full((2, 3), np.nan)] + [sd] * 3))
    res = adjust(net.obs, initial=net, points=pts, datum="control", snooping=False)
    prob = pr.problem_from_observations(net.obs, adjustment=res, datum="control", points=pts)
    assert prob.network.datum is None and prob.network.n_extra == 9
    assert prob.network.target_held[:2].all() and not prob.network.target_held[2:].any()
    _check(res, prob)


def test_couplings_not_drawn_would_be_caught():
    """The mutation the tests guard against: weighted control held at its coordinates in every trial
    gives a Monte Carlo spread far below the linear one (the control σ dominates here)."""
    net = synthetic_network(np.random.default_rng([2024, 9]))
    tid = net.obs.target_ids
    sd = np.full(3, 50e-6)
    rng = np.random.default_rng(2)
    ctrl = [(p, net.target_xyz_m[tid.index(p)] + rng.normal(0, sd), sd) for p in tid[:4]]
    pts = Points(tuple(p for p, _, _ in ctrl), np.vstack([x for _, x, _ in ctrl]), np.vstack([sd] * 4))
    res = adjust(net.obs, initial=net, points=pts, datum="control", snooping=False)
    prob = pr.problem_from_observations(net.obs, adjustment=res, datum="control", points=pts)
    nw = prob.network
    g = np.random.default_rng(3)
    d = prob.distance_m + g.standard_normal((2000, nw.n_obs)) * nw.sigma_m
    held = nw.solve(d)                                              # couplings at their values
    drawn = nw.solve(d, extra=nw.extra_value + g.standard_normal((2000, nw.n_extra))
                     * nw.extra_sigma)
    lin = np.sqrt(np.diag(nw.linear_covariance()))[4 * nw.n_stations:]
    sd_held = held.target_xyz_m.reshape(2000, -1).std(axis=0, ddof=1)
    sd_drawn = drawn.target_xyz_m.reshape(2000, -1).std(axis=0, ddof=1)
    se = np.sqrt(1 / (2 * 1999))
    assert np.max(np.abs(sd_drawn / lin - 1)) < 5 * se
    assert np.median(sd_held / lin) < 1 - 10 * se


def test_identical_for_chunk_sizes():
    obs = read_observations(EXAMPLE / "obs.csv")
    prob = pr.problem_from_observations(obs)
    a = pr.propagate(prob, trials=3000, rng=5, noise="gaussian", chunk_size=1000)
    b = pr.propagate(prob, trials=3000, rng=5, noise="gaussian", chunk_size=3000)
    assert np.array_equal(a.mc_std, b.mc_std) and np.array_equal(a.samples, b.samples)


def test_model_noise_on_heads_over_stations():
    """The distance model's errors per head (the seed's head A for heads the instrument does not name):
    runs, converges, and the MC agrees with the linear sandwich of the drawn errors' std."""
    obs = read_observations(EXAMPLE / "obs.csv")
    prob = pr.problem_from_observations(obs)
    r = pr.propagate(prob, trials=3000, rng=2, noise="model", instrument="seed2020")
    k = prob.network.n_params
    ratio = r.mc_std[:k] / r.lin_std[:k]
    # non-gaussian inputs: the SE of a std uses the sample kurtosis (mc_std_se)
    assert np.max(np.abs(r.mc_std[:k] - r.lin_std[:k]) / r.mc_std_se[:k]) < 6, ratio


def test_cli_heads_bars_and_control(tmp_path, capsys):
    obs = str(EXAMPLE / "obs.csv")
    assert main(["propagate", obs, "--noise", "gaussian", "--trials", "2000", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["solver"] == "batched-coupled" and doc["trials"] == 2000
    refs = tmp_path / "bars.csv"
    refs.write_text("target_a,target_b,length_m,u_m\nP1,P2,0.5,2e-6\n")
    # a bar between unknown points: one line naming the file
    bad = tmp_path / "bad.csv"
    bad.write_text("target_a,target_b,length_m,u_m\nP1,NOPE,0.5,2e-6\n")
    assert main(["propagate", obs, "--noise", "gaussian", "--trials", "100", "--references", str(bad),
                 "--scale-bars"]) != 0
    err = capsys.readouterr().err
    assert "NOPE" in err and "Traceback" not in err
    assert main(["propagate", obs, "--noise", "gaussian", "--trials", "100", "--scale-bars"]) != 0
    assert "--scale-bars needs --references" in capsys.readouterr().err
    assert main(["propagate", "small-volume", "--trials", "100", "--scales"]) != 0
    assert "campaign file" in capsys.readouterr().err


def test_cli_weighted_control(tmp_path, capsys):
    o = read_observations(EXAMPLE / "obs.csv")
    truth = {r.split(",")[0]: [float(v) for v in r.split(",")[1:]]
             for r in (EXAMPLE / "truth.csv").read_text().splitlines()[1:]}
    res = adjust(o, snooping=False)
    # control: four targets at their adjusted coordinates in the truth frame, 30 µm
    ids = [t for t in o.target_ids][:4]
    pts = tmp_path / "pts.csv"
    pts.write_text("point,x_m,y_m,z_m,sx_m,sy_m,sz_m\n" + "".join(
        f"{p},{truth[p][0]},{truth[p][1]},{truth[p][2]},3e-5,3e-5,3e-5\n" for p in ids))
    assert res is not None
    assert main(["propagate", str(EXAMPLE / "obs.csv"), "--noise", "gaussian", "--trials", "1000",
                 "--datum", "control", "--points", str(pts), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["solver"] == "batched-coupled" and doc["n_failed"] == 0


def test_refusals_left():
    """What stays refused, in one line: a network the adjustment had to thin out."""
    obs = read_observations(EXAMPLE / "obs.csv")
    with pytest.raises(MultilatError, match="control"):
        pr.problem_from_observations(obs, datum="control")


def _small_volume_both():
    """The small volume's problem, its batched network and the same network for the general solver."""
    from multilat.network.synthetic.configs import small_volume

    pb = pr.problem_from_config(small_volume(), sigma_m=4.7e-6)
    net = pb.network
    s = net.n_stations
    gen = CoupledBatchedNetwork(net.station_index, net.target_index, net.sigma_m, np.arange(s),
                                net.station_xyz_m, net.offset_m, np.zeros(s), net.target_xyz_m,
                                np.zeros(s, bool), np.zeros(net.n_targets, bool), np.ones(s, bool),
                                np.zeros(s, bool), datum=net.datum)
    return pb, net, gen


def test_general_solver_equals_the_batched_solver_where_both_apply():
    """A second method: on the seed's small volume (one head per station, no couplings) the general
    solver's trials equal the specialised batched solver's (compiled, Schur over targets) to 1e-9 m —
    both converge to each trial's least-squares minimum (steps below 1e-10 m) and apply the same datum."""
    pb, net, gen = _small_volume_both()
    d = pb.distance_m + np.random.default_rng(2).standard_normal((500, pb.distance_m.size)) * 4.7e-6
    a, b = gen.solve(d), net.solve(d)
    assert a.converged.all() and b.converged.all()
    assert np.max(np.abs(a.target_xyz_m - b.target_xyz_m)) < 1e-9
    assert np.max(np.abs(a.station_xyz_m - b.station_xyz_m)) < 1e-9
    assert np.max(np.abs(a.offset_m - b.offset_m)) < 1e-9
    np.testing.assert_allclose(a.sigma0, b.sigma0, rtol=1e-6)
    np.testing.assert_allclose(gen.linear_covariance(), net.linear_covariance(), rtol=1e-7,
                               atol=1e-9 * np.abs(net.linear_covariance()).max())


def test_far_trials_fall_back_to_gauss_newton():
    """Trials with 2 mm errors (sigma0 ~ 350, far from the nominal solution) are re-solved by full
    Gauss-Newton, and agree with the batched solver's full Gauss-Newton on the same trials within
    0.1 µm: 5e-5 of the perturbation (the two stop at steps below 1e-10 m on a cost this flat)."""
    pb, net, gen = _small_volume_both()
    d = pb.distance_m + np.random.default_rng(4).standard_normal((3, pb.distance_m.size)) * 2e-3
    a = gen.solve(d, max_iter=2)
    b = net.solve(d, method="gauss-newton", max_iter=30)
    assert a.retried.all() and a.converged.all() and b.converged.all()
    assert np.max(np.abs(a.target_xyz_m - b.target_xyz_m)) < 1e-7


def test_angles_are_drawn_and_match_the_adjustments_covariance():
    """A mixed campaign (4 heads, 2 trackers with angles): the general solver's linear covariance equals
    adjust's (with the angles and orientations, a second implementation) to 1e-8, and the Monte Carlo
    (distances, angles drawn) agrees with it within 5 MC standard errors; without drawing the angles the
    targets' spread falls below it."""
    from multilat.network.synthetic.generator import synthetic_network

    net = synthetic_network(np.random.default_rng([18, 1]), population="mixed")
    res = adjust(net.obs, initial=net, snooping=False)
    prob = pr.problem_from_observations(net.obs, adjustment=res)
    nw = prob.network
    assert nw.n_extra == len(res.angles) and nw.n_orientation == 6
    r = _check(res, prob)
    # mutation: the angles held at their values in every trial -> less spread than the linear covariance
    g = np.random.default_rng(9)
    d = prob.distance_m + g.standard_normal((2000, nw.n_obs)) * nw.sigma_m
    held = nw.solve(d)
    lin = np.sqrt(np.diag(nw.linear_covariance()))[4 * nw.n_stations:]
    sd = held.target_xyz_m.reshape(2000, -1).std(axis=0, ddof=1)
    assert np.median(sd / lin) < 1 - 5 * np.sqrt(1 / (2 * 1999))     # measured 0.88: 7.5 SE below
    assert r.to_dict()["solver"] == "batched-coupled"


def test_levelled_trackers_propagate_about_z_and_match_the_adjustment():
    """The mixed campaign with its two trackers on their level (κ only, the vertical observed, 4 datum
    defects): the trials' datum fit turns about z only, and the general solver's linear covariance
    equals adjust's 4-defect covariance to 1e-8; the Monte Carlo agrees with it within 5 MC SE.
    Mutation: the same trials moved by the full 6-parameter rigid fit (a tilt the data forbid) put a
    target's spread 6.7 MC standard errors off."""
    from multilat.network.synthetic.generator import synthetic_network

    net = synthetic_network(np.random.default_rng([18, 1]), population="mixed", levelled=True)
    assert net.obs.levelled == ("AT1", "AT2")
    res = adjust(net.obs, initial=net, snooping=False)
    prob = pr.problem_from_observations(net.obs, adjustment=res)
    nw = prob.network
    assert nw.datum.about_z and nw.datum.n_defect == 4
    assert nw.dof == res.dof
    _check(res, prob)
    from multilat.network.montecarlo.trial_datum import TrialDatum

    g = np.random.default_rng(9)
    n = 2000
    d = prob.distance_m + g.standard_normal((n, nw.n_obs)) * nw.sigma_m
    ex = nw.extra_value + g.standard_normal((n, nw.n_extra)) * nw.extra_sigma
    sol = nw.solve(d, extra=ex)
    lin = np.sqrt(np.diag(nw.linear_covariance()))[4 * nw.n_stations:]
    _, tilted = TrialDatum.inner().apply(sol.station_xyz_m, sol.target_xyz_m, nw.station_xyz_m, nw.target_xyz_m)
    se = np.sqrt(1 / (2 * (n - 1)))
    for x, off in ((sol.target_xyz_m, False), (tilted, True)):
        ratio = x.reshape(n, -1).std(axis=0, ddof=1) / lin
        assert (np.max(np.abs(ratio - 1)) > 5 * se) == off    # measured 0.033 (2.1 SE) and 0.105 (6.7 SE)
    with pytest.raises(MultilatError, match="321 would tilt"):
        pr.problem_from_observations(net.obs, adjustment=res, datum="321:H1,H2,H3")


def test_cli_propagate_levelled(tmp_path, capsys):
    from multilat.network.io.files import write_observations
    from multilat.network.synthetic.generator import synthetic_network

    net = synthetic_network(np.random.default_rng([18, 1]), population="mixed", levelled=True)
    p = tmp_path / "mixed.csv"
    write_observations(p, net.obs)                       # levelled is not a column: --levelled says it
    assert main(["propagate", str(p), "--trials", "300", "--noise", "gaussian", "--levelled", "AT1,AT2",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["solver"] == "batched-coupled" and doc["n_failed"] == 0
    assert main(["propagate", str(p), "--trials", "300", "--noise", "gaussian", "--levelled", "NOPE"]) != 0
    err = capsys.readouterr().err.strip()
    assert "--levelled: unknown station 'NOPE'" in err and len(err.splitlines()) == 1   # as `adjust` says it
