"""multilat's own tables (``Observations``, ``Points``, scale bars) as a general network
(``multilat adjust obs.csv --model general``, ``docs/general-network.md`` "Your CSV networks").

The mapping keeps the conventions of the distance path exactly (``docs/conventions.md``,
:mod:`multilat.network.model.distance`, :mod:`multilat.network.model.angle_rows`):

* every station and every target is one point (ids are disjoint in ``Observations``);
* a distance row is a ``slope_distance`` from its station to its target, measured by the station's
  **head** as instrument: ``d = (1 + k_h) |T - H| + o_h`` with the head's additive constant ``o_h``
  (estimated unless ``offsets`` holds it: a held value is subtracted from the head's distances and
  the constant held at 0, the same model) and scale ``k_h`` (estimated for the heads ``scales``
  names); a head on several stations has one constant and one scale, as on the distance path;
* an azimuth / elevation **with its σ** is a ``tracker_angles`` row of its station's set-up (one
  per station, its id the station's): ``v = R^T (T - H)``, ``R = Rz(κ) Ry(φ) Rx(ω)``, the same
  :mod:`multilat.network.model.angles` functions; ω, φ held at 0 for the ``levelled`` stations. Angles
  without σ are not observations (as on the distance path) and serve the approximate coordinates;
* a scale bar (``--references`` with ``--scale-bars``) is a ``slope_distance`` between its two
  points with no instrument (``s = |B - A|``), weighted by its ``u_m`` (validated by
  :func:`multilat.network.model.couplings.coupling_spec`, the distance path's check);
* datum ``free`` is inner constraints over every point, ``free:P,..`` over those points; ``control``
  (``control:P,..``) holds the given points' coordinates (``FIXED``) or, with ``sx_m, sy_m, sz_m``,
  observes them (``WEIGHTED``); the other rows of ``--points`` are approximate coordinates.
  ``321:A,B,C`` moves the approximate coordinates into the 3-2-1 frame of A, B, C and holds A's x,
  y, z, B's y, z and C's z (:func:`in_frame_321`): the distance path's frame and cofactors; refused
  where levelled stations' angles observe the vertical (:func:`check_321`).

Approximate coordinates: the ``--points`` rows, then the general chain (:mod:`.approximate`: polar
points, resection, intersection, multilateration, the distance-only search of
:func:`multilat.network.adjust.approximate.starts.initial_for`; the first set-up of a network with no known point at
the origin, axes the world's), the angles read without σ serving it as readings. A point it does not
reach keeps NaN and is left out and named by :func:`~.run.adjust_network`.
"""

from __future__ import annotations

import warnings

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust.general.adjust import AdjustOptions
from multilat.network.model.observations import Block, Network
from multilat.network.model.points import FIXED, FREE, WEIGHTED, PointSet

__all__ = ["network_from_tables", "check_321", "in_frame_321"]


def network_from_tables(obs, *, points=None, datum="free", offsets=None, scales=False, scale_bars=None,
                        rng=0, source: str = "", backend: str = "auto") -> tuple[Network, AdjustOptions]:
    """The general network of multilat's tables and the adjustment options of its datum.

    obs : :class:`multilat.network.model.data.Observations`; points : :class:`~multilat.network.model.data.Points`
    or None; datum : ``free[:P,..]``, ``321:A,B,C``, ``control[:P,..]``; offsets, scales : as
    :func:`multilat.network.adjust.distance.adjust.adjust` (keys are head ids); scale_bars : ReferenceLengths or None;
    rng : seed of the distance path's initial values (networks without angles); source : the file
    name, for labels; backend : :attr:`.adjust.AdjustOptions.backend`, whose size limit is checked
    before the approximate coordinates (:func:`.run.check_sizes`).
    """
    from multilat.network.adjust.distance.adjust import _fixed_offsets, _scale_flags
    from multilat.network.model.couplings import coupling_spec
    from multilat.network.model.datum import parse_datum

    d = parse_datum(datum)
    if d.kind == "321":
        check_321(obs, datum)
    ids = obs.station_ids + obs.target_ids
    if d.points is not None:
        for p in d.points:
            if p not in ids:
                raise MultilatError(f"--datum {datum}: unknown point id {p!r}")
    if d.kind == "control" and points is None:
        raise MultilatError("datum control needs control coordinates (--points)")
    if points is not None:
        known = set(ids)                            # once: a set per point was O(n²) (16 s at 16 000)
        stray = [i for i in points.ids if i not in known]
        if stray:
            warnings.warn(f"points: {len(stray)} id(s) not in the observations, ignored: "
                          f"{', '.join(stray[:8])}{'...' if len(stray) > 8 else ''}", UserWarning, stacklevel=2)
        if points.std_m is not None and d.kind != "control":      # the distance path's warning, its words
            warnings.warn("points: the standard uncertainties (sx_m, sy_m, sz_m) make weighted control under "
                          "--datum control only; here the points are approximate coordinates", UserWarning,
                          stacklevel=2)
    spec = coupling_spec(obs, bars=scale_bars, points=points, control=d.kind == "control")
    pts = _point_set(obs, points, d, spec, rng)
    off_free, off_val = _fixed_offsets(offsets, obs)
    sc_free = _scale_flags(scales, obs)
    blocks = _distance_blocks(obs, off_free, off_val, sc_free)
    blocks += _angle_blocks(obs)
    if spec is not None and spec.bars:
        ix = {p: k for k, p in enumerate(pts.ids)}
        bars = spec.bars
        lines = scale_bars.line_numbers or tuple(range(1, len(bars) + 1))
        blocks.append(Block("slope_distance", np.array([b[2] for b in bars]), np.array([b[3] for b in bars]), None,
                            {"from": np.array([ix[b[0]] for b in bars]), "to": np.array([ix[b[1]] for b in bars])},
                            labels=tuple(f"{scale_bars.path or 'scale bars'}:{ln} scale bar {b[0]}-{b[1]}"
                                         for ln, b in zip(lines, bars))))
    notes = []
    if not np.all(off_free):
        notes.append("held head offsets subtracted from their heads' distances (the constant held at 0)")
    net = Network(pts, tuple(blocks), tuple(notes))
    opts = AdjustOptions(datum="auto" if (d.kind != "free" or d.points is not None) else "free", backend=backend)
    from multilat.network.adjust.general.run import check_sizes

    if np.isnan(pts.xyz_m).any():                   # the approximate chain has work: the size first
        check_sizes(net, opts)                      # (else adjust_network checks it, as for any input)
    net = _with_approximations(net, obs, rng)
    if d.kind == "321":
        net = in_frame_321(net, d, datum)
    return net, opts


def check_321(obs, datum: str) -> None:
    """``--datum 321:A,B,C`` means on the general layer what it means on the distance path (A at the
    origin, B on +x, C in the xy-plane: a rigid motion of the network, 6 coordinates held) only when
    the observations leave the 6 rigid motions free: refused in one line when angles read by levelled
    stations observe the vertical (the frame may then turn about z only: datum defect 4)."""
    if obs.sigma_azimuth_rad is None and obs.sigma_elevation_rad is None:
        return
    ang = np.zeros(obs.n_obs, bool)
    for s in (obs.sigma_azimuth_rad, obs.sigma_elevation_rad):
        if s is not None:
            ang |= np.isfinite(s)
    lev = sorted({obs.station_ids[i] for i in np.unique(obs.station_index[ang]) if obs.station_ids[i] in obs.levelled})
    if lev:
        raise MultilatError(f"--datum {datum} does not apply to this network on the general model: the angles of "
                            f"levelled station(s) {', '.join(lev[:5])}{', ...' if len(lev) > 5 else ''} observe the "
                            "vertical, so the frame can turn about z only (datum defect 4, not the 6 rigid motions "
                            "3-2-1 holds); use --datum free[:P,..] or control[:P,..]")


def in_frame_321(net: Network, d, datum: str) -> Network:
    """``net`` moved rigidly into the 3-2-1 frame of its approximate coordinates (``d.points`` = A, B,
    C: :func:`multilat.network.model.datum.frame_321`, the distance path's), with A's x, y, z, B's y, z and
    C's z held there (``FIXED``): minimal constraints, whose cofactor is the S-transformation of any
    other datum's onto ``Eᵀ dx = 0`` (:func:`multilat.network.model.datum.s_transform`, E those 6 rows),
    and whose solution is the distance path's 3-2-1 frame of the adjusted A, B, C. A point of the three
    without approximate coordinates is named."""
    from multilat.network.model.datum import apply_rigid, frame_321
    from multilat.network.adjust.approximate.general import reasons

    pts = net.points
    ix = [pts.index(p) for p in d.points]
    for p, i in zip(d.points, ix):
        if not np.all(np.isfinite(pts.xyz_m[i])):
            why = reasons(net).get(p, "no approximate coordinates")
            raise MultilatError(f"--datum {datum}: point {p!r} cannot carry the datum: {why}")
    R, t = frame_321(*pts.xyz_m[ix])
    xyz = apply_rigid(R, t, pts.xyz_m)
    status = pts.status.copy()
    for i, axes in zip(ix, ((0, 1, 2), (1, 2), (2,))):
        xyz[i, list(axes)] = 0.0                    # exactly, not 1e-16
        status[i, list(axes)] = FIXED
    moved = type(pts)(pts.ids, xyz, status, pts.sigma_m, pts.constrained)
    note = f"datum {d.describe()} (minimal constraints: {d.points[0]} x, y, z, {d.points[1]} y, z, {d.points[2]} z held)"
    return Network(moved, net.blocks, net.notes + (note,))


def _point_set(obs, points, d, spec, rng) -> PointSet:
    ids = obs.station_ids + obs.target_ids
    n = len(ids)
    xyz = np.full((n, 3), np.nan)
    status = np.full((n, 3), FREE)
    sigma = np.full((n, 3), np.nan)
    if points is not None:
        for k, p in enumerate(ids):
            v = points.get(p)
            if v is not None:
                xyz[k] = v
    constrained = np.zeros(n, bool)
    if d.kind == "control":
        from multilat.network.adjust.distance.fit import control_ids

        ctrl = control_ids(obs, d, points)
        weighted = {w[0]: w[2] for w in (spec.control if spec is not None else ())}
        for k, p in enumerate(ids):
            if p in ctrl:
                if p in weighted:
                    status[k], sigma[k] = WEIGHTED, weighted[p]
                else:
                    status[k] = FIXED
    elif d.kind == "free" and d.points is not None:
        constrained[[ids.index(p) for p in d.points]] = True
    return PointSet(tuple(ids), xyz, status, sigma, constrained)


def _label(obs, k: int, what: str) -> str:
    return f"row {k + 1} {obs.label(k)}{what}"


def _distance_blocks(obs, off_free, off_val, sc_free) -> list:
    """One ``slope_distance`` block per (offset estimated, scale estimated) pair of head flags."""
    heads = obs.head_ids
    hi = obs.head_index
    h_off = np.zeros(len(heads), bool)
    h_sc = np.zeros(len(heads), bool)
    h_val = np.zeros(len(heads))
    h_off[hi], h_sc[hi], h_val[hi] = off_free, sc_free, off_val
    row_head = hi[obs.station_index]
    n_st = obs.n_stations
    out = []
    for of in (True, False):
        for sf in (False, True):
            rows = np.flatnonzero((h_off[row_head] == of) & (h_sc[row_head] == sf))
            if not rows.size:
                continue
            used = sorted(set(row_head[rows].tolist()))
            remap = {h: k for k, h in enumerate(used)}
            value = obs.distance_m[rows] - np.where(of, 0.0, h_val[row_head[rows]])
            out.append(Block("slope_distance", value, obs.sigma_m[rows], None,
                             {"from": obs.station_index[rows], "to": n_st + obs.target_index[rows],
                              "instrument": np.array([remap[h] for h in row_head[rows]], int)},
                             labels=tuple(_label(obs, int(k), " distance") for k in rows),
                             names={"instrument": tuple(heads[h] for h in used)},
                             options={"estimate_offset": bool(of), "estimate_scale": bool(sf)}))
    return out


def _angle_blocks(obs) -> list:
    """``tracker_angles`` blocks: levelled set-ups in one, the others in another (ω, φ estimated)."""
    rows, comps, vals, sigs = [], [], [], []
    for c, (v, s) in enumerate(((obs.azimuth_rad, obs.sigma_azimuth_rad),
                                (obs.elevation_rad, obs.sigma_elevation_rad))):
        if s is None:
            continue
        k = np.flatnonzero(np.isfinite(s))
        rows.append(k)
        comps.append(np.full(k.size, c))
        vals.append(v[k])
        sigs.append(s[k])
    if not rows:
        return []
    rows, comps, vals, sigs = (np.concatenate(a) for a in (rows, comps, vals, sigs))
    lev = np.array([obs.station_ids[i] in obs.levelled for i in obs.station_index[rows]], bool)
    out = []
    for flag in (True, False):
        sel = lev == flag
        if not sel.any():
            continue
        r = rows[sel]
        st = obs.station_index[r]
        used = sorted(set(st.tolist()))
        remap = {s: k for k, s in enumerate(used)}
        out.append(Block("tracker_angles", vals[sel], sigs[sel], None,
                         {"from": st, "to": obs.n_stations + obs.target_index[r],
                          "setup": np.array([remap[s] for s in st], int), "component": comps[sel]},
                         labels=tuple(_label(obs, int(k), f" {('azimuth', 'elevation')[int(c)]}")
                                      for k, c in zip(r, comps[sel])),
                         names={"setup": tuple(obs.station_ids[s] for s in used)}, options={"levelled": flag}))
    return out


# ----------------------------------------------------------------------------- approximate coordinates


def _with_approximations(net: Network, obs, rng) -> Network:
    """The approximate coordinates of the general chain (:func:`..approximate.approximate`), with the
    angles read without σ as readings for it alone; a point it does not reach keeps NaN."""
    from multilat.network.adjust.approximate.general import approximate

    return approximate(net, extra=_angle_readings(obs), rng=rng, partial=True)


def _angle_readings(obs) -> tuple:
    """Every row's azimuth and elevation (with or without σ) as ``tracker_angles`` blocks of the
    stations' set-ups, for the approximations only (σ 1 rad: not used)."""
    if obs.azimuth_rad is None or obs.elevation_rad is None:
        return ()
    k = np.flatnonzero(np.isfinite(obs.azimuth_rad) & np.isfinite(obs.elevation_rad))
    out = []
    lev = np.array([obs.station_ids[i] in obs.levelled for i in obs.station_index[k]], bool)
    for flag in (True, False):
        r = k[lev == flag]
        if not r.size:
            continue
        st = obs.station_index[r]
        used = sorted(set(st.tolist()))
        remap = {s: q for q, s in enumerate(used)}
        m = r.size
        out.append(Block("tracker_angles", np.concatenate([obs.azimuth_rad[r], obs.elevation_rad[r]]), np.ones(2 * m),
                         None, {"from": np.tile(st, 2), "to": np.tile(obs.n_stations + obs.target_index[r], 2),
                                "setup": np.tile([remap[s] for s in st], 2), "component": np.repeat([0, 1], m)},
                         names={"setup": tuple(obs.station_ids[s] for s in used)}, options={"levelled": flag}))
    return tuple(out)
