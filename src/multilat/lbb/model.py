"""The bar's length-change model (seed 003, §3-4): HTM error model, DMI reading, initialization.

Pure, vectorised functions of sampled inputs. Every array argument broadcasts over leading axes, so
one call evaluates one bar pose, a Monte Carlo ensemble ``(trials,)``, or ``(trials, points, 6)``.

Pieces, in the order of the paper:

- :func:`section_lengths`: the middle tube's free position (a uniform input ``u`` in [0, 1]) splits
  the extension between ``Lb`` and ``Lc`` (§3.1.1).
- :func:`sag_offsets`: gravity sag of the stepped beam (:mod:`multilat.lbb.sag`) expressed as the
  y-offset and z-rotation of CS2 in CS1 and of CS3 in CS2 (§3.1.1).
- :func:`cs3_to_cs1`: the actual ``1T3`` (eq. 3) with axis-motion errors (Table 1), bearing
  compliance (§3.1.3), cosine misalignment (§3.1.4) and sag.
- :func:`retroreflector_x_cs1`: the DMI's measurement point, x of eq. (4), with the thermal error of
  the unsensed length (§3.1.6).
- :func:`length_for_reading` and :func:`true_length_change`: §4.1 steps 1-4, the true change of the
  ball-centre distance (eq. 5) behind a nominal DMI reading, with the interferometer error (§3.1.7).
- :func:`fixture_length` (eq. 6) and :func:`initialization_length` (§4.2, §5 steps 1-3).
- :func:`true_side_lengths` (eq. 7, §4.3, §5 step 5) with the base edges' thermal drift.

Sign conventions: CS1's y axis points up (away from gravity) in the vertical plane through the bar;
the sag and the bearing compliance therefore lower the free end (negative z-rotations). The
elevation of a bar is its angle above the horizontal; only ``cos(elevation)`` enters (the axial
component of gravity, which compresses the bar by < 1 nm, is neglected).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.distributions import Constant, Normal, Uniform
from multilat.lbb import htm
from multilat.lbb.config import LBBConfig
from multilat.lbb.sag import stepped_beam, tube_section

__all__ = ["BarModel", "MECH_SOURCES", "READ_SOURCES", "pose_distributions", "section_lengths",
           "sag_offsets", "cs3_to_cs1", "retroreflector_x_cs1", "length_for_reading",
           "true_length_change", "fixture_length", "initialization_length", "true_side_lengths"]

#: per-pose mechanical inputs: axis-motion errors of the middle (2) and inner (3) tube and the free
#: position of the middle tube
MECH_SOURCES = ("ey2", "ez2", "sy2", "sz2", "ey3", "ez3", "sy3", "sz3", "u_mid")
#: per-reading inputs: thermal error of the unsensed length and interferometer error
READ_SOURCES = ("thermal_m", "dmi_m")


@dataclass(frozen=True)
class BarModel:
    """Everything deterministic the length model needs, derived from an :class:`LBBConfig`.

    Attributes
    ----------
    la_m, lb_min_m, lb_max_m, lc_min_m, lc_max_m : float
        Section lengths and travel limits (m).
    x_rr_cs3_m : float
        Nominal x of the retroreflector apex in CS3 (m, negative: towards the left ball).
    ei_n_m2 : ndarray (3,)
        Bending stiffness of the outer, middle and inner segments (N·m²).
    weight_n_per_m : ndarray (3,)
        Weight per length of the three segments at full gravity (N/m): segment a carries the three
        nested tubes and the optics package, b the middle and inner tube, c the inner tube.
    compliance_rad : float
        Bearing compliance at a horizontal bar (rad).
    """

    la_m: float
    lb_min_m: float
    lb_max_m: float
    lc_min_m: float
    lc_max_m: float
    x_rr_cs3_m: float
    ei_n_m2: np.ndarray
    weight_n_per_m: np.ndarray
    compliance_rad: float

    @classmethod
    def from_config(cls, cfg: LBBConfig) -> "BarModel":
        b = cfg.bar
        g = b.gravity_m_s2
        secs = [tube_section(t.outer_diameter_m, t.wall_m, t.youngs_modulus_pa, t.density_kg_m3, g)
                for t in (b.outer_tube, b.middle_tube, b.inner_tube)]
        ei = np.array([s[0] for s in secs])
        w_o, w_m, w_i = (s[1] for s in secs)
        w = np.array([w_o + w_m + w_i + b.optics_mass_kg * g / b.la_m, w_m + w_i, w_i])
        return cls(b.la_m, b.lb_min_m, b.lb_max_m, b.lc_min_m, b.lc_max_m,
                   b.retroreflector_x_in_cs3_m, ei, w, cfg.errors.bearing_compliance_rad)


def _axis(bound: float, kind: str):
    if bound == 0:
        return Constant(0.0)
    return Normal(0.0, bound / 2.0) if kind == "normal_2sigma" else Uniform(-bound, bound)


def pose_distributions(cfg: LBBConfig) -> dict:
    """The distributions of the per-pose inputs (:data:`MECH_SOURCES` + :data:`READ_SOURCES`).

    Axis-motion errors follow ``errors.axis_distribution`` (normal with sigma = bound/2, the
    paper's convention, or uniform on ±bound); the straightness part of Table 1's ``d`` is drawn
    here, the ``e·L`` part comes out of the HTM chain. ``u_mid`` is uniform on [0, 1]. The thermal
    error is ``CTE · L_unsensed · ΔT``: normal with sigma ``CTE·L·ΔT_max/2`` (``paper_normal``,
    0.147 µm) or uniform (``uniform``, sigma 0.170 µm). The DMI error is normal.
    """
    e = cfg.errors
    k = e.axis_distribution
    th_max = e.unsensed_cte_per_c * cfg.bar.unsensed_length_m * e.unsensed_temperature_bound_c
    if th_max == 0:
        thermal = Constant(0.0)
    elif e.thermal_model == "paper_normal":
        thermal = Normal(0.0, th_max / 2.0)
    else:
        thermal = Uniform(-th_max, th_max)
    return {
        "ey2": _axis(e.middle_angle_bound_rad, k), "ez2": _axis(e.middle_angle_bound_rad, k),
        "sy2": _axis(e.middle_straightness_bound_m, k), "sz2": _axis(e.middle_straightness_bound_m, k),
        "ey3": _axis(e.inner_angle_bound_rad, k), "ez3": _axis(e.inner_angle_bound_rad, k),
        "sy3": _axis(e.inner_straightness_bound_m, k), "sz3": _axis(e.inner_straightness_bound_m, k),
        "u_mid": Uniform(0.0, 1.0),
        "thermal_m": thermal,
        "dmi_m": Normal(0.0, e.interferometer_std_m),
    }


def section_lengths(bar: BarModel, length_m, u_mid):
    """Split the extension ``L - La`` into ``Lb`` (middle tube) and ``Lc`` (inner tube).

    The middle tube is free between its limiting positions: ``Lb`` is uniform (through ``u_mid`` in
    [0, 1]) on ``[max(Lb_min, L-La-Lc_max), min(Lb_max, L-La-Lc_min)]``.

    Returns
    -------
    lb_m, lc_m : ndarray, broadcast shape of the inputs
    """
    ext = np.asarray(length_m, dtype=float) - bar.la_m
    lo = np.maximum(bar.lb_min_m, ext - bar.lc_max_m)
    hi = np.minimum(bar.lb_max_m, ext - bar.lc_min_m)
    lb = lo + np.asarray(u_mid) * (hi - lo)
    return lb, ext - lb


def sag_offsets(bar: BarModel, lb_m, lc_m, elevation_rad):
    """Gravity sag as HTM parameters (§3.1.1).

    The bar is a simply supported beam on its balls with segments ``[0, La]``, ``[La, La+Lb]``,
    ``[La+Lb, L]`` loaded by ``weight · cos(elevation)``. CS1 turns with the outer tube at the left
    ball (slope ``θ0``), so in CS1 (y up)::

        CS2 origin: dy2 = -v(x2) + θ0·x2,  rotation ez2 = θ0 - θ(x2)
        CS3 in CS2: dy3 =  v(x2) + θ(x2)·Lc, rotation ez3 = θ(x2) - θ(L)

    with ``v`` and ``θ`` positive downwards (:func:`multilat.lbb.sag.stepped_beam`).

    Returns
    -------
    dy2_m, ez2_rad, dy3_m, ez3_rad : ndarray
    """
    lb, lc, el = np.broadcast_arrays(np.asarray(lb_m, float), np.asarray(lc_m, float),
                                     np.asarray(elevation_rad, float))
    x2 = bar.la_m + lb
    length = x2 + lc
    breaks = np.stack([np.zeros_like(lb), np.full_like(lb, bar.la_m), x2, length], axis=-1)
    w = bar.weight_n_per_m * np.cos(el)[..., None]
    v, th = stepped_beam(breaks, bar.ei_n_m2, w)          # at the segment ends 0, La, x2, L
    th0, v2, th2, thl = th[..., 0], v[..., 2], th[..., 2], th[..., 3]
    return -v2 + th0 * x2, th0 - th2, v2 + th2 * lc, th2 - thl


def cs3_to_cs1(bar: BarModel, length_m, elevation_rad, *, ey2=0.0, ez2=0.0, sy2=0.0, sz2=0.0,
               ey3=0.0, ez3=0.0, sy3=0.0, sz3=0.0, u_mid=0.5, cos_theta=0.0, cos_phi=0.0,
               sag: bool = True):
    """The actual ``1T3`` of eq. (3) for a bar of nominal length ``length_m`` (= La+Lb+Lc, eq. 2).

    Parameters
    ----------
    bar : BarModel
    length_m, elevation_rad : array_like
        Nominal ball-centre distance (m) and angle above the horizontal (rad).
    ey2, ez2, sy2, sz2 : array_like
        Middle-tube axis-motion errors (rad, rad, m, m), Table 1.
    ey3, ez3, sy3, sz3 : array_like
        Inner-tube axis-motion errors, Table 1.
    u_mid : array_like
        Free middle-tube position in [0, 1].
    cos_theta, cos_phi : array_like
        Cosine misalignment angle between DMI axis and motion axis (rad) and its direction about
        the DMI axis (rad): CS3 is offset laterally by ``θ·L·(cos φ, sin φ)`` (§3.1.4).
    sag : bool or tuple
        Include gravity sag (True), not (False), or use precomputed :func:`sag_offsets`
        ``(dy2, ez2, dy3, ez3)`` (the solver holds them fixed while the extension changes by
        micrometres, which changes them by < 1e-9 relative).

    Returns
    -------
    ndarray, shape (..., 4, 4)
    """
    lb, lc = section_lengths(bar, length_m, u_mid)
    if isinstance(sag, tuple):
        dy2, sez2, dy3, sez3 = sag
    elif sag:
        dy2, sez2, dy3, sez3 = sag_offsets(bar, lb, lc, elevation_rad)
    else:
        dy2 = sez2 = dy3 = sez3 = 0.0
    compliance = -bar.compliance_rad * np.cos(np.asarray(elevation_rad, dtype=float))
    t12 = htm.cs2_to_cs1(bar.la_m, lb, ey_rad=ey2, ez_rad=ez2, sy_m=sy2, sz_m=sz2,
                         sag_dy_m=dy2, sag_ez_rad=sez2)
    t23 = htm.cs3_to_cs2(lc, ey_rad=ey3, ez_rad=ez3, sy_m=sy3, sz_m=sz3, compliance_ez_rad=compliance,
                         sag_dy_m=dy3, sag_ez_rad=sez3)
    lat = np.asarray(cos_theta) * np.asarray(length_m)
    tcos = htm.translation(0.0, lat * np.cos(cos_phi), lat * np.sin(cos_phi))
    return tcos @ t12 @ t23


def retroreflector_x_cs1(bar: BarModel, cs3_to_cs1_htm, thermal_m=0.0):
    """x of the retroreflector apex in CS1 (eq. 4): the DMI's measurement point.

    The thermal growth ``thermal_m`` of the unsensed lengths (both of them, lumped on the
    retroreflector side; to first order only their sum matters along the axis) moves the apex away
    from the right ball: ``3P_rr = (x_rr - thermal, 0, 0)``. An increase lowers the DMI reading
    for fixed balls, as §3.1.6 says.
    """
    t = np.asarray(cs3_to_cs1_htm)
    p = np.stack(np.broadcast_arrays(bar.x_rr_cs3_m - np.asarray(thermal_m, float), 0.0, 0.0), axis=-1)
    return htm.transform_point(t, p)[..., 0]


def length_for_reading(bar: BarModel, target_x_rr_m, elevation_rad, *, start_length_m,
                       thermal_m=0.0, iterations: int = 2, **pose):
    """The bar pose whose retroreflector apex sits at ``target_x_rr_m`` in CS1 (§4.1 step 3).

    Solves ``x_rr(L) = target`` for the nominal extension ``L`` by fixed-point iteration
    ``L <- L + (target - x_rr(L))`` (``dx_rr/dL = 1 + O(1e-7)``: each step gains seven digits).

    Returns
    -------
    length_m : ndarray
        Nominal extension found.
    cs3_to_cs1_htm : ndarray (..., 4, 4)
        The pose at that extension.
    """
    length = np.asarray(start_length_m, dtype=float)
    sag = pose.pop("sag", True)
    if sag is True:
        sag = sag_offsets(bar, *section_lengths(bar, length, pose.get("u_mid", 0.5)), elevation_rad)
    for _ in range(iterations):
        t = cs3_to_cs1(bar, length, elevation_rad, sag=sag, **pose)
        length = length + (target_x_rr_m - retroreflector_x_cs1(bar, t, thermal_m))
    return length, cs3_to_cs1(bar, length, elevation_rad, sag=sag, **pose)


def _pose(draws: dict, prefix: str, const: dict) -> dict:
    out = {k: draws[prefix + k] for k in MECH_SOURCES if prefix + k in draws}
    out.update(const)
    return out


def true_length_change(bar: BarModel, *, from_length_m, from_elevation_rad, from_pose: dict,
                       to_length_m, to_elevation_rad, to_pose: dict, thermal_m, dmi_m):
    """True change of the ball-centre distance behind a nominal DMI reading (§4.1, eq. 5).

    1. The initial pose (DMI zeroed) gives the apex ``x_rr,0`` and ball distance ``|1P3,0|``.
    2. The nominal reading ``to_length - from_length`` is corrected for the interferometer error
       (``dmi_m``: the apex really moved ``reading + dmi``) and the thermal error (``thermal_m``,
       applied to the apex in CS3 of the new pose).
    3. The new pose is the one whose apex is at ``x_rr,0 + reading + dmi`` (:func:`length_for_reading`).
    4. ``ΔL_act = |1P3| - |1P3,0|``.

    ``from_pose``/``to_pose`` are keyword dicts of :func:`cs3_to_cs1` (axis errors, ``u_mid``,
    cosine misalignment). All arrays broadcast.

    Returns
    -------
    ndarray
        ΔL_act (m).
    """
    t0 = cs3_to_cs1(bar, from_length_m, from_elevation_rad, **from_pose)
    x0 = retroreflector_x_cs1(bar, t0)
    reading = np.asarray(to_length_m) - np.asarray(from_length_m)
    _, t1 = length_for_reading(bar, x0 + reading + dmi_m, to_elevation_rad, start_length_m=to_length_m,
                               thermal_m=thermal_m, **to_pose)
    return np.linalg.norm(htm.origin(t1), axis=-1) - np.linalg.norm(htm.origin(t0), axis=-1)


def fixture_length(l12_m, delta_l_m, dy_m):
    """True socket 2-3 distance of a non-collinear fixture (eq. 6).

    Socket 3 lies ``dy`` off the line through sockets 1 and 2, at ``L12 + ΔL`` from socket 1::

        L23 = [ (sqrt((L12 + ΔL)² - dy²) - L12)² + dy² ]^(1/2)
    """
    l13 = np.asarray(l12_m) + np.asarray(delta_l_m)
    dy2 = np.asarray(dy_m) ** 2
    return np.sqrt((np.sqrt(l13**2 - dy2) - l12_m) ** 2 + dy2)


def initialization_length(cfg: LBBConfig, bar: BarModel, draws: dict, *, cos_theta=0.0, cos_phi=0.0):
    """True initialization length ``L0`` (§4.2, §5 steps 1-3).

    The bar is zeroed between fixture sockets 1-2 (``L12``, horizontal, pose ``init_a_*``), moved to
    sockets 1-3 (nominal reading ``L23``, pose ``init_b_*`` with ``init_b_thermal_m``,
    ``init_b_dmi_m``), the true change is converted by eq. (6) with the fixture offset
    ``fixture_dy`` into the true 2-3 distance: the value the bar's length is set to is the nominal
    ``L23``, the true one is returned. With ``initialization.enabled = false`` L0 is exact.

    Returns
    -------
    ndarray
        True L0 (m), shape of the draws.
    """
    ini = cfg.initialization
    if not ini.enabled:
        return np.full(np.shape(draws["fixture_dy"]), ini.l23_m)
    const = {"cos_theta": cos_theta, "cos_phi": cos_phi}
    dl = true_length_change(bar, from_length_m=ini.l12_m, from_elevation_rad=0.0,
                            from_pose=_pose(draws, "init_a_", const),
                            to_length_m=ini.l12_m + ini.l23_m, to_elevation_rad=0.0,
                            to_pose=_pose(draws, "init_b_", const),
                            thermal_m=draws["init_b_thermal_m"], dmi_m=draws["init_b_dmi_m"])
    return fixture_length(ini.l12_m, dl, draws["fixture_dy"])


def true_side_lengths(cfg: LBBConfig, bar: BarModel, l0_m, nominal_edges_m, elevations_rad, draws: dict,
                      *, cos_theta=0.0, cos_phi=0.0, base_dt_c=0.0):
    """True tetrahedron edges behind the nominal readings (eq. 7, §4.3, §5 step 5).

    ``L_i = L0 + ΔL_i`` where ``ΔL_i`` is the true change from the bar set to L0 in the fixture
    (sockets 2-3, horizontal, pose ``set_*``, shared by the six sides) to side ``i`` (pose
    ``side_*`` with a trailing axis of 6, reading ``nominal_i - L23``). The three base edges also
    drift thermally during the cycle: ``+ CTE_base · ΔT · L_nominal`` with one ``base_dt_c`` shared
    by the three.

    Parameters
    ----------
    l0_m : array_like, shape (...)
        True L0 per trial.
    nominal_edges_m, elevations_rad : array_like, shape (..., 6)
        Nominal edges (order ``l12, l13, l23, l1, l2, l3``) and bar elevations.
    draws : dict
        ``set_<mech>`` of shape (...), ``side_<mech>``, ``side_thermal_m``, ``side_dmi_m`` of
        shape (..., 6).

    Returns
    -------
    ndarray, shape (..., 6)
        True edge lengths (m).
    """
    l23 = cfg.initialization.l23_m
    c = {"cos_theta": np.asarray(cos_theta)[..., None], "cos_phi": np.asarray(cos_phi)[..., None]}
    set_pose = {k: np.asarray(v)[..., None] for k, v in _pose(draws, "set_", {}).items()}
    set_pose.update(c)
    dl = true_length_change(bar, from_length_m=l23, from_elevation_rad=0.0, from_pose=set_pose,
                            to_length_m=nominal_edges_m, to_elevation_rad=elevations_rad,
                            to_pose=_pose(draws, "side_", c), thermal_m=draws["side_thermal_m"],
                            dmi_m=draws["side_dmi_m"])
    out = np.asarray(l0_m)[..., None] + dl
    drift = cfg.base.thermal_cte_per_c * np.asarray(base_dt_c)[..., None] * np.asarray(nominal_edges_m)[..., :3]
    return np.concatenate([out[..., :3] + drift, out[..., 3:]], axis=-1)
