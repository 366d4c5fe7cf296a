"""Observation model: analytic Jacobian vs central finite differences; Schur-reduced normal
equations vs the dense normal equations (two independent routes to the same step)."""

import numpy as np
import pytest

from multilat.network.adjust.solve.normal_equations import back_substitute, reduced_normal_equations
from multilat.network.model.distance import Q, dense_jacobian, inv3, predicted_distance_m, residuals_and_jacobian


def _random_params(rng, s=5, t=7):
    H = rng.normal(size=(s, 3)) * 2.0
    T = rng.normal(size=(t, 3)) * 0.5
    off = rng.normal(size=s) * 1e-3
    sc = rng.normal(size=s) * 1e-5
    si = np.repeat(np.arange(s), t)
    ti = np.tile(np.arange(t), s)
    keep = rng.uniform(size=si.size) > 0.2
    return H, T, off, sc, si[keep], ti[keep]


def _pack(H, T, off, sc):
    g = np.concatenate([H, off[:, None], sc[:, None]], axis=1).ravel()
    return np.concatenate([g, T.ravel()])


def _unpack(x, s, t):
    g = x[:Q * s].reshape(s, Q)
    return g[:, :3], x[Q * s:].reshape(t, 3), g[:, 3], g[:, 4]


@pytest.mark.parametrize("cost", ["distance", "squared"])
def test_jacobian_matches_central_differences(cost):
    rng = np.random.default_rng(11)
    H, T, off, sc, si, ti = _random_params(rng)
    s, t = H.shape[0], T.shape[0]
    d_obs = predicted_distance_m(H, T, off, sc, si, ti) + rng.normal(size=si.size) * 1e-4
    r, Js, Jt = residuals_and_jacobian(d_obs, H, T, off, sc, si, ti, cost=cost)
    J = dense_jacobian(Js, Jt, si, ti, s, t)
    x0 = _pack(H, T, off, sc)
    Jfd = np.empty_like(J)
    for p in range(x0.size):
        h = 1e-6 if (p < Q * s and p % Q == 4) else 1e-6   # scale is dimensionless, same step
        xp, xm = x0.copy(), x0.copy()
        xp[p] += h
        xm[p] -= h
        rp = residuals_and_jacobian(d_obs, *_unpack(xp, s, t)[:2], *_unpack(xp, s, t)[2:], si, ti, cost=cost)[0]
        rm = residuals_and_jacobian(d_obs, *_unpack(xm, s, t)[:2], *_unpack(xm, s, t)[2:], si, ti, cost=cost)[0]
        Jfd[:, p] = -(rp - rm) / (2 * h)       # J is d(computed - observed)/dx = -dr/dx
    # central differences: truncation ~h^2 * third derivative (~1/|H-T|^2 ~ 1) and rounding
    # ~eps*|r|/h ~ 1e-10: 1e-7 relative to the largest entry covers both
    np.testing.assert_allclose(J, Jfd, atol=1e-7 * np.abs(J).max())


def test_inv3_matches_numpy():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(50, 3, 3))
    A = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(3)
    np.testing.assert_allclose(inv3(A), np.linalg.inv(A), rtol=1e-10, atol=1e-12)


def test_schur_step_equals_dense_normal_equations():
    rng = np.random.default_rng(5)
    H, T, off, sc, si, ti = _random_params(rng, s=6, t=30)
    s, t = H.shape[0], T.shape[0]
    d_obs = predicted_distance_m(H, T, off, sc, si, ti) + rng.normal(size=si.size) * 1e-3
    sigma = rng.uniform(1e-6, 5e-6, size=si.size)
    r, Js, Jt = residuals_and_jacobian(d_obs, H, T, off, sc, si, ti)
    gfree = np.ones((s, Q), bool)
    gfree[0, :3] = False
    gfree[1, 1:3] = False
    gfree[2, 2] = False
    gfree[:, 4] = False        # scales fixed
    w = 1 / sigma
    Js_w = Js * w[:, None] * gfree[si]
    Jt_w = Jt * w[:, None]
    sys_ = reduced_normal_equations(r * w, Js_w, Jt_w, si, ti, s, t, chunk_targets=4)
    f = gfree.ravel()
    dg = np.zeros(Q * s)
    dg[f] = np.linalg.solve(sys_.N[np.ix_(f, f)], sys_.b[f])
    dt = back_substitute(sys_, dg, Js_w, Jt_w, si, ti)
    # dense route
    J = dense_jacobian(Js_w, Jt_w, si, ti, s, t)
    keep = np.concatenate([f, np.ones(3 * t, bool)])
    Jk = J[:, keep]
    x = np.linalg.lstsq(Jk, r * w, rcond=None)[0]
    full = np.zeros(keep.size)
    full[keep] = x
    # the normal-equation route squares the condition number: agreement to kappa^2 * eps relative
    kappa = np.linalg.cond(Jk)
    tol = 10 * kappa ** 2 * np.finfo(float).eps
    assert tol < 1e-5
    np.testing.assert_allclose(np.concatenate([dg, dt.ravel()]), full, rtol=0, atol=tol * np.abs(x).max())


@pytest.mark.parametrize("cost", ["distance", "squared"])
def test_residuals_alone_equal_those_with_the_jacobian(cost):
    """``residuals`` (the cost of a trial step, no Jacobian) gives the very numbers of
    ``residuals_and_jacobian``: bit for bit."""
    from multilat.network.model.distance import residuals, residuals_and_jacobian

    r = np.random.default_rng(3)
    H, T = r.normal(size=(5, 3)) * 3, r.normal(size=(40, 3)) * 3
    si, ti = r.integers(0, 5, 200), r.integers(0, 40, 200)
    off, sc = r.normal(size=5) * 1e-3, r.normal(size=5) * 1e-6
    d = np.linalg.norm(H[si] - T[ti], axis=1) + r.normal(size=200) * 1e-5
    a = residuals(d, H, T, off, sc, si, ti, cost=cost)
    b, _, _ = residuals_and_jacobian(d, H, T, off, sc, si, ti, cost=cost)
    assert np.array_equal(a, b)
