"""The parameters of a general network: the name, column, value and free flag of every parameter the
observations need, on the one parameter layout
(:class:`multilat.network.model.parameter_layout.ParameterLayout`: the points' ``x, y, z`` its first
block, each registration a block after it; the names, the reduced columns written there once).

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
from multilat.network.model.parameter_layout import ParameterLayout, parameter_name, reduced_columns
from multilat.network.model.points import FIXED, PointSet

__all__ = ["Layout"]


class Layout:
    """Parameters of one network: built from its points, extended by each kind's ``register``."""

    def __init__(self, points: PointSet):
        self.points = points
        self.params = ParameterLayout.general(points.n)
        # the points' coordinates in one pass (what ``add`` does name by name; the ids are unique)
        self.point_cols = self.params.point_columns()
        self.names: list[str] = self.params.blocks[0].names(points.ids)
        xyz = np.asarray(points.xyz_m, float).reshape(-1)
        self._values: list[float] = np.where(np.isfinite(xyz), xyz, 0.0).tolist()
        self._free: list[bool] = (np.asarray(points.status).reshape(-1) != FIXED).tolist()
        self._col: dict[str, int] = dict(zip(self.names, range(len(self.names))))

    def _check(self, name: str, col: int, free: bool) -> int:
        if self._free[col] != free:
            raise MultilatError(f"parameter {name!r} is registered both free and held")
        return col

    def add(self, name: str, value: float = 0.0, *, free: bool = True) -> int:
        """The column of parameter ``name`` (``field:owner``), created with ``value`` and ``free`` on
        first use. A second registration must agree on the free flag."""
        col = self._col.get(name)
        if col is not None:
            return self._check(name, col, free)
        field, _, owner = name.partition(":")
        return int(self._append(field, [owner], value, free)[0])

    def _append(self, field: str, owners: list, value: float, free: bool) -> np.ndarray:
        """A block of ``field`` for new ``owners``: its (len(owners),) columns."""
        cols = self.params.append(field, (field,), len(owners)).ravel()
        names = self.params.blocks[-1].names(owners)
        self._col.update(zip(names, cols.tolist()))
        self.names.extend(names)
        self._values.extend([float(value)] * len(owners))
        self._free.extend([bool(free)] * len(owners))
        return cols

    def column(self, name: str) -> int:
        try:
            return self._col[name]
        except KeyError:
            raise MultilatError(f"no parameter {name!r} in the layout") from None

    def columns(self, prefix: str, keys, *, value: float = 0.0, free: bool = True) -> np.ndarray:
        """Columns of ``prefix:key`` for each key (int array), the new keys registered as one block."""
        names = [parameter_name(prefix, k) for k in keys]
        new = {n: k for n, k in zip(names, keys) if n not in self._col}
        if new:
            self._append(prefix, list(new.values()), value, free)
        return np.array([self._check(n, self._col[n], free) for n in names], int).reshape(-1)

    @property
    def n(self) -> int:
        return self.params.n

    @property
    def free(self) -> np.ndarray:
        return np.array(self._free, bool)

    @property
    def reduced(self) -> np.ndarray:
        """Full column -> reduced (free) column, -1 for a held parameter; one extra entry for column -1."""
        return reduced_columns(self.free)

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
