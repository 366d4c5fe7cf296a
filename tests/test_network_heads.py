"""Heads that occupy several stations (sequential multilateration): offsets and scales belong to
heads (issue 16 item 1).

Independent check: a second, plain implementation written here — every unknown in one vector
(station coordinates with 6 of them held as a minimal constraint, one offset (and scale) per head,
target coordinates), scipy's MINPACK Levenberg-Marquardt, covariance ``(JᵀJ)⁻¹`` — against
``adjust``'s Schur-reduced solver with the tie map. Compared: the datum-invariant quantities (head
offsets and scales, vᵀPv, every station-target distance) and the offsets' standard uncertainties
(invariant under the rigid datum). Tolerances: values 1e-9 m (both converge to the float64 floor,
~1e-12 m; 1e-9 leaves room for MINPACK's stopping rule), uncertainties 1e-6 relative (two
different factorisations of a matrix with condition ~1e8).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import least_squares

from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.model.data import Observations
from multilat.network.model.datum import rigid_fit, apply_rigid
from multilat.network.io.files import read_observations, read_points
from multilat.network.synthetic.generator import synthetic_network
from multilat.network.adjust.distance.result import result_to_json

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples" / "network" / "sequential"


def _independent(obs: Observations, truth, *, fixed_offsets=None, scale_heads=()):
    """Plain full-vector least squares with shared head offsets (and scales). Returns
    (offset per head, scale per head, vtpv, station-target distances (s, t), offset std per head)."""
    s, t = obs.n_stations, obs.n_targets
    heads = list(obs.head_ids)
    hi = obs.head_index
    fixed_offsets = fixed_offsets or {}
    est_off = [h for h in heads if h not in fixed_offsets]
    est_sc = [h for h in heads if h in scale_heads]
    held = np.zeros((s, 3), bool)
    held[0, :], held[1, 1:], held[2, 2] = True, True, True     # a minimal constraint (6 coordinates)
    S0 = truth.station_xyz_m.copy()
    rng = np.random.default_rng(5)
    x0 = np.concatenate([(S0 + rng.normal(0, 2e-3, S0.shape))[~held], np.zeros(len(est_off)),
                         np.zeros(len(est_sc)), (truth.target_xyz_m + rng.normal(0, 2e-3, (t, 3))).ravel()])
    n_s, n_o, n_k = int((~held).sum()), len(est_off), len(est_sc)

    def unpack(x):
        S = S0.copy()
        S[~held] = x[:n_s]
        off = np.array([fixed_offsets.get(h, 0.0) for h in heads])
        off[[heads.index(h) for h in est_off]] = x[n_s:n_s + n_o]
        k = np.zeros(len(heads))
        k[[heads.index(h) for h in est_sc]] = x[n_s + n_o:n_s + n_o + n_k]
        T = x[n_s + n_o + n_k:].reshape(t, 3)
        return S, off, k, T

    def res(x):
        S, off, k, T = unpack(x)
        i, j = obs.station_index, obs.target_index
        rho = np.linalg.norm(S[i] - T[j], axis=1)
        return (obs.distance_m - (1 + k[hi[i]]) * rho - off[hi[i]]) / obs.sigma_m

    free_s = np.flatnonzero(~held.ravel())
    cols_o = {h: n_s + n for n, h in enumerate(est_off)}
    cols_k = {h: n_s + n_o + n for n, h in enumerate(est_sc)}

    def jac(x):
        S, off, k, T = unpack(x)
        i, j = obs.station_index, obs.target_index
        dv = S[i] - T[j]
        rho = np.linalg.norm(dv, axis=1)
        u = dv / rho[:, None]
        m = obs.n_obs
        Jf = np.zeros((m, x.size))
        g = -(1 + k[hi[i]])[:, None] * u / obs.sigma_m[:, None]         # d r / d S_i  (= - d r / d T_j)
        Js = np.zeros((m, 3 * s))
        Js[np.arange(m)[:, None], 3 * i[:, None] + np.arange(3)] = g
        Jf[:, :n_s] = Js[:, free_s]
        for h, c in cols_o.items():
            Jf[:, c] = -(hi[i] == heads.index(h)).astype(float) / obs.sigma_m
        for h, c in cols_k.items():
            Jf[:, c] = -(hi[i] == heads.index(h)).astype(float) * rho / obs.sigma_m
        Jf[np.arange(m)[:, None], n_s + n_o + n_k + 3 * j[:, None] + np.arange(3)] = -g
        return Jf

    sol = least_squares(res, x0, jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=20000)
    S, off, k, T = unpack(sol.x)
    J = sol.jac
    C = np.linalg.inv(J.T @ J)
    std = np.full(len(heads), np.nan)
    for n, h in enumerate(est_off):
        std[heads.index(h)] = np.sqrt(C[n_s + n, n_s + n])
    rho = np.linalg.norm(S[:, None] - T[None], axis=2)
    return off, k, float(sol.fun @ sol.fun), rho, std


def _head_values(r, key):
    h = r.heads()
    return np.array([h[k][key] for k in r.obs.head_ids])


def _rho(r):
    return np.linalg.norm(r.station_xyz_m[:, None] - r.target_xyz_m[None], axis=2)


@pytest.fixture(scope="module")
def seq():
    return synthetic_network(np.random.default_rng([16, 1]), population="sequential")


def test_shared_offsets_match_an_independent_solution(seq):
    r = adjust(seq.obs, initial=seq, solver="dense")
    off, _, vtpv, rho, std = _independent(seq.obs, seq)
    assert r.obs.shares_heads and len(r.obs.head_ids) == 2
    assert np.max(np.abs(_head_values(r, "offset_m") - off)) < 1e-9
    assert abs(r.sigma0 ** 2 * r.dof - vtpv) < 1e-9 * vtpv
    assert np.max(np.abs(_rho(r) - rho)) < 1e-9
    np.testing.assert_allclose(_head_values(r, "offset_std_m"), std, rtol=1e-6)
    # dof: 110ish distances - (3 s + 3 t + 2 offsets - 6)
    o = seq.obs
    assert r.dof == o.n_obs - (3 * o.n_stations + 3 * o.n_targets + 2 - 6)
    # every station of a head carries the head's value, fully correlated
    for hid, h in r.heads().items():
        idx = [r.station_ids.index(s) for s in h["stations"]]
        assert np.all(r.offset_m[idx] == h["offset_m"])
        C = r.global_cov
        a, b = 5 * idx[0] + 3, 5 * idx[1] + 3
        assert C[a, b] == pytest.approx(C[a, a], rel=1e-12)


def test_one_head_fixed_and_scales_per_head_match_the_independent_solution(seq):
    fixed = {"T1": float(seq.offset_m[0])}
    r = adjust(seq.obs, initial=seq, offsets=fixed, scales=["T2"], solver="dense")
    off, k, vtpv, rho, std = _independent(seq.obs, seq, fixed_offsets=fixed, scale_heads=("T2",))
    h = r.heads()
    assert h["T1"]["offset_m"] == fixed["T1"] and not h["T1"]["offset_estimated"]
    assert h["T2"]["scale_estimated"] and not h["T1"]["scale_estimated"]
    assert np.max(np.abs(_head_values(r, "offset_m") - off)) < 1e-9
    assert np.max(np.abs(_head_values(r, "scale") - k)) < 1e-10
    assert abs(r.sigma0 ** 2 * r.dof - vtpv) < 1e-9 * vtpv
    assert np.max(np.abs(_rho(r) - rho)) < 1e-9
    assert h["T2"]["offset_std_m"] == pytest.approx(std[1], rel=1e-6)


def test_dense_and_sparse_agree_with_shared_heads(seq):
    a = adjust(seq.obs, initial=seq, solver="dense")
    b = adjust(seq.obs, initial=seq, solver="sparse")
    assert b.solver == "sparse"
    assert np.max(np.abs(a.offset_m - b.offset_m)) < 1e-12
    assert np.max(np.abs(a.station_xyz_m - b.station_xyz_m)) < 1e-11
    np.testing.assert_allclose(a.offset_std_m, b.offset_std_m, rtol=1e-9)
    np.testing.assert_allclose(a.redundancy, b.redundancy, atol=1e-9)


def test_one_station_per_head_gives_the_old_result_bit_for_bit():
    net = synthetic_network(np.random.default_rng([2024, 3]))
    o = net.obs
    named = Observations(o.station_ids, o.target_ids, o.station_index, o.target_index, o.distance_m, o.sigma_m,
                         station_heads=tuple(f"H{i}" for i in range(o.n_stations)))
    assert named.station_heads is not None and not named.shares_heads
    a = adjust(o, initial=net)
    b = adjust(named, initial=net)
    for f in ("station_xyz_m", "target_xyz_m", "offset_m", "offset_std_m", "redundancy", "global_cov"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f
    assert list(b.heads()) == [f"H{i}" for i in range(o.n_stations)]
    # offsets are named by head
    with pytest.raises(MultilatError, match="is a station of head 'H0'"):
        adjust(named, initial=net, offsets={"S1": 0.0})


def test_heads_in_the_json(seq):
    r = adjust(seq.obs, initial=seq)
    doc = result_to_json(r)
    assert set(doc["heads"]) == {"T1", "T2"}
    assert doc["heads"]["T1"]["stations"] == ["S1", "S3", "S5", "S7"]
    assert set(doc["heads"]["T1"]) >= {"offset_m", "offset_std_m", "scale", "scale_std", "stations"}
    assert doc["stations"]["S3"]["head"] == "T1"
    assert doc["stations"]["S3"]["offset_m"] == doc["heads"]["T1"]["offset_m"]


# ------------------------------------------------------------------ the shipped example
def test_shipped_example_is_the_generator_output():
    net = synthetic_network(np.random.default_rng(2026), population="sequential")
    obs = read_observations(EX / "obs.csv")
    assert obs.station_heads == net.obs.station_heads
    assert np.max(np.abs(obs.distance_m - net.obs.distance_m)) < 1e-9      # printed with 9 decimals


def test_shipped_example_recovers_the_head_offsets():
    """From distances alone (no initial values given): each head's offset within 3 of its standard
    uncertainties of the truth, and the station/target coordinates consistent with their covariance
    after a rigid fit (Σ eᵀ C⁻¹ e against χ² with 3 (s + t) - 6 dof, 99.9 % band)."""
    from scipy import stats

    obs = read_observations(EX / "obs.csv")
    truth = read_points(EX / "truth.csv")
    true_off = dict(line.split(",") for line in (EX / "heads_truth.csv").read_text().split()[1:])
    r = adjust(obs, rng=0)
    assert r.global_test.passed
    for hid, h in r.heads().items():
        z = (h["offset_m"] - float(true_off[hid])) / h["offset_std_m"]
        assert abs(z) < 3, (hid, z)
    ids = r.station_ids + r.target_ids
    est = np.vstack([r.station_xyz_m, r.target_xyz_m])
    tru = np.array([truth.get(i) for i in ids])
    R, t = rigid_fit(tru, est)
    e = (apply_rigid(R, t, tru) - est).ravel()
    n = len(ids)
    rows = np.concatenate([(5 * np.arange(obs.n_stations)[:, None] + np.arange(3)).ravel(),
                           5 * obs.n_stations + np.arange(3 * obs.n_targets)])
    C = r.covariance.block(rows)
    q = float(e @ np.linalg.pinv(C, rcond=1e-10) @ e)
    dof = 3 * n - 6
    assert stats.chi2.ppf(0.0005, dof) < q < stats.chi2.ppf(0.9995, dof)


# ------------------------------------------------------------------ files and instruments
def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_head_column_errors_name_the_line(tmp_path):
    p = _write(tmp_path, "o.csv", "station,target,head,distance_m,sigma_m\nS1,P1,H1,1.0,5e-6\n"
                                  "S1,P2,H2,1.1,5e-6\n")
    with pytest.raises(MultilatError, match=r"o\.csv:3: station 'S1' has head 'H2' here but 'H1' at line 2"):
        read_observations(p)
    p = _write(tmp_path, "u.csv", "station,target,head,distance_m\nS1,P1,A,1.0\nS2,P1,Q7,1.1\n")
    with pytest.raises(MultilatError, match=r"u\.csv:3: column 'head': unknown head 'Q7' in instrument"):
        read_observations(p, instrument="seed2020")


def _instrument_with(tmp_path, heads_block: str) -> Path:
    base = (ROOT / "src" / "multilat" / "presets" / "seed2020.toml").read_text()
    cut = base.index("[heads.A]")
    rest = base[cut:]
    after = rest.index("[target]") if "[target]" in rest else len(rest)
    return _write(tmp_path, "inst.toml", base[:cut] + heads_block + "\n" + rest[after:])


HEAD_A = """a_limit_m = 190e-6
c_limit_m = 230e-6
alpha_deg = [-0.05, 0.12]
gamma_deg = [-0.09, 0.02]
toh_m = -1e-6
toh_std_m = 2e-6
"""


def test_one_head_type_for_many_heads(tmp_path):
    """H1..H6 of one design: one [heads.default] block (or one [head_types.X] + head_map) gives
    every head the sigma of seed2020's head A (same block), computed independently per name."""
    from multilat import budget
    from multilat.instrument import load_instrument

    rows = "".join(f"S{i},P{j},H{i},{1.0 + 0.5 * j}\n" for i in range(1, 7) for j in range(1, 3))
    obs_path = _write(tmp_path, "o.csv", "station,target,head,distance_m\n" + rows)
    want = budget.distance_std_m("seed2020", np.array([1.5, 2.0]), head="A")
    p = _instrument_with(tmp_path, "[heads.default]\n" + HEAD_A)
    o = read_observations(obs_path, instrument=str(p))
    assert o.head_ids == tuple(f"H{i}" for i in range(1, 7))
    np.testing.assert_allclose(o.sigma_m, np.tile(want, 6), rtol=1e-12)
    typed = _instrument_with(tmp_path, "[head_types.tracer]\n" + HEAD_A + "\n[head_map]\n"
                             + "".join(f'H{i} = "tracer"\n' for i in range(1, 7)))
    o2 = read_observations(obs_path, instrument=str(typed))
    np.testing.assert_allclose(o2.sigma_m, o.sigma_m, rtol=1e-12)
    bad = _instrument_with(tmp_path, "[head_types.tracer]\n" + HEAD_A + '\n[head_map]\nH1 = "tracker"\n')
    with pytest.raises(MultilatError, match="unknown head type 'tracker'"):
        load_instrument(bad)


def test_raw_head_column(tmp_path):
    """A raw file with a head column: the head's transit offset and sigma are used, the head goes
    through to the observations; an unknown head is FILE:LINE."""
    from multilat.campaign.correct import correct_file

    env = "temperature_c,pressure_hpa,humidity_pct"
    txt = (f"station,target,head,optical_path_m,{env}\nS1,P1,B,2.0,20,1013.25,50\n"
           f"S2,P1,B,2.5,20,1013.25,50\nS3,P1,C,3.0,20,1013.25,50\n")
    c = correct_file(_write(tmp_path, "raw.csv", txt))
    o = c.to_observations()
    assert o.head_of_station == ("B", "B", "C")
    from multilat import budget

    np.testing.assert_allclose(c.sigma_model_m[:2], budget.distance_std_m("seed2020", c.distance_m[:2], head="B"),
                               rtol=1e-12)
    with pytest.raises(MultilatError, match=r"raw2\.csv:3: head 'Z' is not a head of the instrument"):
        correct_file(_write(tmp_path, "raw2.csv", txt.replace("S2,P1,B", "S2,P1,Z")))


def test_cli_adjust_with_heads(capsys):
    from multilat.cli import main

    def run(args):
        rc = main(args)
        out = capsys.readouterr()
        return rc, out.out, out.err

    rc, out, err = run(["adjust", str(EX / "obs.csv"), "--json"])
    assert rc == 0, err
    doc = json.loads(out)
    assert doc["heads"]["T2"]["stations"] == ["S2", "S4", "S6", "S8"]
    rc, out, err = run(["adjust", str(EX / "obs.csv"), "--json", "--fix-offsets-um", "T1=1097.528"])
    assert rc == 0, err
    doc = json.loads(out)
    assert doc["heads"]["T1"]["offset_m"] == pytest.approx(1097.528e-6, abs=1e-12)
    assert not doc["heads"]["T1"]["offset_estimated"]
    rc, out, err = run(["adjust", str(EX / "obs.csv"), "--fix-offsets-um", "S1=0"])
    assert rc != 0 and "error: --fix-offsets-um: unknown head id 'S1' (heads: T1, T2)" in err
    assert len(err.strip().splitlines()) == 1


def test_demo_section_verdicts():
    """The demo's computed verdicts on the shipped example and the quick coverage study."""
    from multilat.report.sequential_demo import section

    html = "".join(str(b) for b in section(seed=20200808, quick=True).blocks)
    assert "within 3 u of the truth: yes" in html
    assert ": consistent;" in html


def test_from_distances_alone_reaches_the_truth_start_minimum():
    """Initial values treat the stations independently, the adjustment ties them: on 12 sequential
    networks `adjust` from distances alone reaches the minimum of a solve started from the truth
    (vᵀPv to 1e-6 relative, offsets to 1e-9 m)."""
    for k in range(12):
        net = synthetic_network(np.random.default_rng([16, 100 + k]), population="sequential")
        a = adjust(net.obs, rng=k, snooping=False)
        b = adjust(net.obs, initial=net, snooping=False)
        assert a.sigma0 == pytest.approx(b.sigma0, rel=1e-6), k
        assert np.max(np.abs(a.offset_m - b.offset_m)) < 1e-9, k


@pytest.mark.slow
def test_raw_readings_with_heads_through_the_cli(tmp_path, capsys):
    """(slow: ~100 s on a loaded machine, 4 x 110 re-adjustments for G C Gᵀ; the default run has
    test_raw_head_column and test_correlated_gain_names_offsets_by_head.) A raw file with a head column (the sequential example's distances as vacuum optical paths in
    standard air): `adjust RAW` ties the heads, and the correlated covariance (G C Gᵀ, by central
    differences of adjust with the offsets named by head) is computed."""
    from multilat import air
    from multilat.cli import main

    o = read_observations(EX / "obs.csv")
    n = float(air.group_index(20.0, 101325.0, humidity_pct=50.0, wavelength_m=1550e-9))
    heads = o.head_of_station
    rows = [f"{o.station_ids[i]},{o.target_ids[j]},{heads[i]},{d * n:.9f},20,1013.25,50"
            for i, j, d in zip(o.station_index, o.target_index, o.distance_m)]
    raw = tmp_path / "raw.csv"
    raw.write_text("station,target,head,optical_path_m,temperature_c,pressure_hpa,humidity_pct\n"
                   + "\n".join(rows) + "\n")
    inst = _instrument_with(tmp_path, "[heads.default]\n" + HEAD_A)
    rc = main(["adjust", str(raw), "--instrument", str(inst), "--json"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    doc = json.loads(out.out)
    assert doc["heads"]["T1"]["stations"] == ["S1", "S3", "S5", "S7"]
    assert "with_correlations" in doc
    # scales per head with a scale bar as the scale datum: the bar enters every re-adjustment of G
    truth = read_points(EX / "truth.csv")
    bars = tmp_path / "bars.csv"
    bars.write_text(f"target_a,target_b,length_m,u_m\nP1,P2,{np.linalg.norm(truth.get('P1') - truth.get('P2')):.9f},"
                    "2e-6\n")
    rc = main(["adjust", str(raw), "--instrument", str(inst), "--scales", "--references", str(bars),
               "--scale-bars", "--json"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    doc = json.loads(out.out)
    assert doc["heads"]["T2"]["scale_estimated"] and "with_correlations" in doc


def test_correlated_gain_names_offsets_by_head():
    """G = ∂x/∂d (campaign.correlated, central differences of `adjust`, used for G C Gᵀ) re-adjusts
    with the offsets named by head. Checked against the analytic linear gain of the tied model,
    ``C Aᵀ P`` from the adjustment's own covariance (offsets are datum-invariant), on noise-free
    distances (with residuals the exact gain has a second-order term ``Σ r_k ∂²f_k``, 0.01-0.3 % here
    in the weak offset direction): held head T1's offset rows are zero, T2's offset rows agree to
    1e-5 relative (the solver's rounding-floor stop, ~1e-4 σ, over a 2e-6 m difference)."""
    from multilat.campaign.correlated import adjustment_gain

    net = synthetic_network(np.random.default_rng([16, 9]), population="sequential", n_stations=6, n_targets=10,
                            gap_fraction=0.0)
    o = net.obs
    exact = np.linalg.norm(net.station_xyz_m[o.station_index] - net.target_xyz_m[o.target_index], axis=1)
    obs = o.with_distances(exact + net.offset_m[o.station_index])
    r = adjust(obs, initial=net, offsets={"T1": float(net.offset_m[0])}, snooping=False)
    g = adjustment_gain(r, step_m=1e-6)
    o = r.obs
    s = o.n_stations
    t1 = [i for i in range(s) if o.head_of_station[i] == "T1"]
    t2 = [i for i in range(s) if o.head_of_station[i] == "T2"]
    assert np.all(g[[4 * i + 3 for i in t1]] == 0.0)
    for k in (0, 7, 23):
        i, j = o.station_index[k], o.target_index[k]
        d = r.station_xyz_m[i] - r.target_xyz_m[j]
        u = d / np.linalg.norm(d)
        a = np.zeros(5 * s + 3 * o.n_targets)
        a[5 * i:5 * i + 3] = u
        a[5 * i + 3] = 0.0 if i in t1 else 1.0
        a[5 * s + 3 * j:5 * s + 3 * j + 3] = -u
        v = r.covariance.times((a / o.sigma_m[k] ** 2)[:, None])[:, 0]
        np.testing.assert_allclose(g[[4 * q + 3 for q in t2], k], v[[5 * q + 3 for q in t2]], rtol=1e-5)
        assert abs(v[5 * t2[0] + 3]) > 1e-3          # a real response, not two zeros
