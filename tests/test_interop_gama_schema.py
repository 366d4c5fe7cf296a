"""gama-local's input format, from its own schema (issue 25 items 3 and 7).

tests/data/interop/gama-local-xsd-2.24.json lists every element of ``xml/gama-local.xsd`` of GNU Gama
2.24 with its attributes (type, enumeration, default, required) and the elements it may contain
(names derived from the XSD; source and version in the file).

- The export is valid against those lists (elements, attributes, enumerations, numbers, required
  attributes, children): ``update-constrained-coordinates``, removed from the format in Gama 2.10,
  is no longer written (gama-local 2.24 refuses the file with it:
  tests/data/interop/small_volume_old_export_gama224_error.xml).
- ``read_gama_local`` applies or refuses every element and attribute: each attribute of the XSD set
  to another valid value in a small document either changes the network read, or is refused in one
  line naming ``FILE:LINE`` and the attribute or its element, or is listed in ``gama.ATTRIBUTES`` with
  the reason it has no effect, and then the network read is the same. Every element the reader does
  not read is refused with its name.
"""

import json
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.io.files import read_observations, read_points
from multilat.network.io.interop.gama import ATTRIBUTES, NAMESPACE, _UNSUPPORTED, gama_local_text, read_gama_local
from multilat.network.io.interop.gama_adjusted import read_gama_adjustment

DATA = Path(__file__).resolve().parent / "data" / "interop"
XSD = json.loads((DATA / "gama-local-xsd-2.24.json").read_text())["elements"]
EX = Path(__file__).resolve().parents[1] / "examples" / "network"
NS = "{" + NAMESPACE + "}"


def xsd_violations(text: str) -> list:
    """Where ``text`` departs from the schema's lists (empty: valid as far as they say)."""
    bad = []

    def walk(el):
        tag = el.tag.removeprefix(NS)
        spec = XSD.get(tag)
        if spec is None:
            return bad.append(f"element <{tag}>")
        for a, v in el.attrib.items():
            at = spec["attributes"].get(a)
            if at is None:
                bad.append(f"<{tag}> {a}=")
            elif "enum" in at and v not in at["enum"]:
                bad.append(f"<{tag}> {a}={v!r} not in {at['enum']}")
            elif at["type"] == "xs:double" and not re.fullmatch(r"[-+]?[0-9]*\.?[0-9]+([eE][-+]?[0-9]+)?", v):
                bad.append(f"<{tag}> {a}={v!r} not a double")
            elif at["type"] == "xs:integer" and not re.fullmatch(r"[-+]?[0-9]+", v):
                bad.append(f"<{tag}> {a}={v!r} not an integer")
        bad.extend(f"<{tag}> needs {a}=" for a, at in spec["attributes"].items() if at.get("required")
                   and a not in el.attrib)
        for c in el:
            if c.tag.removeprefix(NS) not in spec["children"]:
                bad.append(f"<{c.tag.removeprefix(NS)}> inside <{tag}>")
            walk(c)

    root = ET.fromstring(text)
    if root.tag != NS + "gama-local":
        bad.append(f"root {root.tag}")
    walk(root)
    return bad


def test_export_of_the_small_volume_example_is_valid_for_gama_local_2_24():
    obs, pts = read_observations(EX / "small_volume_obs.csv"), read_points(EX / "small_volume_points.csv")
    res = adjust(obs, points=pts)
    text = gama_local_text(obs, pts, offsets=dict(zip(res.station_ids, res.offset_m)), fixed=("B",))
    assert xsd_violations(text) == []
    assert "update-constrained-coordinates" not in text


def test_export_with_angles_is_valid_for_gama_local_2_24():
    from test_interop_gama_axes import small_levelled

    obs, pts, zero, _ = small_levelled()
    text = gama_local_text(obs, pts, offsets=zero)
    assert "<direction" in text and "<z-angle" in text
    assert xsd_violations(text) == []


def test_the_checker_sees_the_removed_parameter():
    """The check above can fail: the 1.18b-era parameter is outside the 2.24 lists, and gama-local
    2.24 refused our old export with it (its stored error output, read as an error)."""
    obs, pts, zero = _tiny()
    old = gama_local_text(obs, pts, offsets=zero).replace('sigma-act="apriori"', 'sigma-act="apriori" '
                                            'update-constrained-coordinates="yes"')
    assert xsd_violations(old) == ["<parameters> update-constrained-coordinates="]
    with pytest.raises(MultilatError, match=r"gama-local reported an error: .*unknown parameter: "
                       r"update-constrained-coordinates"):
        read_gama_adjustment(DATA / "small_volume_old_export_gama224_error.xml")


def _tiny():
    from multilat.network.model.data import Observations, Points

    obs = Observations.from_labels(["S1", "S1"], ["T1", "T2"], np.array([1.0, 1.2]), np.array([5e-6, 5e-6]))
    pts = Points(("S1", "T1", "T2"), np.array([[0.0, 0, 0], [1, 0, 0], [0, 1.2, 0]]))
    return obs, pts, {"S1": 0.0}


# ------------------------------------------------------------------------------ the reader
#: a document with every element the reader reads, each attribute where the schema puts it; the
#: second distance and angles take their σ from the set's defaults
BASE = f"""<?xml version="1.0" encoding="UTF-8"?>
<gama-local xmlns="{NAMESPACE}">
<network axes-xy="en" angles="right-handed" epoch="0.0">
<description>a test network</description>
<parameters sigma-apr="1" conf-pr="0.95" tol-abs="1000" sigma-act="apriori" algorithm="svd" language="en"
 encoding="utf-8" angular="400" angles="400" latitude="50" ellipsoid="grs80" cov-band="-1" />
<points-observations distance-stdev="5" direction-stdev="10" zenith-angle-stdev="10" angle-stdev="10"
 azimuth-stdev="10">
<point id="S1" x="0.1" y="0.2" z="0.3" adj="xyz" />
<point id="T1" x="1.1" y="0.2" z="0.3" fix="XYZ" />
<point id="T2" x="0.1" y="1.7" z="0.3" adj="XYZ" />
<obs from="S1" orientation="10">
  <s-distance from="S1" to="T1" val="1.00001" stdev="0.005" from_dh="0" to_dh="0" extern="e1" />
  <s-distance to="T2" val="1.49999" />
  <direction to="T1" val="0.0001" stdev="12" from_dh="0" to_dh="0" extern="e2" />
  <direction to="T2" val="100.0002" />
  <z-angle from="S1" to="T1" val="100.0003" stdev="12" from_dh="0" to_dh="0" extern="e3" />
  <z-angle to="T2" val="99.9996" />
</obs>
</points-observations>
</network>
</gama-local>
"""


def _read(tmp_path, text):
    p = tmp_path / "in.xml"
    p.write_text(text)
    return read_gama_local(p)


def _content(net):
    o = net.obs
    return (o.station_ids, o.target_ids, o.station_index.tolist(), o.target_index.tolist(), o.distance_m.tolist(),
            o.sigma_m.tolist(), np.nan_to_num(o.azimuth_rad, nan=9).tolist(), np.nan_to_num(o.elevation_rad, nan=9)
            .tolist(), np.nan_to_num(o.sigma_azimuth_rad, nan=9).tolist(),
            np.nan_to_num(o.sigma_elevation_rad, nan=9).tolist(), tuple(o.levelled), net.points.ids,
            net.points.xyz_m.tolist(), net.fixed)


def _sample(el, name, spec):
    """A valid value of the attribute other than the one ``el`` has (or its default)."""
    now = el.get(name, spec.get("default"))
    if "enum" in spec:
        return next(v for v in spec["enum"] if v != now)
    if spec["type"] in ("xs:double", "xs:NMTOKEN", "xs:NMTOKENS"):
        return repr(float(now) + 1.5) if now not in (None, "") else "1.5"
    if spec["type"] in ("xs:integer", "xs:nonNegativeInteger"):
        return str(int(now or 0) + 2)
    return (now or "x") + "X"


def _cases():
    ET.register_namespace("", NAMESPACE)
    root = ET.fromstring(BASE)
    tags = {el.tag.removeprefix(NS) for el in root.iter()}
    out = []
    for tag, spec in sorted(XSD.items()):
        if tag in _UNSUPPORTED:
            continue
        assert tag in tags, f"the base document lacks <{tag}>"
        for name, at in sorted(spec["attributes"].items()):
            out.append((tag, name, at))
    return out


@pytest.mark.parametrize("tag, name, spec", _cases(), ids=lambda v: v if isinstance(v, str) else "")
def test_every_attribute_of_the_schema_is_applied_or_refused(tmp_path, tag, name, spec):
    ET.register_namespace("", NAMESPACE)
    root = ET.fromstring(BASE)
    el = next(e for e in root.iter() if e.tag == NS + tag)
    now, value = el.get(name), _sample(el, name, spec)
    el.set(name, value)
    text = ET.tostring(root, encoding="unicode")
    base = _content(_read(tmp_path, BASE))
    try:
        got = _content(_read(tmp_path, text))
    except MultilatError as exc:
        msg = str(exc)
        assert re.match(r".*in\.xml:\d+: ", msg) and "\n" not in msg, msg
        # named: the element, the attribute, or the value (new, or the one it replaced: a renamed id)
        assert f"<{tag}>" in msg or f"{name}=" in msg or value in msg or (now and repr(now) in msg), msg
        return
    if got == base:
        reason = ATTRIBUTES[tag].get(name)
        assert reason and reason != "read", f"<{tag}> {name}={value!r} changed nothing and is not listed as without effect"
    else:
        assert ATTRIBUTES[tag].get(name) == "read", (tag, name)


def test_the_reader_lists_exactly_the_schema_attributes():
    for tag, spec in XSD.items():
        if tag in _UNSUPPORTED:
            continue
        extra = set(ATTRIBUTES[tag]) - set(spec["attributes"]) - {"update-constrained-coordinates"}
        assert set(spec["attributes"]) <= set(ATTRIBUTES[tag]) and not extra, tag
    assert set(XSD) == set(ATTRIBUTES) | set(_UNSUPPORTED)


def _parents(tag):
    return [p for p, spec in XSD.items() if tag in spec["children"]]


@pytest.mark.parametrize("tag", sorted(_UNSUPPORTED))
def test_every_element_the_reader_does_not_read_is_refused_by_name(tmp_path, tag):
    assert tag in XSD
    chain = [tag]
    while not any(p in ("obs", "points-observations") for p in _parents(chain[-1])):
        chain.append(_parents(chain[-1])[0])
    parent = "obs" if "obs" in _parents(chain[-1]) else "points-observations"
    inner = ""
    for t in chain:
        attrs = " ".join(f'{a}="{_sample(ET.Element("x"), a, s)}"' for a, s in XSD[t]["attributes"].items()
                         if s.get("required"))
        inner = f"<{t} {attrs}>{inner}</{t}>"
    marker = "</obs>" if parent == "obs" else "</points-observations>"
    text = BASE.replace(marker, inner + "\n" + marker)
    with pytest.raises(MultilatError, match=rf"in\.xml:\d+: .*<{re.escape(chain[-1])}>"):
        _read(tmp_path, text)


@pytest.mark.parametrize("where, attr", [("<network ", 'foo="1" '), ("<s-distance to=\"T2\"", ' bar="2"'),
                                         ("<parameters ", 'update="yes" ')])
def test_an_attribute_outside_the_format_is_refused_by_name(tmp_path, where, attr):
    text = BASE.replace(where, where + attr, 1)
    name = attr.strip().split("=")[0]
    with pytest.raises(MultilatError, match=rf"in\.xml:\d+: <[a-z-]+> attribute {name}= is not in gama-local's"):
        _read(tmp_path, text)


def test_an_element_outside_the_format_is_refused_by_name(tmp_path):
    with pytest.raises(MultilatError, match=r"in\.xml:\d+: unknown element <stations> in <network>"):
        _read(tmp_path, BASE.replace("<description>", "<stations/>\n<description>"))


# ------------------------------------------------------------------------------ heights
def test_set_wide_instrument_height_on_distances_is_refused_naming_the_obs_line(tmp_path):
    text = BASE.replace('<obs from="S1" orientation="10">', '<obs from="S1" from_dh="1.500">')
    line = text.splitlines().index('<obs from="S1" from_dh="1.500">') + 1
    with pytest.raises(MultilatError, match=rf"in\.xml:{line}: <obs> from_dh=1\.5 \(the set's instrument height\) "
                       r"applies to <s-distance> S1->T2"):
        _read(tmp_path, text)


def test_an_observation_height_of_its_own_overrides_the_set_height(tmp_path):
    """Gama's rule: an observation's own from_dh replaces the set's; zero on every distance and
    zenith angle leaves only the directions, where heights have no effect."""
    text = BASE.replace('<obs from="S1" orientation="10">', '<obs from="S1" from_dh="1.500">')
    for t in ('<s-distance to="T2"', '<z-angle to="T2"'):
        text = text.replace(t, t + ' from_dh="0"')
    text = text.replace('from_dh="0" to_dh="0" extern="e2"', 'from_dh="0.3" to_dh="0.2" extern="e2"')
    net = _read(tmp_path, text)
    assert _content(net) == _content(_read(tmp_path, BASE))
    assert any("heights on 2 direction(s) ignored" in n for n in net.notes)


@pytest.mark.parametrize("old, new, message", [
    ('<z-angle from="S1" to="T1" val="100.0003" stdev="12" from_dh="0"', '<z-angle from="S1" to="T1" val="100.0003" '
     'stdev="12" from_dh="0.25"', r"<z-angle> S1->T1 from_dh=0\.25 is not supported"),
    ('<s-distance from="S1" to="T1" val="1.00001" stdev="0.005" from_dh="0" to_dh="0"',
     '<s-distance from="S1" to="T1" val="1.00001" stdev="0.005" from_dh="0" to_dh="0.1"',
     r"<s-distance> S1->T1 to_dh=0\.1 is not supported"),
    ('<point id="S1" x="0.1" y="0.2" z="0.3" adj="xyz"', '<point id="S1" x="0.1" y="0.2" z="0.3" adj="XY"',
     r"point 'S1' adj='XY' \(a 2D or height-only unknown\)"),
])
def test_heights_and_2d_points_are_refused(tmp_path, old, new, message):
    assert old in BASE
    with pytest.raises(MultilatError, match=r"in\.xml:\d+: " + message):
        _read(tmp_path, BASE.replace(old, new))
