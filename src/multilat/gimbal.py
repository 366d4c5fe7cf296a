"""Gimbal mechanics of the heads and the target: seed eqs. (2), (4), (5), and the 3D geometry behind them.

Conventions (see docs/distance-model.md for the derivations)
-------------------------------------------------------------
* World frame: z up. A gimbal has a vertical *standing* axis and a horizontal *transit* axis; its
  reference point ``O`` is on the standing axis (at the height of the transit axis). The transit
  offset is the distance between the two axes, along their common perpendicular, which is
  horizontal and perpendicular to the transit axis, i.e. along the horizontal projection of the
  pointing direction.
* Elevation angles (``elevation_rad``, the seed's phi and phi') are measured **from the
  horizontal** (0 = horizontal sight, +90 deg = zenith). This is the convention in which eq. (2)'s
  ``cos(phi)`` is right: a horizontal offset changes a horizontal sight's distance by its full
  length, a vertical sight's not at all (to first order). With an angle from the zenith, the
  cosine would have to be a sine.
* Head (eqs. 2 and 4): ``toh_m > 0`` means the emission point sits behind the standing axis (away
  from the target), so the measured distance is *longer*: ``Rm^2 = Rt^2 + Toh^2 + 2 Toh Rt cos(phi)``.
* Target (eq. 5): offsets in the corner-cube frame (x along the transit axis, y the cube axis
  pointing to the head, z = x × y, up at zero elevation); ``b_m`` and
  ``tot_m`` are positive **towards the head** (the apex comes closer: the distance is shorter).
  At perfect alignment eq. (5) gives ``Rm^2 = Rt^2 + Tot^2 - 2 Tot Rt cos(phi')`` (b' = 0).
* The sign of the Tot term: eq. (2), written for the target with ``+2 Tot Rt cos(phi')``, and
  eq. (5), with ``-2 Tot Rt [...]``, cannot both hold with one meaning of Tot. Eq. (5) is the
  norm of a sum of vectors (head position minus apex position) and its three cross terms
  ``-2 b' Rt cos.cos``, ``+2 b' Tot cos(phi')`` and ``-2 Tot Rt cos(phi')...`` must have signs
  whose product is positive (for collinear vectors ``s1 s2 . s1 s3 . s2 s3 = (s1 s2 s3)^2``); the
  product is ``(-)(+)(-) = +``: eq. (5) is consistent. Eq. (2)'s target sign with eq. (5)'s other
  terms gives ``(-)(+)(+) = -``: impossible. So eq. (5)'s sign is the right one for Table IV's
  ``Tot = +11 um`` (eq. 5's convention, same source); eq. (2)'s target form holds only for the
  opposite convention (``Tot_eq2 = -Tot_eq5``). :func:`target_transit_offset_correction` uses
  eq. (5)'s convention; correcting with eq. (2) as printed would double the error instead of
  removing it (2 Tot cos(phi') = 22 um at horizontal sight). Tests rebuild both from the 3D
  geometry (:func:`head_measured_distance_3d`, :func:`target_measured_distance_3d`).

All functions are pure and broadcast over numpy arrays (one sighting or a Monte Carlo ensemble).
Distances in metres, angles in radians.
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError

__all__ = ["head_true_from_intermediate", "head_intermediate_from_true", "head_measured_distance",
           "head_true_distance", "transit_offset_effect", "transit_offset_correction",
           "target_measured_distance", "target_transit_projection", "target_transit_offset_correction", "line_of_sight_elevation",
           "head_measured_distance_3d", "target_measured_distance_3d"]


def _a(x):
    return np.asarray(x, dtype=float)


def _check_distance(name, d):
    d = _a(d)
    if not np.all(np.isfinite(d)) or np.any(d <= 0):
        raise MultilatError(f"{name} must be finite and > 0")
    return d


# ------------------------------------------------------------------ head, eq. (4)
def head_true_from_intermediate(intermediate_m, *, a_m, c_m, alpha_rad, gamma_rad):
    """First line of eq. (4): the true distance ``Rt`` from ``Ri`` (beam offset a, c and tilt alpha, gamma).

    ``Rt^2 = Ri^2 + a^2 + c^2 - 2 a S sin(alpha) - 2 c Ri sin(gamma)``, ``S = sqrt(Ri^2 + c^2 - 2 c Ri sin(gamma))``.
    """
    ri = _a(intermediate_m)
    a, c, al, ga = _a(a_m), _a(c_m), _a(alpha_rad), _a(gamma_rad)
    s = np.sqrt(ri * ri + c * c - 2 * c * ri * np.sin(ga))
    return np.sqrt(ri * ri + a * a + c * c - 2 * a * s * np.sin(al) - 2 * c * ri * np.sin(ga))


def head_intermediate_from_true(true_distance_m, *, a_m, c_m, alpha_rad, gamma_rad):
    """Inverse of the first line of eq. (4), closed form: ``Ri`` from ``Rt``.

    Since ``S^2 = Ri^2 + c^2 - 2 c Ri sin(gamma)``, the first line reads ``Rt^2 = S^2 + a^2 - 2 a S sin(alpha)``:
    ``S = a sin(alpha) + sqrt(Rt^2 - a^2 cos^2(alpha))`` and ``Ri = c sin(gamma) + sqrt(S^2 - c^2 cos^2(gamma))``
    (the roots that tend to ``Rt`` when the offsets vanish).
    """
    rt = _a(true_distance_m)
    a, c, al, ga = _a(a_m), _a(c_m), _a(alpha_rad), _a(gamma_rad)
    s = a * np.sin(al) + np.sqrt(rt * rt - (a * np.cos(al)) ** 2)
    return c * np.sin(ga) + np.sqrt(s * s - (c * np.cos(ga)) ** 2)


def head_measured_distance(true_distance_m, *, a_m, c_m, alpha_rad, gamma_rad, toh_m, elevation_rad):
    """Eq. (4) forward: the distance a head measures (m) for a true distance ``Rt`` (m).

    Parameters
    ----------
    true_distance_m : ndarray
        ``Rt`` from the head's reference point to the target (> 0).
    a_m, c_m : ndarray
        Beam offsets (m).
    alpha_rad, gamma_rad : ndarray
        Beam tilts (rad); gamma tilts in the vertical plane (it enters as ``cos(phi - gamma)``).
    toh_m : ndarray
        Transit offset (m), eq. 2/4 convention (positive lengthens the measurement).
    elevation_rad : ndarray
        Head elevation phi from the horizontal (rad).

    Returns
    -------
    ndarray
        ``Rm = sqrt(Toh^2 + Ri^2 + 2 Toh Ri cos(alpha) cos(phi - gamma))``, broadcast shape.
    """
    _check_distance("true_distance_m", true_distance_m)
    ri = head_intermediate_from_true(true_distance_m, a_m=a_m, c_m=c_m, alpha_rad=alpha_rad, gamma_rad=gamma_rad)
    t, al, ga, ph = _a(toh_m), _a(alpha_rad), _a(gamma_rad), _a(elevation_rad)
    return np.sqrt(t * t + ri * ri + 2 * t * ri * np.cos(al) * np.cos(ph - ga))


def head_true_distance(measured_m, *, a_m, c_m, alpha_rad, gamma_rad, toh_m, elevation_rad):
    """Eq. (4) inverse: the true distance (m) from the measured one, all head parameters known."""
    rm = _check_distance("measured_m", measured_m)
    t, al, ga, ph = _a(toh_m), _a(alpha_rad), _a(gamma_rad), _a(elevation_rad)
    k = np.cos(al) * np.cos(ph - ga)
    ri = -t * k + np.sqrt(rm * rm - t * t * (1 - k * k))
    return head_true_from_intermediate(ri, a_m=a_m, c_m=c_m, alpha_rad=alpha_rad, gamma_rad=gamma_rad)


# ------------------------------------------------------------------ eq. (2), head convention
def transit_offset_effect(true_distance_m, offset_m, elevation_rad):
    """Eq. (2) forward: ``Rm = sqrt(Rt^2 + T^2 + 2 T Rt cos(phi))`` (m), phi from the horizontal."""
    rt = _check_distance("true_distance_m", true_distance_m)
    t, ph = _a(offset_m), _a(elevation_rad)
    return np.sqrt(rt * rt + t * t + 2 * t * rt * np.cos(ph))


def transit_offset_correction(measured_m, offset_m, elevation_rad):
    """Eq. (2) inverse: the true distance from the measured one, ``Rt = -T cos(phi) + sqrt(Rm^2 - T^2 sin^2(phi))``.

    Parameters
    ----------
    measured_m : ndarray
        Measured distance ``Rm`` (m, > |offset|).
    offset_m : ndarray
        Transit offset in eq. (2)'s (head) convention: positive lengthens the measurement at
        horizontal sight. For a target offset given in eq. (5)'s convention (Table IV) use
        :func:`target_transit_offset_correction` (or pass ``-tot_m``).
    elevation_rad : ndarray
        Elevation from the horizontal (rad).

    Returns
    -------
    ndarray
        ``Rt`` (m), broadcast shape.
    """
    rm = _check_distance("measured_m", measured_m)
    t, ph = _a(offset_m), _a(elevation_rad)
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(ph))):
        raise MultilatError("offset_m and elevation_rad must be finite")
    disc = rm * rm - (t * np.sin(ph)) ** 2
    if np.any(disc < 0):
        raise MultilatError("measured_m is shorter than the transit offset")
    return -t * np.cos(ph) + np.sqrt(disc)


# ------------------------------------------------------------------ target, eq. (5)
def target_measured_distance(true_distance_m, *, a_m, b_m, c_m, tot_m, elevation_rad, theta_rad, phi_rad):
    """Eq. (5): distance measured to a misaligned target (m), with the primed offsets a', b', c'.

    Parameters
    ----------
    true_distance_m : ndarray
        ``Rt`` from the head to the target's reference point (on its standing axis).
    a_m, b_m, c_m : ndarray
        Apex offsets a', b', c' in the corner-cube frame (m; b' along the cube axis, towards the head).
    tot_m : ndarray
        Target transit offset (m), eq. (5) convention (towards the head).
    elevation_rad : ndarray
        Target elevation phi' (rad, from the horizontal).
    theta_rad, phi_rad : ndarray
        Misalignment theta'', phi'' of the line of sight in the cube frame (rad).

    Returns
    -------
    ndarray
        ``Rm`` (m), broadcast shape::

            Rm^2 = Rt^2 + Tot^2 + a'^2 + b'^2 + c'^2 + 2 a' Rt sin(th'') + 2 b' [Tot cos(ph') - Rt cos(th'') cos(ph'')]
                   + 2 c' [Rt sin(ph'') - Tot sin(ph')] - 2 Tot Rt [cos(ph') cos(th'') cos(ph'') + sin(ph') sin(ph'')]
    """
    rt = _check_distance("true_distance_m", true_distance_m)
    a, b, c, t = _a(a_m), _a(b_m), _a(c_m), _a(tot_m)
    e, th, ph = _a(elevation_rad), _a(theta_rad), _a(phi_rad)
    ce, se, ct, st, cp, sp = np.cos(e), np.sin(e), np.cos(th), np.sin(th), np.cos(ph), np.sin(ph)
    rm2 = (rt * rt + t * t + a * a + b * b + c * c + 2 * a * rt * st + 2 * b * (t * ce - rt * ct * cp)
           + 2 * c * (rt * sp - t * se) - 2 * t * rt * (ce * ct * cp + se * sp))
    return np.sqrt(rm2)


def line_of_sight_elevation(elevation_rad, theta_rad, phi_rad):
    """Elevation (rad, from the horizontal) of the direction target -> head.

    The target's axis is at elevation phi'; the head is seen at misalignment (theta'', phi'') in the
    cube frame: ``sin(eps) = cos(th'') cos(ph'') sin(phi') - sin(ph'') cos(phi')`` (``phi' - phi''`` when theta'' = 0).
    """
    e, th, ph = _a(elevation_rad), _a(theta_rad), _a(phi_rad)
    return np.arcsin(np.clip(np.cos(th) * np.cos(ph) * np.sin(e) - np.sin(ph) * np.cos(e), -1.0, 1.0))


def target_transit_projection(elevation_rad, theta_rad=0.0, phi_rad=0.0):
    """Cosine between the target's transit-offset direction and the line of sight to the head.

    ``k = cos(phi') cos(th'') cos(ph'') + sin(phi') sin(ph'')`` (the bracket of eq. 5's Tot Rt term);
    ``cos(phi')`` at perfect alignment.
    """
    e, th, ph = _a(elevation_rad), _a(theta_rad), _a(phi_rad)
    return np.cos(e) * np.cos(th) * np.cos(ph) + np.sin(e) * np.sin(ph)


def target_transit_offset_correction(measured_m, tot_m, elevation_rad, *, theta_rad=0.0, phi_rad=0.0):
    """True distance from a measurement to the target, its transit offset removed (eq. 5 convention).

    Eq. (5) with zero beam offsets: ``Rm^2 = Rt^2 + Tot^2 - 2 Tot Rt k``, ``k`` from
    :func:`target_transit_projection`, so ``Rt = Tot k + sqrt(Rm^2 - Tot^2 (1 - k^2))``. With the
    default zero misalignment, ``k = cos(elevation)``: pass the target's elevation phi' (the seed's
    literal reading) or the elevation of the line of sight. Equal to
    :func:`transit_offset_correction` with ``-tot_m`` when ``k = cos(elevation)``.

    Parameters
    ----------
    measured_m : ndarray
        Measured distance (m, > |tot|).
    tot_m : ndarray
        Target transit offset, eq. (5) convention (positive towards the head), m.
    elevation_rad, theta_rad, phi_rad : ndarray
        phi', theta'', phi'' (rad).
    """
    rm = _check_distance("measured_m", measured_m)
    t = _a(tot_m)
    k = target_transit_projection(elevation_rad, theta_rad, phi_rad)
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(k))):
        raise MultilatError("tot_m and the angles must be finite")
    disc = rm * rm - t * t * (1.0 - k * k)
    if np.any(disc < 0):
        raise MultilatError("measured_m is shorter than the transit offset")
    return t * k + np.sqrt(disc)


# ------------------------------------------------------------------ explicit 3D geometry
def _rot_z(az):
    c, s = np.cos(az), np.sin(az)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def head_measured_distance_3d(true_distance_m, *, a_m, c_m, alpha_rad, gamma_rad, toh_m, elevation_rad):
    """Head distance measurement by explicit 3D vectors (check of eqs. 2 and 4; not used by the budget).

    World frame, head reference point ``O`` at the origin, azimuth 0 (pointing along +y). The transit
    axis is the line through ``-Toh y`` parallel to x (``Toh > 0``: behind the standing axis). The
    platform, elevated by phi about the transit axis, has axes ``u = (0, cos phi, sin phi)`` (nominal
    beam) and ``w = (0, -sin phi, cos phi)`` (up in the platform). The beam leaves from
    ``E = -Toh y + a x + c w`` in direction ``d = normalise(cos(alpha) cos(gamma) u - sin(alpha) x - sin(gamma) w)``
    (tilts towards -x and -w, the signs that match eq. 4's first-order terms). The target is where
    the beam is at distance ``Rt`` from ``O``; the measured distance is the path from ``E`` to it.

    Returns
    -------
    ndarray
        Measured distance (m), broadcast shape. Agrees with :func:`head_measured_distance` to
        second order in the offsets and tilts (the seed's eq. 4 composes two planar steps).
    """
    rt = _a(true_distance_m)
    a, c, al, ga, t, ph = (_a(v) for v in (a_m, c_m, alpha_rad, gamma_rad, toh_m, elevation_rad))
    shape = np.broadcast_shapes(rt.shape, a.shape, c.shape, al.shape, ga.shape, t.shape, ph.shape)
    rt, a, c, al, ga, t, ph = (np.broadcast_to(v, shape) for v in (rt, a, c, al, ga, t, ph))
    zero = np.zeros(shape)
    x = np.stack([np.ones(shape), zero, zero], -1)
    y = np.stack([zero, np.ones(shape), zero], -1)
    u = np.stack([zero, np.cos(ph), np.sin(ph)], -1)
    w = np.stack([zero, -np.sin(ph), np.cos(ph)], -1)
    e = -t[..., None] * y + a[..., None] * x + c[..., None] * w
    d = (np.cos(al) * np.cos(ga))[..., None] * u - np.sin(al)[..., None] * x - np.sin(ga)[..., None] * w
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    # |E + s d| = Rt  ->  s = -E.d + sqrt((E.d)^2 - |E|^2 + Rt^2)
    ed = np.sum(e * d, -1)
    return -ed + np.sqrt(ed * ed - np.sum(e * e, -1) + rt * rt)


def target_measured_distance_3d(true_distance_m, *, a_m, b_m, c_m, tot_m, elevation_rad, theta_rad, phi_rad,
                                azimuth_rad=0.0):
    """Target distance measurement by explicit 3D vectors (check of eq. 5; not used by the budget).

    World frame, target reference point ``O`` (on its standing axis) at the origin. The target points
    at azimuth ``psi`` (``azimuth_rad``) and elevation phi'. Its transit axis ``x_c = (cos psi, sin psi, 0)``
    passes through ``Tot h`` with ``h = (-sin psi, cos psi, 0)`` the horizontal pointing direction
    (``Tot > 0``: towards the head). Cube axis ``y_c = cos(phi') h + sin(phi') z``, ``z_c = -sin(phi') h + cos(phi') z``.
    Apex ``A = Tot h + a' x_c + b' y_c + c' z_c``. The head is at ``H = Rt w`` with the unit direction
    ``w = -sin(th'') cos(ph'') x_c + cos(th'') cos(ph'') y_c - sin(ph'') z_c`` (the misalignment). The measured
    distance is ``|H - A|`` (a hollow corner cube returns the beam as if reflected at its apex).

    Returns
    -------
    ndarray
        Measured distance (m). Equal to eq. (5) except that eq. (5) writes ``a' sin(th'')`` where the
        unit vector gives ``a' sin(th'') cos(ph'')`` (a second-order difference).
    """
    rt = _a(true_distance_m)
    a, b, c, t, e, th, ph, az = (_a(v) for v in (a_m, b_m, c_m, tot_m, elevation_rad, theta_rad, phi_rad,
                                                  azimuth_rad))
    shape = np.broadcast_shapes(rt.shape, a.shape, b.shape, c.shape, t.shape, e.shape, th.shape, ph.shape, az.shape)
    rt, a, b, c, t, e, th, ph, az = (np.broadcast_to(v, shape) for v in (rt, a, b, c, t, e, th, ph, az))
    zero = np.zeros(shape)
    z = np.stack([zero, zero, np.ones(shape)], -1)
    h = np.stack([-np.sin(az), np.cos(az), zero], -1)
    xc = np.stack([np.cos(az), np.sin(az), zero], -1)
    yc = np.cos(e)[..., None] * h + np.sin(e)[..., None] * z
    zc = -np.sin(e)[..., None] * h + np.cos(e)[..., None] * z
    apex = t[..., None] * h + a[..., None] * xc + b[..., None] * yc + c[..., None] * zc
    w = (-(np.sin(th) * np.cos(ph))[..., None] * xc + (np.cos(th) * np.cos(ph))[..., None] * yc
         - np.sin(ph)[..., None] * zc)
    return np.linalg.norm(rt[..., None] * w - apex, axis=-1)
