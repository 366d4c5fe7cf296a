"""The one parameter layout: which column holds station i's ``x``, offset or scale, head h's offset,
target j's ``x``, an orientation, or (the general layer, :class:`multilat.network.model.layout.Layout`)
point P's ``x`` and instrument I's offset; with names, free flags, reduced columns, head ties and
datum rows (issue 27).

A layout is an ordered list of blocks. A block holds a group of fields for every owner of one kind
(``station``, ``head``, ``target``, ``orientation``), owner-major: owner ``k``'s field ``f`` is column
``start + k * len(fields) + fields.index(f)``. That arithmetic is written here once; everything else
asks for the columns (:meth:`ParameterLayout.columns`, :meth:`block`, :meth:`point_columns`) and the
compiled kernels take the arrays it returns. The layouts in use, one constructor each:

``adjustment(s, t)``      the adjustment's vector: ``x, y, z, offset, scale`` per station, then
                          ``x, y, z`` per target (``t = 0``: the reduced, station-only system of the
                          Schur complement), then the orientations of the stations with angles;
                          :data:`multilat.network.model.distance.Q` is its block width
``station_system(s)``     the Schur-reduced station system ``x, y, z, offset`` per station (the
                          sparse kernels, the batched solver's frozen matrix, the fast design
                          evaluator; ``offsets=False``: ``x, y, z``), with the targets ``t > 0``
``batched(s, t)``         the Monte Carlo's reported vector ``[station xyz (3s), offsets (s), target
                          xyz (3t)]`` (:func:`multilat.network.montecarlo.batched.flatten`, linear covariances)
``coupled(s, t, head_index, n_oriented)``  the general Monte Carlo's unknowns ``[station xyz, head
                          offsets, head scales, target xyz, orientations]``

``general(n_points)``      the general layer's vector: ``x, y, z`` per point, then the parameters the
                          kinds register (:meth:`append`, one block per registration: ``offset``,
                          ``scale``, ``orientation``, ``omega``, ...) in the order they register

A field held per head in one layout and per station in another is the head tie: station ``i``'s
offset is its head's column (:meth:`station_columns`, :meth:`index_in`, :meth:`tie_source`).

A parameter's name is ``field:owner`` (:func:`parameter_name`: ``x:P``, ``offset:I``,
``orientation:S``), the vocabulary of docs/general-network.md; the distance path's offsets and
scales are named by their head. The adjustment solves for the free parameters; the reduced column
of full column ``c`` is ``reduced_columns(free)[c]`` (-1 for a held one).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ParameterLayout", "STATION_FIELDS", "XYZ", "ORIENTATION_FIELDS", "gather", "parameter_name",
           "reduced_columns"]

XYZ = ("x", "y", "z")
STATION_FIELDS = XYZ + ("offset", "scale")
ORIENTATION_FIELDS = ("omega", "phi", "kappa")


def gather(v, cols) -> np.ndarray:
    """``v[..., cols]`` (a leading trial axis allowed) as a C-ordered array: the memory order a
    reshape of the vector would have (numpy's ``einsum`` sums in memory order, so the numbers stay
    those of the reshape, bit for bit)."""
    return np.ascontiguousarray(np.asarray(v)[..., cols])


def parameter_name(field: str, owner) -> str:
    """The printed name of ``field`` of ``owner``: ``x:P``, ``offset:I``, ``kappa:T1``."""
    return f"{field}:{owner}"


def reduced_columns(free) -> np.ndarray:
    """(n + 1,) full column -> reduced (free) column, -1 for a held parameter; the extra last entry
    (-1) is column -1's ("no parameter" in a kind's Jacobian)."""
    f = np.asarray(free, bool)
    red = np.full(f.size + 1, -1, int)
    red[:-1][f] = np.arange(int(f.sum()))
    return red


@dataclass(frozen=True)
class _Block:
    kind: str
    count: int
    fields: tuple[str, ...]
    start: int

    def columns(self) -> np.ndarray:
        """(count, len(fields)) columns of the block."""
        return self.start + np.arange(self.count * len(self.fields)).reshape(self.count, len(self.fields))

    def names(self, owners) -> list[str]:
        """Names of the block's columns in column order, owner-major."""
        return [parameter_name(f, o) for o in owners for f in self.fields]


class ParameterLayout:
    """Columns of one parameter vector, the distance path's or the general layer's (see the module docstring)."""

    def __init__(self, blocks, *, n_stations: int = 0, n_targets: int = 0, head_index=None, n_oriented: int = 0,
                 n_points: int = 0):
        self.n_stations, self.n_targets = int(n_stations), int(n_targets)
        self.head_index = (np.arange(self.n_stations) if head_index is None
                           else np.asarray(head_index, np.int64).reshape(-1))
        self.n_heads = int(self.head_index.max()) + 1 if self.head_index.size else 0
        counts = {"station": self.n_stations, "head": self.n_heads, "target": self.n_targets,
                  "orientation": int(n_oriented), "point": int(n_points)}
        self.blocks: tuple[_Block, ...] = ()
        self.n = 0
        for kind, fields in blocks:
            self.append(kind, fields, counts[kind])

    def append(self, kind: str, fields, count: int) -> np.ndarray:
        """A new block of ``fields`` for ``count`` owners of ``kind`` after the last column; its
        (count, len(fields)) columns."""
        b = _Block(kind, int(count), tuple(fields), self.n)
        self.blocks += (b,)
        self.n += b.count * len(b.fields)
        return b.columns()

    # -- the layouts in use ---------------------------------------------------------------------
    @classmethod
    def adjustment(cls, n_stations: int, n_targets: int = 0, n_oriented: int = 0) -> ParameterLayout:
        blocks = ([("station", STATION_FIELDS)] + ([("target", XYZ)] if n_targets else [])
                  + ([("orientation", ORIENTATION_FIELDS)] if n_oriented else []))
        return cls(blocks, n_stations=n_stations, n_targets=n_targets, n_oriented=n_oriented)

    @classmethod
    def station_system(cls, n_stations: int, n_targets: int = 0, *, offsets: bool = True) -> ParameterLayout:
        blocks = [("station", XYZ + (("offset",) if offsets else ()))] + ([("target", XYZ)] if n_targets else [])
        return cls(blocks, n_stations=n_stations, n_targets=n_targets)

    @classmethod
    def batched(cls, n_stations: int, n_targets: int) -> ParameterLayout:
        return cls([("station", XYZ), ("station", ("offset",)), ("target", XYZ)],
                   n_stations=n_stations, n_targets=n_targets)

    @classmethod
    def general(cls, n_points: int) -> ParameterLayout:
        return cls([("point", XYZ)], n_points=n_points)

    @classmethod
    def coupled(cls, n_stations: int, n_targets: int, head_index, n_oriented: int = 0) -> ParameterLayout:
        return cls([("station", XYZ), ("head", ("offset",)), ("head", ("scale",)), ("target", XYZ),
                    ("orientation", ORIENTATION_FIELDS)],
                   n_stations=n_stations, n_targets=n_targets, head_index=head_index, n_oriented=n_oriented)

    # -- columns --------------------------------------------------------------------------------
    def _find(self, kind: str, field: str):
        for b in self.blocks:
            if b.kind == kind and field in b.fields:
                return b
        return None

    def columns(self, kind: str, field: str) -> np.ndarray | None:
        """(count,) column of ``field`` for every owner of ``kind``; None when the layout has none."""
        b = self._find(kind, field)
        return None if b is None else b.columns()[:, b.fields.index(field)]

    def station_columns(self, field: str) -> np.ndarray | None:
        """(s,) column of a station's ``field``; for a field held per head, its head's (the tie)."""
        c = self.columns("station", field)
        if c is None:
            c = self.columns("head", field)
            c = None if c is None else c[self.head_index]
        return c

    def block(self, kind: str, fields=None) -> np.ndarray:
        """(count, len(fields)) columns of ``fields`` (default every field of ``kind``, in block order)."""
        if fields is None:
            fields = tuple(f for b in self.blocks if b.kind == kind for f in b.fields)
        cols = [self.station_columns(f) if kind == "station" else self.columns(kind, f) for f in fields]
        count = {"station": self.n_stations, "head": self.n_heads, "target": self.n_targets}.get(kind)
        if count is None:
            count = next((b.count for b in self.blocks if b.kind == kind), 0)
        return np.stack(cols, axis=1) if cols else np.zeros((count, 0), np.int64)

    def station_block(self, fields=None) -> np.ndarray:
        """(s, k) columns of each station's fields (default all of them; head fields through the tie)."""
        return self.block("station", fields if fields is not None else
                          tuple(f for f in STATION_FIELDS if self.station_columns(f) is not None))

    def target_block(self) -> np.ndarray:
        """(t, 3) columns of each target's ``x, y, z``."""
        return self.block("target", XYZ)

    def point_columns(self) -> np.ndarray:
        """(s + t, 3) columns of the stacked points ``[stations; targets]`` (stations only without a
        target block); a general layout's points' (n_points, 3)."""
        if self._find("point", "x") is not None:
            return self.block("point", XYZ)
        tb = self.target_block() if self._find("target", "x") is not None else np.zeros((0, 3), np.int64)
        return np.concatenate([self.station_block(XYZ), tb])

    def index_in(self, other: ParameterLayout) -> np.ndarray:
        """(n,) for each of this layout's columns, the column of the same parameter in ``other``
        (-1 where ``other`` has none); a per-station field maps to ``other``'s head column (the tie)."""
        out = np.full(self.n, -1, np.int64)
        for b in self.blocks:
            for f_i, f in enumerate(b.fields):
                if b.kind == "station":
                    dst = other.station_columns(f)
                elif b.kind == "head":
                    dst = other.columns("head", f)
                    if dst is None and other.station_columns(f) is not None:
                        dst = other.station_columns(f)[np.unique(self.head_index, return_index=True)[1]]
                else:
                    dst = other.columns(b.kind, f)
                if dst is not None:
                    out[b.columns()[:, f_i]] = dst
        return out

    def tie_source(self, head_index) -> np.ndarray:
        """(n,) the head tie ``g = T g_r`` of a per-station layout, ``T[k, src[k]] = 1``: each station's
        offset and scale columns read its head's first (lead) station's."""
        hi = np.asarray(head_index, np.int64)
        lead = np.unique(hi, return_index=True)[1][hi]
        src = np.arange(self.n)
        for f in ("offset", "scale"):
            c = self.columns("station", f)
            if c is not None:
                src[c] = c[lead]
        return src

    # -- names, free flags, datum rows ----------------------------------------------------------
    def names(self, station_ids, target_ids=(), head_ids=None, oriented_ids=()) -> list[str]:
        """``"x:H1"``, ``"offset:A"`` (a station's offset and scale named by its head, default the
        station), ``"kappa:T1"``, ... in column order (:func:`parameter_name`)."""
        heads = list(station_ids) if head_ids is None else list(head_ids)
        head_name = {int(h): heads[i] for i, h in enumerate(self.head_index)}
        owners = {"station": list(station_ids), "target": list(target_ids),
                  "head": [head_name[h] for h in range(self.n_heads)], "orientation": list(oriented_ids)}
        of_head = [head_name[int(h)] for h in self.head_index]
        out = [""] * self.n
        for b in self.blocks:
            cols = b.columns()
            for f_i, f in enumerate(b.fields):
                of = of_head if b.kind == "station" and f in ("offset", "scale") else owners[b.kind]
                for k in range(b.count):
                    out[cols[k, f_i]] = parameter_name(f, of[k])
        return out

    def free_mask(self, **by_kind) -> np.ndarray:
        """(n,) bool: True unless held. ``station={"x": (s,) bool, ...}``, ``head={...}``,
        ``target={...}``, ``orientation={...}``: each field's flags per owner (omitted: free)."""
        free = np.ones(self.n, bool)
        for kind, flags in by_kind.items():
            for f, v in (flags or {}).items():
                free[self.columns(kind, f)] = np.asarray(v, bool)
        return free

    def datum_rows(self, point_rows, *, dtype=float) -> np.ndarray:
        """(n, k): per-point rows (the rigid motions of :func:`multilat.network.model.datum.helmert_basis`,
        datum conditions) of the stacked points, (3 (s + t), k) (stations only for a layout without
        targets), placed on the coordinate columns; zero on offsets, scales and orientations."""
        rows = np.asarray(point_rows)
        out = np.zeros((self.n,) + rows.shape[1:], dtype)
        out[self.point_columns().ravel()] = rows
        return out

    def point_rows(self, v) -> np.ndarray:
        """The inverse of :meth:`datum_rows`: the coordinate rows of ``v`` (n, ...) in stacked-point order."""
        return np.asarray(v)[self.point_columns().ravel()]
