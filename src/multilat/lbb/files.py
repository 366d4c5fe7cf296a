"""LBB file formats: tetrahedron edges and reference coordinates (CSV, strict, ``FILE:LINE`` errors).

Edges CSV (``multilat lbb trilaterate``)::

    point,l12_m,l13_m,l23_m,l1_m,l2_m,l3_m
    P1,0.564,0.564,0.564,0.4,0.41,0.39

``l12, l13, l23``: base edges (sockets 1-2, 1-3, 2-3); ``l1, l2, l3``: tool socket to sockets 1, 2, 3.

Reference CSV (``multilat lbb compare``; e.g. CMM coordinates already in the LBB base frame)::

    point,x_m,y_m,z_m
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.io import read_csv_table
from multilat.lbb.trilateration import EDGE_NAMES, check_edges

__all__ = ["EdgeTable", "read_edges", "read_reference", "ReferenceTable", "match_points"]


@dataclass(frozen=True)
class EdgeTable:
    """Edges per point: ``points`` (labels), ``edges_m`` (n, 6) in :data:`EDGE_NAMES` order,
    ``line_labels`` (``FILE:LINE point P``) for messages."""

    points: tuple[str, ...]
    edges_m: np.ndarray
    line_labels: tuple[str, ...]


@dataclass(frozen=True)
class ReferenceTable:
    """Reference coordinates: ``points`` (labels), ``xyz_m`` (n, 3)."""

    points: tuple[str, ...]
    xyz_m: np.ndarray


def _labels(t):
    ids = t.column("point")
    seen = set()
    for i, p in enumerate(ids):
        if p == "":
            raise t.error(i, "empty point id")
        if p in seen:
            raise t.error(i, f"duplicate point id {p!r}")
        seen.add(p)
    return tuple(ids)


def read_edges(path) -> EdgeTable:
    """Read and validate an edges CSV (finite, > 0, triangle inequality on every face).

    Raises
    ------
    MultilatError
        ``FILE:LINE: ...`` naming the row and the edge or face.
    """
    t = read_csv_table(path, required=("point",) + EDGE_NAMES)
    ids = _labels(t)
    cols = [t.floats(n, positive=True) for n in EDGE_NAMES]
    labels = tuple(f"{t.path}:{ln}: point {p}" for p, ln in zip(ids, t.line_numbers))
    check_edges(*cols, labels=labels)
    return EdgeTable(ids, np.stack(cols, axis=-1), labels)


def read_reference(path) -> ReferenceTable:
    """Read a reference-coordinates CSV ``point,x_m,y_m,z_m``."""
    t = read_csv_table(path, required=("point", "x_m", "y_m", "z_m"))
    ids = _labels(t)
    xyz = np.stack([t.floats(c) for c in ("x_m", "y_m", "z_m")], axis=-1)
    return ReferenceTable(ids, xyz)


def match_points(edges: EdgeTable, ref: ReferenceTable):
    """Indices pairing the reference points with the edge rows (every reference point must have edges)."""
    pos = {p: i for i, p in enumerate(edges.points)}
    missing = [p for p in ref.points if p not in pos]
    if missing:
        raise MultilatError(f"reference point(s) without edges: {', '.join(missing[:5])}")
    extra = [p for p in edges.points if p not in set(ref.points)]
    if extra:
        import warnings

        warnings.warn(f"{len(extra)} measured point(s) without a reference coordinate, "
                      f"not compared: {', '.join(extra[:5])}{' ...' if len(extra) > 5 else ''}",
                      UserWarning, stacklevel=2)
    return np.array([pos[p] for p in ref.points])
