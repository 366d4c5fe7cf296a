"""Angle observations in the adjustment: azimuths and elevations read by oriented stations.

An observation row of :class:`multilat.network.model.data.Observations` may carry, beside its distance, an
azimuth and an elevation of the target in the station's own frame; with their a-priori σ
(``sigma_azimuth_rad``, ``sigma_elevation_rad``) they are observations of the least squares (without
σ they only serve the initial values). The model is :mod:`multilat.network.model.angles`::

    v = R_iᵀ (T_j - H_i),   azimuth = atan2(v_y, v_x),   elevation = atan2(v_z, hypot(v_x, v_y))

with ``R_i = Rz(κ) Ry(φ) Rx(ω)`` the orientation of station ``i``: three unknowns per station that
reports angles, estimated in the same least squares. The unknowns are appended after the targets and
eliminated with them in the dense coupled path (:mod:`multilat.network.adjust.solve.coupled`), so the reduced
station system, the tie of heads and the datum are those of distances alone: a rigid motion of all
points together with the same rotation of every orientation leaves every observation unchanged (6
datum defects, as for distances; angles fix no scale and no position). Residuals are observed −
computed, azimuths wrapped to ``[-π, π)``.

A **levelled** station (``Observations.levelled``: a tracker on its level, its vertical axis the
world's +z) has one orientation unknown, κ (ω = φ = 0 held). Its angles then observe the world's
vertical, so the network's tilt is no longer a datum defect: 4 defects remain (3 translations and the
rotation about z), and :mod:`multilat.network.adjust.distance.fit` places the internal frame and the free datum with
rotations about z only (the 3-2-1 datum, which would tilt the network, is refused with levelled
stations).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.angles import angle_jacobian, predicted_angles, rotation_matrix, wrap_angle
from multilat.network.model.data import Observations
from multilat.network.model.distance import Q

__all__ = ["AngleRows", "angle_rows", "orientation_from_matrix", "initial_orientations", "KIND_NAMES",
           "angle_results", "angle_w", "orientation_free_mask"]

KIND_NAMES = ("azimuth", "elevation")


def orientation_free_mask(levelled) -> np.ndarray:
    """(3 n,) bool over the orientation unknowns (ω, φ, κ) of ``n`` oriented stations: False for the
    held ω, φ of the levelled ones (``levelled`` (n,) bool)."""
    lev = np.asarray(levelled, bool)
    return np.column_stack([~lev, ~lev, np.ones_like(lev)]).ravel()


@dataclass(frozen=True, eq=False)
class AngleRows:
    """The angle observations of an :class:`Observations` (azimuths first, then elevations).

    obs_index (a,)       the observation row each angle belongs to
    kind (a,)            0 azimuth, 1 elevation
    value_rad, sigma_rad (a,)
    station_index, target_index (a,)
    oriented (s,) bool   stations with an orientation (3 unknowns each, in station order)
    levelled (s,) bool   oriented stations whose ω, φ are held at 0 (only κ estimated)
    """

    obs_index: np.ndarray
    kind: np.ndarray
    value_rad: np.ndarray
    sigma_rad: np.ndarray
    station_index: np.ndarray
    target_index: np.ndarray
    oriented: np.ndarray
    levelled: np.ndarray = None

    def __post_init__(self):
        if self.levelled is None:
            object.__setattr__(self, "levelled", np.zeros_like(self.oriented))

    @property
    def orientation_free(self) -> np.ndarray:
        """(n_o,) bool: False for the held ω, φ of levelled stations."""
        return orientation_free_mask(self.levelled[self.oriented])

    @property
    def any_levelled(self) -> bool:
        return bool(np.any(self.levelled & self.oriented))

    @property
    def n_rows(self) -> int:
        return int(self.obs_index.size)

    @property
    def n_orientation(self) -> int:
        """Orientation unknowns (3 per oriented station)."""
        return 3 * int(self.oriented.sum())

    def station_orientations(self, orientation_rad: np.ndarray) -> np.ndarray:
        """(s, 3) orientations (zeros for stations without angles) from the unknowns (n_o,)."""
        out = np.zeros((self.oriented.size, 3))
        out[self.oriented] = np.asarray(orientation_rad, float).reshape(-1, 3)
        return out

    def residuals(self, station_xyz_m, target_xyz_m, orientation_rad) -> np.ndarray:
        """Observed − computed angles (a,), radians (azimuths wrapped)."""
        O = self.station_orientations(orientation_rad)
        az, el = predicted_angles(station_xyz_m, O, target_xyz_m, self.station_index, self.target_index)
        pred = np.where(self.kind == 0, az, el)
        r = self.value_rad - pred
        return np.where(self.kind == 0, wrap_angle(r), r)

    def whitened(self, station_xyz_m, target_xyz_m, orientation_rad, n_stations: int, n_targets: int):
        """Whitened residuals (a,) and Jacobian rows (a, 5s + 3t + n_o) of the computed side."""
        O = self.station_orientations(orientation_rad)
        d_st, d_or, d_tg = angle_jacobian(station_xyz_m, O, target_xyz_m, self.station_index, self.target_index)
        a = self.n_rows
        rk = np.arange(a)
        k = self.kind
        Js, Jo, Jt = d_st[rk, k], d_or[rk, k], d_tg[rk, k]                  # (a, 3) each
        s, t = n_stations, n_targets
        col_o = np.cumsum(self.oriented) - 1                                 # oriented station -> slot
        J = np.zeros((a, Q * s + 3 * t + self.n_orientation))
        for c in range(3):
            J[rk, Q * self.station_index + c] = Js[:, c]
            J[rk, Q * s + 3 * self.target_index + c] = Jt[:, c]
            J[rk, Q * s + 3 * t + 3 * col_o[self.station_index] + c] = Jo[:, c]
        w = 1.0 / self.sigma_rad
        return self.residuals(station_xyz_m, target_xyz_m, orientation_rad) * w, J * w[:, None]


def angle_rows(obs: Observations) -> AngleRows | None:
    """The angle observations of ``obs`` (None when it has none); ``obs.levelled`` stations get one
    orientation unknown (κ)."""
    if not obs.has_angle_observations:
        return None
    parts = []
    for kind, sig, val in ((0, obs.sigma_azimuth_rad, obs.azimuth_rad), (1, obs.sigma_elevation_rad,
                                                                          obs.elevation_rad)):
        if sig is None:
            continue
        k = np.flatnonzero(np.isfinite(sig))
        parts.append((k, np.full(k.size, kind), np.asarray(val, float)[k], np.asarray(sig, float)[k]))
    k = np.concatenate([p[0] for p in parts])
    kind = np.concatenate([p[1] for p in parts])
    val = np.concatenate([p[2] for p in parts])
    sig = np.concatenate([p[3] for p in parts])
    si = np.asarray(obs.station_index)[k]
    oriented = np.zeros(obs.n_stations, bool)
    oriented[si] = True
    levelled = np.array([sid in obs.levelled for sid in obs.station_ids], bool)
    ti = np.asarray(obs.target_index)[k]
    for i in np.flatnonzero(oriented):
        on = si == i
        sid = obs.station_ids[i]
        if levelled[i]:
            # the heading kappa is seen by azimuths only (elevations of a levelled station do not turn with it)
            if not np.any(on & (kind == 0)):
                raise MultilatError(f"levelled station {sid!r} has no azimuth observation: its heading (kappa) "
                                    "needs at least one")
        elif int(on.sum()) < 3 or np.unique(ti[on]).size < 2:
            # three rotation angles: three angle observations, to two targets at least (the angles of
            # one target leave the roll about its line of sight free)
            raise MultilatError(f"station {sid!r} has {int(on.sum())} angle observation(s) to "
                                f"{np.unique(ti[on]).size} target(s): its orientation (3 angles) needs at least "
                                "3, to 2 targets")
    return AngleRows(k, kind, val, sig, si, ti, oriented, levelled)


def orientation_from_matrix(R) -> np.ndarray:
    """``(ω, φ, κ)`` (…, 3) with ``R = Rz(κ) Ry(φ) Rx(ω)`` (…, 3, 3); φ in [-π/2, π/2]."""
    R = np.asarray(R, float)
    phi = -np.arcsin(np.clip(R[..., 2, 0], -1.0, 1.0))
    omega = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    kappa = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([omega, phi, kappa], -1)


def initial_orientations(obs: Observations, rows: AngleRows, station_xyz_m, target_xyz_m) -> np.ndarray:
    """Orientation unknowns (n_o,) fitted to the observed directions at given coordinates: per station
    the rotation taking the local unit directions (from its azimuths and elevations; an azimuth without
    its elevation, or the reverse, is paired with the other angle when the row has it, else 0) onto the
    world directions ``(T - H)/|T - H|`` (Kabsch / Wahba)."""
    az = obs.azimuth_rad if obs.azimuth_rad is not None else np.zeros(obs.n_obs)
    el = obs.elevation_rad if obs.elevation_rad is not None else np.zeros(obs.n_obs)
    az = np.where(np.isfinite(az), az, 0.0)
    el = np.where(np.isfinite(el), el, 0.0)
    H = np.asarray(station_xyz_m, float)
    T = np.asarray(target_xyz_m, float)
    out = []
    for i in np.flatnonzero(rows.oriented):
        k = np.unique(rows.obs_index[rows.station_index == i])
        loc = np.stack([np.cos(el[k]) * np.cos(az[k]), np.cos(el[k]) * np.sin(az[k]), np.sin(el[k])], -1)
        d = T[obs.target_index[k]] - H[i]
        wld = d / np.linalg.norm(d, axis=1)[:, None]
        if rows.levelled[i]:        # heading only: the horizontal directions' mean angle difference
            dk = np.arctan2(wld[:, 1], wld[:, 0]) - np.arctan2(loc[:, 1], loc[:, 0])
            out.append(np.array([0.0, 0.0, np.arctan2(np.mean(np.sin(dk)), np.mean(np.cos(dk)))]))
            continue
        U, _, Vt = np.linalg.svd(wld.T @ loc)
        D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
        out.append(orientation_from_matrix(U @ D @ Vt))
    return np.concatenate(out) if out else np.zeros(0)


def rotate_orientations(rows: AngleRows, orientation_rad, R) -> np.ndarray:
    """The unknowns after every point is rotated by ``R`` (3, 3): ``R_i -> R R_i``."""
    O = np.asarray(orientation_rad, float).reshape(-1, 3)
    return orientation_from_matrix(np.asarray(R, float) @ rotation_matrix(O)).ravel()


def _param_jacobian(orientation_rad) -> np.ndarray:
    """``∂vec(R)/∂(ω, φ, κ)`` (k, 9, 3) for orientations (k, 3)."""
    from multilat.network.model.angles import rotation_derivatives

    dR = rotation_derivatives(np.asarray(orientation_rad, float).reshape(-1, 3))    # (k, 3, 3, 3)
    return dR.reshape(dR.shape[0], 3, 9).transpose(0, 2, 1)


def _skew(w) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def orientation_covariance(cov, rows: AngleRows, orientation_internal, R, G, E, n_stations: int,
                           n_targets: int, rotation_axes=(0, 1, 2)) -> np.ndarray:
    """Covariance (n_o, n_o) of the orientation unknowns in the requested datum.

    ``cov`` is the adjustment's :class:`~multilat.network.adjust.covariance.CoupledCovariance` (internal frame),
    ``R`` the rotation of the move to the datum (``R_i -> R R_i``, coordinates ``X -> R X + t``), ``G``
    and ``E`` (5s + 3t, 6) the datum's rigid motions and constraints in the moved frame (None under a
    control datum: no S-transformation). The orientation rows of the rigid motions, which ``G`` lacks,
    are those of a small rotation ``w`` of everything: ``δR_i = [w]× R_i`` (``δ(ω, φ, κ)`` from the
    parametrisation's Jacobian), zero for translations; ``E`` has no orientation rows, so
    ``S_ox = −G_o (EᵀG)⁻¹ Eᵀ`` and ``S_oo = I``. ``rotation_axes``: the world axes of ``G``'s rotation
    columns after its 3 translations (``(2,)`` with levelled stations). Held ω, φ (levelled stations)
    have zero variance.
    """
    s, t = n_stations, n_targets
    n = Q * s + 3 * t
    n_o = rows.n_orientation
    V = np.zeros((n + n_o, n_o))
    V[n:] = np.eye(n_o)
    CV = cov._times(V)
    C_xo, C_oo = CV[:n], CV[n:]
    # the move's rotation: coordinates' xyz rotated by R, orientations by F (the Jacobian of R R(p))
    Rm = np.asarray(R, float)
    xyz = np.concatenate([(Q * np.arange(s)[:, None] + np.arange(3)).ravel(), Q * s + np.arange(3 * t)])
    P_int = np.asarray(orientation_internal, float).reshape(-1, 3)
    P_new = rotate_orientations(rows, P_int.ravel(), Rm).reshape(-1, 3)
    J_int, J_new = _param_jacobian(P_int), _param_jacobian(P_new)
    F = np.zeros((n_o, n_o))
    for i in range(P_int.shape[0]):
        Ji = J_int[i].reshape(3, 3, 3)                                     # (3, 3 [vec of R], 3 params)
        RJ = np.einsum("ab,bcp->acp", Rm, Ji).reshape(9, 3)
        F[3 * i:3 * i + 3, 3 * i:3 * i + 3] = np.linalg.lstsq(J_new[i], RJ, rcond=None)[0]

    def rot_x(A):
        B = np.array(A, float, copy=True)
        B3 = B[xyz].reshape(-1, 3, B.shape[1])
        B[xyz] = np.einsum("ab,pbk->pak", Rm, B3).reshape(-1, B.shape[1])
        return B

    C_xo = rot_x(C_xo) @ F.T
    C_oo = F @ C_oo @ F.T
    if G is None:
        return 0.5 * (C_oo + C_oo.T)
    Ro = rotation_matrix(P_new)                                             # (k, 3, 3)
    G_o = np.zeros((n_o, G.shape[1]))
    for col, axis in enumerate(rotation_axes):                              # rotations about world axes
        w = np.eye(3)[axis]
        for i in range(P_new.shape[0]):
            dR = (_skew(w) @ Ro[i]).reshape(9)
            G_o[3 * i:3 * i + 3, 3 + col] = np.linalg.lstsq(J_new[i], dR, rcond=None)[0]
    K = np.linalg.inv(E.T @ G)
    # E' C_xx' E with C_xx' = Rx C_xx Rxᵀ: through the internal product with Rxᵀ E
    Et = np.array(E, float, copy=True)
    E3 = Et[xyz].reshape(-1, 3, E.shape[1])
    Et[xyz] = np.einsum("ba,pbk->pak", Rm, E3).reshape(-1, E.shape[1])     # Rᵀ on each xyz block
    M6 = Et.T @ cov._times(Et)
    B = G_o @ K
    EC = E.T @ C_xo
    out = C_oo + B @ M6 @ B.T - B @ EC - EC.T @ B.T
    return 0.5 * (out + out.T)


def _w_and_mdb(a: dict, lam0: float):
    rows = a["rows"]
    r = a["redundancy"]
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(r > 1e-12, a["residual_rad"] / (rows.sigma_rad * np.sqrt(r)), 0.0)
        mdb = np.where(r > 1e-12, rows.sigma_rad * np.sqrt(lam0 / r), np.inf)
    return w, mdb


def angle_w(core, lam0: float) -> np.ndarray:
    """Baarda's w of each angle observation of an adjustment's core (one per angle row)."""
    w, _ = _w_and_mdb(core.angles, lam0)
    return w


def angle_results(core, lam0: float, crit: float) -> tuple[tuple, dict]:
    """Per angle observation (station, target, kind, value_rad, sigma_rad, residual_rad, redundancy,
    w, mdb_rad, w_test_passed) and per oriented station its orientation (ω, φ, κ) and standard
    uncertainties, in the adjustment's datum (JSON-ready)."""
    a = core.angles
    if a is None:
        return (), {}
    rows = a["rows"]
    w, mdb = _w_and_mdb(a, lam0)
    sids, tids = a["station_ids"], a["target_ids"]
    out = tuple({"station": sids[rows.station_index[q]], "target": tids[rows.target_index[q]],
                 "kind": KIND_NAMES[rows.kind[q]], "value_rad": float(rows.value_rad[q]),
                 "sigma_rad": float(rows.sigma_rad[q]), "residual_rad": float(a["residual_rad"][q]),
                 "redundancy": float(a["redundancy"][q]), "w": float(w[q]), "mdb_rad": float(mdb[q]),
                 "w_test_passed": bool(abs(w[q]) <= crit)} for q in range(rows.n_rows))
    std = np.where(rows.orientation_free, np.sqrt(np.clip(np.diag(a["orientation_cov"]), 0.0, None)), 0.0)
    o = np.asarray(a["orientation_rad"]).reshape(-1, 3)
    orient = {sids[i]: {"orientation_rad": o[q].tolist(), "orientation_std_rad": std[3 * q:3 * q + 3].tolist(),
                        "parameters": ["omega", "phi", "kappa"]}
              for q, i in enumerate(np.flatnonzero(rows.oriented))}
    return out, orient
