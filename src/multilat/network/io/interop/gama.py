"""GNU Gama: the ``gama-local`` XML input (write and read) and its adjusted XML output (read).

Input format (GNU Gama manual, ch. 2 "XML input data format for gama-local"; schema
``xml/gama-local.xsd`` of the Gama 2.24 sources, its version 1.01 plus the ``angular`` attribute
of 1.02)::

    <gama-local xmlns="http://www.gnu.org/software/gama/gama-local">
    <network axes-xy="en" angles="right-handed">
      <description>...</description>
      <parameters sigma-apr="1" sigma-act="apriori" .../>
      <points-observations>
        <point id="A" x=".." y=".." z=".." adj="XYZ"/>     (fix="XYZ" for control)
        <obs from="A"> <s-distance to="1" val="0.7756052" stdev="0.0047"/> </obs>
      </points-observations>
    </network>
    </gama-local>

Distances and coordinates are in metres, standard deviations of distances in **millimetres**.
``adj="XYZ"`` (capitals: *constrained*) makes every point a datum point of Gama's free network
(the regularisation over constrained coordinates, as multilat's free datum over all points);
``fix="XYZ"`` holds a point fixed. gama-local moves the constrained points between its linearisation
iterations (the default since 2.09; ``update-constrained-coordinates``, which switched it on
before, was removed from the format in 2.10 and makes current gama-local refuse the file, so the
export does not write it; gama-local before 2.09 keeps the constrained points at their approximate
values, docs/interop.md); ``cov-band="-1"``: the full covariance of the adjusted coordinates in the XML output (its default
there is a band of 1). ``axes-xy="en"``: Gama's x is east, y north, z up, the same
right-handed axes as multilat's x, y, z; on import any ``axes-xy`` is turned to those axes.

Gama has **no additive constant per instrument** (and no scale): the export writes
``(d - o) / (1 + k)`` with each head's offset o (and scale k, when one was estimated) fixed at given
values (:func:`~.common.apply_offsets`) and records in ``<description>`` the lines
``multilat-offsets-m: S1=.. S2=..``, ``multilat-heads: S1=T1 S2=T2 ..`` (which head stood on each
station) and ``multilat-scales: T1=..``; the importer restores the distances and the heads when it
finds them (any other Gama file is read as distances without offsets, every station its own head).

The adjusted output (``gama-local --xml``) is read by :mod:`.gama_adjusted`.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from multilat.errors import MultilatError
from multilat.io import write_text_atomic
from multilat.network.model.data import Observations, Points
from multilat.network.io.interop.angles import angle_sigmas, join_angles
from multilat.network.io.interop.common import (ModelTags, Network, apply_offsets, build_network, check_ids, fmt_m,
                                              model_lines, parse_xml, refuse_weighted_points, restore_model,
                                              xml_escape, xml_float)

__all__ = ["write_gama_local", "gama_local_text", "read_gama_local", "NAMESPACE", "GON_PER_RAD"]

NAMESPACE = "http://www.gnu.org/software/gama/gama-local"
#: gama-local's observation elements that multilat does not read (refused, named)
_UNSUPPORTED = {"distance": "horizontal distances",
                "angle": "horizontal angles", "azimuth": "azimuths",
                "height-differences": "height differences", "dh": "height differences",
                "coordinates": "observed coordinates", "vectors": "coordinate differences",
                "vec": "coordinate differences", "cov-mat": "a covariance matrix of observations"}
_AXES = {"n": (0.0, 1.0), "s": (0.0, -1.0), "e": (1.0, 0.0), "w": (-1.0, 0.0)}
_READ = "read"
_PROCESSING = "gama-local's processing or output setting: no effect on the network read"
_EXTERN = "an external tag Gama copies to its output: no effect"
#: every attribute of the elements the reader reads (xml/gama-local.xsd of Gama 2.24, the names
#: kept in tests/data/interop/gama-local-xsd-2.24.json) and what the reader does with it: "read"
#: (applied, or refused by value in the element's reader), or why it has no effect on the network;
#: any other attribute is refused by name (:func:`_check_attributes`); the elements of
#: :data:`_UNSUPPORTED` are refused whole
ATTRIBUTES = {
    "gama-local": {},
    "network": {"axes-xy": _READ, "angles": _READ,
                "epoch": "the epoch of the observations: a label, no effect on the network read"},
    "description": {},
    "parameters": {**{a: _PROCESSING for a in (
        "sigma-apr", "conf-pr", "tol-abs", "sigma-act", "algorithm", "language", "encoding", "angular", "angles",
        "latitude", "ellipsoid", "cov-band")},
        "update-constrained-coordinates": _PROCESSING + " (gama-local before 2.10; current gama-local refuses it)"},
    "points-observations": {"distance-stdev": _READ, "direction-stdev": _READ, "zenith-angle-stdev": _READ,
                            "angle-stdev": "the default σ of <angle>, which is refused",
                            "azimuth-stdev": "the default σ of <azimuth>, which is refused"},
    "point": {"id": _READ, "x": _READ, "y": _READ, "z": _READ, "fix": _READ, "adj": _READ},
    "obs": {"from": _READ, "from_dh": _READ,
            "orientation": "Gama's approximate orientation of the set (a start value): no effect on the network"},
    "s-distance": {**{a: _READ for a in ("from", "to", "val", "stdev", "from_dh", "to_dh")}, "extern": _EXTERN},
    "z-angle": {**{a: _READ for a in ("from", "to", "val", "stdev", "from_dh", "to_dh")}, "extern": _EXTERN},
    "direction": {**{a: _READ for a in ("to", "val", "stdev")}, "extern": _EXTERN,
                  "from_dh": "Gama ignores heights on directions (a horizontal angle): no effect",
                  "to_dh": "Gama ignores heights on directions (a horizontal angle): no effect"},
}


# ============================================================================ write
def gama_local_text(obs: Observations, points: Points, *, offsets=None, fixed=(),
                    description: str = "", scales=None) -> str:
    """The gama-local XML of the network (see the module docstring). ``offsets``: fixed values
    (a number, or a mapping by head or station, m) subtracted from the distances; ``scales``: fixed
    head scales divided out; ``fixed``: point ids held fixed (``fix="XYZ"``), the others are
    constrained datum points of a free network. The heads, offsets and scales are recorded in
    ``<description>`` (:func:`~.common.model_lines`)."""
    check_ids(obs, points, "gama")
    refuse_weighted_points(points, "gama")
    corrected, notes = apply_offsets(obs, offsets, "GNU Gama", scales)
    ids = list(obs.station_ids) + list(obs.target_ids)
    missing = [i for i in ids if points.get(i) is None]
    if missing:
        raise MultilatError(f"gama: point {missing[0]!r} has no approximate coordinates; gama-local "
                            "needs x, y, z for every point (give --points covering every point)")
    for f in fixed:
        if f not in ids:
            raise MultilatError(f"gama: fixed point {f!r} is in no observation")
    desc = "\n".join([description or "multilat network", *model_lines(obs, offsets, scales, "gama"), *notes])
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           f'<gama-local xmlns="{NAMESPACE}">',
           '<network axes-xy="en" angles="right-handed">',
           f"<description>\n{xml_escape(desc)}\n</description>",
           '<parameters sigma-apr="1" conf-pr="0.95" tol-abs="1000" sigma-act="apriori" '
           'algorithm="svd" cov-band="-1" />',
           "<points-observations>"]
    fixed = set(fixed)
    for i in ids:
        x, y, z = points.get(i)
        flag = 'fix="XYZ"' if i in fixed else 'adj="XYZ"'
        out.append(f'<point id="{xml_escape(i)}" x="{fmt_m(x)}" y="{fmt_m(y)}" z="{fmt_m(z)}" {flag} />')
    d, sig = corrected.distance_m, corrected.sigma_m
    sa, se = angle_sigmas(obs, "gama", "gama-local")
    for si, sid in enumerate(obs.station_ids):
        ks = np.flatnonzero(obs.station_index == si)
        out.append(f'<obs from="{xml_escape(sid)}">')
        for k in ks:
            tid = obs.target_ids[obs.target_index[k]]
            out.append(f'  <s-distance to="{xml_escape(tid)}" val="{fmt_m(d[k])}" '
                       f'stdev="{fmt_m(sig[k] * 1e3, 7)}" />')
        for k in ks:
            tid = xml_escape(obs.target_ids[obs.target_index[k]])
            if np.isfinite(sa[k]):
                out.append(f'  <direction to="{tid}" val="{_gon(obs.azimuth_rad[k] % (2 * math.pi))}" '
                           f'stdev="{_cc(sa[k])}" />')
            if np.isfinite(se[k]):
                out.append(f'  <z-angle to="{tid}" val="{_gon(math.pi / 2 - obs.elevation_rad[k])}" '
                           f'stdev="{_cc(se[k])}" />')
        out.append("</obs>")
    out += ["</points-observations>", "</network>", "</gama-local>", ""]
    return "\n".join(out)


#: gons per radian; 1 gon = 10 000 cc (centesimal seconds), the units of gama-local's angles
GON_PER_RAD = 200.0 / math.pi


def _gon(a_rad: float) -> str:
    return f"{float(a_rad) * GON_PER_RAD:.12f}"          # 1e-12 gon = 1.6e-14 rad


def _cc(s_rad: float) -> str:
    return f"{float(s_rad) * GON_PER_RAD * 1e4:.9f}"      # 1e-9 cc = 1.6e-15 rad


def write_gama_local(path, obs: Observations, points: Points, **kw) -> None:
    """Write :func:`gama_local_text` to ``path`` atomically."""
    write_text_atomic(path, gama_local_text(obs, points, **kw))


# ============================================================================ read input
def _axes(path, node, code: str | None):
    code = (code or "ne").strip()
    if len(code) != 2 or code[0] not in _AXES or code[1] not in _AXES:
        raise MultilatError(f"{path}:{node.line}: axes-xy={code!r} is not one of Gama's codes")
    ex, ey = np.array(_AXES[code[0]]), np.array(_AXES[code[1]])
    return ex, ey


def _to_enu(xyz, ex, ey):
    x, y, z = xyz
    e, n = x * ex + y * ey
    return (float(e), float(n), float(z))


def _stdev_model(path, node):
    """``distance-stdev="a [b [c]]"``: σ = a + b·D^c mm with D in km (None when absent)."""
    text = node.attrib.get("distance-stdev")
    if text is None:
        return None
    try:
        vals = [float(v) for v in text.split()]
    except ValueError:
        vals = []
    if not 1 <= len(vals) <= 3 or not all(math.isfinite(v) for v in vals):
        raise MultilatError(f"{path}:{node.line}: distance-stdev={text!r} must be 'a [b [c]]'")
    a, b, c = (vals + [0.0, 1.0][len(vals) - 1:])[:3]
    return lambda d_m: (a + b * (d_m / 1000.0) ** c) * 1e-3


def read_gama_local(path) -> Network:
    """Read a gama-local XML input: points, slope distances (metres; stdev mm -> m), directions and
    zenith angles (gons or ``d-m-s``; stdev cc, or arc seconds with ``d-m-s`` values).

    Directions become azimuths (counter-clockwise: ``angles="right-handed"`` as they stand,
    ``left-handed`` — clockwise seen from above, Gama's default — negated; the sense is physical,
    whatever ``axes-xy`` says), zenith angles elevations ``pi/2 - z``; a station with either is
    levelled (Gama's instruments are: one orientation per station, the vertical known). Each angle
    joins the slope distance of the same station and target (multilat's observation row).

    Every element and attribute of gama-local's input format is read or refused (:data:`ATTRIBUTES`).
    Refused with the element named: any other observation type (horizontal distances, angles,
    azimuths, height differences, observed coordinates and vectors, covariance matrices), non-zero
    instrument/target heights on a distance or zenith angle (its own ``from_dh``/``to_dh`` or its set's
    ``<obs from_dh>``; on a direction they are read and ignored, as gama-local ignores them), 2D or
    height-only points (``fix``/``adj``), an attribute or element the format does not have there, a
    station's directions in two ``<obs>`` sets (two orientation unknowns), an angle without a slope
    distance beside it. An observation to a point without a ``<point>`` element is an error
    ``FILE:LINE``."""
    root = parse_xml(path)
    if root.tag != "gama-local":
        raise MultilatError(f"{path}:{root.line}: expected a <gama-local> document, found <{root.tag}>"
                            + (" (the adjusted output: import it with --adjusted)"
                               if root.tag == "gama-local-adjustment" else ""))
    net = _network(path, root)
    ex, ey = _axes(path, net, net.attrib.get("axes-xy"))
    sense = net.attrib.get("angles", "left-handed").strip()
    if sense not in ("left-handed", "right-handed"):
        raise MultilatError(f"{path}:{net.line}: angles={sense!r} must be left-handed or right-handed")
    declared, coords, fixed, rows, notes = {}, {}, [], [], []
    arows, dir_sets, dir_heights = [], {}, 0
    tags = ModelTags()
    desc_el = net.find("description")
    for k, line in enumerate([] if desc_el is None else desc_el.text.split("\n")):
        tags.read(f"{path}:{desc_el.line + k}", line.strip())
    for po in net.findall("points-observations"):
        model = _stdev_model(path, po)
        angle_sd = {"direction": xml_float(path, po, "direction-stdev", positive=True, required=False),
                    "z-angle": xml_float(path, po, "zenith-angle-stdev", positive=True, required=False)}
        for el in po.children:
            if el.tag not in ("point", "obs"):
                _refuse(path, el)
            _check_attributes(path, el)
            if el.tag == "point":
                _read_point(path, el, declared, coords, fixed, ex, ey)
                continue
            xml_float(path, el, "orientation", required=False)
            for o in el.children:
                if o.tag not in ("s-distance", "direction", "z-angle"):
                    _refuse(path, o)
                _check_attributes(path, o)
                if o.tag == "s-distance":
                    rows.append(_read_sdist(path, o, el, model))
                else:
                    arows.append(_read_angle(path, o, el, angle_sd[o.tag], sense, dir_sets))
                    dir_heights += o.tag == "direction" and _direction_heights(path, o, el)
    if dir_heights:
        notes.append(f"instrument/target heights on {dir_heights} direction(s) ignored, as gama-local ignores "
                     "them on directions")
    rows, heads = restore_model(path, rows, tags, notes)
    network = build_network(path, rows, declared, coords, fixed, notes, "Gama", heads)
    network = join_angles(path, network, arows) if arows else network
    return replace(network, restored=any(v is not None for v in (tags.offsets, tags.heads, tags.scales)))


def _network(path, root):
    """The one ``<network>`` of the document, its children and their attributes checked: an element
    or attribute that gama-local's input format does not have there is refused by name."""
    _check_attributes(path, root)
    nets = root.findall("network")
    for el in root.children:
        if el.tag != "network":
            raise MultilatError(f"{path}:{el.line}: unknown element <{el.tag}> in <gama-local> (gama-local's "
                                "input holds one <network>)")
    if not nets:
        raise MultilatError(f"{path}:{root.line}: <gama-local> has no <network>")
    if len(nets) > 1:
        raise MultilatError(f"{path}:{nets[1].line}: a second <network> in <gama-local>")
    _check_attributes(path, nets[0])
    for el in nets[0].children:
        if el.tag not in ("description", "parameters", "points-observations"):
            raise MultilatError(f"{path}:{el.line}: unknown element <{el.tag}> in <network> (gama-local's "
                                "input has <description>, <parameters> and <points-observations> there)")
        _check_attributes(path, el)
    return nets[0]


def _direction_heights(path, o, obs_el) -> bool:
    """Whether a direction carries a non-zero height (its own, or its set's ``from_dh``)."""
    return any(xml_float(path, n, h, required=False) for n, h in ((o, "from_dh"), (o, "to_dh"), (obs_el, "from_dh")))


def _dms_or_gon(path, o, name):
    """An angle attribute in radians and whether it was written in degrees (``d-m-s``)."""
    text = (o.attrib.get(name) or "").strip()
    body = text.lstrip("+-")
    if "-" in body:
        parts = body.split("-")
        try:
            d, m, sec = (float(v) for v in parts) if len(parts) == 3 else (math.nan,) * 3
        except ValueError:
            d = m = sec = math.nan
        if not (math.isfinite(d) and 0 <= m < 60 and 0 <= sec < 60):
            raise MultilatError(f"{path}:{o.line}: <{o.tag}> {name}={text!r} is not d-m-s")
        return (-1.0 if text.startswith("-") else 1.0) * math.radians(d + m / 60 + sec / 3600), True
    return xml_float(path, o, name) / GON_PER_RAD, False


def _read_angle(path, o, obs_el, default_sd, sense, dir_sets):
    """One ``<direction>`` or ``<z-angle>``: (line, station, target, kind, value_rad, sigma_rad)."""
    s = (o.attrib.get("from") or obs_el.attrib.get("from") or "").strip()
    t = o.attrib.get("to", "").strip()
    if not s or not t:
        raise MultilatError(f"{path}:{o.line}: <{o.tag}> needs from (or <obs from=>) and to")
    if o.tag == "direction":
        for h in ("from_dh", "to_dh"):          # read (a number) and ignored, as gama-local does
            xml_float(path, o, h, required=False)
    else:
        _refuse_heights(path, o, obs_el, f"{s}->{t}")
    val, dms = _dms_or_gon(path, o, "val")
    sd = xml_float(path, o, "stdev", positive=True, required=False)
    if sd is None:
        sd = default_sd
    if sd is None:
        raise MultilatError(f"{path}:{o.line}: <{o.tag}> {s}->{t} has no stdev and <points-observations> no "
                            f"{'direction' if o.tag == 'direction' else 'zenith-angle'}-stdev")
    sigma = math.radians(sd / 3600) if dms else sd / (GON_PER_RAD * 1e4)
    if o.tag == "direction":
        first = dir_sets.setdefault(s, obs_el.line)
        if first != obs_el.line:
            raise MultilatError(f"{path}:{o.line}: station {s!r} has directions in a second <obs> set (the first "
                                f"at line {first}): two orientation unknowns; multilat has one per station")
        az = val if sense == "right-handed" else -val
        return (o.line, s, t, "azimuth", (az + math.pi) % (2 * math.pi) - math.pi, sigma)
    if not 0.0 <= val <= math.pi:
        raise MultilatError(f"{path}:{o.line}: <z-angle> {s}->{t} val is outside 0..200 gon")
    return (o.line, s, t, "elevation", math.pi / 2 - val, sigma)


def _refuse(path, el):
    what = _UNSUPPORTED.get(el.tag)
    if what is None:
        raise MultilatError(f"{path}:{el.line}: unknown element <{el.tag}> in a gama-local document")
    raise MultilatError(f"{path}:{el.line}: <{el.tag}> ({what}) is not supported: multilat reads slope "
                        "distances (<s-distance>), directions and zenith angles")


def _read_point(path, el, declared, coords, fixed, ex, ey):
    pid = el.attrib.get("id", "").strip()
    if not pid:
        raise MultilatError(f"{path}:{el.line}: <point> without id")
    if pid in declared:
        raise MultilatError(f"{path}:{el.line}: point {pid!r} declared twice (first at line "
                            f"{declared[pid]})")
    declared[pid] = el.line
    xyz = [xml_float(path, el, c, required=False) for c in ("x", "y", "z")]
    if all(v is not None for v in xyz):
        coords[pid] = _to_enu(xyz, ex, ey)
    elif any(v is not None for v in xyz):
        raise MultilatError(f"{path}:{el.line}: point {pid!r} has some of x, y, z but not all (a 2D "
                            "or height-only point): multilat's network is 3D")
    adj = el.attrib.get("adj", "")
    if adj and adj.lower() != "xyz":
        raise MultilatError(f"{path}:{el.line}: point {pid!r} adj={adj!r} (a 2D or height-only unknown) is not "
                            "supported: multilat's points are 3D (adj=\"xyz\" or \"XYZ\")")
    flag = el.attrib.get("fix", "")
    if flag and pid not in coords:
        raise MultilatError(f"{path}:{el.line}: fixed point {pid!r} needs x, y and z")
    if flag:
        if flag.lower() != "xyz":
            raise MultilatError(f"{path}:{el.line}: fix={flag!r} (a 2D or height-only fix) is not "
                                "supported: multilat fixes x, y and z together")
        fixed.append(pid)


def _refuse_heights(path, o, obs_el, label):
    """Refuse a non-zero instrument or target height of a distance or zenith angle: its own
    ``from_dh``/``to_dh``, or the set-wide ``<obs from_dh>`` that gama-local applies to it when
    it has none of its own (Gama 2.24 ``gkfparser.cpp``: ``obs_from_dh`` is each observation's
    default instrument height)."""
    for h in ("from_dh", "to_dh"):
        v = xml_float(path, o, h, required=False)
        if v:
            raise MultilatError(f"{path}:{o.line}: <{o.tag}> {label} {h}={v} is not supported "
                                "(instrument and target heights are not in multilat's model)")
    if o.attrib.get("from_dh") is None:
        v = xml_float(path, obs_el, "from_dh", required=False)
        if v:
            raise MultilatError(f"{path}:{obs_el.line}: <obs> from_dh={v} (the set's instrument height) applies "
                                f"to <{o.tag}> {label} at line {o.line}: not supported (instrument and target "
                                "heights are not in multilat's model)")


def _check_attributes(path, el):
    """Refuse an attribute that gama-local's input format does not have on this element
    (:data:`ATTRIBUTES`)."""
    known = ATTRIBUTES.get(el.tag, {})
    for name in el.attrib:
        if name not in known:
            raise MultilatError(f"{path}:{el.line}: <{el.tag}> attribute {name}= is not in gama-local's input "
                                "format (xml/gama-local.xsd): not read")


def _read_sdist(path, o, obs_el, model):
    s = (o.attrib.get("from") or obs_el.attrib.get("from") or "").strip()
    t = o.attrib.get("to", "").strip()
    if not s or not t:
        raise MultilatError(f"{path}:{o.line}: <s-distance> needs from (or <obs from=>) and to")
    d = xml_float(path, o, "val", positive=True)
    _refuse_heights(path, o, obs_el, f"{s}->{t}")
    sd = xml_float(path, o, "stdev", positive=True, required=False)
    if sd is None:
        if model is None:
            raise MultilatError(f"{path}:{o.line}: <s-distance> {s}->{t} has no stdev and "
                                "<points-observations> no distance-stdev")
        sig = model(d)
    else:
        sig = sd * 1e-3
    return (o.line, s, t, d, sig)
