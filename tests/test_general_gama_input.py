"""read_gama_input: what it applies (σ defaults, axes, angle sense, heights) and what it refuses,
each refusal one line naming FILE:LINE."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from multilat.errors import MultilatError
from multilat.network.adjust.general.adjust import adjust
from multilat.network.adjust.approximate.general import approximate
from multilat.network.io.interop.gama_input import CC_PER_RAD, read_gama_input

DATA = Path(__file__).resolve().parent / "data" / "gama3d"
HEAD = ('<?xml version="1.0" ?>\n<gama-local xmlns="http://www.gnu.org/software/gama/gama-local">\n'
        '<network axes-xy="ne" angles="left-handed">\n')


def _write(tmp_path, body, po=""):
    p = tmp_path / "net.xml"
    p.write_text(HEAD + f"<points-observations{po}>\n" + body + "\n</points-observations>\n</network>\n</gama-local>\n")
    return p


POINTS = ('<point id="A" x="0" y="0" z="10" fix="xyz" />\n<point id="B" x="100" y="10" z="11" fix="xyz" />\n'
          '<point id="C" x="50" y="80" z="9" adj="xyz" />\n')


@pytest.mark.parametrize("body, line, match", [
    ('<obs from="A"><azimuth to="B" val="1" /></obs>', 8, r"<azimuth> is not read \(azimuths"),
    ('<obs from="A"><s-distance to="Z" val="10" stdev="1" /></obs>', 8, r"point 'Z' is observed but has no <point>"),
    ('<point id="D" x="1" y="2" z="3" adj="XYz" />', 8, r"adj='XYz': mixed case"),
    ('<point id="D" x="1" y="2" z="3" fix="xy" />', 8, r"its z is neither fixed"),
    ('<obs from="A"><s-distance to="B" val="10" /></obs>', 8, r"no stdev and <points-observations> no distance-stdev"),
    ('<obs from="A"><direction to="B" val="10" /></obs>', 8, r"no stdev and <points-observations> no direction-stdev"),
    ('<vectors><vec from="A" to="C" dx="1" dy="2" dz="3" to_dh="1.5" />\n<cov-mat dim="3" band="0">1 1 1</cov-mat>'
     '</vectors>', 8, r"<vec> to_dh= is not applied"),
    ('<vectors><vec from="A" to="C" dx="1" dy="2" dz="3" />\n<cov-mat dim="4" band="0">1 1 1 1</cov-mat></vectors>',
     9, r"<cov-mat> dim=4, but the block has 3"),
    ('<vectors><vec from="A" to="C" dx="1" dy="2" dz="3" />\n<cov-mat dim="3" band="2">1 0 0 1 0</cov-mat></vectors>',
     9, r"holds 5 values, expected 6"),
    ('<height-differences><dh from="A" to="C" val="1" /></height-differences>', 8, r"no stdev, no dist"),
    ('<obs from="A"><s-distance to="B" val="10" stdev="1" bogus="1" /></obs>', 8, r"attribute bogus= is not in"),
    ('<obs from="A"><dh to="B" val="1" stdev="1" /></obs>', 8, r"<dh> inside <obs> is not read"),
    ('<dh from="A" to="B" val="1" stdev="1" />', 8, r"<dh> is not read in <points-observations>"),
    ('<obs from="A"><s-distance to="B" val="10" stdev="1" /><cov-mat dim="1" band="0">1</cov-mat></obs>', 8,
     r"<cov-mat> inside <obs>"),
])
def test_refused_by_file_and_line(tmp_path, body, line, match):
    p = _write(tmp_path, POINTS + body)
    with pytest.raises(MultilatError, match=re.escape(f"{p}:{line}:") + ".*" + match) as err:
        read_gama_input(p)
    assert "\n" not in str(err.value)


def test_sigma_defaults_and_units(tmp_path):
    """distance-stdev="a b c" is a + b D^c mm (D km), direction and zenith defaults in cc."""
    body = ('<obs from="A"><s-distance to="B" val="2000" /><direction to="B" val="10" />'
            '<z-angle to="B" val="100" /><direction to="C" val="100" stdev="3" /></obs>')
    net = read_gama_input(_write(tmp_path, POINTS + body, ' distance-stdev="1 2 1.5" direction-stdev="5"'
                                 ' zenith-angle-stdev="7"'))
    b = {x.kind: x for x in net.blocks}
    assert b["slope_distance"].sigma[0] == pytest.approx((1 + 2 * 2 ** 1.5) * 1e-3)
    assert b["direction"].sigma * CC_PER_RAD == pytest.approx([5, 3])
    assert b["zenith_angle"].sigma[0] * CC_PER_RAD == pytest.approx(7)
    # left-handed: clockwise readings negated into multilat's counter-clockwise directions
    assert b["direction"].value == pytest.approx([-10 / 200 * np.pi, -100 / 200 * np.pi])


def test_axes_do_not_change_the_network(tmp_path):
    """The traverse written with x east, y north (axes-xy="en") instead of x north, y east: the same
    adjusted coordinates in multilat's frame (the angle sense is physical, left-handed in both)."""
    text = (DATA / "traverse.xml").read_text()
    swapped = re.sub(r'x="([-\d.]+)" y="([-\d.]+)"', r'x="\2" y="\1"', text).replace('axes-xy="ne"', 'axes-xy="en"')
    p = tmp_path / "traverse_en.xml"
    p.write_text(swapped)
    a = adjust(approximate(read_gama_input(DATA / "traverse.xml")))
    b = adjust(approximate(read_gama_input(p)))
    assert np.abs(a.xyz_m - b.xyz_m).max() < 1e-9
    assert a.sigma0 == pytest.approx(b.sigma0, rel=1e-12)


def test_point_without_approximate_coordinates_is_named(tmp_path):
    body = ('<point id="D" adj="xyz" />\n<obs from="A"><s-distance to="C" val="50" stdev="1" /></obs>'
            '<height-differences><dh from="C" to="D" val="1" stdev="1" /></height-differences>')
    net = read_gama_input(_write(tmp_path, POINTS.replace('x="50" y="80" z="9" ', '') + body))
    with pytest.raises(MultilatError, match=r"point 'C' \(and 1 more\): no approximate coordinates"):
        approximate(net)


def test_fix_takes_precedence_over_adj(tmp_path):
    """gama-local's manual: a coordinate in both fix and adj is fixed; a note says so."""
    net = read_gama_input(_write(tmp_path, POINTS + '<point id="D" x="1" y="2" z="3" fix="z" adj="xyz" />'))
    d = net.points.ids.index("D")
    assert list(net.points.status[d]) == [0, 0, 1]
    assert any("point 'D': z both fixed and adjusted: fixed" in n for n in net.notes)


def test_levelling_sigma_from_the_section_length(tmp_path):
    """<dh dist> without stdev: σ = m0 sqrt(D_km) with m0 = sigma-apr in mm (gama-local's manual);
    a stdev wins over dist."""
    body = ('<height-differences><dh from="A" to="C" val="1" dist="0.25" />'
            '<dh from="C" to="B" val="1" dist="0.25" stdev="0.7" /></height-differences>')
    p = _write(tmp_path, POINTS + body)
    p.write_text(p.read_text().replace("<points-observations>", '<parameters sigma-apr="2" />\n<points-observations>'))
    b = read_gama_input(p).blocks[0]
    assert b.sigma == pytest.approx([2 * 0.5e-3, 0.7e-3])
