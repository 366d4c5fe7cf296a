"""The Monte Carlo's linear (GUM, first-order) covariance is the adjustment's (issue 27): one function,
:meth:`multilat.network.adjust.covariance.NetworkCovariance.linear_covariance`, behind
``BatchedNetwork.linear_covariance`` and ``CoupledBatchedNetwork.linear_covariance``.

Independent values:

* ``adjust``'s reported covariances: the per-point 3x3 blocks (``station_cov_m2``, ``target_cov_m2``:
  :meth:`NetworkCovariance.target_blocks` / :meth:`global_block`, their own block formulas, not the
  product the propagation uses) and the offsets' standard deviations. ``propagate``'s GUM column equals
  them to 1e-13 relative (the largest difference over the largest element; measured 1.0e-14 at most:
  float64 sums of the same terms in another order); the code before this change (its own Jacobian,
  penalty inverse and S-transformation) differed by 4.5e-12 (distance only), 1.0e-10 (heads over
  stations), 9.5e-13 and 4.6e-12 (angles, levelled), so each test fails on it;
* a dense first-order propagation written out here (the distances' Jacobian from the unit vectors,
  the Moore-Penrose inverse instead of the Schur form, the S-transformation ``I - G (EᵀG)⁻¹Eᵀ``) for the
  sandwich ``N⁺ Jᵀ W C W J N⁺`` of distances whose σ differ from the weights' or are correlated: 1e-9
  (the pseudo-inverse of a matrix of condition ~1e8 in metres and offsets loses ~8 digits of 16);
* the known truth of a built-in configuration against ``adjust`` of its exact distances: another
  generalised inverse (a penalty on the stations' rigid motions against ``adjust``'s held 3-2-1
  coordinates) in another frame, so equal to the rounding of the two, measured 3.7e-12: 1e-11.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.io.files import read_observations
from multilat.network.model.data import Observations
from multilat.network.model.datum import helmert_basis, s_transform
from multilat.network.model.parameter_layout import XYZ, ParameterLayout
from multilat.network.montecarlo import propagate as pr
from multilat.network.montecarlo.batched_coupled import CoupledBatchedNetwork
from multilat.network.synthetic.configs import small_volume
from multilat.network.synthetic.generator import synthetic_network

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "network"


def _assert_propagate_is_adjust(obs, res, **kw):
    """``propagate``'s linear std and point covariances against ``adjust``'s reported ones, 1e-13."""
    prob = pr.problem_from_observations(obs, adjustment=res, **kw)
    r = pr.propagate(prob, trials=1000, rng=3, noise="gaussian")
    s, k = obs.n_stations, prob.network.n_params
    ref_cov = np.concatenate([res.station_cov_m2, res.target_cov_m2])
    scale = np.abs(ref_cov).max()
    assert np.abs(r.point_cov_lin - ref_cov).max() <= 1e-13 * scale
    ref_std = np.concatenate([np.sqrt(np.einsum("sii->si", res.station_cov_m2)).ravel(), res.offset_std_m,
                              np.sqrt(np.einsum("tii->ti", res.target_cov_m2)).ravel()])
    assert np.abs(r.lin_std[:k] - ref_std).max() <= 1e-13 * ref_std.max()
    assert r.lin_std[s * 3:s * 4].tolist() != [0.0] * s
    return prob, r


def test_distance_only_propagate_is_the_adjustments_covariance():
    obs = read_observations(EXAMPLES / "small_volume_obs.csv")
    res = adjust(obs, snooping=False)
    prob, _ = _assert_propagate_is_adjust(obs, res)
    assert type(prob.network).__name__ == "BatchedNetwork" and prob.network.nominal_covariance is res.covariance


def test_heads_over_stations_propagate_is_the_adjustments_covariance():
    obs = read_observations(EXAMPLES / "sequential" / "obs.csv")
    assert obs.shares_heads
    res = adjust(obs, snooping=False)
    prob, r = _assert_propagate_is_adjust(obs, res)
    assert isinstance(prob.network, CoupledBatchedNetwork)
    # a head's offset: one unknown on each of its stations, the same linear std
    s, hi = obs.n_stations, obs.head_index
    off = r.lin_std[3 * s:4 * s]
    assert np.array_equal(off, off[np.unique(hi, return_index=True)[1]][hi])


@pytest.mark.parametrize("levelled", [False, True])
def test_angles_and_orientations_propagate_is_the_adjustments_covariance(levelled):
    net = synthetic_network(np.random.default_rng([18, 1]), population="mixed", levelled=levelled)
    res = adjust(net.obs, initial=net, snooping=False)
    prob, _ = _assert_propagate_is_adjust(net.obs, res)
    assert prob.network.n_orientation == 6 and prob.network.datum.about_z == levelled


def _dense_sandwich(net, C_obs):
    """``S N⁺ Jᵀ W C W J N⁺ Sᵀ`` written out: the reported layout, unit vectors, pinv, S-transform."""
    lay, si, ti = net.reported_layout, net.station_index, net.target_index
    d = net.station_xyz_m[si] - net.target_xyz_m[ti]
    u = d / np.linalg.norm(d, axis=1)[:, None]
    k = np.arange(net.n_obs)
    J = np.zeros((net.n_obs, lay.n))
    J[k[:, None], lay.station_block(XYZ)[si]] = u
    J[k[:, None], lay.target_block()[ti]] = -u
    J[k, lay.station_columns("offset")[si]] = 1.0
    W = np.diag(1.0 / net.sigma_m ** 2)
    Np = np.linalg.pinv(J.T @ W @ J, rcond=1e-13, hermitian=True)
    E = net.datum.constraint_matrix(net.station_xyz_m, net.target_xyz_m)
    G = lay.datum_rows(helmert_basis(np.concatenate([net.station_xyz_m, net.target_xyz_m])))
    S = s_transform(G, E)
    return S @ Np @ J.T @ W @ C_obs @ W @ J @ Np @ S.T


@pytest.mark.parametrize("datum", ["free", "321:A,B,C"])
def test_the_sandwich_against_a_dense_propagation(datum):
    """Distances whose σ are not the weights' (the distance model's), or correlated (shared sensors)."""
    net = pr.problem_from_config(small_volume(), sigma_m=4.7e-6, datum=datum).network
    g = np.random.default_rng(5)
    ratio = g.uniform(0.7, 1.5, net.n_obs)
    A = g.normal(size=(net.n_obs, 3)) * 0.3
    full = np.diag((net.sigma_m * ratio) ** 2) + (A @ A.T) * np.outer(net.sigma_m, net.sigma_m)
    for got, C in ((net.linear_covariance(), np.diag(net.sigma_m ** 2)),
                   (net.linear_covariance(sigma_m=net.sigma_m * ratio), np.diag((net.sigma_m * ratio) ** 2)),
                   (net.linear_covariance(cov_m2=full), full)):
        ref = _dense_sandwich(net, C)
        assert np.abs(got - ref).max() <= 1e-9 * np.abs(ref).max()
        assert np.array_equal(got, got.T)


def test_columns_in_chunks_give_the_same_covariance():
    """One column per product (``chunk_elements`` 1) against all at once: the same sums per column, so
    equal to rounding (BLAS may block a matrix product differently by its width): 1e-14."""
    net = pr.problem_from_config(small_volume(), sigma_m=4.7e-6).network
    cov = net.nominal_covariance
    ratio = np.random.default_rng(2).uniform(0.7, 1.5, net.n_obs)
    for kw in ({}, dict(weight_sigma_m=net.sigma_m, sigma_m=net.sigma_m * ratio)):
        whole, one = cov.linear_covariance(**kw), cov.linear_covariance(chunk_elements=1, **kw)
        assert np.abs(whole - one).max() <= 1e-14 * np.abs(whole).max()


@pytest.mark.parametrize("datum", ["free", "321:A,B,C"])
def test_a_known_truth_is_the_adjustment_of_its_exact_distances(datum):
    prob = pr.problem_from_config(small_volume(), sigma_m=4.7e-6, datum=datum)
    net = prob.network
    obs = Observations(list(prob.station_ids), list(prob.target_ids), net.station_index, net.target_index,
                       prob.distance_m, net.sigma_m)

    class Start:
        station_xyz_m, target_xyz_m, offset_m = net.station_xyz_m, net.target_xyz_m, net.offset_m

    res = adjust(obs, datum=datum, initial=Start(), snooping=False)
    assert np.abs(res.target_xyz_m - net.target_xyz_m).max() < 1e-12        # the same point, the same frame
    idx = net.reported_layout.index_in(ParameterLayout.adjustment(net.n_stations, net.n_targets))
    ref = res.covariance.full()[np.ix_(idx, idx)]
    assert net.covariance is None
    assert np.abs(net.linear_covariance() - ref).max() <= 1e-11 * np.abs(ref).max()


def test_the_trials_do_not_read_the_linear_covariance():
    """Bit-identical trials whatever the covariance the network holds (here the adjustment's times 4):
    only the GUM column moves (x 2 in standard deviation)."""
    obs = read_observations(EXAMPLES / "sequential" / "obs.csv")
    res = adjust(obs, snooping=False)
    prob = pr.problem_from_observations(obs, adjustment=res)
    cov = res.covariance
    four = type(cov).__new__(type(cov))
    four.__dict__.update(cov.__dict__)
    four.factor, four.CHt, four.HCHt = 4.0 * cov.factor, 4.0 * cov.CHt, 4.0 * cov.HCHt
    from dataclasses import replace

    other = replace(prob, network=replace(prob.network, covariance=four))
    a = pr.propagate(prob, trials=1000, rng=3, noise="gaussian", keep_samples=True)
    b = pr.propagate(other, trials=1000, rng=3, noise="gaussian", keep_samples=True)
    assert np.array_equal(a.samples, b.samples) and np.array_equal(a.mc_std, b.mc_std)
    np.testing.assert_allclose(b.lin_std, 2.0 * a.lin_std, rtol=1e-12)


def test_refusals():
    obs = read_observations(EXAMPLES / "small_volume_obs.csv")
    res = adjust(obs, snooping=False)
    prob = pr.problem_from_observations(obs, adjustment=res)
    other = read_observations(EXAMPLES / "sequential" / "obs.csv")
    from dataclasses import replace

    wrong = replace(prob.network, covariance=adjust(other, snooping=False).covariance)
    with pytest.raises(MultilatError, match="covariance: not this network's"):
        wrong.linear_covariance()
    net = synthetic_network(np.random.default_rng([18, 1]), population="mixed")
    res = adjust(net.obs, initial=net, snooping=False)
    nw = pr.problem_from_observations(net.obs, adjustment=res).network
    with pytest.raises(MultilatError, match="is its adjustment's"):
        replace(nw, covariance=None).linear_covariance()
