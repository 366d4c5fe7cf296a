"""Interactive 3-D view of a network (stations, targets, 95 % ellipsoids) with plotly.

plotly is the optional ``report`` extra; without it :func:`html_fragment` returns ``None`` and the
reports fall back to the static matplotlib view. The fragment carries plotly.js inline
(``include_plotlyjs=True``, about 4.6 MB) so that the report stays one self-contained file.
Ellipsoids are magnified per class (stations, targets) with the factors in the legend, as in
:func:`multilat.report.network_figures.plot_top_view`. Declared obstructions (a design's
``[[occluders]]`` boxes) are drawn as grey boxes, one ``Mesh3d`` trace each.
"""

from __future__ import annotations

import numpy as np

from multilat.network.adjust.statistics import CHI2_3_95
from multilat.report.network_figures import class_magnifications

_K95 = float(np.sqrt(CHI2_3_95))     # sqrt(chi2_3(0.95))


def available() -> bool:
    try:
        import plotly.graph_objects  # noqa: F401
    except ImportError:
        return False
    return True


def _occluder_traces(fig, occluders) -> None:
    """One grey ``Mesh3d`` box per ``(box_min_m, box_max_m)``: its 8 corners, 12 triangles."""
    import plotly.graph_objects as go

    from multilat.report.design_figures import BOX_FACES, box_corners

    tri = np.array([t for f in BOX_FACES for t in ((f[0], f[1], f[2]), (f[0], f[2], f[3]))])
    for n, (lo, hi) in enumerate(occluders):
        c = box_corners(lo, hi)
        fig.add_trace(go.Mesh3d(x=c[:, 0], y=c[:, 1], z=c[:, 2], i=tri[:, 0], j=tri[:, 1], k=tri[:, 2],
                                color="#7f7f7f", opacity=0.3, flatshading=True, name="obstruction",
                                legendgroup="obstruction", showlegend=n == 0, hoverinfo="name"))


def figure(result, *, max_ellipsoids: int = 300, occluders=()):
    """A plotly Figure of ``result`` (anything with station/target ids, xyz and 3x3 covariances);
    ``occluders``: boxes ``(box_min_m, box_max_m)`` drawn as obstructions."""
    import plotly.graph_objects as go

    mags = class_magnifications(result)
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 17), np.linspace(0, np.pi, 9))
    sphere = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], axis=-1)
    fig = go.Figure()
    for name, ids, xyz, cov, mag, col, sym in (
            ("stations", result.station_ids, result.station_xyz_m, result.station_cov_m2, mags[0],
             "#d62728", "diamond"),
            ("targets", result.target_ids, result.target_xyz_m, result.target_cov_m2, mags[1],
             "#1f77b4", "circle")):
        xyz = np.asarray(xyz, float)
        fig.add_trace(go.Scatter3d(x=xyz[:, 0], y=xyz[:, 1], z=xyz[:, 2], mode="markers+text",
                                   text=[str(i) for i in ids], name=name,
                                   marker=dict(size=4, color=col, symbol=sym), textfont=dict(size=9)))
        if len(xyz) > max_ellipsoids:
            continue
        first = True
        for p, c in zip(xyz, np.asarray(cov, float)):
            if not np.all(np.isfinite(c)):
                continue
            w, V = np.linalg.eigh(c)
            e = sphere @ (V * (_K95 * mag * np.sqrt(np.clip(w, 0, None)))).T + p
            fig.add_trace(go.Surface(x=e[..., 0], y=e[..., 1], z=e[..., 2], showscale=False, opacity=0.35,
                                     colorscale=[[0, col], [1, col]], name=f"{name} 95 % ×{mag:g}",
                                     legendgroup=name + "ell", showlegend=first, hoverinfo="skip"))
            first = False
    _occluder_traces(fig, occluders)
    fig.update_layout(scene=dict(aspectmode="data", xaxis_title="x (m)", yaxis_title="y (m)",
                                 zaxis_title="z (m)"),
                      margin=dict(l=0, r=0, t=30, b=0), height=600,
                      title=f"95 % ellipsoids magnified: stations ×{mags[0]:g}, targets ×{mags[1]:g}")
    return fig


def html_fragment(result, occluders=()) -> str | None:
    """The view as an HTML ``<div>`` with plotly.js inline, or ``None`` without plotly."""
    if not available():
        return None
    return figure(result, occluders=occluders).to_html(include_plotlyjs=True, full_html=False,
                                  config={"displaylogo": False})


def write_html(result, path) -> bool:
    """Write the view as a standalone page (atomically); False without plotly."""
    if not available():
        return False
    from multilat.io import write_text_atomic

    write_text_atomic(path, figure(result).to_html(include_plotlyjs=True, full_html=True))
    return True
