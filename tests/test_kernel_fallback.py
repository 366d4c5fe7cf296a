"""The kernels' pure-Python fallback (numba absent): the same functions run as plain Python.

It is live code: without numba the sparse back end, multilateration and the blocks' test call
:mod:`multilat.network.adjust.solve._sparse_kernels` as Python. ``MULTILAT_PURE_PYTHON=1`` (read by
:mod:`multilat._numba` at import) makes a process behave as if numba were not installed; a
subprocess runs a few kernels that way on a small network against independent numpy paths
(tolerances: rounding of sums of a few hundred terms, 1e-12 relative; coordinates 1e-9 m)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

_SCRIPT = r"""
import sys
import numpy as np

from multilat import _numba
assert not _numba.HAVE_NUMBA
from multilat.network.adjust import _covariance_kernels as CK
from multilat.network.adjust.solve import _sparse_kernels as SK
from multilat.network.adjust.distance.adjust import Start, adjust
from multilat.network.model.data import Observations
from multilat.network.adjust.approximate.large import multilaterate_targets
from multilat.network.synthetic.generator import synthetic_network
from multilat.network.model.distance import residuals_and_jacobian

s, t = 6, 14
net = synthetic_network(3, population="rings", n_stations=s, n_targets=t, per_target=5, size_m=5.0)
obs = Observations(tuple(f"S{i}" for i in range(s)), tuple(f"T{j}" for j in range(t)),
                   net.station_index, net.target_index, net.distance_m, net.sigma_m)
start = Start(net.station_xyz_m, net.target_xyz_m, net.offset_m)

# the sparse back end (assemble, back_substitute as Python) against the dense one
sp = adjust(obs, initial=start, solver="sparse", snooping=False)
de = adjust(obs, initial=start, solver="dense", snooping=False)
assert np.abs(sp.target_xyz_m - de.target_xyz_m).max() < 1e-9, "sparse vs dense"
print("sparse back end")

# multilateration of every target from the true stations and noise-free distances: the truth
true_d = (np.linalg.norm(net.station_xyz_m[net.station_index] - net.target_xyz_m[net.target_index], axis=1)
          + net.offset_m[net.station_index])
x, rms, _ = multilaterate_targets(net.station_xyz_m, net.offset_m, net.station_index, net.target_index,
                                  true_d, net.sigma_m, t)
assert np.abs(x - net.target_xyz_m).max() < 1e-9, "multilaterate"
print("multilaterate")

# the blocks' degeneracy test against numpy's eigenvalues
N = np.random.default_rng(0).normal(size=(6, 3, 3))
N = N @ np.swapaxes(N, 1, 2)
N[2] = np.outer([1.0, 2, 3], [1.0, 2, 3])                     # rank 1: degenerate
bad = np.empty(6, bool)
SK.degenerate_blocks(N, 1e-10, bad)
ev = np.linalg.eigvalsh(N)
assert bad.tolist() == (~(ev[:, 0] > 1e-10 * ev[:, 2])).tolist() and bad[2], "degenerate_blocks"
print("degenerate_blocks")

# residuals and whitened Jacobian against the numpy model
p = de
r, Js, Jt = residuals_and_jacobian(obs.distance_m, p.station_xyz_m, p.target_xyz_m, p.offset_m, p.scale,
                                   obs.station_index, obs.target_index)
out = np.empty(obs.n_obs)
SK.distance_residuals(p.station_xyz_m, p.target_xyz_m, p.offset_m, np.asarray(p.scale, float), obs.station_index,
                      obs.target_index, obs.distance_m, out)
assert np.allclose(out, r, rtol=0, atol=1e-15), "distance_residuals"
print("distance_residuals")

# the statistics kernels against the numpy path of the covariance (both target paths)
cov = de.covariance
Qgg, Minv, Js_w, Jt_w, P, si, ti, order, tptr = cov._kernel_args()
h_n = cov.hat_diagonal(kernels=False)
tb_n = cov._target_blocks_internal(kernels=False)
for few in (CK.FEW_PER_TARGET, 0):
    CK.FEW_PER_TARGET = few
    h = np.empty(obs.n_obs)
    CK.hat_diagonal(Qgg, Minv, Js_w, Jt_w, P, si, order, tptr, h)
    assert np.allclose(h, h_n, rtol=1e-12, atol=1e-13), ("hat_diagonal", few, np.abs(h - h_n).max())
    tb = np.empty((t, 3, 3))
    CK.target_blocks(Qgg, Minv, Js_w, P, si, order, tptr, tb)
    assert np.abs(tb - tb_n).max() <= 1e-12 * np.abs(tb_n).max(), ("target_blocks", few)
row = np.empty(obs.n_obs)
CK.hat_row(3, Qgg, Minv, Js_w, Jt_w, P, si, ti, order, tptr, row)
assert np.allclose(row, cov.hat_row(3, kernels=False), rtol=1e-12, atol=1e-13), "hat_row"
print("statistics kernels")
assert "numba" not in sys.modules, "numba was imported"
"""


def test_kernels_run_as_plain_python_without_numba():
    env = dict(os.environ, MULTILAT_PURE_PYTHON="1",
               PYTHONPATH=str(Path(__file__).resolve().parents[1] / "src"))
    p = subprocess.run([sys.executable, "-c", _SCRIPT], env=env, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    assert p.stdout.split() == ["sparse", "back", "end", "multilaterate", "degenerate_blocks", "distance_residuals",
                                "statistics", "kernels"]
