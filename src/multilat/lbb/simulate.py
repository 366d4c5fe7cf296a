"""Coordinate uncertainty of LBB trilateration: the §5 procedure and a direct propagation.

Two Monte Carlo methods over the same model (:mod:`multilat.lbb.model`):

``procedure`` (the paper's §5, steps 1-8, as written)
    1-3. one initialization: true L0 behind the nominal reading (HTM model + eq. 6);
    4.   repeated ``init_draws`` (2000) times -> mean and std of L0;
    5.   for a target point: the six nominal readings, their true length changes, each added to an
         L0 drawn from N(mean, std) of step 4 (one L0 per repetition, shared by the six sides);
    6.   repeated ``side_draws`` (100) times -> mean and std of each of the six sides;
    7.   ``point_draws`` (100) side sets drawn *independently per side* from N(mean_i, std_i) ->
         trilateration -> point cloud;
    8.   next point.

``direct``
    every trial draws every error source once (one initialization, one fixture state, six side
    poses, one table temperature, one cosine misalignment) and trilaterates; the engine is
    :func:`multilat.montecarlo.run_mc`, one run per point.

Where they agree and where not: step 7 re-samples the six sides independently, which drops their
correlation: the shared L0 error (it shifts all six edges together) and the shared table
temperature (it scales the three base edges together). Each side's *marginal* distribution is the
same in both methods; a coordinate's distribution is the same only when the correlated part of the
side-length covariance does not project onto it (e.g. with the initialization and the table drift
switched off). ``docs/lbb.md`` and ``tests/test_lbb_simulate.py`` quantify this.

Errors are ``simulated - commanded`` (the paper's Fig. 8 definition): the cloud of possible true
tool positions behind the nominal readings, minus the commanded position.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from multilat.distributions import Constant, Normal, Uniform
from multilat.errors import MultilatError
from multilat.lbb.config import LBBConfig
from multilat.lbb.model import (MECH_SOURCES, READ_SOURCES, BarModel, initialization_length,
                                pose_distributions, true_side_lengths)
from multilat.lbb.trilateration import base_sockets_xyz, edges_from_points, trilaterate
from multilat.montecarlo import resolve_seed, run_mc, summarize

__all__ = ["LBBSimulation", "PerSide", "base_xyz", "nominal_geometry", "reachable", "inside_base",
           "volume_points", "direct_inputs",
           "direct_model", "l0_distribution", "run_procedure", "run_direct", "simulate"]


@dataclass(frozen=True)
class PerSide:
    """An input drawn independently for each of the six sides: ``sample(rng, n) -> (n, 6)``."""

    dist: object
    k: int = 6

    def sample(self, rng, size) -> np.ndarray:
        size = (size,) if np.ndim(size) == 0 else tuple(size)
        return self.dist.sample(rng, size + (self.k,))


@dataclass(frozen=True)
class LBBSimulation:
    """Per-point coordinate errors of LBB trilateration.

    Attributes
    ----------
    method : str
        ``"procedure"`` or ``"direct"``.
    nominal_m : ndarray (p, 3)
        Commanded tool positions in the base frame (m).
    mean_error_m : ndarray (p, 3)
        Mean of ``simulated - commanded`` (m).
    std_m : ndarray (p, 3)
        Standard deviation of each coordinate (m).
    cov_m2 : ndarray (p, 3, 3)
        Covariance of the coordinates (m²).
    trials : int
        Points in each point cloud (step 7 draws, or direct trials).
    error_samples_m : ndarray (trials, p, 3)
        The clouds, ``simulated - commanded`` (m).
    nominal_edges_m : ndarray (p, 6)
        Nominal edges ``l12, l13, l23, l1, l2, l3`` (m).
    side_mean_error_m, side_std_m : ndarray (p, 6)
        Mean of ``true - nominal`` and std of each side (procedure: step 6; direct: from the trials).
    l0_mean_error_m, l0_std_m : float
        True L0 minus its nominal value: mean and std (procedure: step 4; direct: NaN).
    seed_entropy : int
        Entropy of the root seed (pass back as ``seed`` to reproduce).
    """

    method: str
    nominal_m: np.ndarray
    mean_error_m: np.ndarray
    std_m: np.ndarray
    cov_m2: np.ndarray
    trials: int
    error_samples_m: np.ndarray
    nominal_edges_m: np.ndarray
    side_mean_error_m: np.ndarray
    side_std_m: np.ndarray
    l0_mean_error_m: float
    l0_std_m: float
    seed_entropy: int

    @property
    def error_magnitude_m(self) -> np.ndarray:
        """|mean error| per point, shape (p,) (the colour of Fig. 8)."""
        return np.linalg.norm(self.mean_error_m, axis=-1)

    @property
    def max_std_m(self) -> float:
        """Largest coordinate standard deviation over all points and axes."""
        return float(np.max(self.std_m))


# ----------------------------------------------------------------------------- geometry
def base_xyz(cfg: LBBConfig) -> np.ndarray:
    """Base sockets (3, 3) of the config in the base frame (m)."""
    b = cfg.base
    return base_sockets_xyz(b.l12_m, b.l13_m, b.l23_m)


def nominal_geometry(cfg: LBBConfig, points_m) -> tuple[np.ndarray, np.ndarray]:
    """Nominal edges and bar elevations for tool points.

    Parameters
    ----------
    points_m : array_like (p, 3)
        Tool positions in the base frame, z > 0.

    Returns
    -------
    edges_m, elevations_rad : ndarray (p, 6)
        Base edges are horizontal (elevation 0); tool edge ``i`` rises by ``asin(z / l_i)``.
    """
    pts = np.atleast_2d(np.asarray(points_m, dtype=float))
    edges = edges_from_points(base_xyz(cfg), pts)
    el = np.zeros_like(edges)
    el[:, 3:] = np.arcsin(np.clip(pts[:, 2:3] / edges[:, 3:], -1.0, 1.0))
    return edges, el


def reachable(cfg: LBBConfig, points_m) -> np.ndarray:
    """True where every tool edge lies within the bar's length range and z > 0; shape (p,)."""
    pts = np.atleast_2d(np.asarray(points_m, dtype=float))
    edges, _ = nominal_geometry(cfg, pts)
    lo, hi = cfg.bar.min_length_m, cfg.bar.max_length_m
    return np.all((edges[:, 3:] >= lo) & (edges[:, 3:] <= hi), axis=1) & (pts[:, 2] > 0)


def inside_base(cfg: LBBConfig, points_m) -> np.ndarray:
    """True where the point's projection on the base plane lies inside the base triangle; (p,)."""
    pts = np.atleast_2d(np.asarray(points_m, dtype=float))
    b = base_xyz(cfg)[:, :2]
    sign = []
    for i in range(3):
        a, c = b[i], b[(i + 1) % 3]
        sign.append((c[0] - a[0]) * (pts[:, 1] - a[1]) - (c[1] - a[1]) * (pts[:, 0] - a[0]))
    s = np.stack(sign)
    return np.all(s >= -1e-12, axis=0) | np.all(s <= 1e-12, axis=0)


def volume_points(cfg: LBBConfig, n: int | None = None) -> np.ndarray:
    """The work-volume lattice of the config (``n`` overrides nx, ny), reachable points only, (p, 3)."""
    pts = cfg.volume.points(n)
    keep = reachable(cfg, pts)
    if cfg.volume.inside_base_only:
        keep &= inside_base(cfg, pts)
    if not np.any(keep):
        raise MultilatError("the work volume holds no reachable point; check [volume] and [bar]")
    return pts[keep]


def _check_points(cfg, points_m) -> np.ndarray:
    pts = np.atleast_2d(np.asarray(points_m, dtype=float))
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] < 1:
        raise MultilatError(f"points must have shape (p, 3), got {np.shape(points_m)}")
    if not np.all(np.isfinite(pts)):
        raise MultilatError("points must be finite")
    ok = reachable(cfg, pts)
    if not np.all(ok):
        i = int(np.flatnonzero(~ok)[0])
        raise MultilatError(f"point {i} {pts[i].tolist()}: below the base plane or out of the bar's "
                            f"reach [{cfg.bar.min_length_m:.3g}, {cfg.bar.max_length_m:.3g}] m")
    return pts


# ----------------------------------------------------------------------------- inputs
def _global_distributions(cfg: LBBConfig) -> dict:
    e, ini, b = cfg.errors, cfg.initialization, cfg.base
    return {
        "fixture_dy": Normal(0.0, ini.fixture_offset_std_m),
        "cos_theta": Normal(0.0, e.cosine_misalignment_std_rad),
        "cos_phi": Uniform(-np.pi, np.pi),
        "base_dt": Uniform(-b.thermal_bound_c, b.thermal_bound_c) if b.thermal_bound_c > 0 else Constant(0.0),
    }


def _init_inputs(cfg: LBBConfig) -> dict:
    pd = pose_distributions(cfg)
    g = _global_distributions(cfg)
    out = {f"init_a_{k}": pd[k] for k in MECH_SOURCES}
    out.update({f"init_b_{k}": pd[k] for k in MECH_SOURCES + READ_SOURCES})
    out.update({k: g[k] for k in ("fixture_dy", "cos_theta", "cos_phi")})
    return out


def _side_inputs(cfg: LBBConfig) -> dict:
    pd = pose_distributions(cfg)
    out = {f"set_{k}": pd[k] for k in MECH_SOURCES}
    out.update({f"side_{k}": PerSide(pd[k]) for k in MECH_SOURCES + READ_SOURCES})
    g = _global_distributions(cfg)
    out.update({k: g[k] for k in ("cos_theta", "cos_phi", "base_dt")})
    return out


def direct_inputs(cfg: LBBConfig) -> dict:
    """Every input of one direct trial, name -> distribution (side inputs give (n, 6) draws)."""
    out = _init_inputs(cfg)
    out.update(_side_inputs(cfg))
    return out


def _trilaterate_errors(cfg, sides, nominal_xyz, label):
    tri = trilaterate(*np.moveaxis(sides, -1, 0), validate=False,
                      min_height_ratio=cfg.monte_carlo.min_height_ratio)
    if not np.all(tri.valid):
        bad = int(np.sum(~tri.valid))
        raise MultilatError(f"{label}: {bad} simulated edge set(s) put the tool at or below the base "
                            "plane (trilateration singularity); move the point higher")
    return tri.xyz_m - nominal_xyz


def direct_model(cfg: LBBConfig, bar: BarModel, edges_m, elevations_rad, nominal_xyz_m, label="point",
                 **draws) -> np.ndarray:
    """One direct trial per row: initialization, six sides, table drift, trilateration.

    Parameters
    ----------
    edges_m, elevations_rad : ndarray (6,)
        Nominal geometry of the point.
    nominal_xyz_m : ndarray (3,)
    **draws
        The inputs of :func:`direct_inputs`, shape (n,) or (n, 6).

    Returns
    -------
    ndarray (n, 3)
        ``simulated - commanded`` coordinates (m).
    """
    return _direct_with_sides(cfg, bar, edges_m, elevations_rad, nominal_xyz_m, label, **draws)[..., :3]


# ----------------------------------------------------------------------------- the §5 procedure
def l0_distribution(cfg: LBBConfig, *, rng=None, draws: int | None = None):
    """Steps 1-4: ``draws`` (default ``init_draws``) initializations -> summary of ``L0_true - L0_nom``.

    Returns
    -------
    multilat.montecarlo.MCResult
        ``estimate`` and ``std`` of the L0 error (m), samples kept.
    """
    n = cfg.monte_carlo.init_draws if draws is None else int(draws)
    g = np.random.default_rng(resolve_seed(rng))
    bar = BarModel.from_config(cfg)
    d = {k: v.sample(g, n) for k, v in _init_inputs(cfg).items()}
    l0 = initialization_length(cfg, bar, d, cos_theta=d["cos_theta"], cos_phi=d["cos_phi"])
    return summarize(l0 - cfg.initialization.l23_m)


def run_procedure(cfg: LBBConfig, points_m, *, rng=None, progress=None) -> LBBSimulation:
    """The §5 procedure, steps 1-8, for every point (draw counts from ``cfg.monte_carlo``).

    Each point draws from its own ``SeedSequence`` child, so the result for a point does not
    depend on the other points. ``progress(done, total)`` is called after each point.
    """
    pts = _check_points(cfg, points_m)
    root = resolve_seed(rng)
    s_init, s_points = root.spawn(2)
    mc = cfg.monte_carlo
    l0 = l0_distribution(cfg, rng=s_init)
    l0_mean, l0_std = float(l0.estimate), float(l0.std)
    l0_dist = Normal(cfg.initialization.l23_m + l0_mean, l0_std)
    bar = BarModel.from_config(cfg)
    edges, els = nominal_geometry(cfg, pts)
    side_in = _side_inputs(cfg)
    unit = Normal(0.0, 1.0)
    p = len(pts)
    mean_e = np.empty((p, 3))
    std = np.empty((p, 3))
    cov = np.empty((p, 3, 3))
    samples = np.empty((mc.point_draws, p, 3))
    side_mean = np.empty((p, 6))
    side_std = np.empty((p, 6))
    for j, child in enumerate(s_points.spawn(p)):
        g = np.random.default_rng(child)
        # step 5 (x side_draws = step 6)
        d = {k: v.sample(g, mc.side_draws) for k, v in side_in.items()}
        l0_j = l0_dist.sample(g, mc.side_draws)
        true = true_side_lengths(cfg, bar, l0_j, edges[j], els[j], d, cos_theta=d["cos_theta"],
                                 cos_phi=d["cos_phi"], base_dt_c=d["base_dt"])
        s6 = summarize(true - edges[j])
        side_mean[j], side_std[j] = s6.estimate, s6.std
        # step 7: independent per-side normals
        sides = edges[j] + side_mean[j] + side_std[j] * unit.sample(g, (mc.point_draws, 6))
        err = _trilaterate_errors(cfg, sides, pts[j], f"point {j} {pts[j].tolist()}")
        s7 = summarize(err)
        mean_e[j], std[j], cov[j] = s7.estimate, s7.std, s7.cov
        samples[:, j] = err
        if progress is not None:
            progress(j + 1, p)
    return LBBSimulation("procedure", pts, mean_e, std, cov, mc.point_draws, samples, edges, side_mean,
                         side_std, l0_mean, l0_std, int(root.entropy))


# ----------------------------------------------------------------------------- direct
def run_direct(cfg: LBBConfig, points_m, *, trials: int | None = None, rng=None, progress=None,
               map=None) -> LBBSimulation:
    """Direct propagation: :func:`multilat.montecarlo.run_mc` of :func:`direct_model` per point.

    ``trials`` defaults to ``cfg.monte_carlo.direct_trials``. The model returns the coordinate
    errors and the six side errors of the same trials (9 outputs), so the side-length statistics
    come from the same draws as the coordinates.
    """
    pts = _check_points(cfg, points_m)
    n = cfg.monte_carlo.direct_trials if trials is None else int(trials)
    if n < 2:
        raise MultilatError(f"trials must be >= 2, got {n}")
    root = resolve_seed(rng)
    bar = BarModel.from_config(cfg)
    edges, els = nominal_geometry(cfg, pts)
    inputs = direct_inputs(cfg)
    p = len(pts)
    mean_e = np.empty((p, 3))
    std = np.empty((p, 3))
    cov = np.empty((p, 3, 3))
    samples = np.empty((n, p, 3))
    side_mean = np.empty((p, 6))
    side_std = np.empty((p, 6))
    for j, child in enumerate(root.spawn(p)):
        model = functools.partial(_direct_with_sides, cfg, bar, edges[j], els[j], pts[j],
                                  f"point {j} {pts[j].tolist()}")
        res = run_mc(model, inputs, trials=n, rng=child, map=map, quantiles="exact")
        y = res.samples
        samples[:, j] = y[:, :3]
        mean_e[j], std[j] = res.estimate[:3], res.std[:3]
        cov[j] = res.cov[:3, :3]
        side_mean[j], side_std[j] = res.estimate[3:], res.std[3:]
        if progress is not None:
            progress(j + 1, p)
    return LBBSimulation("direct", pts, mean_e, std, cov, n, samples, edges, side_mean, side_std,
                         float("nan"), float("nan"), int(root.entropy))


def _direct_with_sides(cfg, bar, edges, els, xyz, label, **draws):
    """:func:`direct_model` plus the six side errors as outputs 3..8 (one pass, same draws)."""
    cos = {"cos_theta": draws["cos_theta"], "cos_phi": draws["cos_phi"]}
    l0 = initialization_length(cfg, bar, draws, **cos)
    sides = true_side_lengths(cfg, bar, l0, edges, els, draws, base_dt_c=draws["base_dt"], **cos)
    err = _trilaterate_errors(cfg, sides, xyz, label)
    return np.concatenate([err, sides - edges], axis=-1)


def simulate(cfg: LBBConfig, points_m, *, method: str = "procedure", rng=None, trials: int | None = None,
             progress=None) -> LBBSimulation:
    """Run ``method`` (``"procedure"`` or ``"direct"``) at ``points_m`` (p, 3).

    ``trials`` overrides the point-cloud size: ``point_draws`` for the procedure,
    ``direct_trials`` for the direct propagation.
    """
    if method == "procedure":
        if trials is not None:
            cfg = cfg.replace(monte_carlo__point_draws=int(trials))
        return run_procedure(cfg, points_m, rng=rng, progress=progress)
    if method == "direct":
        return run_direct(cfg, points_m, trials=trials, rng=rng, progress=progress)
    raise MultilatError(f"method must be 'procedure' or 'direct', got {method!r}")
