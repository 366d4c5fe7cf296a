"""Figures of the distance budget: the seed's Figs. 9 (three groups) and 10 (their sum)."""

from __future__ import annotations

import numpy as np

from multilat.budget import GROUPS
from multilat.errors import MultilatError

__all__ = ["plot_budget"]

_TITLES = {"telemetric": "telemetric system", "head": "measurement head", "target": "target",
           "air": "air index", "combined": "combined (Fig. 10)"}


def _panel(ax, x_um, title, u_um, paper_um=None):
    from multilat.montecarlo import coverage_interval

    lo68, hi68 = coverage_interval(x_um, 0.68)
    lo95, hi95 = coverage_interval(x_um, 0.95)
    lim = np.quantile(x_um, [0.0005, 0.9995])
    bins = np.linspace(lim[0], lim[1], 121)
    counts, edges = np.histogram(x_um, bins=bins)
    dens = counts / (x_um.size * np.diff(edges))
    centres = 0.5 * (edges[1:] + edges[:-1])
    colours = np.where((centres >= lo68) & (centres <= hi68), "tab:red",
                       np.where((centres >= lo95) & (centres <= hi95), "tab:blue", "0.6"))
    ax.bar(centres, dens, width=np.diff(edges), color=colours, linewidth=0)
    g = np.linspace(lim[0], lim[1], 300)
    sd = float(np.std(x_um))
    mu = float(np.mean(x_um))
    ax.plot(g, np.exp(-0.5 * ((g - mu) / sd) ** 2) / (sd * np.sqrt(2 * np.pi)), "k--", lw=0.8,
            label="gaussian, same mean/std")
    ref = f", paper {paper_um:.1f}" if paper_um is not None else ""
    ax.set_title(f"{title}: u = {u_um:.2f} µm{ref}", fontsize=9)
    ax.set_xlabel("error (µm)")
    ax.set_ylabel("density (1/µm)")
    ax.legend(fontsize=7, loc="upper right")


def plot_budget(budget, *, fig=None, paper_um: dict | None = None):
    """Histograms of each group's error and of their sum (68 % red, 95 % red + blue), like Figs. 9-10.

    Parameters
    ----------
    budget : multilat.budget.DistanceBudget
        With ``samples`` kept (``keep_samples=True``).
    fig : matplotlib Figure, optional
    paper_um : dict, optional
        Paper values (µm) to print beside ours, keys ``telemetric``, ``head``, ``target``, ``combined``.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if budget.samples is None:
        raise MultilatError("the budget has no samples: run distance_budget(..., keep_samples=True)")
    paper_um = paper_um or {}
    s = budget.samples * 1e6
    cols = [0, 1, 2, 3] if budget.include_air else [0, 1, 2]
    panels = [(GROUPS[j], s[:, j], budget.components[GROUPS[j]] * 1e6) for j in cols]
    panels.append(("combined", s[:, cols].sum(axis=1), budget.error_rms_m * 1e6))
    ncol = 2 if len(panels) <= 4 else 3
    fig = fig or plt.figure(figsize=(4.6 * ncol, 7.0))
    axes = fig.subplots(2, ncol).ravel()
    for ax, (name, x, u) in zip(axes, panels):
        title = _TITLES[name] + (f" {budget.head}" if name == "head" else "")
        if name == "combined" and budget.include_air:
            title = "combined incl. air"  # the paper's 4.7 um excludes the air
        _panel(ax, x, title, u, None if name == "combined" and budget.include_air else paper_um.get(name))
    for ax in axes[len(panels):]:
        ax.axis("off")
    fig.suptitle(f"Distance errors, instrument {budget.instrument}, head {budget.head}: "
                 f"{budget.trials:,} pooled trials over {budget.distances_m.size} distances "
                 f"({budget.distances_m[0]:g}-{budget.distances_m[-1]:g} m)", fontsize=10)
    fig.tight_layout()
    return fig
