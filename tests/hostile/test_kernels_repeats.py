"""Hostile inputs for the compiled statistics kernels (:mod:`multilat.network.adjust._covariance_kernels`):
many readings of one target, and signals while a long kernel runs.

10 000 repeated readings of one pair beside the 56-row example ran for more than 15 minutes in the
hat-diagonal kernel (two n x n matrices of 800 MB and an n^3 sum over the target's observations),
and neither Ctrl-C nor SIGTERM stopped it: a Python signal handler runs only when compiled code
returns. The kernels are now linear in a target's observations and run in blocks of targets."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from multilat.network.adjust import covariance as C
from multilat.network.adjust.distance.adjust import Start, adjust
from multilat.network.model.data import Observations
from multilat.network.synthetic.generator import synthetic_network

from conftest import CLI, EX, cli_env

K = pytest.importorskip("multilat.network.adjust._covariance_kernels")
if not K.HAVE_NUMBA:                                      # pragma: no cover
    pytest.skip("numba not installed: the numpy path is the only one", allow_module_level=True)


def _repeated_network(repeats=300, s=6, t=40, rng=21):
    """A small network plus ``repeats`` readings of the pair (S0, T0) (noise 5 µm) and target T1 seen
    ``repeats // 10`` more times by every station: targets far above :data:`K.FEW_PER_TARGET`."""
    net = synthetic_network(rng, population="rings", n_stations=s, n_targets=t, per_target=5, size_m=6.0)
    g = np.random.default_rng(rng)
    si, ti, d = [net.station_index], [net.target_index], [net.distance_m]
    first = int(np.flatnonzero((net.station_index == 0) & (net.target_index == 0))[0])
    si.append(np.zeros(repeats, np.int64))
    ti.append(np.zeros(repeats, np.int64))
    d.append(net.distance_m[first] + g.normal(0, 5e-6, repeats))
    for i in range(s):
        k = np.flatnonzero((net.station_index == i) & (net.target_index == 1))
        if k.size:
            n = repeats // 10
            si.append(np.full(n, i, np.int64))
            ti.append(np.full(n, 1, np.int64))
            d.append(net.distance_m[k[0]] + g.normal(0, 5e-6, n))
    si, ti, d = (np.concatenate(x) for x in (si, ti, d))
    obs = Observations(tuple(f"S{i}" for i in range(s)), tuple(f"T{j}" for j in range(t)), si, ti, d,
                       np.full(d.size, 5e-6))
    return net, obs


@pytest.mark.parametrize("few", [getattr(K, "FEW_PER_TARGET", 32), 0])
def test_many_readings_of_a_target_kernels_equal_numpy(monkeypatch, few):
    """Hat diagonal and target blocks of targets with 300 and 30 x 6 readings through the kernels'
    linear-time sums (``few = 0``: every target through them) against the numpy path, which treats a
    pair's repeated readings as one observation of all their weight (1e-12 relative: rounding of
    sums of ~10^3 terms); and, independently, the trace of the hat matrix against the number of
    estimated parameter combinations, observations minus degrees of freedom."""
    net, obs = _repeated_network()
    res = adjust(obs, initial=Start(net.station_xyz_m, net.target_xyz_m, net.offset_m), snooping=False,
                 solver="dense")
    cov = res.covariance
    monkeypatch.setattr(C, "KERNELS_ABOVE_OBS", 0)
    monkeypatch.setattr(K, "FEW_PER_TARGET", few)
    h_k, h_n = cov.hat_diagonal(), cov.hat_diagonal(kernels=False)
    np.testing.assert_allclose(h_k, h_n, rtol=1e-12, atol=1e-13)
    tb_k, tb_n = cov.target_blocks(), cov.target_blocks(kernels=False)
    assert np.abs(tb_k - tb_n).max() <= 1e-12 * np.abs(tb_n).max()
    # independent: trace(hat) = number of estimable parameter combinations = n_obs - dof
    assert h_k.sum() == pytest.approx(obs.n_obs - res.dof, abs=1e-8)


def test_blocks_cover_every_target_once():
    """The target ranges of the blocked kernels: consecutive, covering 0..t, each about
    ``block_obs`` observations or a single larger target."""
    tptr = np.concatenate([[0], np.cumsum([3, 1, 500, 2, 2, 2, 0, 7])]).astype(np.int64)
    got = list(K.target_ranges(tptr, block_obs=5))
    assert got[0][0] == 0 and got[-1][1] == tptr.size - 1
    assert all(a[1] == b[0] for a, b in zip(got, got[1:]))
    assert (2, 3) in got                                      # the 500-reading target alone
    assert all(tptr[j1] - tptr[j0] <= 5 or j1 == j0 + 1 for j0, j1 in got)


def _hostile_file(tmp_path, repeats=10_000):
    lines = (EX / "network" / "small_volume_obs.csv").read_text().splitlines()
    rows = [ln for ln in lines if ln and not ln.startswith("#")]
    pair = next(r for r in rows[1:] if r.startswith("A,1,"))
    p = tmp_path / "repeats.csv"
    p.write_text("\n".join(rows + [pair] * repeats) + "\n")
    return p


def test_ten_thousand_readings_of_one_pair_finish(tmp_path):
    """The 56-row example plus 10 000 readings of (A, 1) ran for hours (the n^3 hat diagonal of the
    pair's target); now the adjustment ends. Bound 600 s: a cold numba cache compiles the kernels
    first on a loaded 2-core machine; the run itself takes seconds."""
    p = _hostile_file(tmp_path)
    t0 = time.monotonic()
    r = subprocess.run(CLI + ["adjust", str(p), "--json"], env=cli_env(), capture_output=True, text=True,
                       timeout=600)
    assert r.returncode in (0, 2), r.stderr[-2000:]
    if r.returncode == 2:                                  # refused: one line naming the file
        lines = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
        assert len(lines) == 1 and str(p.name) in lines[0], r.stderr
    assert time.monotonic() - t0 < 600


_LONG_KERNEL = r"""
import signal, sys, time
import numpy as np
from multilat.network.adjust import _covariance_kernels as K

class Stop(BaseException):
    pass

def on_term(signum, frame):
    raise Stop()

signal.signal(signal.SIGTERM, on_term)
# 4000 targets of 200 observations, 4 stations (Q = 5): the n x n sums (FEW_PER_TARGET raised
# above 200) take ~10 ms a target, ~20-40 s in all; blocks of 2000 observations (10 targets)
s, t, n = 4, 4000, 200
g = np.random.default_rng(0)
m = t * n
Qgg = np.eye(5 * s)
Minv = np.tile(np.eye(3), (t, 1, 1))
Js, Jt, P = g.normal(size=(m, 5)), g.normal(size=(m, 3)), g.normal(size=(m, 3))
si = np.arange(m, dtype=np.int64) % s
order = np.arange(m, dtype=np.int64)
tptr = np.arange(0, m + 1, n, dtype=np.int64)
h = np.empty(m)
K.FEW_PER_TARGET = 10**9
K.BLOCK_OBS = 2000
small = np.array([0, n], np.int64)
K.hat_diagonal(Qgg, Minv[:1], Js[:n], Jt[:n], P[:n], si[:n], order[:n], small, h[:n])   # compiled
print("running", flush=True)
t0 = time.monotonic()
try:
    K.hat_diagonal(Qgg, Minv, Js, Jt, P, si, order, tptr, h)
except Stop:
    print(f"stopped {time.monotonic() - t0:.2f}", flush=True)
    sys.exit(143)
print("finished", flush=True)
"""


def test_sigterm_stops_a_long_statistics_kernel_between_blocks():
    """SIGTERM 1 s into a ~20-40 s hat-diagonal computation: the process's handler runs when the current
    block of targets returns, and the process exits with 143 well before the computation would have
    ended (it waited for the whole kernel). Bound: 15 s after the signal (a block takes ~0.1 s;
    margin for a loaded machine)."""
    p = subprocess.Popen([sys.executable, "-c", _LONG_KERNEL], env=cli_env(), stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "running"
        time.sleep(1.0)
        p.send_signal(signal.SIGTERM)
        t0 = time.monotonic()
        out, _ = p.communicate(timeout=15)
        waited = time.monotonic() - t0
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 143 and out.startswith("stopped"), (p.returncode, out)
    assert waited < 15
