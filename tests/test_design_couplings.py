"""Pre-analysis with scale bars and weighted control points (network/design/couplings.py) against a
dense normal-matrix computation written out here, and from the CLI."""

import json

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.design.couplings import preanalyse_coupled
from multilat.network.design.preanalysis import Layout, preanalyse

SIG = 5e-6


def _layout(seed=1, t=12):
    rng = np.random.default_rng(seed)
    H = np.array([[0.0, 0, 0], [2, 0, 0.5], [1, 2, 0], [1, 1, 2.0], [2.2, 2.1, 1.2]])
    T = rng.uniform(0.2, 1.8, (t, 3))
    return Layout(tuple("ABCDE"), H, tuple(f"T{j}" for j in range(t)), T, np.ones((5, t), bool))


def _dense(lay, bars=(), control=()):
    """Normal matrix of [x, y, z, offset per station; x, y, z per target] with distance, bar and
    control rows (whitened), and its covariance: the Moore-Penrose inverse without control (the null
    space is the rigid motions of the points, offsets not in it: the minimum-norm solution is the inner
    constraint over all points), the plain inverse with control."""
    s, t = lay.n_stations, lay.n_targets
    n = 4 * s + 3 * t
    rows = []
    for i in range(s):
        for j in range(t):
            e = lay.station_xyz_m[i] - lay.target_xyz_m[j]
            e /= np.linalg.norm(e)
            r = np.zeros(n)
            r[4 * i:4 * i + 3] = e
            r[4 * i + 3] = 1.0
            r[4 * s + 3 * j:4 * s + 3 * j + 3] = -e
            rows.append(r / SIG)
    pos = {p: j for j, p in enumerate(lay.target_ids)}
    for a, b, u in bars:
        ja, jb = pos[a], pos[b]
        e = lay.target_xyz_m[ja] - lay.target_xyz_m[jb]
        e /= np.linalg.norm(e)
        r = np.zeros(n)
        r[4 * s + 3 * ja:4 * s + 3 * ja + 3] = e
        r[4 * s + 3 * jb:4 * s + 3 * jb + 3] = -e
        rows.append(r / u)
    for p, *s3 in control:
        j = pos[p]
        for c in range(3):
            r = np.zeros(n)
            r[4 * s + 3 * j + c] = 1.0 / s3[c]
            rows.append(r)
    A = np.array(rows)
    N = A.T @ A
    C = np.linalg.inv(N) if control else np.linalg.pinv(N, rcond=1e-13)
    return np.stack([C[4 * s + 3 * j:4 * s + 3 * j + 3, 4 * s + 3 * j:4 * s + 3 * j + 3] for j in range(t)])


def test_scale_bars_against_the_dense_normal_matrix():
    lay = _layout()
    bars = [("T0", "T1", 1e-6), ("T2", "T7", 2e-6)]
    pc = preanalyse_coupled(lay, SIG, scale_bars=bars)
    ref = _dense(lay, bars)
    # both solve the same normal equations; 1e-6 relative leaves room for the pseudo-inverse's rounding
    assert np.max(np.abs(pc.target_cov_m2 - ref)) < 1e-6 * np.max(np.abs(ref))
    # a bar known to 1 m changes nothing: the plain pre-analysis
    loose = preanalyse_coupled(lay, SIG, scale_bars=[("T0", "T1", 1.0)])
    plain = preanalyse(lay, SIG)
    assert np.max(np.abs(loose.target_cov_m2 - plain.target_cov_m2)) < 1e-6 * np.max(np.abs(plain.target_cov_m2))
    # a tight bar: the length between its ends is known to about its own uncertainty
    tight = preanalyse_coupled(lay, SIG, scale_bars=[("T0", "T1", 1e-6)], lengths=[("T0", "T1")])
    assert tight.lengths[0][3] < 1e-6 and tight.dof == plain.dof + 1


def test_weighted_control_against_the_dense_normal_matrix():
    lay = _layout(2)
    ctrl = [("T0", 1e-5, 1e-5, 2e-5), ("T3", 1e-5, 1e-5, 1e-5), ("T8", 3e-5, 1e-5, 1e-5)]
    pc = preanalyse_coupled(lay, SIG, control=ctrl)
    ref = _dense(lay, control=ctrl)
    assert np.max(np.abs(pc.target_cov_m2 - ref)) < 1e-6 * np.max(np.abs(ref))
    # a control point is known at best to its own uncertainty
    assert np.all(np.sqrt(np.diagonal(pc.target_cov_m2[0])) <= np.array([1e-5, 1e-5, 2e-5]) * (1 + 1e-9))


@pytest.mark.parametrize("kw, words", [
    (dict(scale_bars=[("T0", "X", 1e-6)]), "'X' is not a target"),
    (dict(scale_bars=[("T0", "T1", 0.0)]), "must be > 0"),
    (dict(control=[("T0", 1e-5, -1, 1e-5)]), "three standard uncertainties"),
])
def test_bad_couplings_are_one_line_errors(kw, words):
    with pytest.raises(MultilatError, match=words):
        preanalyse_coupled(_layout(), SIG, **kw)


def test_cli_design_with_a_scale_bar(tmp_path, capsys):
    lay = _layout(3)
    (tmp_path / "t.csv").write_text("point,x_m,y_m,z_m\n" + "".join(
        f"{p},{x!r},{y!r},{z!r}\n" for p, (x, y, z) in zip(lay.target_ids, lay.target_xyz_m.tolist())))
    (tmp_path / "h.csv").write_text("point,x_m,y_m,z_m\n" + "".join(
        f"{p},{x!r},{y!r},{z!r}\n" for p, (x, y, z) in zip(lay.station_ids, lay.station_xyz_m.tolist())))
    base = ('[targets]\nfile = "t.csv"\n[instrument]\nsigma_um = 5.0\n'
            '[[network.scale_bars]]\na = "T0"\nb = "T1"\nu_um = 1.0\n')
    (tmp_path / "c.toml").write_text(base + '[heads]\nfixed = "h.csv"\n')
    assert main(["design", str(tmp_path / "c.toml"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    ref = preanalyse_coupled(lay, SIG, scale_bars=[("T0", "T1", 1e-6)])
    assert doc["criterion_m"] == pytest.approx(float(ref.u95_max_m.max()), rel=1e-9)
    # the optimisation does not model bars yet: a one-line refusal
    (tmp_path / "o.toml").write_text(base + '[heads]\ncount = 4\nbox_min_m = [-1, -1, 0]\nbox_max_m = [3, 3, 2]\n')
    assert main(["design", str(tmp_path / "o.toml")]) == 2
    err = capsys.readouterr().err
    assert "the optimisation does not model them yet" in err and err.count("\n") == 1
