"""Figures of an adjustment: the top view's labels do not collide (review finding: 'A' and '13'
overlapped in the small-volume example in the 3-2-1 frame B, D, C)."""

from pathlib import Path

import numpy as np

from multilat.network.adjust import adjust
from multilat.network.files import read_observations, read_points

EX = Path(__file__).resolve().parents[1] / "examples" / "network"


def _boxes(ax):
    fig = ax.figure
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    return {t.get_text(): t.get_window_extent(r) for t in ax.texts}


def test_top_view_labels_do_not_overlap():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from multilat.report.network_figures import plot_top_view

    obs = read_observations(EX / "small_volume_obs.csv")
    res = adjust(obs, points=read_points(EX / "small_volume_points.csv"), datum="321:B,D,C")
    # in this frame A stands above target 13: their markers nearly coincide in the top view
    assert np.linalg.norm(res.xyz("A")[:2] - res.xyz("13")[:2]) < 0.01
    ax = plot_top_view(res)
    boxes = _boxes(ax)
    assert set(boxes) == set(res.station_ids) | set(res.target_ids)
    names = sorted(boxes)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            assert not boxes[a].overlaps(boxes[b]), (a, b)
    plt.close(ax.figure)
