"""multilat's own tables (``Observations``, ``Points``, scale bars) as a general network
(``multilat adjust obs.csv --model general``, ``docs/general-network.md`` "Your CSV networks").

The mapping keeps the conventions of the distance path exactly (``docs/conventions.md``,
:mod:`multilat.network.model`, :mod:`multilat.network.angle_rows`):

* every station and every target is one point (ids are disjoint in ``Observations``);
* a distance row is a ``slope_distance`` from its station to its target, measured by the station's
  **head** as instrument: ``d = (1 + k_h) |T - H| + o_h`` with the head's additive constant ``o_h``
  (estimated unless ``offsets`` holds it: a held value is subtracted from the head's distances and
  the constant held at 0, the same model) and scale ``k_h`` (estimated for the heads ``scales``
  names); a head on several stations has one constant and one scale, as on the distance path;
* an azimuth / elevation **with its σ** is a ``tracker_angles`` row of its station's set-up (one
  per station, its id the station's): ``v = R^T (T - H)``, ``R = Rz(κ) Ry(φ) Rx(ω)``, the same
  :mod:`multilat.network.angles` functions; ω, φ held at 0 for the ``levelled`` stations. Angles
  without σ are not observations (as on the distance path) and serve the approximate coordinates;
* a scale bar (``--references`` with ``--scale-bars``) is a ``slope_distance`` between its two
  points with no instrument (``s = |B - A|``), weighted by its ``u_m`` (validated by
  :func:`multilat.network.couplings.coupling_spec`, the distance path's check);
* datum ``free`` is inner constraints over every point, ``free:P,..`` over those points; ``control``
  (``control:P,..``) holds the given points' coordinates (``FIXED``) or, with ``sx_m, sy_m, sz_m``,
  observes them (``WEIGHTED``); the other rows of ``--points`` are approximate coordinates.
  ``321:A,B,C`` is refused (not available on this path).

Approximate coordinates: the ``--points`` rows; then, for a network without angles, the distance
path's own initial values (:func:`multilat.network.starts.initial_for`); then a chain: polar points
from set-ups of known position and frame (``polar_to_xyz``), set-ups placed and oriented by a rigid
fit of their polar readings to three or more known points (the first set-up of a network with no
known point at the origin, axes the world's), points multilaterated from four or more known ends.
A point none of these reaches keeps NaN and is left out and named by
:func:`~.run.adjust_network` (``no approximate coordinates``).
"""

from __future__ import annotations

import warnings

import numpy as np

from multilat.errors import MultilatError
from multilat.network.general.adjust import AdjustOptions
from multilat.network.general.observations import Block, Network
from multilat.network.general.points import FIXED, FREE, WEIGHTED, PointSet

__all__ = ["network_from_tables"]


def network_from_tables(obs, *, points=None, datum="free", offsets=None, scales=False, scale_bars=None,
                        rng=0, source: str = "") -> tuple[Network, AdjustOptions]:
    """The general network of multilat's tables and the adjustment options of its datum.

    obs : :class:`multilat.network.data.Observations`; points : :class:`~multilat.network.data.Points`
    or None; datum : ``free[:P,..]``, ``control[:P,..]`` (``321`` refused); offsets, scales : as
    :func:`multilat.network.adjust.adjust` (keys are head ids); scale_bars : ReferenceLengths or None;
    rng : seed of the distance path's initial values (networks without angles); source : the file
    name, for labels.
    """
    from multilat.network.adjust import _fixed_offsets, _scale_flags
    from multilat.network.couplings import coupling_spec
    from multilat.network.datum import parse_datum

    d = parse_datum(datum)
    if d.kind == "321":
        raise MultilatError(f"--datum {datum}: the 3-2-1 datum is not available with --model general "
                            "(use free[:P,..] or control[:P,..])")
    ids = obs.station_ids + obs.target_ids
    if d.points is not None:
        for p in d.points:
            if p not in ids:
                raise MultilatError(f"--datum {datum}: unknown point id {p!r}")
    if d.kind == "control" and points is None:
        raise MultilatError("datum control needs control coordinates (--points)")
    if points is not None:
        stray = [i for i in points.ids if i not in set(ids)]
        if stray:
            warnings.warn(f"points: {len(stray)} id(s) not in the observations, ignored: "
                          f"{', '.join(stray[:8])}{'...' if len(stray) > 8 else ''}", UserWarning, stacklevel=2)
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
    net = _with_approximations(net, obs, points, rng)
    opts = AdjustOptions(datum="auto" if (d.kind == "control" or d.points is not None) else "free")
    return net, opts


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
        from multilat.network.fit import control_ids

        ctrl = control_ids(obs, d, points)
        weighted = {w[0]: w[2] for w in (spec.control if spec is not None else ())}
        for k, p in enumerate(ids):
            if p in ctrl:
                if p in weighted:
                    status[k], sigma[k] = WEIGHTED, weighted[p]
                else:
                    status[k] = FIXED
    elif d.points is not None:
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


def _with_approximations(net: Network, obs, points, rng) -> Network:
    pts = net.points
    xyz = pts.xyz_m.copy()
    notes = list(net.notes)
    known = np.all(np.isfinite(xyz), 1)
    if known.all():
        return net
    has_angles = obs.azimuth_rad is not None and obs.elevation_rad is not None and bool(
        np.any(np.isfinite(obs.azimuth_rad) & np.isfinite(obs.elevation_rad)))
    if not has_angles:
        xyz, how = _distance_start(obs, points, rng, xyz, known)
        if how is not None:
            notes.append(how)
        known = np.all(np.isfinite(xyz), 1)
        if known.all():
            return Network(pts.with_xyz(xyz), net.blocks, tuple(notes))
    n_before = int((~known).sum())
    xyz = _chain(obs, xyz)
    placed = n_before - int((~np.all(np.isfinite(xyz), 1)).sum())
    notes.append(f"approximate coordinates of {placed} point(s) chained from polar readings, set-ups fitted to "
                 "known points and multilateration")
    return Network(PointSet(pts.ids, xyz, pts.status, pts.sigma_m, pts.constrained), net.blocks, tuple(notes))


def _distance_start(obs, points, rng, xyz, known):
    """The distance path's initial values (:func:`multilat.network.starts.initial_for`) on the targets
    three or more stations see (the others are left to the chain, or left out): (xyz, note or None)."""
    from multilat.network.data import distinct_pair_codes
    from multilat.network.starts import initial_for

    pairs = distinct_pair_codes(obs.station_index, obs.target_index, obs.n_targets)
    seen_by = np.bincount(pairs % obs.n_targets, minlength=obs.n_targets)
    keep = seen_by[obs.target_index] >= 3
    try:
        sub = obs if keep.all() else obs.subset(keep)
        start, how = initial_for(sub, None, points, rng)
    except MultilatError as e:
        return xyz, f"the distance path's initial values failed ({e}); chained instead"
    xyz = xyz.copy()
    ids = obs.station_ids + obs.target_ids
    got = dict(zip(sub.station_ids + sub.target_ids, np.vstack([start.station_xyz_m, start.target_xyz_m])))
    fill = [k for k, p in enumerate(ids) if not known[k] and p in got]
    for k in fill:
        xyz[k] = got[ids[k]]
    return xyz, (f"approximate coordinates of {len(fill)} point(s) from the distance path's initial values "
                 f"({how.get('method', '?')})")


def _polar_local(obs):
    """Per row: the target in its station's frame from distance, azimuth, elevation (NaN without angles)."""
    from multilat.network.angles import polar_to_xyz

    m = obs.n_obs
    az = obs.azimuth_rad if obs.azimuth_rad is not None else np.full(m, np.nan)
    el = obs.elevation_rad if obs.elevation_rad is not None else np.full(m, np.nan)
    return polar_to_xyz(np.zeros(3), np.zeros(3), obs.distance_m, az, el)


def _chain(obs, xyz):
    """Polar points, fitted set-ups and multilateration, pass by pass until nothing new is placed."""
    from multilat.network.datum import rigid_fit
    from multilat.network.initial import multilaterate

    s = obs.n_stations
    xyz = xyz.copy()
    local = _polar_local(obs)
    polar = np.all(np.isfinite(local), 1)
    frame: dict = {}
    si, ti = obs.station_index, s + obs.target_index
    angle_st = [i for i in range(s) if np.any(polar & (si == i))]
    if angle_st and not np.any(np.all(np.isfinite(xyz), 1)):
        xyz[angle_st[0]] = 0.0                      # the first set-up: origin, the world's axes
        frame[angle_st[0]] = np.eye(3)
    changed = True
    while changed:
        changed = False
        known = np.all(np.isfinite(xyz), 1)
        for i in angle_st:
            rows = np.flatnonzero(polar & (si == i))
            if i not in frame:
                ok = rows[known[ti[rows]]]
                if len(ok) < 3:
                    continue
                try:
                    if known[i]:
                        R, _ = rigid_fit(local[ok], xyz[ti[ok]] - xyz[i])
                    else:
                        R, t = rigid_fit(local[ok], xyz[ti[ok]])
                        xyz[i], known[i] = t, True
                except MultilatError:
                    continue
                frame[i], changed = R, True
            new = rows[~known[ti[rows]]]
            if new.size:
                xyz[ti[new]] = xyz[i] + local[new] @ frame[i].T
                known[ti[new]], changed = True, True
        for p in np.flatnonzero(~known):            # multilateration from >= 4 known other ends
            rows = np.flatnonzero((si == p) | (ti == p))
            other = np.where(si[rows] == p, ti[rows], si[rows])
            ok = known[other]
            if len(set(other[ok].tolist())) >= 4:
                xyz[p], _ = multilaterate(xyz[other[ok]], obs.distance_m[rows][ok])
                known[p], changed = True, True
    return xyz
