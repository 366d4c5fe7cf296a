"""Figures of a network adjustment: residuals per target and station (seed 000 Fig. 13), top and 3-D
views of heads, targets and their 95 % confidence ellipsoids (Figs. 11-12).

Plot functions take ``ax=None`` and return the axes; :func:`save_figures` writes PNGs atomically.
Ellipsoids are magnified (``magnify``) to be visible beside metre-sized layouts, separately for heads
and targets (:func:`class_magnifications`); the factors are in the title and legend, a scale bar per
class gives the true size.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from multilat.network.adjust.statistics import chi2_ppf

__all__ = ["plot_residuals", "station_label", "plot_top_view", "plot_3d", "save_figures", "auto_magnify",
           "class_magnifications", "place_labels"]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


#: above this many points a figure draws densities or a subsample, not one marker per point (a
#: million markers take seconds to draw and merge into one blot)
LARGE_PLOT_POINTS = 20_000


def plot_residuals(result, ax=None):
    """Residuals (µm) of every observation against the target position, one marker per station
    (labelled "station S1", with "head T1" where the head is not the station itself); rejected
    observations as crosses. Above :data:`LARGE_PLOT_POINTS` used observations: their
    density (observations per cell, log colour scale, all heads), rejected ones still as crosses."""
    plt = _plt()
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 3.5))
    o = result.obs
    if int(np.count_nonzero(result.used)) > LARGE_PLOT_POINTS:
        return _residual_density(result, ax)
    markers = "os^vD<>ph*"
    heads = o.head_of_station
    for i, sid in enumerate(o.station_ids):
        m = (o.station_index == i) & result.used
        ax.plot(o.target_index[m] + 1, result.residuals_m[m] * 1e6, markers[i % len(markers)],
                ms=4, label=station_label(sid, heads[i]), alpha=0.85)
    bad = ~result.used
    if bad.any():
        ax.plot(o.target_index[bad] + 1, result.residuals_m[bad] * 1e6, "kx", ms=7, label="rejected")
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.set_xlabel("target position")
    ax.set_ylabel("residual (measured - adjusted), µm")
    t = o.n_targets
    if t <= 30:
        ax.set_xticks(np.arange(1, t + 1))
        ax.set_xticklabels(o.target_ids, rotation=90 if t > 14 else 0, fontsize=8)
    ax.set_title(f"residuals per target and station (σ0 = {result.sigma0:.3g}, dof {result.dof})")
    ax.legend(fontsize=7, ncol=min(o.n_stations + 1, 6), loc="best")
    return ax


def station_label(station_id: str, head_id: str) -> str:
    """A station's legend entry: "station S1", and "station S1 (head T1)" when another head id
    occupies it (a station is a set-up, a head the instrument on it)."""
    return f"station {station_id}" + ("" if head_id == station_id else f" (head {head_id})")


def _residual_density(result, ax):
    """The residual figure of a large network: a 2-D histogram of (target position, residual)."""
    from matplotlib.colors import LogNorm

    o = result.obs
    used = np.asarray(result.used, bool)
    x = o.target_index[used] + 1.0
    y = result.residuals_m[used] * 1e6
    ok = np.isfinite(y)
    x, y = x[ok], y[ok]
    t = o.n_targets
    lo, hi = (float(y.min()), float(y.max())) if y.size else (-1.0, 1.0)
    if not hi > lo:                                   # all residuals equal: a band around them
        lo, hi = lo - 1.0, hi + 1.0
    counts, xe, ye = np.histogram2d(x, y, bins=(min(t, 400), 120), range=((0.5, t + 0.5), (lo, hi)))
    mesh = ax.pcolormesh(xe, ye, np.ma.masked_equal(counts.T, 0), norm=LogNorm(vmin=1), cmap="viridis",
                         rasterized=True)
    ax.figure.colorbar(mesh, ax=ax, label="observations per cell")
    bad = ~used
    if bad.any():
        ax.plot(o.target_index[bad] + 1, result.residuals_m[bad] * 1e6, "rx", ms=5,
                label=f"rejected ({int(bad.sum())})")
        ax.legend(fontsize=7, loc="upper right")
    ax.axhline(0.0, color="0.5", lw=0.8)
    from matplotlib.ticker import MaxNLocator, StrMethodFormatter

    ax.xaxis.set_major_locator(MaxNLocator(6, integer=True))
    ax.xaxis.set_major_formatter(StrMethodFormatter("{x:,.0f}"))
    ax.set_xlabel("target position")
    ax.set_ylabel("residual (measured - adjusted), µm")
    ax.set_title(f"residuals of {int(ok.sum()):,} observations, all heads (σ0 = {result.sigma0:.3g}, "
                 f"dof {result.dof})", fontsize=9)
    return ax


def auto_magnify(result) -> float:
    """A 1-2-5 magnification making the largest 95 % ellipsoid about 8 % of the layout."""
    (sa, _), (ta, _) = result.ellipsoids()
    big = max(float(np.nanmax(sa, initial=0.0)), float(np.nanmax(ta, initial=0.0)))
    pts = np.vstack([result.station_xyz_m, result.target_xyz_m])
    span = float(np.ptp(pts, axis=0).max()) or 1.0
    if big <= 0:
        return 1.0
    want = 0.08 * span / big
    dec = 10 ** np.floor(np.log10(want))
    return float(max(m for m in (1, 2, 5) if m * dec <= want) * dec)


def _nice(x: float) -> float:
    """The largest 1-2-5 number <= x (x > 0)."""
    dec = 10 ** np.floor(np.log10(x))
    return float(max(m for m in (1, 2, 5) if m * dec <= x * (1 + 1e-12)) * dec)


def _largest_semi_axes(result) -> tuple[float, float]:
    """The largest 95 % semi-axis of the stations and of the targets (0 for an empty class; NaN
    ellipsoids, of points not located, are skipped)."""
    (sa, _), (ta, _) = result.ellipsoids()
    return tuple(float(np.nanmax(a[:, 2], initial=0.0)) if len(a) else 0.0 for a in (sa, ta))


def class_magnifications(result, *, share: float = 0.06) -> tuple[float, float]:
    """1-2-5 magnifications (stations, targets), each making the largest 95 % ellipsoid of its class
    about ``share`` of the layout's span: a target ellipsoid ten times smaller than the heads' does
    not vanish beside them."""
    pts = np.vstack([result.station_xyz_m, result.target_xyz_m])
    span = float(np.ptp(pts, axis=0).max()) or 1.0
    out = [1.0 if not big > 0 else _nice(share * span / big) for big in _largest_semi_axes(result)]
    return out[0], out[1]


def _as_pair(magnify, result) -> tuple[float, float]:
    if magnify is None:
        return class_magnifications(result)
    if np.ndim(magnify) == 0:
        return float(magnify), float(magnify)
    return float(magnify[0]), float(magnify[1])


def _scale_bar(ax, mag: float, length_m: float, col: str, label: str, row: int) -> None:
    """A bar of ``length_m * mag`` (data units) anchored in a lower corner (row 0 left, 1 right),
    labelled with the true length it stands for."""
    from matplotlib.font_manager import FontProperties
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    ax.add_artist(AnchoredSizeBar(ax.transData, length_m * mag, f"{label}: {length_m * 1e6:g} µm (×{mag:g})",
                                  "lower left" if row == 0 else "lower right", pad=0.4, color=col,
                                  frameon=False, size_vertical=0, fontproperties=FontProperties(size=7)))


def plot_top_view(result, ax=None, *, magnify=None):
    """Top view (x, y) of stations and targets with the shadows of their 95 % ellipsoids on the
    xy-plane (the projection of ``{x: x^T C^-1 x <= chi2_3(0.95)}`` is the ellipse of the 2x2
    marginal with the same bound), magnified per class (``magnify``: one factor, a pair
    (stations, targets), or None for :func:`class_magnifications`); a scale bar per class gives the
    true size."""
    plt = _plt()
    from matplotlib.patches import Ellipse

    if ax is None:
        _, ax = plt.subplots(figsize=(6, 6))
    mags = _as_pair(magnify, result)
    k = np.sqrt(chi2_ppf(0.95, 3))
    classes = ((result.station_xyz_m, result.station_cov_m2, "^", "C3", "stations"),
               (result.target_xyz_m, result.target_cov_m2, "o", "C0", "targets"))
    for (xyz, cov, style, col, name), mag in zip(classes, mags):
        xyz = np.asarray(xyz, float)
        many = len(xyz) > LARGE_PLOT_POINTS
        ax.plot(xyz[:, 0], xyz[:, 1], style, color=col, ms=6 if style == "^" else (1 if many else 4),
                label=f"{name}: 95 % ellipses ×{mag:g}", rasterized=many)
        for p, c in zip(xyz, cov):
            if len(xyz) > 2000:      # too many to draw one by one
                break
            w, V = np.linalg.eigh(np.asarray(c)[:2, :2])
            w = np.clip(w, 0, None)
            ang = np.degrees(np.arctan2(V[1, 1], V[0, 1]))
            ax.add_patch(Ellipse(p[:2], 2 * k * mag * np.sqrt(w[1]), 2 * k * mag * np.sqrt(w[0]),
                                 angle=ang, fill=False, color=col, lw=0.8))
    ax.set_aspect("equal", adjustable="datalim")
    names = list(result.station_ids) + list(result.target_ids)
    if len(names) <= 60:
        place_labels(ax, np.vstack([result.station_xyz_m, result.target_xyz_m])[:, :2], names,
                     colors=["darkred"] * len(result.station_ids) + ["k"] * len(result.target_ids))
    ax.apply_aspect()
    for row, ((xyz, cov, _s, col, name), mag, big) in enumerate(zip(classes, mags, _largest_semi_axes(result))):
        if big > 0:
            _scale_bar(ax, mag, _nice(big), col, f"{name} scale", row)
    ax.legend(fontsize=7, loc="upper right")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"top view: stations (▲) ×{mags[0]:g}, targets (●) ×{mags[1]:g}; 95 % ellipses", fontsize=10)
    return ax


#: label offsets tried in turn (points from the marker): upper right first, then around it
_LABEL_OFFSETS_PT = [(3, 3), (3, -10), (-9, 3), (-9, -10), (5, -3), (-12, -3), (-3, 6), (-3, -13),
                     (9, 9), (9, -16), (-16, 9), (-16, -16)]


def place_labels(ax, xy, names, *, fontsize: float = 7, colors=None) -> list:
    """Annotate the points ``xy`` (p, 2), data units, with ``names`` so that no two labels overlap
    and no label covers another point's marker, where possible.

    Greedy: each label (in order) takes the first offset of ``_LABEL_OFFSETS_PT`` whose box (text
    size estimated from the font size) clears the boxes already placed and the other markers; if
    none does, the offset with the least overlap. Call after the axes limits and aspect are final.

    Returns
    -------
    list of matplotlib ``Annotation``
    """
    ax.apply_aspect()
    fig = ax.figure
    px = fig.dpi / 72.0                                  # pixels per point
    disp = ax.transData.transform(np.asarray(xy, float))
    h = fontsize * px
    marker_r = 3.5 * px
    placed: list[tuple[float, float, float, float]] = []
    out = []

    def overlap(a, b):
        return max(0.0, min(a[2], b[2]) - max(a[0], b[0])) * max(0.0, min(a[3], b[3]) - max(a[1], b[1]))

    for i, name in enumerate(names):
        w = 0.62 * fontsize * px * max(len(str(name)), 1)
        best, best_cost = _LABEL_OFFSETS_PT[0], np.inf
        for dx, dy in _LABEL_OFFSETS_PT:
            x0, y0 = disp[i, 0] + dx * px, disp[i, 1] + dy * px
            box = (x0, y0, x0 + w, y0 + h)
            cost = sum(overlap(box, b) for b in placed)
            for j in range(len(disp)):
                if j != i:
                    mk = (disp[j, 0] - marker_r, disp[j, 1] - marker_r, disp[j, 0] + marker_r,
                          disp[j, 1] + marker_r)
                    cost += overlap(box, mk)
            if cost < best_cost:
                best, best_cost = (dx, dy), cost
            if cost == 0.0:
                break
        x0, y0 = disp[i, 0] + best[0] * px, disp[i, 1] + best[1] * px
        placed.append((x0, y0, x0 + w, y0 + h))
        out.append(ax.annotate(str(name), np.asarray(xy, float)[i], fontsize=fontsize, xytext=best,
                               textcoords="offset points", ha="left", va="bottom",
                               color=None if colors is None else colors[i]))
    return out


def plot_3d(result, ax=None, *, magnify: float | None = None):
    """3-D view of stations and targets with their 95 % confidence ellipsoids (wireframes), magnified."""
    plt = _plt()

    if ax is None:
        fig = plt.figure(figsize=(6.5, 6))
        ax = fig.add_subplot(projection="3d")
    mags = _as_pair(magnify, result)
    k = np.sqrt(chi2_ppf(0.95, 3))
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 13), np.linspace(0, np.pi, 7))
    sphere = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], axis=-1)
    step = -(-len(result.target_xyz_m) // LARGE_PLOT_POINTS)       # every step-th target when many
    for (xyz, cov, style, col), mag in zip(((result.station_xyz_m, result.station_cov_m2, "^", "C3"),
                                            (result.target_xyz_m[::step], result.target_cov_m2, "o", "C0")), mags):
        ax.scatter(xyz[:, 0], xyz[:, 1], xyz[:, 2], marker=style, color=col, s=18 if step == 1 else 2)
        if len(xyz) > 300:
            continue
        for p, c in zip(xyz, cov):
            w, V = np.linalg.eigh(c)
            A = V * (k * mag * np.sqrt(np.clip(w, 0, None)))
            e = sphere @ A.T + p
            ax.plot_wireframe(e[..., 0], e[..., 1], e[..., 2], color=col, lw=0.3, alpha=0.6)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    n_t = len(result.target_xyz_m)
    shown = "" if step == 1 else f"\n(1 target in {step} shown: {len(range(0, n_t, step)):,} of {n_t:,})"
    ax.set_title(f"95 % ellipsoids: stations (▲) ×{mags[0]:g}, targets (●) ×{mags[1]:g}{shown}")
    return ax


def save_figures(result, out_dir: str | os.PathLike) -> list[Path]:
    """Write ``residuals.png``, ``top_view.png`` and ``view_3d.png`` into ``out_dir`` atomically."""
    _plt()                      # the non-interactive backend
    from multilat.report.png import save_png

    out = Path(out_dir)
    written = []
    for name, fn in (("residuals.png", plot_residuals), ("top_view.png", plot_top_view),
                     ("view_3d.png", plot_3d)):
        ax = fn(result)
        fig = ax.figure
        p = out / name
        save_png(fig, p)
        written.append(p)
    return written
