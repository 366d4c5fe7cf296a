"""The reader columns of the observation kinds: what a kind's rows of ``observations.csv`` hold and
how they become the kind's :class:`~..observations.Block` and back (``docs/general-network.md``,
"multilat's files for the general network").

Each kind module declares ``UNIT`` (of its values: ``m`` or ``rad``) and ``COLUMNS``, a tuple of
:class:`Column`, and has ``from_rows(rows) -> Block`` and ``to_rows(block, point_ids) -> dict``;
the two generic functions here do the work the declarations describe, so a kind's columns are
written once, in its module. :mod:`multilat.network.io.general_files` reads and writes the files
(the columns every kind shares: ``kind``, ``block``, ``unit``; the grouping into blocks; the
covariances) and calls the kinds through the registry.

Roles of a column (``Column.role``):

``value``, ``sigma``
    the observed value and its a-priori standard deviation, in the kind's ``UNIT``
    (read by :mod:`..files`, listed here for the documentation);
``point``
    a point id of ``points.csv`` -> ``Block.index[key]``;
``name``
    an id of an instrument, a direction set or a set-up -> ``Block.index[key]`` into
    ``Block.names[key]`` (numbered in order of first appearance in the block; an empty cell of an
    optional one is ``-1``, none);
``enum``
    one of ``choices`` -> ``Block.index[key]`` (its position);
``number``
    a number per observation -> ``Block.data[key]`` (an empty cell is 0; all empty: not given);
``option``
    ``true`` / ``false``, one value for the whole block -> ``Block.options[key]`` (empty: the
    kind's default).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.inputs import finite_number
from multilat.network.model.observations import Block

__all__ = ["Column", "Rows", "value_sigma", "block_from_rows", "rows_from_block", "BOOLEANS"]

#: the words of an option cell
BOOLEANS = {"true": True, "false": False}


@dataclass(frozen=True)
class Column:
    """One column of a kind in ``observations.csv``.

    name : the column's header name (units in the name: ``from_dh_m``)
    role : ``value``, ``sigma``, ``point``, ``name``, ``enum``, ``number`` or ``option``
    doc : one line for the documentation
    required : a row of the kind must fill it
    key : the Block's key (``index``, ``data``, ``names`` or ``options``); default: ``name``
    choices : the words of an ``enum`` column
    within : ``(lo, hi, text)``: the range of a ``value`` or ``number``
    """

    name: str
    role: str
    doc: str
    required: bool = False
    key: str = ""
    choices: tuple = ()
    within: tuple | None = None

    @property
    def block_key(self) -> str:
        return self.key or self.name


def value_sigma(unit: str, what: str, within: tuple | None = None) -> tuple:
    """The ``value`` and ``sigma`` columns of a kind whose values are ``what`` in ``unit``."""
    rng = f", within {within[2]}" if within is not None else ""
    return (Column("value", "value", f"{what}, {unit}{rng}", required=True, within=within),
            Column("sigma", "sigma", f"a-priori standard deviation, {unit} (> 0; may be empty in a block "
                   "with covariances: their diagonal)", required=True))


@dataclass(frozen=True)
class Rows:
    """The rows of one block as read: ``cells`` (column -> the block's cells; an absent column is
    all empty), ``where`` (``FILE:LINE`` per row), ``points`` (point id -> index), ``value``,
    ``sigma`` (SI) and ``cov`` (None: independent rows)."""

    cells: dict
    where: tuple
    points: dict
    value: np.ndarray
    sigma: np.ndarray
    cov: np.ndarray | None = None

    def column(self, name: str) -> list:
        return self.cells.get(name) or [""] * len(self.where)


def block_from_rows(kind: str, columns, rows: Rows) -> Block:
    """The :class:`Block` of kind ``kind`` that the ``columns`` of ``rows`` describe; a bad cell is
    ``FILE:LINE: ...`` (module docstring for the roles)."""
    index, data, names, options = {}, {}, {}, {}
    for col in columns:
        cells = rows.column(col.name)
        key = col.block_key
        if col.required:
            for k, c in enumerate(cells):
                if c == "" and col.role not in ("value", "sigma"):
                    raise MultilatError(f"{rows.where[k]}: a {kind} row needs column '{col.name}' ({col.doc})")
        if col.role == "value" and col.within is not None:
            lo, hi, text = col.within
            bad = np.flatnonzero(~((rows.value >= lo) & (rows.value <= hi)))
            if bad.size:
                raise MultilatError(f"{rows.where[bad[0]]}: column 'value': a {kind} must be within {text}, got "
                                    f"{float(rows.value[bad[0]])!r}")
        elif col.role == "point":
            index[key] = np.array([_point(rows, k, col.name, c) for k, c in enumerate(cells)], int)
        elif col.role == "name" and any(cells):
            names[key] = tuple(dict.fromkeys(c for c in cells if c))
            pos = {n: i for i, n in enumerate(names[key])}
            index[key] = np.array([pos.get(c, -1) for c in cells], int)
        elif col.role == "enum":
            index[key] = np.array([_choice(rows, k, col, c) for k, c in enumerate(cells)], int)
        elif col.role == "number" and any(cells):
            data[key] = np.array([_number(rows, k, col, c) for k, c in enumerate(cells)], float)
        elif col.role == "option" and any(cells):
            options[key] = _option(rows, col, cells)
    return Block(kind, rows.value, rows.sigma, rows.cov, index, data, tuple(rows.where), names, options)


def _point(rows: Rows, k: int, name: str, cell: str) -> int:
    i = rows.points.get(cell)
    if i is None:
        raise MultilatError(f"{rows.where[k]}: column '{name}': point {cell!r} is not in points.csv")
    return i


def _choice(rows: Rows, k: int, col: Column, cell: str) -> int:
    if cell not in col.choices:
        raise MultilatError(f"{rows.where[k]}: column '{col.name}' must be one of {', '.join(col.choices)}, "
                            f"got {cell!r}")
    return col.choices.index(cell)


def _number(rows: Rows, k: int, col: Column, cell: str) -> float:
    if cell == "":
        return 0.0
    v = finite_number(cell, f"{rows.where[k]}: column '{col.name}'")
    if col.within is not None and not col.within[0] <= v <= col.within[1]:
        raise MultilatError(f"{rows.where[k]}: column '{col.name}': must be within {col.within[2]}, got {cell!r}")
    return v


def _option(rows: Rows, col: Column, cells) -> bool:
    first = None
    for k, c in enumerate(cells):
        v = BOOLEANS.get(c.lower())
        if v is None:
            raise MultilatError(f"{rows.where[k]}: column '{col.name}' must be true or false (the same on every "
                                f"row of its block), got {c!r}")
        if first is None:
            first = (k, v)
        elif v != first[1]:
            raise MultilatError(f"{rows.where[k]}: column '{col.name}' is {c!r} here but "
                                f"{'true' if first[1] else 'false'} at {rows.where[first[0]]}: one value per block")
    return first[1]


def rows_from_block(block: Block, columns, point_ids) -> dict:
    """The cells (column -> list of str, one per row) of ``block``'s own columns: the inverse of
    :func:`block_from_rows` (``value``, ``sigma`` are written by :mod:`..files`)."""
    m = block.n_rows
    out = {}
    for col in columns:
        key = col.block_key
        if col.role == "point":
            out[col.name] = [point_ids[int(i)] for i in block.index[key]]
        elif col.role == "name" and key in block.index:
            nm = block.names[key]
            out[col.name] = [nm[int(i)] if i >= 0 else "" for i in block.index[key]]
        elif col.role == "enum":
            out[col.name] = [col.choices[int(i)] for i in block.index[key]]
        elif col.role == "number" and key in block.data:
            out[col.name] = [repr(float(v)) for v in block.data[key]]
        elif col.role == "option" and key in block.options:
            out[col.name] = ["true" if block.options[key] else "false"] * m
    return out
