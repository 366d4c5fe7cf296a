"""Figures of the laser ball bar study (seed 003, Figs. 7-9). Each function returns a Figure or axes.

- :func:`volume_map`: Fig. 8, colour = |mean error| (or the largest coordinate std) on horizontal
  slices of the work volume, arrows = direction of the in-plane mean error, base sockets marked.
- :func:`error_cdf`: Fig. 9, cumulative distributions of error magnitudes.
- :func:`reference_comparison`: Fig. 7, per-axis differences from reference coordinates with 2σ bars.
- :func:`std_vs_height`: the 1/z growth of the coordinate uncertainty towards the base plane.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["volume_map", "error_cdf", "reference_comparison", "std_vs_height"]

UM = 1e6


def _grid(xy, values):
    xs = np.unique(np.round(xy[:, 0], 9))
    ys = np.unique(np.round(xy[:, 1], 9))
    out = np.full((len(ys), len(xs)), np.nan)
    ix = np.searchsorted(xs, np.round(xy[:, 0], 9))
    iy = np.searchsorted(ys, np.round(xy[:, 1], 9))
    out[iy, ix] = values
    return xs, ys, out


def _edges(c):
    if len(c) == 1:
        return np.array([c[0] - 0.01, c[0] + 0.01])
    mid = (c[1:] + c[:-1]) / 2
    return np.concatenate([[2 * c[0] - mid[0]], mid, [2 * c[-1] - mid[-1]]])


def volume_map(sim, base_xyz_m, *, quantity: str = "mean", levels=None, marks_m=None, title=None):
    """Fig. 8: one panel per height.

    Parameters
    ----------
    sim : multilat.lbb.simulate.LBBSimulation
        Points on a lattice (``Volume.points``).
    base_xyz_m : ndarray (3, 3)
        Base sockets (drawn as triangles).
    quantity : {"mean", "std"}
        Colour: |mean error| (µm) or the largest coordinate standard deviation (µm).
    levels : sequence of float, optional
        Heights to draw (default: every height present).
    marks_m : ndarray (q, 3), optional
        Extra points (e.g. the comparison points) drawn as dots on the nearest panel.
    """
    pts = sim.nominal_m
    zs = np.unique(np.round(pts[:, 2], 9)) if levels is None else np.asarray(levels)
    if quantity == "mean":
        val = sim.error_magnitude_m * UM
        label = "|mean error| (µm)"
    else:
        val = np.max(sim.std_m, axis=1) * UM
        label = "largest coordinate std (µm)"
    vmax = float(np.nanmax(val))
    n = len(zs)
    ncol = min(n, 3)
    nrow = int(np.ceil(n / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.7 * nrow), squeeze=False,
                             constrained_layout=True)
    mesh = None
    for k, z in enumerate(zs):
        ax = axes.flat[k]
        sel = np.isclose(pts[:, 2], z)
        xs, ys, g = _grid(pts[sel], val[sel])
        mesh = ax.pcolormesh(_edges(xs) * 1e3, _edges(ys) * 1e3, g, vmin=0, vmax=vmax, cmap="viridis",
                             shading="flat")
        if quantity == "mean":
            e = sim.mean_error_m[sel]
            norm = np.maximum(np.linalg.norm(e[:, :2], axis=1), 1e-30)
            ax.quiver(pts[sel, 0] * 1e3, pts[sel, 1] * 1e3, e[:, 0] / norm, e[:, 1] / norm,
                      color="white", scale=25, width=0.006, pivot="mid")
        tri = np.vstack([base_xyz_m, base_xyz_m[:1]]) * 1e3
        ax.plot(tri[:, 0], tri[:, 1], "w--", lw=0.8)
        ax.plot(base_xyz_m[:, 0] * 1e3, base_xyz_m[:, 1] * 1e3, "r^", ms=8, label="base sockets")
        if marks_m is not None:
            m = np.asarray(marks_m)
            near = np.abs(m[:, 2] - z) <= 0.5 * (np.min(np.diff(zs)) if n > 1 else np.inf)
            if np.any(near):
                ax.plot(m[near, 0] * 1e3, m[near, 1] * 1e3, "k.", ms=4)
        ax.set_title(f"z = {z * 1e3:.0f} mm")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_aspect("equal")
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    fig.colorbar(mesh, ax=axes.ravel().tolist(), label=label, shrink=0.8)
    fig.suptitle(title or (f"LBB work volume, {sim.method}: " +
                           ("mean error magnitude and in-plane direction" if quantity == "mean"
                            else "largest coordinate standard deviation")))
    return fig


def error_cdf(sim, *, measured_magnitudes_m=None, ax=None, label=None):
    """Fig. 9: cumulative distribution of error magnitudes (normalised by the sample size).

    Draws the |mean error| per point and the |error| of every simulated trial; optionally the
    magnitudes of measured errors (e.g. LBB - CMM per point).
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(5.5, 3.8), constrained_layout=True)
    lab = label or sim.method

    def cdf(v, **kw):
        v = np.sort(np.asarray(v) * UM)
        ax.step(v, np.arange(1, len(v) + 1) / len(v), where="post", **kw)

    cdf(sim.error_magnitude_m, label=f"{lab}: |mean error| per point")
    cdf(np.linalg.norm(sim.error_samples_m, axis=-1).ravel(), label=f"{lab}: |error| of every trial", ls="--")
    if measured_magnitudes_m is not None:
        cdf(measured_magnitudes_m, label="measured", color="k")
    ax.set_xlabel("error magnitude (µm)")
    ax.set_ylabel("cumulative fraction")
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return ax


def reference_comparison(labels, diff_m, sim_mean_m, sim_std_m, *, diff_std_m=None):
    """Fig. 7: for x, y, z (top to bottom) the measured difference from the reference (with 2σ bars
    when ``diff_std_m`` is given) and the simulated mean error with its 2σ bars.

    Parameters
    ----------
    labels : sequence of str (p,)
    diff_m, sim_mean_m, sim_std_m : ndarray (p, 3)
    diff_std_m : ndarray (p, 3), optional
    """
    p = len(labels)
    idx = np.arange(p)
    fig, axes = plt.subplots(3, 1, figsize=(max(6.0, 0.12 * p + 3), 7.5), sharex=True,
                             constrained_layout=True)
    for k, (ax, name) in enumerate(zip(axes, "xyz")):
        ax.errorbar(idx + 0.15, sim_mean_m[:, k] * UM, yerr=2 * sim_std_m[:, k] * UM, fmt="s", ms=3,
                    color="tab:orange", elinewidth=0.8, label="simulation mean ± 2σ")
        yerr = None if diff_std_m is None else 2 * diff_std_m[:, k] * UM
        ax.errorbar(idx - 0.15, diff_m[:, k] * UM, yerr=yerr, fmt="o", ms=3, color="tab:blue",
                    elinewidth=0.8, label="LBB - reference" + (" ± 2σ" if yerr is not None else ""))
        ax.axhline(0, color="k", lw=0.6)
        ax.set_ylabel(f"{name} difference (µm)")
        z = (diff_m[:, k] - sim_mean_m[:, k]) / sim_std_m[:, k]
        inside = np.mean(np.abs(z) <= 2)
        ax.set_title(f"{name}: {inside:.0%} inside ± 2σ, RMS (diff - mean)/σ = {np.sqrt(np.mean(z**2)):.2f}",
                     fontsize=8, loc="right")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, ncol=2)
    axes[-1].set_xlabel("point")
    if p <= 40:
        axes[-1].set_xticks(idx, labels, rotation=90, fontsize=7)
    return fig


def std_vs_height(z_m, std_m, *, slope=None, ax=None):
    """Coordinate std against height on log axes (the 1/z law near the base plane).

    Parameters
    ----------
    z_m : ndarray (n,)
    std_m : ndarray (n, 3)
    slope : float, optional
        Fitted log-log slope of the z std, shown in the legend.
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(5.5, 3.8), constrained_layout=True)
    for k, name in enumerate("xyz"):
        lab = f"std {name}" + (f" (slope {slope:.2f})" if (k == 2 and slope is not None) else "")
        ax.loglog(np.asarray(z_m) * 1e3, np.asarray(std_m)[:, k] * UM, "o-", ms=3, label=lab)
    zz = np.asarray(z_m) * 1e3
    ref = np.asarray(std_m)[-1, 2] * UM * zz[-1] / zz
    ax.loglog(zz, ref, "k:", lw=0.8, label="∝ 1/z")
    ax.set_xlabel("height above the base plane z (mm)")
    ax.set_ylabel("standard deviation (µm)")
    from matplotlib.ticker import FormatStrFormatter, NullFormatter

    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(FormatStrFormatter("%g"))
        axis.set_minor_formatter(NullFormatter())
    ax.set_xticks([t for t in (10, 20, 30, 50, 100, 200, 300, 500) if zz.min() <= t <= zz.max()])
    sv = np.asarray(std_m) * UM
    ax.set_yticks([t for t in (0.1, 0.2, 0.5, 1, 2, 3, 5, 10, 20, 50, 100) if sv.min() * 0.9 <= t <= sv.max() * 1.1])
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return ax
