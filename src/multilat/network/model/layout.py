"""The one parameter layout of a general network: the name, column, value and free flag of every
parameter the observations need.

Columns ``0 .. n-1`` index the *full* parameter vector ``x`` (fixed parameters included, so a kind
never needs to know what is held); the adjustment solves for the free ones, whose reduced column is
``reduced[col]`` (``-1`` for a held parameter). Column ``-1`` in a kind's Jacobian means "no
parameter" (an observation without an instrument, say) and is dropped at assembly.

Parameters, by name:

* ``x:P``, ``y:P``, ``z:P``: the coordinates of point P (metres), free unless the point's status
  holds them (:mod:`.points`);
* ``offset:I``, ``scale:I``: instrument I's additive constant (metres) and scale (dimensionless,
  ``d = (1 + scale) rho + offset``), estimated or held per instrument;
* ``orientation:S``: the orientation unknown of direction set S (radians);
* ``omega:U``, ``phi:U``, ``kappa:U``: the frame of instrument set-up U (a tracker; ``R = Rz(kappa)
  Ry(phi) Rx(omega)``, :mod:`multilat.network.model.angles`); ``omega`` and ``phi`` held at 0 when levelled.
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.points import FIXED, PointSet

__all__ = ["Layout"]


class Layout:
    """Parameters of one network: built from its points, extended by each kind's ``register``."""

    def __init__(self, points: PointSet):
        self.points = points
        # the points' coordinates in one pass (what ``add`` does name by name; the ids are unique)
        self.names: list[str] = [f"{c}:{p}" for p in points.ids for c in "xyz"]
        xyz = np.asarray(points.xyz_m, float).reshape(-1)
        self._values: list[float] = np.where(np.isfinite(xyz), xyz, 0.0).tolist()
        self._free: list[bool] = (np.asarray(points.status).reshape(-1) != FIXED).tolist()
        self._col: dict[str, int] = dict(zip(self.names, range(len(self.names))))
        self.point_cols = np.arange(3 * points.n).reshape(points.n, 3)

    def add(self, name: str, value: float = 0.0, *, free: bool = True) -> int:
        """The column of parameter ``name``, created with ``value`` and ``free`` on first use.
        A second registration must agree on the free flag."""
        col = self._col.get(name)
        if col is not None:
            if self._free[col] != free:
                raise MultilatError(f"parameter {name!r} is registered both free and held")
            return col
        col = len(self.names)
        self._col[name] = col
        self.names.append(name)
        self._values.append(float(value))
        self._free.append(bool(free))
        return col

    def column(self, name: str) -> int:
        try:
            return self._col[name]
        except KeyError:
            raise MultilatError(f"no parameter {name!r} in the layout") from None

    def columns(self, prefix: str, keys, *, value: float = 0.0, free: bool = True) -> np.ndarray:
        """Columns of ``prefix:key`` for each key (int array), registering them as needed."""
        return np.array([self.add(f"{prefix}:{k}", value, free=free) for k in keys], int).reshape(-1)

    @property
    def n(self) -> int:
        return len(self.names)

    @property
    def free(self) -> np.ndarray:
        return np.array(self._free, bool)

    @property
    def reduced(self) -> np.ndarray:
        """Full column -> reduced (free) column, -1 for a held parameter; one extra entry for column -1."""
        f = self.free
        red = np.full(self.n + 1, -1, int)
        red[:-1][f] = np.arange(int(f.sum()))
        return red

    def initial(self) -> np.ndarray:
        """The full parameter vector at its registered (approximate or held) values."""
        return np.array(self._values, float)

    def set_value(self, name: str, value: float) -> None:
        self._values[self.column(name)] = float(value)

    def point_coordinate_mask(self) -> np.ndarray:
        """(n,) bool: the columns that are point coordinates."""
        m = np.zeros(self.n, bool)
        m[self.point_cols.ravel()] = True
        return m

    def owner(self, col: int) -> str:
        """The name of parameter ``col`` (for messages)."""
        return self.names[col]
