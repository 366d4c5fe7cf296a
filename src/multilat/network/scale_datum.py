"""The scale datum: with every station's scale estimated the network's scale is a 7th datum defect,
fixed by a held scale or by one reference length (a scale bar)."""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.covariance import NetworkCovariance
from multilat.network.data import Observations, ReferenceLengths
from multilat.network.datum import datum_matrices
from multilat.network.fit import fit_once
from multilat.network.model import Q

__all__ = ["check_scale_datum", "scale_bar_datum", "apply_scale_bar"]


def check_scale_datum(obs: Observations, sc_free, datum) -> None:
    """Distances fix the size of a network through the scales held fixed: with every station's scale
    estimated (and no control points) the scale is a 7th datum defect."""
    if datum.kind == "control" or not np.all(sc_free):
        return
    raise MultilatError("every station's scale is estimated, so the network's scale is undetermined (a 7th "
                        "datum defect): estimate the scales of some stations only (--scales A,B) so the "
                        "others fix it, hold one station's scale (--fixed-scale STATION), or fix the "
                        "scale by a reference length (--references FILE --scale-bar)")


def scale_bar_datum(refs: ReferenceLengths, obs: Observations, sc_free, datum, cost):
    """Validate a reference length as the scale datum: (a, b, length_m, u_m)."""
    if len(refs) != 1:
        raise MultilatError(f"scale bar: one reference length fixes the scale, got {len(refs)} (several scale "
                            "bars as weighted observations are not supported yet)")
    refs.check_ids(obs.station_ids + obs.target_ids)
    if datum.kind == "control" or cost != "distance":
        raise MultilatError("scale bar: needs the free or 321 datum and the distance cost (control points "
                            "already fix the scale)")
    if not np.all(sc_free):
        raise MultilatError("scale bar: the stations whose scale is held already fix the network's scale; "
                            "a scale bar is the scale datum when every station's scale is estimated "
                            "(--scales)")
    u = float(refs.u_m[0])
    return refs.target_a[0], refs.target_b[0], float(refs.length_m[0]), 0.0 if np.isnan(u) else u


def apply_scale_bar(core, bar, obs, used, datum, start, points, off_free, off_val, sc_free, max_iter,
                     solver, chunk_targets):
    """Move the adjusted network (scale held on its first station) along the exact similarity that
    leaves every distance residual unchanged — coordinates times ``f`` about their centroid, each
    ``1 + k_i`` divided by ``f`` — so that the bar's length is the reference; re-adjust there (the
    Jacobian at the scaled solution) and express the covariance in the datum whose 7th condition
    is the bar's length, plus the bar's own uncertainty along the scale direction."""
    from types import SimpleNamespace

    sub = obs if used.all() else obs.subset(used)
    smap, tmap = core["smap"], core["tmap"]
    ids = list(sub.station_ids + sub.target_ids)
    xyz = np.vstack([core["sx"], core["tx"]])
    a, b, L_ref, u_L = bar
    ia, ib = ids.index(a), ids.index(b)
    f = L_ref / float(np.linalg.norm(xyz[ia] - xyz[ib]))
    c = xyz.mean(axis=0)
    xyz = c + f * (xyz - c)
    s = sub.n_stations
    S_all, T_all = obs.n_stations, obs.n_targets
    sx_all, tx_all = np.zeros((S_all, 3)), np.zeros((T_all, 3))
    off_all, sc_all = np.zeros(S_all), np.zeros(S_all)
    sx_all[smap], tx_all[tmap] = xyz[:s], xyz[s:]
    off_all[smap], sc_all[smap] = core["off"], (1.0 + core["sc"]) / f - 1.0
    scaled = SimpleNamespace(station_xyz_m=sx_all, target_xyz_m=tx_all, offset_m=off_all, scale=sc_all)
    new = fit_once(sub, datum, scaled, start, obs, used, points, "distance", off_free, off_val, sc_free,
                       max_iter, solver, chunk_targets, warn=False)
    sx, tx, sc = new["sx"], new["tx"], new["sc"]
    G, E = datum_matrices(datum, sub.station_ids, sub.target_ids, sx, tx)
    n = G.shape[0]
    rows = np.concatenate([(Q * np.arange(s)[:, None] + np.arange(3)).ravel(), Q * s + np.arange(3 * sub.n_targets)])
    pts = np.vstack([sx, tx])
    g_s = np.zeros(n)
    g_s[rows] = (pts - pts.mean(axis=0)).ravel()
    g_s[Q * np.arange(s) + 4] = -(1.0 + sc)
    e_bar = np.zeros(n)
    d = pts[ia] - pts[ib]
    d /= np.linalg.norm(d)
    e_bar[rows[3 * ia:3 * ia + 3]] = d
    e_bar[rows[3 * ib:3 * ib + 3]] = -d
    g_hat = g_s - G @ np.linalg.solve(E.T @ G, E.T @ g_s)
    cov = new["cov"]
    new["cov"] = NetworkCovariance(cov.Qgg, cov.Minv, cov.Js_w, cov.Jt_w, cov.si, cov.ti, factor=cov.factor,
                                   R=cov.R, G=np.column_stack([G, g_s]), E=np.column_stack([E, e_bar]),
                                   extra=(u_L / L_ref) * g_hat[:, None] if u_L > 0 else None)
    new["sc_free"] = np.ones(s, bool)
    return new
