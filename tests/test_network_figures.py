"""Figures of an adjustment: the top view's labels do not collide (review finding: 'A' and '13'
overlapped in the small-volume example in the 3-2-1 frame B, D, C)."""

from pathlib import Path

import numpy as np

from multilat.network.adjust.distance.adjust import adjust
from multilat.network.io.files import read_observations, read_points

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


def test_large_networks_draw_densities_and_subsamples(monkeypatch):
    """Above LARGE_PLOT_POINTS the residual figure is a 2-D histogram: its cells hold every used
    observation once (the counts sum to their number); the rejected ones stay crosses at their own
    residuals; the 3-D view draws every k-th target and says so. The threshold is lowered here to
    test on a small network."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from multilat.network.model.data import Observations
    from multilat.network.synthetic.generator import synthetic_network
    from multilat.network.adjust.distance.result import Start
    from multilat.report import network_figures as NF

    net = synthetic_network(3, population="rings", n_stations=8, n_targets=300, per_target=6)
    d = net.distance_m.copy()
    d[5] += 200e-6                                                  # one blunder: rejected
    obs = Observations(tuple(f"S{i}" for i in range(8)), tuple(f"T{j}" for j in range(300)),
                       net.station_index, net.target_index, d, net.sigma_m)
    res = adjust(obs, initial=Start(net.station_xyz_m, net.target_xyz_m, net.offset_m))
    assert not res.used[5]
    monkeypatch.setattr(NF, "LARGE_PLOT_POINTS", 100)
    ax = NF.plot_residuals(res)
    (mesh,) = ax.collections
    assert int(mesh.get_array().sum()) == int(res.used.sum())
    (cross,) = ax.lines[:1]
    assert np.allclose(cross.get_ydata(), res.residuals_m[~res.used] * 1e6)
    plt.close(ax.figure)
    ax = NF.plot_3d(res)
    assert "1 target in 3 shown: 100 of 300" in ax.get_title()
    scatters = [c for c in ax.collections if hasattr(c, "_offsets3d")]        # heads, then targets
    assert [len(c._offsets3d[0]) for c in scatters] == [8, 100]
    plt.close(ax.figure)


def test_density_of_equal_residuals(monkeypatch):
    """A hostile case for the density: every residual the same (exact distances, zeroed residuals):
    a band around the value, every observation counted, no error."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from dataclasses import replace

    from multilat.network.model.data import Observations
    from multilat.network.synthetic.generator import synthetic_network
    from multilat.network.adjust.distance.result import Start
    from multilat.report import network_figures as NF

    net = synthetic_network(9, population="rings", n_stations=6, n_targets=60, per_target=5)
    obs = Observations(tuple(f"S{i}" for i in range(6)), tuple(f"T{j}" for j in range(60)),
                       net.station_index, net.target_index, net.distance_m, net.sigma_m)
    res = adjust(obs, initial=Start(net.station_xyz_m, net.target_xyz_m, net.offset_m), snooping=False)
    res = replace(res, residuals_m=np.zeros_like(res.residuals_m))
    monkeypatch.setattr(NF, "LARGE_PLOT_POINTS", 10)
    ax = NF.plot_residuals(res)
    assert int(ax.collections[0].get_array().sum()) == int(res.used.sum())
    plt.close(ax.figure)
