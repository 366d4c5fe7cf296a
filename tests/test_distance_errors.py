"""The compiled draw of the distance model (multilat.distance_errors) against budget.py's numpy model.

Two checks of different kinds: (1) the compiled formulas equal :func:`multilat.budget.group_errors`
for the same inputs (a second implementation of the same equations, to rounding); (2) the compiled
draws have the distribution of :func:`multilat.budget.sample_distance_errors` (another generator:
equal in distribution, within Monte Carlo standard errors).
"""

import numpy as np
import pytest

from multilat import budget, instrument as instr
from multilat.distance_errors import INPUTS, draw_errors, error_model, errors_of_inputs


def _variant(**target):
    inst = instr.load_instrument("seed2020")
    return inst.model_copy(update={"target": inst.target.model_copy(update=target)})


@pytest.mark.parametrize("inst", [
    instr.load_instrument("seed2020"),
    _variant(transit_correction="line_of_sight"),
    _variant(transit_correction="target_axis"),
    _variant(misalignment_shape="square"),
], ids=["seed2020", "line_of_sight", "target_axis", "square"])
def test_compiled_formulas_equal_the_numpy_model(inst):
    rng = np.random.default_rng(3)
    n = 5000
    dists = budget.group_inputs(inst, "A")
    X = np.stack([dists[nm].sample(rng, n) for nm in INPUTS], axis=1)
    L = rng.uniform(0.2, 20.0, n)
    air = {k: np.zeros(n) for k in ("d_t", "d_p", "d_rh", "d_co2")}
    ref = budget.group_errors(budget._params(inst, "A"), L, **{nm: X[:, k] for k, nm in enumerate(INPUTS)},
                              **air)[:, :3].sum(axis=1)
    got = errors_of_inputs(error_model(inst, ["A"]), 0, L, X)
    # the two evaluate the same equations in a different order (e.g. cos(phi - gamma) expanded, the
    # misalignment's sines without the angles): rounding of terms of size L ~ 20 m, eps L ~ 4e-15 m,
    # is the scale; 1e-13 m (0.1 pm) allows a few dozen roundings and is 1e-8 of the errors' size
    assert np.max(np.abs(got - ref)) < 1e-13


def test_compiled_draws_have_the_numpy_distribution():
    inst = instr.load_instrument("seed2020")
    d = np.array([0.5, 2.0, 6.0, 12.0])
    n = 200_000
    a = draw_errors(error_model(inst, ["A"]), np.zeros(4, int), d, n, np.random.default_rng(1))
    b = budget.sample_distance_errors(inst, d, rng=np.random.default_rng(2), head="A", trials=n)
    for k in range(4):
        x, y = a[:, k], b[:, k]
        sd = y.std()
        # means: difference of two independent means, SE = sd sqrt(2/n); 4.5 SE over 4 distances
        assert abs(x.mean() - y.mean()) < 4.5 * sd * np.sqrt(2 / n)
        # standard deviations: SE of a sample std is sd sqrt((kurt - 1) / (4 n)); kurtosis from the data
        kurt = np.mean((y - y.mean()) ** 4) / sd ** 4
        se_sd = sd * np.sqrt((kurt - 1) / (4 * n)) * np.sqrt(2)
        assert abs(x.std() - sd) < 4.5 * se_sd
        # 2.5 %, 50 %, 97.5 % quantiles: within 2 % of the std (their SE here is ~0.5 %)
        qa, qb = np.quantile(x, [0.025, 0.5, 0.975]), np.quantile(y, [0.025, 0.5, 0.975])
        assert np.max(np.abs(qa - qb)) < 0.02 * sd
    # distances within a trial are independent (each reading draws its own inputs)
    assert abs(np.corrcoef(a[:, 0], a[:, 3])[0, 1]) < 4.5 / np.sqrt(n)


def test_same_seed_same_numbers_whatever_the_threads():
    numba = pytest.importorskip("numba")
    inst = instr.load_instrument("seed2020")
    model = error_model(inst, ["A", "B"])
    d = np.linspace(0.5, 9, 30)
    rows = np.arange(30) % 2
    x1 = draw_errors(model, rows, d, 257, np.random.default_rng(9))
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        x2 = draw_errors(model, rows, d, 257, np.random.default_rng(9))
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(x1, x2)
    assert not np.array_equal(x1, draw_errors(model, rows, d, 257, np.random.default_rng(10)))
    # the first trials of a longer draw are the trials of a shorter one (per-trial streams)
    assert np.array_equal(draw_errors(model, rows, d, 500, np.random.default_rng(9))[:257], x1)
