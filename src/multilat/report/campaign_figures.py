"""Figures of a measurement campaign: the environment per sensor, the index correction per reading."""

from __future__ import annotations

import os

import numpy as np

__all__ = ["plot_environment", "plot_index_correction", "correction_figure", "save_correction_figure"]


def _hours(t_s, t0):
    return (np.asarray(t_s, dtype=float) - t0) / 3600.0


def _t0(corrected, log):
    cands = []
    if log is not None:
        cands.append(log.span_s[0])
    if corrected is not None and corrected.time_s is not None:
        cands.append(float(np.min(corrected.time_s)))
    return min(cands) if cands else 0.0


def plot_environment(log, quantity: str = "temperature_c", *, t0: float | None = None, ax=None):
    """Readings of every sensor of ``log`` over time (hours from ``t0``); returns ``ax``."""
    import matplotlib.pyplot as plt

    ax = ax or plt.gca()
    t0 = log.span_s[0] if t0 is None else t0
    units = {"temperature_c": "temperature / °C", "pressure_hpa": "pressure / hPa",
             "humidity_pct": "humidity / %RH", "co2_ppm": "CO2 / ppm"}
    for sid, h, ts, rd in zip(log.sensor_ids, log.height_m, log.times_s, log.readings):
        lab = sid if not np.isfinite(h) else f"{sid} ({h:g} m)"
        ax.plot(_hours(ts, t0), rd[quantity], ".-", ms=3, lw=1, label=lab)
    ax.set_ylabel(units[quantity])
    ax.set_xlabel("time / h")
    ax.grid(alpha=0.3)
    return ax


def plot_index_correction(corrected, *, t0: float | None = None, ax=None):
    """Per-observation air-index correction, relative (µm/m), with its ±1σ sensor uncertainty.

    The correction of reading ``i`` is ``D_i - L_i = -L_i (1 - 1/n_i)``; plotted is its size per
    metre ``(1 - 1/n_i)·1e6``, positive: the correction shortens the reading (the JSON/CSV
    ``index_correction_m`` = D - L is negative); readings of different lengths compare. The error bar is
    ``σ_air,i / D_i``. Against time (hours from ``t0``) when the readings have times, else against
    the row number. Returns ``ax``.
    """
    import matplotlib.pyplot as plt

    ax = ax or plt.gca()
    if corrected.time_s is not None:
        x = _hours(corrected.time_s, corrected.time_s.min() if t0 is None else t0)
        ax.set_xlabel("time / h")
    else:
        x = np.arange(1, corrected.distance_m.size + 1)
        ax.set_xlabel("observation")
    y = -corrected.index_correction_m / corrected.vacuum_path_m * 1e6
    yerr = corrected.sigma_air_m / corrected.distance_m * 1e6
    heads = list(dict.fromkeys(corrected.station_ids))
    st = np.array(corrected.station_ids, dtype=object)
    for h in heads:
        k = st == h
        ax.errorbar(x[k], y[k], yerr=yerr[k], fmt="o", ms=3, capsize=2, lw=1, label=f"head {h}")
    ax.set_ylabel("shortening (L - D)/L / (µm/m)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=len(heads), title="error bar: sensor part (k=1)", title_fontsize=7)
    return ax


def correction_figure(corrected, log=None):
    """A figure: temperature and pressure per sensor (if a log), and the index correction per reading."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t0 = _t0(corrected, log)
    n = 3 if log is not None else 1
    fig, axes = plt.subplots(n, 1, figsize=(7.5, 2.6 * n + 0.6), sharex=log is not None and
                             corrected.time_s is not None, squeeze=False)
    axes = axes[:, 0]
    if log is not None:
        plot_environment(log, "temperature_c", t0=t0, ax=axes[0])
        axes[0].legend(fontsize=7, ncol=2)
        axes[0].set_title("environment over the campaign (per sensor)")
        plot_environment(log, "pressure_hpa", t0=t0, ax=axes[1])
        for a in axes[:-1]:
            a.set_xlabel("")
    plot_index_correction(corrected, t0=t0, ax=axes[-1])
    axes[-1].set_title("air-index correction of each reading")
    fig.tight_layout()
    return fig


def save_correction_figure(path: str | os.PathLike, corrected, log=None) -> None:
    """Write :func:`correction_figure` as a PNG, atomically."""
    from multilat.report.png import save_png

    save_png(correction_figure(corrected, log), path, tight=False)
