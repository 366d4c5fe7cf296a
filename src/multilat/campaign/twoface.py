"""Two-face (double-centering) distance measurements: the head's transit offset from distances alone.

The double-centering method of seed 000 §3.3 points the same target twice: in face I, then in
face II (180° about the standing axis, then 180° about the transit axis). What distances alone
can tell (derivation in ``docs/campaign.md``, from eq. 4):

- Face II turns the alidade, which carries the transit axis at ``Toh`` from the standing axis, by
  180°, so the transit-offset term of eqs. (2)/(4) changes sign: ``2 Toh Ri cos(φ)`` in face I,
  ``-2 Toh Ri cos(φ)`` in face II (the head's eq.-2 elevation reads ``π - φ`` in face II).
- Face II maps the platform (mirror, beam) by a 180° rotation about the line of sight, so the beam
  offset ``(a, c)`` *and* the beam tilt ``(α, γ)`` both change sign in space; their distance
  effect, to first order ``B = a sin α + c sin γ`` (eq. 4), is a product and is **the same in both
  faces**. The second-order term ``-(a² + c²)/(2R)`` is also face-independent.

Model, for row ``i`` (target ``j``, face sign ``f_i = +1`` for I, ``-1`` for II, elevation ``φ_i``)::

    m_i = sqrt(R_j² + Toh² + 2 f_i Toh R_j cos φ_i)

with ``R_j`` the target's *face-mean* distance, which lumps the true distance, the head's
beam-offset term ``B`` and the instrument's additive constant ``K``: ``R_j = Rt_j + B + K``.
Hence

- ``Toh`` is observable (from ``m_I - m_II ≈ 2 Toh cos φ``), if some target has both faces at an
  elevation with ``cos φ`` away from 0;
- the beam offset is observable only through ``B + K``, and only when the true distance ``Rt_j`` of
  some target is known (a ``reference_distance_m``): then ``R_j = Rt_j + C`` and the constant
  ``C = B + K`` is estimated. ``B`` and ``K`` cannot be separated by distances (both are additive
  constants of the head, which the self-calibration also absorbs in the head's offset);
- ``a``, ``c``, ``α``, ``γ`` individually are not observable from distances (the paper measures
  them from where the beam lands); nor is ``a² + c²`` in practice (its 1/R signature is below
  0.3 µm beyond 0.2 m for the 320 µm worst offset).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.io import read_csv_table

__all__ = ["TwoFaceData", "TwoFaceResult", "read_two_face", "estimate_two_face", "face_model"]

_FACES = {"i": 1, "1": 1, "front": 1, "f1": 1, "ii": -1, "2": -1, "back": -1, "f2": -1}


@dataclass(frozen=True)
class TwoFaceData:
    """Two-face readings (``m`` rows).

    Attributes
    ----------
    head : str or None
    target_ids : tuple of str (m,)
    face : ndarray (m,) int, +1 (face I) or -1 (face II)
    distance_m : ndarray (m,)
        Corrected distances (air index applied; transit offsets *not* corrected).
    elevation_rad : ndarray (m,)
        Line-of-sight elevation in the face-I convention of eq. (2), the same for both faces.
    sigma_m : ndarray (m,) or None
    reference_distance_m : ndarray (m,)
        Known true distance of the row's target (NaN when unknown).
    """

    head: str | None
    target_ids: tuple[str, ...]
    face: np.ndarray
    distance_m: np.ndarray
    elevation_rad: np.ndarray
    sigma_m: np.ndarray | None
    reference_distance_m: np.ndarray


def read_two_face(path: str | os.PathLike) -> TwoFaceData:
    """Read ``target,face,distance_m,elevation_rad[,sigma_m][,reference_distance_m][,head]``.

    ``face`` is ``I``/``II`` (also ``1``/``2``, ``front``/``back``). Errors name ``FILE:LINE``.
    """
    t = read_csv_table(path, required=("target", "face", "distance_m", "elevation_rad"),
                       optional=("sigma_m", "reference_distance_m", "head"))
    where = lambda i: f"{t.path}:{t.line_numbers[i]}"  # noqa: E731
    faces = np.empty(len(t.rows), dtype=int)
    for i, s in enumerate(t.column("face")):
        f = _FACES.get(s.strip().lower())
        if f is None:
            raise MultilatError(f"{where(i)}: column 'face': expected I or II, got {s!r}")
        faces[i] = f
    targets = tuple(t.column("target"))
    for i, s in enumerate(targets):
        if not s:
            raise MultilatError(f"{where(i)}: empty target id")
    head = None
    if t.has("head"):
        hs = t.ids("head")
        head = hs[0]
        for i, h in enumerate(hs):
            if h != head:
                raise MultilatError(f"{where(i)}: one head per file (got {head!r} and {h!r})")
    ref = t.floats("reference_distance_m", required=False, positive=True) \
        if t.has("reference_distance_m") else np.full(len(t.rows), np.nan)
    for j in set(targets):
        rows = [i for i, s in enumerate(targets) if s == j]
        r = ref[rows]
        if np.any(np.isfinite(r)) and (np.any(np.isnan(r)) or np.ptp(r) > 0):
            raise MultilatError(f"{where(rows[0])}: target {j!r}: reference_distance_m must be the "
                                f"same on all its rows")
    return TwoFaceData(head=head, target_ids=targets, face=faces,
                       distance_m=t.floats("distance_m", positive=True),
                       elevation_rad=t.floats("elevation_rad"),
                       sigma_m=t.floats("sigma_m", positive=True) if t.has("sigma_m") else None,
                       reference_distance_m=ref)


def face_model(range_m, toh_m, face, elevation_rad):
    """Measured distance in a face: ``sqrt(R² + Toh² + 2 f Toh R cos φ)`` (eq. 2 with the face sign).

    Broadcasts; ``face`` is +1 (I) or -1 (II). Metres, radians.
    """
    r = np.asarray(range_m, dtype=float)
    return np.sqrt(r * r + toh_m * toh_m + 2.0 * np.asarray(face) * toh_m * r * np.cos(elevation_rad))


@dataclass(frozen=True)
class TwoFaceResult:
    """Estimates from two-face distances.

    Attributes
    ----------
    head : str or None
    transit_offset_m, transit_offset_std_m : float
        ``Toh`` and its standard uncertainty.
    constant_m, constant_std_m : float or None
        ``C = B + K`` (beam-offset term plus the instrument's additive constant), only when some
        target has a reference distance.
    target_ids : tuple of str
    target_distance_m, target_distance_std_m : ndarray (t,)
        Face-mean distance ``R_j`` of each target (``Rt_j + C`` for reference targets).
    parameters : tuple of str
        Labels of ``covariance`` (``"toh"``, ``"constant"``, ``"R:<target>"``).
    covariance : ndarray (p, p)
        Covariance of the parameters (a priori sigmas; see ``scaled``).
    residuals_m : ndarray (m,)
    chi2 : float
    dof : int
    sigma0 : float
        ``sqrt(chi2/dof)`` (NaN if dof = 0).
    scaled : bool
        True when no sigma_m was given: unit weights, covariance scaled by ``sigma0²``.
    """

    head: str | None
    transit_offset_m: float
    transit_offset_std_m: float
    constant_m: float | None
    constant_std_m: float | None
    target_ids: tuple[str, ...]
    target_distance_m: np.ndarray
    target_distance_std_m: np.ndarray
    parameters: tuple[str, ...]
    covariance: np.ndarray
    residuals_m: np.ndarray
    chi2: float
    dof: int
    sigma0: float
    scaled: bool


def _reference_per_target(data, tix, n_targets: int) -> np.ndarray:
    """The known distance of each target (the largest given on its rows; NaN where none is)."""
    return np.array([np.nanmax(np.r_[data.reference_distance_m[tix == j], np.nan])
                     if np.any(np.isfinite(data.reference_distance_m[tix == j])) else np.nan
                     for j in range(n_targets)])


def _require_both_faces(data, tix, n_targets: int) -> None:
    """Raise unless some target is read in both faces at an elevation whose cosine is away from 0
    (else the transit offset is not observable)."""
    both = [j for j in range(n_targets)
            if {1, -1} <= set(data.face[tix == j].tolist())
            and np.any(np.abs(np.cos(data.elevation_rad[tix == j])) > 0.01)]
    if not both:
        raise MultilatError("transit offset not observable: no target measured in both faces at an "
                            "elevation with cos(elevation) away from 0")


def estimate_two_face(data: TwoFaceData, *, sigma_m=None) -> TwoFaceResult:
    """Weighted least squares of the two-face model (module docstring) by Gauss-Newton.

    Parameters
    ----------
    data : TwoFaceData
    sigma_m : float or ndarray (m,), optional
        Standard uncertainty of each distance (overrides ``data.sigma_m``). Without any, unit
        weights are used and the covariance is scaled by the a-posteriori ``sigma0²``.

    Raises
    ------
    MultilatError
        If ``Toh`` is not observable (no target in both faces with ``|cos φ|`` > 0.01), or without
        sigmas when there is no redundancy.
    """
    m = data.distance_m.size
    sig = sigma_m if sigma_m is not None else data.sigma_m
    scaled = sig is None
    sig = np.ones(m) if sig is None else np.broadcast_to(np.asarray(sig, dtype=float), (m,)).copy()
    targets = tuple(dict.fromkeys(data.target_ids))
    tix = np.array([targets.index(s) for s in data.target_ids])
    ref_t = _reference_per_target(data, tix, len(targets))
    has_ref = np.isfinite(ref_t)
    _require_both_faces(data, tix, len(targets))
    free = [j for j in range(len(targets)) if not has_ref[j]]
    labels = ["toh"] + (["constant"] if has_ref.any() else []) + [f"R:{targets[j]}" for j in free]
    p = len(labels)
    dof = m - p
    if scaled and dof <= 0:
        raise MultilatError("no sigma_m given and no redundancy (dof = 0): give sigma_m")
    col_of = {j: labels.index(f"R:{targets[j]}") for j in free}

    x = np.zeros(p)
    if has_ref.any():
        x[1] = float(np.mean([np.mean(data.distance_m[tix == j]) - ref_t[j]
                              for j in range(len(targets)) if has_ref[j]]))
    for j in free:
        x[col_of[j]] = np.mean(data.distance_m[tix == j])

    def ranges(x):
        r = np.empty(len(targets))
        for j in range(len(targets)):
            r[j] = ref_t[j] + x[1] if has_ref[j] else x[col_of[j]]
        return r

    cosv = np.cos(data.elevation_rad)
    for _ in range(50):
        R = ranges(x)[tix]
        toh = x[0]
        pred = face_model(R, toh, data.face, data.elevation_rad)
        res = data.distance_m - pred
        dR = (R + data.face * toh * cosv) / pred
        J = np.zeros((m, p))
        J[:, 0] = (toh + data.face * R * cosv) / pred
        for i in range(m):
            j = tix[i]
            J[i, 1 if has_ref[j] else col_of[j]] = dR[i]
        Jw = J / sig[:, None]
        step, *_ = np.linalg.lstsq(Jw, res / sig, rcond=None)
        x = x + step
        if np.max(np.abs(step)) < 1e-13:
            break
    R = ranges(x)[tix]
    res = data.distance_m - face_model(R, x[0], data.face, data.elevation_rad)
    N = Jw.T @ Jw
    if np.linalg.cond(N) > 1e14:
        raise MultilatError("two-face problem is singular (transit offset not separable from the "
                            "distances with these faces and elevations)")
    cov = np.linalg.inv(N)
    chi2 = float(np.sum((res / sig) ** 2))
    sigma0 = float(np.sqrt(chi2 / dof)) if dof > 0 else float("nan")
    if scaled:
        cov = cov * sigma0**2
    std = np.sqrt(np.diag(cov))
    # face-mean distance of every target and its uncertainty
    tdist = ranges(x)
    tstd = np.empty(len(targets))
    for j in range(len(targets)):
        if has_ref[j]:
            tstd[j] = std[1]
        else:
            tstd[j] = std[col_of[j]]
    return TwoFaceResult(
        head=data.head, transit_offset_m=float(x[0]), transit_offset_std_m=float(std[0]),
        constant_m=float(x[1]) if has_ref.any() else None,
        constant_std_m=float(std[1]) if has_ref.any() else None,
        target_ids=targets, target_distance_m=tdist, target_distance_std_m=tstd,
        parameters=tuple(labels), covariance=cov, residuals_m=res, chi2=chi2, dof=int(dof),
        sigma0=sigma0, scaled=scaled)
