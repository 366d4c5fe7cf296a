"""The one Gauss-Newton / Levenberg-Marquardt loop (``multilat.network.adjust.solve.loop.iterate``)
that the distance path and the general layer share (issue 27): its damping on a problem whose
minimum is known in closed form, the general layer's damped steps (dense = sparse), and a start from
which the general layer's former plain Gauss-Newton oscillated and failed but the damped loop
converges to the minimum found from a near start.
"""

from __future__ import annotations

import importlib
from pathlib import Path

import numpy as np
import pytest

from multilat.network.adjust.solve.loop import iterate
from multilat.network.model.observations import Network
from multilat.network.model.points import FIXED, FREE, PointSet

general_adjust = importlib.import_module("multilat.network.adjust.general.adjust")   # the package's `adjust` is
sparse_backend = importlib.import_module("multilat.network.adjust.general.sparse")   # the function
DATA = Path(__file__).resolve().parent / "data" / "gama3d"


class _Arctan:
    """One residual ``atan(x)``: the minimum is ``x = 0`` (zero residual). Gauss-Newton (here Newton's
    method) moves to ``x - atan(x) (1 + x²)``, which overshoots and diverges from ``|x|`` above 1.39
    (the classic example), oscillating in sign. ``step_sigma`` is ``|dx|`` (σ = 1)."""

    n_rows = 1
    rounding = 4 * np.finfo(float).eps

    def cost(self, x: float) -> float:
        return float(np.arctan(x) ** 2) if np.isfinite(x) else np.inf

    def step(self, x: float, lam: float):
        dx = -float(np.arctan(x)) * (1.0 + x * x) / (1.0 + lam)
        return dx, abs(dx)

    def apply(self, x: float, dx: float) -> float:
        return x + dx


def test_damping_converges_where_gauss_newton_diverges():
    toy, x, seen = _Arctan(), 2.0, []
    for _ in range(4):                                    # plain Gauss-Newton: diverges, oscillating
        x = toy.apply(x, toy.step(x, 0.0)[0])
        seen.append(x)
    assert abs(seen[-1]) > 1e3 and np.all(np.diff(np.abs(seen)) > 0) and np.all(np.diff(np.sign(seen)) != 0)
    records = []
    x, cost, conv = iterate(toy, 2.0, max_iter=100, on_accept=lambda x0, dx, c: records.append(c))
    assert conv.converged, conv
    assert abs(x) < 1e-12 and cost < 1e-24                # the closed-form minimum (quadratic convergence)
    assert all(b < a for a, b in zip(records, records[1:]))     # the cost never rises
    assert len(records) < 20


def _gama(name: str):
    from multilat.network.adjust.approximate.general import approximate
    from multilat.network.io.interop.gama_input import read_gama_input

    return approximate(read_gama_input(DATA / f"{name}.xml"))


@pytest.mark.parametrize("name, datum, defect", [("two_trackers", "auto", 4), ("trilateration_free", "free", 6),
                                                 ("trilateration_fixed", "auto", 0)])
@pytest.mark.parametrize("lam", [1e-4, 1.0, 1e3])
def test_sparse_damped_step_equals_the_dense_bordered_system(name, datum, defect, lam):
    """The sparse back end's Levenberg-Marquardt step (``sparse.damped_step``: the damped Schur
    elimination and the inner constraints by ``W (BᵀW)⁻¹``) against the dense back end's damped
    bordered system ``[[N + lam diag N, B], [Bᵀ, 0]]``, a second method: equal to 1e-9 of the step
    (both solve the same regular system, through differently conditioned factorisations), at a start
    1 dm off the minimum; with a datum defect (inner constraints on the datum points) and without."""
    net = _gama(name)
    res = general_adjust.adjust(net)
    system = general_adjust.System(net)
    x = res.parameters + np.where(system.layout.free, 0.1, 0.0) * np.cos(np.arange(res.parameters.size))
    mask = system.datum_mask(datum)
    _, rw, jw, det, _, _ = system.linearise(x, mask)
    dense = general_adjust._step(jw, rw, det, lam)[0]
    lin = sparse_backend.linearise(system, x, mask, lambda det: None)
    sparse = sparse_backend.damped_step(system, lin, lam)
    assert np.abs(sparse - dense).max() <= 1e-9 * np.abs(dense).max()
    if det.defect:                                        # the step keeps the datum
        assert np.abs(det.constraints.T @ sparse).max() <= 1e-12 * np.abs(sparse).max()
    assert det.defect == defect


STATIONS = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 10.0, 0.0], [10.0, 10.0, 3.0]])
POINT = np.array([5.0, 5.0, 2.0])
#: 3 km from the 10 m network: plain Gauss-Newton oscillates (vᵀPv rose at 25 of its first 66 steps,
#: measured) and needed 67 iterations (not converged in the default 50); the damped loop descends in 23
FAR = np.array([-1932.87, -1128.61, -1997.56])


def _far_network(start: np.ndarray) -> Network:
    from multilat.network.model.observations import Block

    rng = np.random.default_rng(3)
    d = np.linalg.norm(STATIONS - POINT, axis=1) + 1e-5 * rng.standard_normal(4)
    block = Block("slope_distance", d, np.full(4, 1e-5), None, {"from": np.arange(4), "to": np.full(4, 4)})
    pts = PointSet.build([f"P{i}" for i in range(5)], np.vstack([STATIONS, [start]]), status=[FIXED] * 4 + [FREE])
    return Network(pts, (block,))


@pytest.mark.parametrize("backend", ["dense", "sparse"])
def test_far_start_converges_by_damping(backend):
    """Four fixed stations, one point started 3 km off (``FAR``): before the one loop the general layer
    ended "did not converge in 50 iterations" here; damped, it converges to the minimum reached from
    a start 1 mm off (1e-9 m: a few iterations of rounding), vᵀPv never rising."""
    opts = general_adjust.AdjustOptions(backend=backend)
    near = general_adjust.adjust(_far_network(POINT + 1e-3), options=opts)
    far = general_adjust.adjust(_far_network(POINT + FAR), options=opts)
    assert far.convergence.converged and near.convergence.converged
    assert np.abs(far.xyz_m - near.xyz_m).max() < 1e-9
    v = [c for _, c in far.iterations]
    assert all(b <= a * (1 + 1e-9) for a, b in zip(v, v[1:])), v      # rises only within rounding
    assert len(v) < 50
