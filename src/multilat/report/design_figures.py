"""Figures of a network design: the layout in 3-D and top view with predicted 95 % ellipsoids
(the network figures, fed a :class:`~multilat.network.design.PreAnalysis`), and maps of the
predicted uncertainty of a point measured anywhere in the volume, over horizontal slices (as seed
003's work-volume maps). Declared obstructions (``[[occluders]]`` boxes) are drawn (hatched where a
slice cuts the box, dashed outline elsewhere; outline in the top view; a grey box in the 3-D views,
static and interactive, from the one geometry :func:`box_faces`) and used: a map point is measured
only by the heads whose line of sight to it no box cuts.

Plot functions take ``ax=None`` and return the axes; :func:`save_design_figures` writes PNGs atomically.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from multilat.network.adjust.statistics import CHI2_3_95
from multilat.report.network_figures import _plt, plot_3d, plot_top_view

__all__ = ["plot_slice_maps", "save_design_figures", "draw_occluders", "draw_occluders_3d", "box_corners",
           "box_faces", "plot_layout_3d"]

#: the six faces of a box as indices of :func:`box_corners` (corner k: x from bit 0, y bit 1, z bit 2)
BOX_FACES = ((0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5))


def box_corners(box_min_m, box_max_m) -> np.ndarray:
    """The 8 corners (8, 3) of the axis-aligned box: corner k takes x, y, z from ``box_max_m`` where
    bit 0, 1, 2 of k is set, else from ``box_min_m``."""
    lo, hi = np.asarray(box_min_m, float), np.asarray(box_max_m, float)
    return np.array([[(hi if k >> i & 1 else lo)[i] for i in range(3)] for k in range(8)])


def box_faces(box_min_m, box_max_m) -> np.ndarray:
    """The six faces (6, 4, 3) of the box, each a quadrilateral of its corners in order round it."""
    c = box_corners(box_min_m, box_max_m)
    return c[np.array(BOX_FACES)]


def draw_occluders_3d(ax, occluders):
    """Each occluder box ``(box_min_m, box_max_m)`` as a grey translucent box (six faces, gid
    ``occluder``) on the 3-D axes ``ax``."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    for i, (lo, hi) in enumerate(occluders):
        ax.add_collection3d(Poly3DCollection(box_faces(lo, hi), facecolor="0.5", edgecolor="k", alpha=0.25,
                                             lw=0.8, gid="occluder", label="obstruction" if i == 0 else None))
    if len(occluders):
        pts = np.vstack([box_corners(lo, hi) for lo, hi in occluders])
        for get, put, j in ((ax.get_xlim3d, ax.set_xlim3d, 0), (ax.get_ylim3d, ax.set_ylim3d, 1),
                            (ax.get_zlim3d, ax.set_zlim3d, 2)):
            a, b = get()
            put(min(a, pts[:, j].min()), max(b, pts[:, j].max()))
    return ax


def plot_layout_3d(pre, occluders=(), ax=None):
    """The 3-D layout with predicted 95 % ellipsoids (:func:`~multilat.report.network_figures.plot_3d`)
    and the declared obstructions."""
    return draw_occluders_3d(plot_3d(pre, ax=ax), occluders)


def draw_occluders(ax, occluders, *, z=None):
    """Outline each occluder box ``(box_min_m, box_max_m)`` in the x-y plane of ``ax``: hatched when
    the height ``z`` lies within the box (the slice cuts it), a dashed outline otherwise."""
    from matplotlib.patches import Rectangle

    for lo, hi in occluders:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        cut = z is not None and lo[2] <= z <= hi[2]
        ax.add_patch(Rectangle((lo[0], lo[1]), hi[0] - lo[0], hi[1] - lo[1], fill=False, edgecolor="k",
                               hatch="///" if cut else None, ls="-" if cut else "--", lw=1.2,
                               label="obstruction", gid="occluder"))
    return ax


def plot_slice_maps(pre, box_min_m, box_max_m, *, n_slices: int = 3, n_grid: int = 40,
                    min_range_m: float = 0.0, max_range_m: float = np.inf, occluders=(), axes=None):
    """Largest 95 % semi-axis (µm) of a point measured by the designed heads, over ``n_slices``
    horizontal (z) slices of the box; a head whose line of sight to a point an ``occluders`` box
    cuts does not measure it (blank where fewer than 3 heads do); returns the axes (one per slice)."""
    from multilat.network.design.search import visibility

    plt = _plt()
    lo, hi = np.asarray(box_min_m, float), np.asarray(box_max_m, float)
    if axes is None:
        _, axes = plt.subplots(1, n_slices, figsize=(4.2 * n_slices, 3.8), squeeze=False)
        axes = axes[0]
    xs, ys = np.linspace(lo[0], hi[0], n_grid), np.linspace(lo[1], hi[1], n_grid)
    X, Y = np.meshgrid(xs, ys)
    zs = np.linspace(lo[2], hi[2], n_slices) if n_slices > 1 else [(lo[2] + hi[2]) / 2]
    maps = []
    for z in zs:
        pts = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, z)])
        vis = visibility(pre.station_xyz_m, pts, occluders=occluders).T if occluders else None
        cov = pre.probe_cov_m2(pts, min_range_m=min_range_m, max_range_m=max_range_m, visible=vis)
        ev = np.linalg.eigvalsh(np.nan_to_num(cov, nan=0.0))[:, -1]
        ev[~np.isfinite(cov).all(axis=(1, 2))] = np.nan
        maps.append(np.sqrt(CHI2_3_95 * np.clip(ev, 0, None)).reshape(X.shape) * 1e6)
    vmax = np.nanmax([np.nanmax(m) for m in maps])
    for ax, z, m in zip(axes, zs, maps):
        im = ax.pcolormesh(X, Y, m, shading="auto", vmin=0, vmax=vmax, cmap="viridis")
        ax.plot(pre.station_xyz_m[:, 0], pre.station_xyz_m[:, 1], "r^", ms=6)
        draw_occluders(ax, occluders, z=z)
        ax.set_aspect("equal")
        ax.set_title(f"z = {z:.2f} m")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.figure.colorbar(im, ax=ax, shrink=0.8, label="largest 95 % semi-axis (µm)")
    return axes


def save_design_figures(pre, out_dir: str | os.PathLike, *, box_min_m, box_max_m,
                        min_range_m: float = 0.0, max_range_m: float = np.inf, occluders=()) -> list[Path]:
    """Write ``layout_3d.png``, ``layout_top.png`` and ``uncertainty_slices.png`` into ``out_dir``
    (``occluders``: the declared obstruction boxes, drawn and used in the maps)."""
    _plt()                      # the non-interactive backend
    from multilat.report.png import save_png

    out = Path(out_dir)
    written = []
    figs = [("layout_3d.png", plot_layout_3d(pre, occluders).figure),
            ("layout_top.png", draw_occluders(plot_top_view(pre), occluders).figure),
            ("uncertainty_slices.png",
             plot_slice_maps(pre, box_min_m, box_max_m, min_range_m=min_range_m,
                             max_range_m=max_range_m, occluders=occluders)[0].figure)]
    for name, fig in figs:
        p = out / name
        save_png(fig, p)
        written.append(p)
    return written
