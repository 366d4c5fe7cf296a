"""Figures of the network Monte Carlo: point clouds with their 95 % coverage ellipsoids."""

from __future__ import annotations

import numpy as np

from multilat.network.propagate import chi2_3_95


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


def clouds_figure(res, *, points=None, max_points: int = 16, plane=(0, 1), max_dots: int = 3000):
    """Small multiples: each point's Monte Carlo cloud (deviation from nominal, um) in a coordinate
    plane with the MC 95 % ellipsoid (solid) and the linear one (dashed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ids = list(points) if points is not None else list(res.point_ids)[-max_points:]
    ncol = min(4, len(ids))
    nrow = -(-len(ids) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.0 * ncol, 2.9 * nrow), squeeze=False)
    names = "xyz"
    samples = res.samples
    step = max(1, 0 if samples is None else samples.shape[0] // max_dots)
    for ax, pid in zip(axes.ravel(), ids):
        q = list(res.point_ids).index(pid)
        idx = [res.labels.index(f"{pid}.{c}") for c in "xyz"]
        if samples is not None:
            d = samples[::step][:, idx].astype(float) * 1e6
            ax.plot(d[:, plane[0]], d[:, plane[1]], ".", ms=1.5, alpha=0.35, color="tab:blue")
        mu = (res.mc_mean[idx] - res.nominal[idx]) * 1e6
        e_mc = ellipse_xy(res.point_cov_mc[q] * 1e12, plane=plane) + mu[list(plane)]
        e_lin = ellipse_xy(res.point_cov_lin[q] * 1e12, plane=plane)
        ax.plot(e_mc[:, 0], e_mc[:, 1], "-", color="tab:red", lw=1.2, label="MC 95 %")
        ax.plot(e_lin[:, 0], e_lin[:, 1], "--", color="k", lw=1.0, label="linear 95 %")
        ax.set_title(f"{pid}  (in MC ell.: {res.ellipsoid_coverage_mc[q]:.3f})", fontsize=8)
        ax.set_aspect("equal", adjustable="datalim")
        ax.tick_params(labelsize=7)
        ax.set_xlabel(f"d{names[plane[0]]} / um", fontsize=7)
        ax.set_ylabel(f"d{names[plane[1]]} / um", fontsize=7)
    for ax in axes.ravel()[len(ids):]:
        ax.axis("off")
    axes.ravel()[0].legend(fontsize=6, loc="upper right")
    fig.suptitle(f"Monte Carlo point clouds, {res.trials} trials, noise={res.noise} "
                 "(95 % coverage ellipsoids, JCGM 102)", fontsize=9)
    fig.tight_layout()
    return fig
