"""Read a gama-local XML input (the format of gama-local 2.24, ``docs/interop.md``) into the general
network: points with their per-coordinate status, and blocks of the observation kinds.

Read and applied:

* ``<point id x y z fix adj>``: ``fix`` = ``xyz`` / ``xy`` / ``z`` holds those coordinates, ``adj``
  makes them unknowns, upper case (``XYZ``, ``XY``, ``Z``) marks the point as a datum point of a
  free network (minimum trace); a coordinate in both ``fix`` and ``adj`` is fixed (gama-local's
  manual: "the fix parameter will take precedence"; a note says so); coordinates may be absent
  (computed by :mod:`.approximate`);
* ``<obs from from_dh>`` sets: ``<direction>`` (one orientation unknown per set, several sets per
  point), ``<s-distance>`` and ``<z-angle>`` with ``from_dh``/``to_dh`` (the set's ``from_dh`` is
  each observation's default), ``<distance>`` (horizontal), ``<angle bs fs>``; on the horizontal
  kinds the heights have no effect (a vertical shift), as in gama-local;
* ``<height-differences>`` with ``<dh stdev>``, ``<dh dist>`` (σ = m0 sqrt(D/km), m0 the
  ``<parameters sigma-apr>`` in mm, default 10: the manual's ``m_dh = m_0 sqrt(D_km)``) or a block
  ``<cov-mat>``; ``<vectors>`` of ``<vec dx dy dz>`` with their ``<cov-mat>``; ``<coordinates>``
  (observed coordinates) with their ``<cov-mat>`` (mm², upper band by rows);
* the σ defaults of ``<points-observations>`` (``distance-stdev="a [b [c]]"``: a + b D^c mm, D in
  km; ``direction-stdev``, ``angle-stdev``, ``zenith-angle-stdev`` in cc);
* ``axes-xy`` (coordinates, vectors and their covariances turned to multilat's x east, y north,
  z up) and ``angles`` (``left-handed``: clockwise seen from above, negated to multilat's
  counter-clockwise directions and angles; the sense is physical, whatever ``axes-xy`` says, as
  :func:`multilat.network.io.interop.gama.read_gama_local` reads it); values in gon or ``d-m-s``.

Refused by ``FILE:LINE``: ``<azimuth>``, a ``<cov-mat>`` inside ``<obs>``, non-zero heights on
``<vec>`` (gama-local ignores them: no model to apply), mixed-case ``adj`` (``XYz``), a coordinate
neither fixed nor adjusted, an observation of an undeclared point, any element or attribute the format does not have there.
"""

from __future__ import annotations

import math

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.observations import Block, Network
from multilat.network.model.points import FIXED, FREE, PointSet
from multilat.network.io.interop.common import parse_xml, xml_float
from multilat.network.io.interop.gama import _axes, _dms_or_gon, _network, _stdev_model

__all__ = ["read_gama_input"]

#: attributes of the observation elements this reader applies (others of the format are refused by name)
_ATTRS = {
    "point": {"id", "x", "y", "z", "fix", "adj"},
    "obs": {"from", "from_dh", "orientation"},
    "direction": {"to", "val", "stdev", "from_dh", "to_dh", "extern"},
    "s-distance": {"from", "to", "val", "stdev", "from_dh", "to_dh", "extern"},
    "z-angle": {"from", "to", "val", "stdev", "from_dh", "to_dh", "extern"},
    "distance": {"from", "to", "val", "stdev", "from_dh", "to_dh", "extern"},
    "angle": {"from", "bs", "fs", "val", "stdev", "from_dh", "bs_dh", "fs_dh", "extern"},
    "height-differences": set(), "dh": {"from", "to", "val", "stdev", "dist", "extern"},
    "vectors": set(), "vec": {"from", "to", "dx", "dy", "dz", "from_dh", "to_dh", "extern"},
    "coordinates": {"extern"}, "cov-mat": {"dim", "band"},
}
_OBS_KINDS = {"direction": "direction", "s-distance": "slope_distance", "z-angle": "zenith_angle",
              "distance": "horizontal_distance", "angle": "horizontal_angle"}
CC_PER_RAD = 200.0 / math.pi * 1e4
ARCSEC_PER_RAD = 180.0 / math.pi * 3600.0


def _check(path, el):
    allowed = _ATTRS.get(el.tag)
    if allowed is None:
        what = {"azimuth": "azimuths are not modelled yet"}.get(el.tag, "not an element of gama-local's input here")
        raise MultilatError(f"{path}:{el.line}: <{el.tag}> is not read ({what})")
    for name in el.attrib:
        if name not in allowed:
            raise MultilatError(f"{path}:{el.line}: <{el.tag}> attribute {name}= is not in gama-local's input "
                                "format: not read")


class _Reader:
    """State of one file being read: points, observation rows per kind, notes."""

    def __init__(self, path, net):
        self.path = path
        self.ex, self.ey = _axes(path, net, net.attrib.get("axes-xy"))
        self.axes = np.array([[self.ex[0], self.ey[0], 0.0], [self.ex[1], self.ey[1], 0.0], [0.0, 0.0, 1.0]])
        sense = net.attrib.get("angles", "left-handed").strip()
        if sense not in ("left-handed", "right-handed"):
            raise MultilatError(f"{path}:{net.line}: angles={sense!r} must be left-handed or right-handed")
        self.sign = -1.0 if sense == "left-handed" else 1.0
        par = net.find("parameters")
        # m0 of <dh dist>: sigma-apr (mm), default 10 (xml/gama-local.xsd; the manual's m_dh = m_0 sqrt(D_km))
        self.m0 = (xml_float(path, par, "sigma-apr", positive=True, required=False) if par is not None else None) or 10.0
        self.points: dict = {}            # id -> [line, xyz(3), status(3), constrained]
        self.rows = {k: [] for k in _OBS_KINDS.values()}
        self.rows["height_difference"] = []
        self.extra_blocks: list = []
        self.sets: list = []
        self.refs: list = []              # (line, point id) of every observed point
        self.notes: list = []

    # ------------------------------------------------------------------ points
    def point(self, el):
        p, pid = self.path, el.attrib.get("id", "").strip()
        if not pid:
            raise MultilatError(f"{p}:{el.line}: <point> without id")
        if pid in self.points:
            raise MultilatError(f"{p}:{el.line}: point {pid!r} declared twice (first at line {self.points[pid][0]})")
        raw = [xml_float(p, el, c, required=False) for c in "xyz"]
        if (raw[0] is None) != (raw[1] is None):
            raise MultilatError(f"{p}:{el.line}: point {pid!r} has one of x, y without the other")
        xy = self.axes[:2, :2] @ np.array(raw[:2], float) if raw[0] is not None else np.full(2, np.nan)
        xyz = np.array([xy[0], xy[1], np.nan if raw[2] is None else raw[2]])
        fix, adj = el.attrib.get("fix", "").strip(), el.attrib.get("adj", "").strip()
        for name, v in (("fix", fix), ("adj", adj)):
            if v and v.lower() not in ("xy", "z", "xyz"):
                raise MultilatError(f"{p}:{el.line}: point {pid!r} {name}={v!r} is not xy, z or xyz")
        if adj and adj not in (adj.lower(), adj.upper()):
            raise MultilatError(f"{p}:{el.line}: point {pid!r} adj={adj!r}: mixed case (part of the point a datum "
                                "point) is not supported; use XYZ or xyz")
        status = np.full(3, -1)
        for letters, st in ((fix.lower(), FIXED), (adj.lower(), FREE)):
            for a in ([0, 1] if "xy" in letters else []) + ([2] if "z" in letters else []):
                if status[a] == FIXED:            # the manual: "the fix parameter will take precedence"
                    self.notes.append(f"{p}:{el.line}: point {pid!r}: {'xyz'[a]} both fixed and adjusted: fixed "
                                      "(fix takes precedence, as in gama-local)")
                    continue
                status[a] = st
        if np.any(status == -1):
            a = int(np.flatnonzero(status == -1)[0])
            raise MultilatError(f"{p}:{el.line}: point {pid!r}: its {'xyz'[a]} is neither fixed (fix=) nor "
                                "adjusted (adj=): not read")
        if np.any((status == FIXED) & ~np.isfinite(xyz)):
            raise MultilatError(f"{p}:{el.line}: point {pid!r} is fixed ({fix}) without those coordinates")
        self.points[pid] = [el.line, xyz, status, bool(adj) and adj == adj.upper()]

    # ------------------------------------------------------------------ observation sets
    def obs_set(self, el, defaults):
        p = self.path
        xml_float(p, el, "orientation", required=False)          # a start value only: no effect
        station = el.attrib.get("from", "").strip()
        set_id = None
        for o in el.children:
            _check(p, o)
            if o.tag == "cov-mat":
                raise MultilatError(f"{p}:{o.line}: <cov-mat> inside <obs> (correlated observations of a set) is "
                                    "not read yet")
            kind = _OBS_KINDS.get(o.tag)
            if kind is None:
                raise MultilatError(f"{p}:{o.line}: <{o.tag}> inside <obs> is not read (not an observation of a set)")
            frm = (o.attrib.get("from") or station).strip()
            if not frm:
                raise MultilatError(f"{p}:{o.line}: <{o.tag}> needs from (or <obs from=>)")
            if kind == "direction" and set_id is None:
                set_id = f"{frm}#{sum(s.split('#')[0] == frm for s in self.sets) + 1}"
                self.sets.append(set_id)
            self.rows[kind].append(self._row(o, el, kind, frm, set_id, defaults))

    def _heights(self, o, obs_el):
        fdh = xml_float(self.path, o, "from_dh", required=False)
        if fdh is None:
            fdh = xml_float(self.path, obs_el, "from_dh", required=False)
        return fdh or 0.0, xml_float(self.path, o, "to_dh", required=False) or 0.0

    def _angle(self, o, defaults, key):
        val, dms = _dms_or_gon(self.path, o, "val")
        sd = xml_float(self.path, o, "stdev", positive=True, required=False)
        if sd is None:
            sd = defaults.get(key)
            if sd is None:
                raise MultilatError(f"{self.path}:{o.line}: <{o.tag}> has no stdev and <points-observations> no "
                                    f"{key}=")
        return val, sd / (ARCSEC_PER_RAD if dms else CC_PER_RAD)

    def _row(self, o, obs_el, kind, frm, set_id, defaults):
        p = self.path
        ref = {"from": frm}
        if kind == "horizontal_angle":
            ref.update(bs=o.attrib.get("bs", "").strip(), fs=o.attrib.get("fs", "").strip())
        else:
            ref["to"] = o.attrib.get("to", "").strip()
        for k, pid in ref.items():
            if not pid:
                raise MultilatError(f"{p}:{o.line}: <{o.tag}> needs {k}=")
            self.refs.append((o.line, pid))
        fdh, tdh = self._heights(o, obs_el)
        if kind in ("slope_distance", "horizontal_distance"):
            val = xml_float(p, o, "val", positive=True)
            sd = xml_float(p, o, "stdev", positive=True, required=False)
            if sd is None and defaults["distance"] is None:
                raise MultilatError(f"{p}:{o.line}: <{o.tag}> has no stdev and <points-observations> no distance-stdev")
            sigma = sd * 1e-3 if sd is not None else defaults["distance"](val)
        else:
            key = {"direction": "direction-stdev", "zenith_angle": "zenith-angle-stdev",
                   "horizontal_angle": "angle-stdev"}[kind]
            val, sigma = self._angle(o, defaults, key)
            if kind != "zenith_angle":
                val *= self.sign
        return dict(line=o.line, ref=ref, value=val, sigma=sigma, from_dh=fdh, to_dh=tdh, set=set_id)

    # ------------------------------------------------------------------ clusters
    def cov_mat(self, el, dim_expected, unit=1e-6):
        """The full covariance of a ``<cov-mat dim band>`` (upper band by rows), mm² -> m²."""
        p = self.path
        cm = el.find("cov-mat")
        if cm is None:
            return None
        _check(p, cm)
        dim, band = (int(xml_float(p, cm, a)) for a in ("dim", "band"))
        if dim != dim_expected:
            raise MultilatError(f"{p}:{cm.line}: <cov-mat> dim={dim}, but the block has {dim_expected} observed values")
        try:
            vals = [float(v) for v in cm.text.split()]
        except ValueError:
            raise MultilatError(f"{p}:{cm.line}: <cov-mat> holds a value that is not a number") from None
        need = sum(min(band, dim - 1 - i) + 1 for i in range(dim))
        if len(vals) != need or not all(map(math.isfinite, vals)):
            raise MultilatError(f"{p}:{cm.line}: <cov-mat> holds {len(vals)} values, expected {need} finite "
                                f"(dim {dim}, band {band})")
        c, k = np.zeros((dim, dim)), 0
        for i in range(dim):
            for j in range(i, min(i + band, dim - 1) + 1):
                c[i, j] = c[j, i] = vals[k]
                k += 1
        return c * unit

    def height_differences(self, el):
        p, rows = self.path, []
        for d in el.children:
            _check(p, d)
            if d.tag == "cov-mat":
                continue
            if d.tag != "dh":
                raise MultilatError(f"{p}:{d.line}: <{d.tag}> in <height-differences> is not read")
            ref = {"from": d.attrib.get("from", "").strip(), "to": d.attrib.get("to", "").strip()}
            for k, pid in ref.items():
                if not pid:
                    raise MultilatError(f"{p}:{d.line}: <dh> needs {k}=")
                self.refs.append((d.line, pid))
            sd, dist = (xml_float(p, d, a, positive=True, required=False) for a in ("stdev", "dist"))
            rows.append(dict(line=d.line, ref=ref, value=xml_float(p, d, "val"),
                             sigma=sd * 1e-3 if sd is not None else (self.m0 * math.sqrt(dist) * 1e-3 if dist else None)))
        cov = self.cov_mat(el, len(rows))
        if cov is None:
            for r in rows:
                if r["sigma"] is None:
                    raise MultilatError(f"{p}:{r['line']}: <dh> has no stdev, no dist and its block no <cov-mat>")
            self.rows["height_difference"] += rows
        elif rows:
            if any(r["sigma"] is not None for r in rows):
                raise MultilatError(f"{p}:{el.line}: <height-differences> has a <cov-mat> and a stdev/dist on a <dh>")
            self.extra_blocks.append(("height_difference", rows, cov))

    def vectors(self, el):
        p, rows = self.path, []
        for v in el.children:
            _check(p, v)
            if v.tag == "cov-mat":
                continue
            if v.tag != "vec":
                raise MultilatError(f"{p}:{v.line}: <{v.tag}> in <vectors> is not read")
            for h in ("from_dh", "to_dh"):
                if xml_float(p, v, h, required=False):
                    raise MultilatError(f"{p}:{v.line}: <vec> {h}= is not applied (gama-local ignores heights on "
                                        "vectors, so the file's meaning is unclear): remove it")
            ref = {"from": v.attrib.get("from", "").strip(), "to": v.attrib.get("to", "").strip()}
            for k, pid in ref.items():
                if not pid:
                    raise MultilatError(f"{p}:{v.line}: <vec> needs {k}=")
                self.refs.append((v.line, pid))
            raw = [xml_float(p, v, a) for a in ("dx", "dy", "dz")]
            rows += [dict(line=v.line, ref=ref, axis=a, value=sg * raw[c]) for c, (a, sg) in enumerate(self._turn())]
        cov = self.cov_mat(el, len(rows))
        if rows and cov is None:
            raise MultilatError(f"{p}:{el.line}: <vectors> without <cov-mat>")
        if rows:
            sg = np.tile([sg for _, sg in self._turn()], len(rows) // 3)
            self.extra_blocks.append(("coordinate_difference", rows, cov * np.outer(sg, sg)))

    def _turn(self):
        """Per file component x, y, z: multilat's axis and its sign (the file's order is kept)."""
        return [(int(np.argmax(np.abs(self.axes[:, c]))), float(self.axes[np.argmax(np.abs(self.axes[:, c])), c]))
                for c in range(3)]

    def coordinates(self, el):
        p, rows = self.path, []
        for q in el.children:
            _check(p, q)
            if q.tag == "cov-mat":
                continue
            if q.tag != "point":
                raise MultilatError(f"{p}:{q.line}: <{q.tag}> in <coordinates> is not read")
            pid = q.attrib.get("id", "").strip()
            extra = set(q.attrib) - {"id", "x", "y", "z"}
            if not pid or extra:
                raise MultilatError(f"{p}:{q.line}: observed <point> needs id= and only x, y, z"
                                    + (f" (got {sorted(extra)[0]}=)" if extra else ""))
            self.refs.append((q.line, pid))
            raw = [xml_float(p, q, c, required=False) for c in "xyz"]
            for c in range(3):
                if raw[c] is not None:
                    a, sg = self._turn()[c]
                    rows.append(dict(line=q.line, point=pid, axis=a, value=sg * raw[c], sign=sg))
        cov = self.cov_mat(el, len(rows))
        if rows and cov is None:
            raise MultilatError(f"{p}:{el.line}: <coordinates> without <cov-mat>")
        if rows:
            sg = np.array([r["sign"] for r in rows])
            self.extra_blocks.append(("observed_coordinates", rows, cov * np.outer(sg, sg)))

    # ------------------------------------------------------------------ network
    def network(self) -> Network:
        ids = tuple(self.points)
        for line, pid in self.refs:
            if pid not in self.points:
                raise MultilatError(f"{self.path}:{line}: point {pid!r} is observed but has no <point> element")
        pts = PointSet.build(ids, [self.points[i][1] for i in ids], status=[self.points[i][2] for i in ids],
                             constrained=[self.points[i][3] for i in ids])
        ix = {p: i for i, p in enumerate(ids)}
        blocks = [b for kind, rows in self.rows.items() if rows for b in [self._block(kind, rows, None, ix)]]
        blocks += [self._block(kind, rows, cov, ix) for kind, rows, cov in self.extra_blocks]
        return Network(pts, tuple(blocks), tuple(self.notes))

    def _block(self, kind, rows, cov, ix) -> Block:
        labels = tuple(f"{self.path}:{r['line']}" for r in rows)
        if kind == "observed_coordinates":
            index = {"point": np.array([ix[r["point"]] for r in rows]), "axis": np.array([r["axis"] for r in rows])}
            return Block(kind, np.array([r["value"] for r in rows]), np.sqrt(np.diag(cov)), cov, index, labels=labels)
        index = {k: np.array([ix[r["ref"][k]] for r in rows]) for k in rows[0]["ref"]}
        data, names = {}, {}
        if kind in ("slope_distance", "zenith_angle"):
            data = {k: np.array([r[k] for r in rows]) for k in ("from_dh", "to_dh")}
        if kind == "direction":
            names["set"] = tuple(dict.fromkeys(r["set"] for r in rows))
            index["set"] = np.array([names["set"].index(r["set"]) for r in rows])
        if kind == "coordinate_difference":
            index["axis"] = np.array([r["axis"] for r in rows])
        value = np.array([r["value"] for r in rows], float)
        sigma = np.sqrt(np.diag(cov)) if cov is not None else np.array([r["sigma"] for r in rows])
        return Block(kind, value, sigma, cov, index, data, labels, names)


def read_gama_input(path) -> Network:
    """The points and observations of a gama-local XML input file, in multilat's frame and SI units
    (module docstring for what is read and what is refused)."""
    root = parse_xml(path)
    if root.tag != "gama-local":
        raise MultilatError(f"{path}:{root.line}: expected a <gama-local> document, found <{root.tag}>")
    net = _network(path, root)
    reader = _Reader(path, net)
    for po in net.findall("points-observations"):
        defaults = {"distance": _stdev_model(path, po)}
        for key in ("direction-stdev", "angle-stdev", "zenith-angle-stdev"):
            defaults[key] = xml_float(path, po, key, positive=True, required=False)
        if po.attrib.get("azimuth-stdev") is not None:
            reader.notes.append("azimuth-stdev: the default σ of <azimuth>, which this file has none of to apply")
        for el in po.children:
            _check(path, el)
            handler = {"point": reader.point, "height-differences": reader.height_differences,
                       "vectors": reader.vectors, "coordinates": reader.coordinates}.get(el.tag)
            if el.tag == "obs":
                reader.obs_set(el, defaults)
            elif handler is None:
                raise MultilatError(f"{path}:{el.line}: <{el.tag}> is not read in <points-observations>")
            else:
                handler(el)
    return reader.network()
