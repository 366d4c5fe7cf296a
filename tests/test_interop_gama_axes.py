"""gama-local's axes and angle senses read back (issue 25 item 4), and the current gama-local (2.24).

One small levelled network (4 stations, 8 targets, distances from all, directions and zenith angles from
two levelled stations at 20 µrad) is written by ``gama_local_text`` (``axes-xy="en"``,
``angles="right-handed"``) and turned into the same network in other axes and senses by
:func:`variant` (coordinates projected on Gama's x and y axes, directions negated for
``left-handed``, which is also gama-local's default when ``angles`` is absent). gama-local 2.24 (built
from the GNU Gama sources, tag gama-2.24) adjusted each; its outputs are stored in
tests/data/interop/axes_*_gama224_out.xml, and adjusted again live when ``gama-local`` is on PATH.

When the axes' handedness differs from the angles' (``en`` or ``ws`` with ``left-handed``; ``sw`` with
``right-handed``), gama-local adjusts with y negated and writes ``<cov-mat>`` in those internal axes
(module docstring of ``gama_adjusted``). Read correctly, every variant gives the same covariance in
multilat's axes: the σ of the 28 target-target distances agree with the ``sw`` file's (consistent,
``left-handed``) to 1e-6 relative (Gama prints 8 significant digits of the covariance: 5e-8
relative each; seen 0); before the fix the inconsistent files were up to 34 % off. Directions are read
as azimuths and orientations as headings in one convention: the orientations agree across variants to
3e-8 rad (6 decimals of gon printed, ±7.9e-9 rad, on each side of a wrap), and each residual equals
the ``en``/``right-handed`` file's.
"""

import itertools
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from multilat.network.adjust.distance.adjust import adjust
from multilat.network.model.angles import predicted_angles
from multilat.network.model.data import Observations, Points
from multilat.network.synthetic.generator import synthetic_network
from multilat.network.io.interop.gama import _AXES, gama_local_text
from multilat.network.io.interop.gama_adjusted import read_gama_adjustment

DATA = Path(__file__).resolve().parent / "data" / "interop"
#: (axes-xy, angles or None for Gama's default left-handed): consistent and inconsistent pairs
VARIANTS = [("en", "right-handed"), ("sw", None), ("ws", None), ("en", None), ("ne", None),
            ("sw", "right-handed")]
SIG_ANGLE = 20e-6


def stored(axes, angles):
    return DATA / f"axes_{axes}_{'rh' if angles == 'right-handed' else 'lh'}_gama224_out.xml"


def small_levelled():
    """The network (distances rounded to the file's 1e-8 m) and its points (our adjustment)."""
    net = synthetic_network(np.random.default_rng([25, 4]), n_stations=(4, 4), n_targets=(8, 8), gap_fraction=0.0)
    o = net.obs
    rng = np.random.default_rng(254)
    ori = np.zeros((o.n_stations, 3))
    ori[:, 2] = rng.uniform(-3, 3, o.n_stations)
    az, el = predicted_angles(net.station_xyz_m, ori, net.target_xyz_m, o.station_index, o.target_index)
    tr = np.isin(o.station_index, [0, 1])
    s = np.where(tr, SIG_ANGLE, np.nan)
    az = az + np.where(tr, rng.normal(0, SIG_ANGLE, az.size), 0.0)
    el = el + np.where(tr, rng.normal(0, SIG_ANGLE, el.size), 0.0)
    d = np.linalg.norm(net.station_xyz_m[o.station_index] - net.target_xyz_m[o.target_index], axis=1)
    d = np.round(d + rng.normal(0, 1, o.n_obs) * o.sigma_m, 8)
    lev = (o.station_ids[0], o.station_ids[1])
    obs = Observations(o.station_ids, o.target_ids, o.station_index, o.target_index, d, o.sigma_m, az, el,
                       None, s, s, lev)
    zero = {sid: 0.0 for sid in o.station_ids}
    res = adjust(obs, initial=net, snooping=False, offsets=zero)
    pts = Points(res.station_ids + res.target_ids, np.vstack([res.station_xyz_m, res.target_xyz_m]))
    return obs, pts, zero, res


def variant(text: str, axes: str, angles: str | None) -> str:
    """The export ``text`` (``en``, right-handed) as the same network in ``axes`` and ``angles``."""
    ex, ey = np.array(_AXES[axes[0]]), np.array(_AXES[axes[1]])

    def point(m):
        e, n = float(m.group(1)), float(m.group(2))
        return f'x="{e * ex[0] + n * ex[1]:.8f}" y="{e * ey[0] + n * ey[1]:.8f}"'

    out = re.sub(r'x="([-0-9.]+)" y="([-0-9.]+)"', point, text)
    if angles != "right-handed":
        out = re.sub(r'(<direction [^>]*val=")([0-9.]+)"',
                     lambda m: f'{m.group(1)}{(400 - float(m.group(2))) % 400:.12f}"', out)
    head = f'<network axes-xy="{axes}"' + (f' angles="{angles}"' if angles else "") + ">"
    return out.replace('<network axes-xy="en" angles="right-handed">', head)


@pytest.fixture(scope="module")
def outputs():
    return {v: read_gama_adjustment(stored(*v)) for v in VARIANTS}


def _interpoint_sigmas(g):
    targets = [i for i in g.adjusted_ids if i.startswith("T")]
    return np.array([g.interpoint_distance_std_m(a, b) for a, b in itertools.combinations(targets, 2)])


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


@pytest.mark.parametrize("v", [v for v in VARIANTS if v != ("sw", None)])
def test_covariance_is_read_in_the_axes_gama_writes_it(outputs, v):
    ref = _interpoint_sigmas(outputs[("sw", None)])
    got = _interpoint_sigmas(outputs[v])
    assert len(ref) == 28
    assert np.max(np.abs(got / ref - 1)) < 1e-6, np.max(np.abs(got / ref - 1))
    # the whole covariance of the coordinates in multilat's axes, not only these σ
    a, b = outputs[("sw", None)].covariance_m2, outputs[v].covariance_m2
    assert np.max(np.abs(a - b)) < 1e-6 * np.max(np.abs(np.diag(a)))


@pytest.mark.parametrize("v", VARIANTS)
def test_orientations_and_azimuths_have_one_sign_convention(outputs, v):
    ref, g = outputs[("en", "right-handed")], outputs[v]
    assert set(g.orientation_rad) == set(ref.orientation_rad) and len(g.orientation_rad) == 2
    for s in ref.orientation_rad:
        assert abs(_wrap(g.orientation_rad[s] - ref.orientation_rad[s])) < 3e-8, (s, v)
        assert g.orientation_std_rad[s] == pytest.approx(ref.orientation_std_rad[s], rel=1e-6)
    k = [i for i, kind in enumerate(ref.angles.kind) if kind == "azimuth"]
    assert np.abs(_wrap(g.angles.observed_rad[k] - ref.angles.observed_rad[k])).max() < 1e-12
    assert np.abs(g.angles.residual_rad - ref.angles.residual_rad).max() < 1e-12
    P, Q = g.points().as_dict(), ref.points().as_dict()
    assert max(np.abs(P[i] - Q[i]).max() for i in P) < 2e-9          # the same coordinates (6+ decimals)


def test_gama_orientation_is_our_heading(outputs):
    """The stored file's orientations, read as headings, against our adjustment of the same network:
    the difference of the two stations' headings (datum-free), and their azimuth residuals."""
    obs, _, _, res = small_levelled()
    lev = obs.levelled
    for v in VARIANTS:
        g = outputs[v]
        dk = (g.orientation_rad[lev[0]] - g.orientation_rad[lev[1]]) - \
            (res.orientations[lev[0]]["orientation_rad"][2] - res.orientations[lev[1]]["orientation_rad"][2])
        assert abs(_wrap(dk)) < 3e-8, (v, dk)


@pytest.mark.skipif(shutil.which("gama-local") is None, reason="gama-local not installed "
                    "(no Debian package; build GNU Gama from source to run this)")
@pytest.mark.parametrize("v", VARIANTS)
def test_gama_local_live_on_the_variants(outputs, tmp_path, v):
    obs, pts, zero, _ = small_levelled()
    (tmp_path / "in.xml").write_text(variant(gama_local_text(obs, pts, offsets=zero), *v))
    r = subprocess.run(["gama-local", str(tmp_path / "in.xml"), "--xml", str(tmp_path / "out.xml")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-500:]
    g, s = read_gama_adjustment(tmp_path / "out.xml"), outputs[v]
    assert g.sigma_aposteriori == pytest.approx(s.sigma_aposteriori, rel=1e-7)
    assert np.max(np.abs(_interpoint_sigmas(g) / _interpoint_sigmas(s) - 1)) < 1e-6
