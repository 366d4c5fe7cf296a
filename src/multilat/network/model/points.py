"""One set of points for the general network: ids, approximate coordinates, and the status of each
coordinate.

Every point of a network is one entry here, whatever it carries: an instrument set-up, a target, a
control point, a nest measured before and occupied later. Coordinates are in multilat's frame
(x east, y north, z up; metres, ``docs/conventions.md``). Each of x, y, z has its own status:

* ``FREE``: an unknown of the adjustment;
* ``FIXED``: held at its value (a control point, or the xy of a point whose height is unknown:
  ``fix="xy"`` in gama-local; or its z, ``fix="z"``);
* ``WEIGHTED``: an unknown that is also observed, its value the observation, ``sigma_m`` its
  standard uncertainty (a weighted control point; :meth:`PointSet.weighted_rows` gives the rows for
  the observed-coordinates kind).

``constrained`` marks the points whose free coordinates carry the datum of a free network (inner
constraints, minimum trace over them; gama-local's upper-case ``adj="XYZ"``). A NaN coordinate is
one without an approximate value yet (:mod:`.approximate` computes it from the observations).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError

__all__ = ["FREE", "FIXED", "WEIGHTED", "PointSet"]

FREE, FIXED, WEIGHTED = 0, 1, 2
_STATUS_NAMES = {FREE: "free", FIXED: "fixed", WEIGHTED: "weighted"}


@dataclass(frozen=True, eq=False)
class PointSet:
    """Points of a network.

    ids : tuple of str, (n,)
    xyz_m : ndarray (n, 3)  approximate (free) or given (fixed, weighted) coordinates, metres; NaN = none yet
    status : ndarray (n, 3) int  ``FREE``, ``FIXED`` or ``WEIGHTED`` per coordinate
    sigma_m : ndarray (n, 3)  standard uncertainty of a weighted coordinate (NaN elsewhere), metres
    constrained : ndarray (n,) bool  datum points of a free network (minimum trace over their free coordinates)
    """

    ids: tuple
    xyz_m: np.ndarray
    status: np.ndarray
    sigma_m: np.ndarray
    constrained: np.ndarray

    def __post_init__(self):
        n = len(self.ids)
        if len(set(self.ids)) != n:
            dup = next(p for p in self.ids if self.ids.count(p) > 1)
            raise MultilatError(f"point {dup!r} is given twice")
        for name, arr, shape in (("xyz_m", self.xyz_m, (n, 3)), ("status", self.status, (n, 3)),
                                 ("sigma_m", self.sigma_m, (n, 3)), ("constrained", self.constrained, (n,))):
            if np.shape(arr) != shape:
                raise MultilatError(f"PointSet.{name}: expected shape {shape}, got {np.shape(arr)}")
        held = self.status != FREE
        if np.any(held & ~np.isfinite(self.xyz_m)):
            i, c = np.argwhere(held & ~np.isfinite(self.xyz_m))[0]
            raise MultilatError(f"point {self.ids[i]!r}: its {'xyz'[c]} is {_STATUS_NAMES[self.status[i, c]]} "
                                "but has no value")
        w = self.status == WEIGHTED
        if np.any(w & ~(np.isfinite(self.sigma_m) & (self.sigma_m > 0))):
            i, c = np.argwhere(w & ~(np.isfinite(self.sigma_m) & (self.sigma_m > 0)))[0]
            raise MultilatError(f"point {self.ids[i]!r}: weighted {'xyz'[c]} needs a finite sigma_m > 0")

    @classmethod
    def build(cls, ids, xyz_m=None, *, status=None, sigma_m=None, constrained=None) -> "PointSet":
        """Points with defaults: every coordinate free, no approximate values, none constrained.
        ``status`` may be (n, 3) or (n,) (one status for the three coordinates)."""
        ids = tuple(str(p) for p in ids)
        n = len(ids)
        xyz = np.full((n, 3), np.nan) if xyz_m is None else np.array(xyz_m, float).reshape(n, 3)
        st = np.zeros((n, 3), int) if status is None else np.array(status, int)
        st = np.repeat(st[:, None], 3, 1) if st.ndim == 1 else st.reshape(n, 3)
        sg = np.full((n, 3), np.nan) if sigma_m is None else np.array(sigma_m, float).reshape(n, 3)
        cn = np.zeros(n, bool) if constrained is None else np.array(constrained, bool).reshape(n)
        return cls(ids, xyz, st, sg, cn)

    @property
    def n(self) -> int:
        return len(self.ids)

    def index(self, pid: str) -> int:
        try:
            return self._lookup()[pid]
        except KeyError:
            raise MultilatError(f"unknown point {pid!r}") from None

    def _lookup(self) -> dict:
        d = self.__dict__.get("_ix")
        if d is None:
            d = {p: i for i, p in enumerate(self.ids)}
            object.__setattr__(self, "_ix", d)
        return d

    def with_xyz(self, xyz_m) -> "PointSet":
        """The same points with other (approximate) coordinates; held coordinates keep their values."""
        xyz = np.array(xyz_m, float).reshape(self.n, 3)
        held = self.status != FREE
        xyz[held] = self.xyz_m[held]
        return PointSet(self.ids, xyz, self.status, self.sigma_m, self.constrained)

    def weighted_rows(self):
        """The weighted coordinates as observations: (point index, axis, value_m, sigma_m) arrays."""
        i, c = np.nonzero(self.status == WEIGHTED)
        return i, c, self.xyz_m[i, c], self.sigma_m[i, c]
