"""Figures of the network Monte Carlo: point clouds (any chosen points, stations by default) in the
three coordinate planes with their 95 % coverage ellipsoids."""

from __future__ import annotations

import numpy as np

from multilat.network.montecarlo.propagate import chi2_3_95


def ellipse_xy(cov3, *, plane=(0, 1), n=181) -> np.ndarray:
    """Outline (n, 2) of the shadow of the 95 % ellipsoid ``x^T C^-1 x <= chi2_3(0.95)`` on a plane.

    The projection of an ellipsoid onto a coordinate plane is the ellipse of the 2x2 marginal
    covariance with the same (3-dof) quantile, so every cloud point inside the ellipsoid lies inside
    the drawn outline.
    """
    c = np.asarray(cov3)[np.ix_(plane, plane)]
    ev, vec = np.linalg.eigh(c)
    ang = np.linspace(0, 2 * np.pi, n)
    circle = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    return (circle * np.sqrt(chi2_3_95 * np.clip(ev, 0, None))) @ vec.T


def default_cloud_points(res, max_points: int = 8) -> list[str]:
    """The stations, then the targets with the largest MC 95 % ellipsoid, ``max_points`` in all."""
    stations = [p for p in res.point_ids if p in set(res.problem.station_ids)]
    others = [q for q, p in enumerate(res.point_ids) if p not in set(stations)]
    big = sorted(others, key=lambda q: -float(np.linalg.eigvalsh(res.point_cov_mc[q])[-1]))
    chosen = stations[:max_points] + [res.point_ids[q] for q in big][:max(0, max_points - len(stations))]
    return chosen


def clouds_figure(res, *, points=None, max_points: int = 8, max_dots: int = 3000):
    """Each chosen point's Monte Carlo cloud (deviation from nominal, µm) in the three coordinate
    planes x-y, x-z, y-z (one row a point), with the MC 95 % ellipsoid's shadow (solid) and the
    linear one (dashed). ``points``: ids to show (stations or targets; an unknown id is a
    :class:`~multilat.errors.MultilatError`); default :func:`default_cloud_points`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from multilat.errors import MultilatError

    ids = list(points) if points else default_cloud_points(res, max_points)
    unknown = [p for p in ids if p not in res.point_ids]
    if unknown:
        raise MultilatError(f"--cloud-points: unknown point id(s) {', '.join(map(repr, unknown))} "
                            f"(points: {', '.join(res.point_ids[:20])}{', ...' if len(res.point_ids) > 20 else ''})")
    stations = set(res.problem.station_ids)
    planes = ((0, 1), (0, 2), (1, 2))
    fig, axes = plt.subplots(len(ids), 3, figsize=(9.0, 2.7 * len(ids)), squeeze=False)
    names = "xyz"
    samples = res.samples
    step = max(1, 0 if samples is None else samples.shape[0] // max_dots)
    for row, pid in zip(axes, ids):
        q = list(res.point_ids).index(pid)
        idx = [res.labels.index(f"{pid}.{c}") for c in "xyz"]
        d = None if samples is None else samples[::step][:, idx].astype(float) * 1e6
        mu = (res.mc_mean[idx] - res.nominal[idx]) * 1e6
        kind = "station" if pid in stations else "target"
        for ax, plane in zip(row, planes):
            if d is not None:
                ax.plot(d[:, plane[0]], d[:, plane[1]], ".", ms=1.5, alpha=0.35,
                        color="tab:red" if kind == "station" else "tab:blue")
            e_mc = ellipse_xy(res.point_cov_mc[q] * 1e12, plane=plane) + mu[list(plane)]
            e_lin = ellipse_xy(res.point_cov_lin[q] * 1e12, plane=plane)
            ax.plot(e_mc[:, 0], e_mc[:, 1], "-", color="k", lw=1.2, label="MC 95 %")
            ax.plot(e_lin[:, 0], e_lin[:, 1], "--", color="0.4", lw=1.0, label="linear 95 %")
            ax.set_aspect("equal", adjustable="datalim")
            ax.tick_params(labelsize=7)
            ax.set_xlabel(f"d{names[plane[0]]} (µm)", fontsize=7)
            ax.set_ylabel(f"d{names[plane[1]]} (µm)", fontsize=7)
        row[0].set_title(f"{kind} {pid}: inside the MC ellipsoid {res.ellipsoid_coverage_mc[q]:.3f}",
                         fontsize=8, loc="left")
    axes[0, 2].legend(fontsize=6, loc="upper right")
    fig.suptitle(f"Monte Carlo clouds, {res.trials} trials, noise={res.noise}: x-y, x-z, y-z "
                 "(95 % coverage ellipsoids, JCGM 102)", fontsize=9)
    fig.tight_layout()
    return fig
