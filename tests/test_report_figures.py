"""Figures a metrologist expects (issue 13 item 3): ellipses magnified per class with the scale
printed; Monte Carlo clouds of chosen points in three projections, stations included."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from multilat.network.adjust.distance.adjust import adjust
from multilat.network.io.files import read_observations

EX = Path(__file__).resolve().parents[1] / "examples" / "network"


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


@pytest.fixture(scope="module")
def res():
    return adjust(read_observations(EX / "small_volume_obs.csv"))


def _largest_95(cov):
    return max(np.sqrt(stats.chi2.ppf(0.95, 3) * np.linalg.eigvalsh(np.asarray(c)).max()) for c in cov)


def test_magnification_per_class_follows_the_1_2_5_rule(res):
    from multilat.report.network_figures import class_magnifications

    ms, mt = class_magnifications(res)
    span = np.ptp(np.vstack([res.station_xyz_m, res.target_xyz_m]), axis=0).max()
    for mag, cov in ((ms, res.station_cov_m2), (mt, res.target_cov_m2)):
        drawn = mag * _largest_95(cov)
        # 1-2-5 steps are at most 2.5 apart: the largest ellipsoid is 6 %/2.5 to 6 % of the span
        assert 0.06 * span / 2.5 < drawn <= 0.06 * span * (1 + 1e-9), (mag, drawn / span)
        assert float(f"{mag / 10 ** np.floor(np.log10(mag)):.6g}") in (1, 2, 5)
    # the targets' ellipsoids are about ten times smaller than the heads': one factor would hide them
    assert mt >= 5 * ms


def test_top_view_prints_both_scales(res):
    plt = _plt()
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    from multilat.report.network_figures import class_magnifications, plot_top_view

    ms, mt = class_magnifications(res)
    ax = plot_top_view(res)
    bars = [a for a in ax.artists if isinstance(a, AnchoredSizeBar)]
    labels = [b.txt_label.get_text() for b in bars]
    assert len(bars) == 2 and any(f"×{ms:g}" in t for t in labels) and any(f"×{mt:g}" in t for t in labels)
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any(f"×{ms:g}" in t for t in legend) and any(f"×{mt:g}" in t for t in legend)
    # a bar stands for the printed length: its data length / magnification = the label's µm
    for b in bars:
        um = float(b.txt_label.get_text().split(": ")[1].split(" µm")[0])
        mag = float(b.txt_label.get_text().split("(×")[1].rstrip(")"))
        size = b.size_bar.get_children()[0].get_width()
        assert size == pytest.approx(um * 1e-6 * mag, rel=1e-12)
    plt.close(ax.figure)


@pytest.fixture(scope="module")
def prop():
    from multilat.network.montecarlo.propagate import problem_from_observations, propagate

    obs = read_observations(EX / "small_volume_obs.csv")
    return propagate(problem_from_observations(obs), trials=60, rng=4, noise="gaussian", keep_samples=True)


def test_clouds_three_projections_of_chosen_points(prop):
    plt = _plt()
    from multilat.report.propagate_figures import clouds_figure

    fig = clouds_figure(prop, points=["A", "3"])
    axes = np.array(fig.axes).reshape(2, 3)
    for row in axes:
        assert [(a.get_xlabel()[:2], a.get_ylabel()[:2]) for a in row] == [("dx", "dy"), ("dx", "dz"),
                                                                            ("dy", "dz")]
        assert all(len(a.lines) == 3 for a in row)          # cloud, MC ellipse, linear ellipse
    assert axes[0, 0].get_title(loc="left").startswith("station A")
    assert axes[1, 0].get_title(loc="left").startswith("target 3")
    # the drawn cloud is the sample itself (µm): x-z panel of A = columns A.x, A.z
    ix, iz = prop.labels.index("A.x"), prop.labels.index("A.z")
    x, z = axes[0, 1].lines[0].get_data()
    np.testing.assert_allclose(x, prop.samples[:, ix] * 1e6, rtol=1e-6)
    np.testing.assert_allclose(z, prop.samples[:, iz] * 1e6, rtol=1e-6)
    plt.close(fig)


def test_clouds_default_includes_every_station_and_refuses_unknown_ids(prop):
    from multilat.errors import MultilatError
    from multilat.report.propagate_figures import clouds_figure, default_cloud_points

    ids = default_cloud_points(prop, 8)
    assert ids[:4] == list(prop.problem.station_ids) and len(ids) == 8
    # then the targets with the largest ellipsoids
    t = [q for q, p in enumerate(prop.point_ids) if p not in prop.problem.station_ids]
    big = sorted(t, key=lambda q: -np.linalg.eigvalsh(prop.point_cov_mc[q])[-1])[:4]
    assert ids[4:] == [prop.point_ids[q] for q in big]
    with pytest.raises(MultilatError, match="unknown point id"):
        clouds_figure(prop, points=["A", "nope"])


def test_cli_cloud_points_unknown_is_one_line(tmp_path, capsys):
    from multilat.cli.app import main

    rc = main(["propagate", str(EX / "small_volume_obs.csv"), "--trials", "20", "--out", str(tmp_path / "o"),
               "--cloud-points", "A,Z9"])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("error: --cloud-points") and err.count("\n") == 1
    assert not (tmp_path / "o").exists()
