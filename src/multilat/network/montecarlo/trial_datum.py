"""The datum of the batched Monte Carlo solver: every trial's solution moved the same way into the
one datum definition (:class:`multilat.network.model.datum.Datum`), in index form."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.datum import ABOUT_Z_COLUMNS, RIGID_FIT_ITERATIONS, frame_axes, helmert_basis, parse_datum
from multilat.network.model.parameter_layout import ParameterLayout

__all__ = ["TrialDatum"]


def _rotation_from_vector(omega: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation matrices (n, 3, 3) from rotation vectors (n, 3) in radians."""
    th = np.sqrt(np.einsum("ni,ni->n", omega, omega))
    small = th < 1e-8
    ths = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th**2 / 6.0, np.sin(ths) / ths)
    b = np.where(small, 0.5 - th**2 / 24.0, (1.0 - np.cos(ths)) / ths**2)
    k = np.zeros(omega.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2] = -omega[..., 2], omega[..., 1]
    k[..., 1, 0], k[..., 1, 2] = omega[..., 2], -omega[..., 0]
    k[..., 2, 0], k[..., 2, 1] = -omega[..., 1], omega[..., 0]
    eye = np.broadcast_to(np.eye(3), k.shape)
    return eye + a[..., None, None] * k + b[..., None, None] * (k @ k)



@dataclass(frozen=True)
class TrialDatum:
    """How every solution is placed in space (the same way in every trial): the index form of the
    one datum definition, :class:`multilat.network.model.datum.Datum` (build it with :meth:`from_datum`).

    Use the constructors:

    ``TrialDatum.inner(points="all"|"stations"|"targets"|sequence of ('station'|'target', index))``
        Least-squares rigid fit (Kabsch) of the datum points onto their nominal coordinates. To first
        order this is the inner-constraint (free-network, minimum-trace over the datum points) datum
        of the adjustment: the linearised conditions ``G^T (x - x_nominal) = 0`` of the inner
        constraints are exactly the stationarity conditions of the rigid fit.
    ``TrialDatum.three_two_one(origin, axis, plane)`` (station indices or ``(kind, index)``)
        Point ``origin`` keeps its nominal position, the direction ``origin -> axis`` its nominal
        direction, and the plane (origin, axis, plane) its nominal orientation. With nominal
        coordinates from ``adjust(..., datum="321:A,B,C")`` (A at the origin, B on +x, C in the
        xy-plane) this is exactly that datum in every trial.
    """

    kind: str
    points: object = "all"
    about_z: bool = False          # levelled stations observe the vertical: translations and a turn about z

    @property
    def n_defect(self) -> int:
        """Datum defects it fixes: 6, or 4 about z (the vertical observed by levelled stations)."""
        return 4 if self.about_z else 6

    @classmethod
    def from_datum(cls, datum, station_ids, target_ids, *, about_z: bool = False) -> "TrialDatum":
        """The index form of a :class:`multilat.network.model.datum.Datum` (or its text, e.g.
        ``"321:B,D,C"``) for the network ``station_ids``/``target_ids``: the one datum definition,
        applied to every trial. The control datum is refused (it fixes points that a Monte Carlo
        must perturb too). ``about_z``: the vertical is observed (levelled stations): the free datum
        fits translations and a rotation about z only; 321 is refused (it would tilt the network)."""
        d = parse_datum(datum)
        station_ids, target_ids = list(station_ids), list(target_ids)

        def ref(p):
            if p in station_ids:
                return ("station", station_ids.index(p))
            if p in target_ids:
                return ("target", target_ids.index(p))
            raise MultilatError(f"datum point {p!r} is neither a station nor a target")

        if d.kind == "free":
            inner = cls.inner("all" if d.points is None else [ref(p) for p in d.points])
            return cls(inner.kind, inner.points, about_z) if about_z else inner
        if d.kind == "321" and about_z:
            raise MultilatError("datum 321 would tilt a network whose vertical is observed (levelled stations)")
        if d.kind == "321":
            return cls.three_two_one(*[ref(p) for p in d.points])
        raise MultilatError("propagation supports the free and 321 datums (a control datum fixes points "
                            "that the Monte Carlo would have to perturb too)")

    @classmethod
    def inner(cls, points="all") -> "TrialDatum":
        if isinstance(points, str):
            if points not in ("all", "stations", "targets"):
                raise MultilatError(f"datum points must be all, stations or targets, got {points!r}")
            return cls("inner", points)
        pts = tuple((str(k), int(i)) for k, i in points)
        for k, _ in pts:
            if k not in ("station", "target"):
                raise MultilatError(f"datum point kind must be 'station' or 'target', got {k!r}")
        if len(pts) < 3:
            raise MultilatError("an inner datum needs at least 3 points")
        return cls("inner", pts)

    @classmethod
    def three_two_one(cls, origin, axis, plane) -> "TrialDatum":
        """Each point: a station index (int) or ``("station"|"target", index)``."""
        pts = tuple(("station", int(p)) if isinstance(p, (int, np.integer)) else (str(p[0]), int(p[1]))
                    for p in (origin, axis, plane))
        for k, _ in pts:
            if k not in ("station", "target"):
                raise MultilatError(f"datum point kind must be 'station' or 'target', got {k!r}")
        if len(set(pts)) != 3:
            raise MultilatError(f"3-2-1 datum needs three different points, got {pts}")
        return cls("321", pts)

    def _stacked(self, s: int, t: int) -> list[int]:
        """Indices of the 3-2-1 points in the stacked [stations; targets] array."""
        out = []
        for k, i in self.points:
            lim = s if k == "station" else t
            if not 0 <= i < lim:
                raise MultilatError(f"datum {k} index {i} out of range (0..{lim - 1})")
            out.append(i if k == "station" else s + i)
        return out

    # -- internals ------------------------------------------------------------------------
    def _mask(self, s: int, t: int) -> np.ndarray:
        """Boolean mask over the stacked points [stations; targets] used by an inner datum."""
        m = np.zeros(s + t, bool)
        if self.points == "all":
            m[:] = True
        elif self.points == "stations":
            m[:s] = True
        elif self.points == "targets":
            m[s:] = True
        else:
            for k, i in self.points:
                lim = s if k == "station" else t
                if not 0 <= i < lim:
                    raise MultilatError(f"datum {k} index {i} out of range (0..{lim - 1})")
                m[i if k == "station" else s + i] = True
        return m

    def constraint_matrix(self, station_xyz_m: np.ndarray, target_xyz_m: np.ndarray) -> np.ndarray:
        """Linear datum conditions ``E^T dx = 0`` at the nominal point, shape (4s + 3t, 6), or
        (4s + 3t, 4) about z (translations and the rotation about z)."""
        h0 = np.asarray(station_xyz_m, float)
        t0 = np.asarray(target_xyz_m, float)
        s, t = len(h0), len(t0)
        layout = ParameterLayout.batched(s, t)
        if self.kind == "inner":
            mask = self._mask(s, t)
            g = helmert_basis(np.concatenate([h0, t0])).reshape(s + t, 3, 6) * mask[:, None, None]
            e = layout.datum_rows(g.reshape(-1, 6))
            return e[:, ABOUT_Z_COLUMNS] if self.about_z else e
        e = np.zeros((layout.n, 6))
        a, b, c = self._stacked(s, t)
        x0 = np.concatenate([h0, t0])
        ex, ey, ez = frame_axes(x0[a], x0[b], x0[c])
        rows = layout.point_columns()[[a, b, c]]                     # (3, 3): each point's x, y, z
        e[rows[0], 0:3] = np.eye(3)
        e[rows[1], 3] = ey
        e[rows[1], 4] = ez
        e[rows[2], 5] = ez
        return e

    def apply(self, station_xyz_m, target_xyz_m, nominal_station_xyz_m, nominal_target_xyz_m, *,
              engine: str = "numpy"):
        """Move each trial's network rigidly into this datum.

        Parameters
        ----------
        station_xyz_m : ndarray, shape (n, s, 3)
        target_xyz_m : ndarray, shape (n, t, 3)
        nominal_station_xyz_m : ndarray, shape (s, 3)
        nominal_target_xyz_m : ndarray, shape (t, 3)

        Returns
        -------
        (station_xyz_m, target_xyz_m) : ndarrays, shapes (n, s, 3) and (n, t, 3)
        """
        h = np.asarray(station_xyz_m, float)
        tg = np.asarray(target_xyz_m, float)
        h0 = np.asarray(nominal_station_xyz_m, float)
        t0 = np.asarray(nominal_target_xyz_m, float)
        s, t = h0.shape[0], t0.shape[0]
        if self.kind == "321":
            a, b, c = self._stacked(s, t)
            x0 = np.concatenate([h0, t0])
            x = np.concatenate([h, tg], axis=1)
            f0 = np.stack(frame_axes(x0[a], x0[b], x0[c]), axis=0)          # rows ex, ey, ez (3, 3)
            f = np.stack(frame_axes(x[:, a], x[:, b], x[:, c]), axis=-2)   # (n, 3, 3) rows
            rot = np.einsum("ji,njk->nik", f0, f)                        # R = F0^T F
            org, org0 = x[:, a], x0[a]
            hn = np.einsum("nij,nsj->nsi", rot, h - org[:, None]) + org0
            tn = np.einsum("nij,ntj->nti", rot, tg - org[:, None]) + org0
            return hn, tn
        mask = self._mask(s, t)
        x0 = np.concatenate([h0, t0])[mask]                     # (q, 3)
        c0 = x0.mean(axis=0)
        g = helmert_basis(x0)                                   # about the nominal centroid
        cols = ABOUT_Z_COLUMNS if self.about_z else list(range(6))
        gk = g[:, cols]
        proj = np.zeros_like(g)                                 # about z: no rotation about x and y
        proj[:, cols] = gk @ np.linalg.inv(gk.T @ gk)
        proj = proj.reshape(-1, 3, 6)                           # (q, 3, 6)
        if engine == "numba":
            from multilat.network.montecarlo import _batched_numba as nb
            pts = np.ascontiguousarray(np.concatenate([h, tg], axis=1))
            nb.apply_inner(pts, np.nonzero(mask)[0], x0 - c0, np.ascontiguousarray(proj), c0, RIGID_FIT_ITERATIONS)
            return pts[:, :s], pts[:, s:]
        pts = np.concatenate([h, tg], axis=1) - c0              # (n, s + t, 3)
        for _ in range(RIGID_FIT_ITERATIONS):   # Gauss-Newton on the rigid fit (rotations ~1e-5 rad)
            dev = pts[:, mask] - (x0 - c0)
            xi = -np.tensordot(dev, proj, axes=([1, 2], [0, 1]))  # (n, 6)
            rot = _rotation_from_vector(xi[:, 3:])
            pts = pts @ rot.transpose(0, 2, 1) + xi[:, None, :3]
            if np.max(np.abs(xi)) < 1e-15:
                break
        pts = pts + c0
        hn, tn = pts[:, :s], pts[:, s:]
        return hn, tn
