"""Observations of a general network: blocks of one kind each, and the network they make with its
points.

A :class:`Block` holds the observations of one kind (:mod:`.kinds`) as arrays: ``value`` and the
a-priori covariance of its rows (SI: metres, radians), per-observation integer references
(``index``: ``from``, ``to``, ``set``, ``instrument``, ...) into the point set or into ``names``,
per-observation numbers (``data``: instrument and target heights), and a label per observation for
messages (``FILE:LINE`` when read from a file). A kind with vector observations (coordinate
differences, observed coordinates) has 3 or 1 rows per observation; ``value`` and ``cov`` are per
row. Rows of different blocks are uncorrelated; inside a block ``cov`` may be full (a correlated
levelling line, a GNSS vector's 3 x 3), or None with ``sigma`` alone (independent rows).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from multilat.errors import MultilatError
from multilat.network.model.points import PointSet

__all__ = ["Block", "Network", "without_points", "without_rows", "point_keys"]


@dataclass(frozen=True, eq=False)
class Block:
    """Observations of one kind.

    kind : str  a name in :data:`multilat.network.model.kinds.KINDS`
    value : ndarray (R,)  observed values per row (SI)
    sigma : ndarray (R,)  a-priori standard deviations per row
    cov : ndarray (R, R) or None  full a-priori covariance (None: diagonal ``sigma**2``)
    index : dict of str -> int ndarray (m,)  references per observation
    data : dict of str -> float ndarray (m,)  numbers per observation (``from_dh``, ``to_dh``: metres)
    labels : tuple of str (m,)  one per observation, for messages
    names : dict of str -> tuple of str  what ``index`` entries other than points refer to
        (``set``: direction-set ids, ``instrument``: instrument ids, ``setup``: set-up ids)
    options : dict  per-block settings of the kind (``levelled``, ``estimate_offset``, ...)
    """

    kind: str
    value: np.ndarray
    sigma: np.ndarray
    cov: np.ndarray | None = None
    index: dict = field(default_factory=dict)
    data: dict = field(default_factory=dict)
    labels: tuple = ()
    names: dict = field(default_factory=dict)
    options: dict = field(default_factory=dict)

    def __post_init__(self):
        r = np.shape(self.value)[0]
        if np.shape(self.sigma) != (r,) or not np.all(np.isfinite(self.sigma) & (np.asarray(self.sigma) > 0)):
            raise MultilatError(f"{self.kind}: sigma must be (R,) finite and > 0")
        if not np.all(np.isfinite(self.value)):
            k = int(np.flatnonzero(~np.isfinite(self.value))[0])
            raise MultilatError(f"{self.kind}: value of row {k + 1} is not finite")
        if self.cov is not None and np.shape(self.cov) != (r, r):
            raise MultilatError(f"{self.kind}: cov must be ({r}, {r}), got {np.shape(self.cov)}")

    @property
    def n_rows(self) -> int:
        return len(self.value)                    # asked once per row by the reports: no np.shape

    @property
    def covariance(self) -> np.ndarray:
        """The full (R, R) a-priori covariance."""
        return np.diag(self.sigma ** 2) if self.cov is None else np.asarray(self.cov, float)

    def whitener(self) -> np.ndarray:
        """Lower Cholesky factor ``L`` of the covariance (``C = L L^T``), diagonal when independent;
        a covariance that is not positive definite is named."""
        if self.cov is None:
            return np.diag(self.sigma)
        try:
            return np.linalg.cholesky(self.covariance)
        except np.linalg.LinAlgError:
            raise MultilatError(f"{self.kind} block at {self.labels[0] if self.labels else '?'}: its covariance "
                                "matrix is not positive definite") from None


@dataclass(frozen=True, eq=False)
class Network:
    """Points and observation blocks; ``notes`` say what a reader applied (one line each)."""

    points: PointSet
    blocks: tuple
    notes: tuple = ()

    @property
    def n_rows(self) -> int:
        return sum(b.n_rows for b in self.blocks)


def without_points(network: Network, ids) -> tuple[Network, int]:
    """The network with the points ``ids`` and every observation row that references one of them
    removed (a correlated block keeps the covariance of its remaining rows; direction sets,
    instruments and set-ups left without rows are dropped), and the number of rows removed."""
    pts = network.points
    gone = np.zeros(pts.n, bool)
    gone[[pts.index(p) for p in ids]] = True
    new_index = np.cumsum(~gone) - 1                      # old point index -> new one
    blocks, removed = [], 0
    for b in network.blocks:
        keep = np.ones(b.n_rows, bool)
        for k in point_keys(b):
            keep &= ~gone[np.asarray(b.index[k], int)]
        removed += int((~keep).sum())
        if keep.any():
            blocks.append(_subset_block(b, keep, new_index))
    k = ~gone
    p = PointSet(tuple(np.array(pts.ids, object)[k]), pts.xyz_m[k], pts.status[k], pts.sigma_m[k],
                 pts.constrained[k])
    return Network(p, tuple(blocks), network.notes), removed


def without_rows(network: Network, drop: dict) -> Network:
    """The network without some observation rows: ``drop`` {block position in ``network.blocks``: (R,)
    bool mask or row indices of the rows to remove}. A correlated block keeps the covariance of its
    remaining rows; a block left without rows is dropped, and so are direction sets, instruments and
    set-ups left without rows (as :func:`without_points`). The points stay."""
    same = np.arange(network.points.n)
    blocks = []
    for q, b in enumerate(network.blocks):
        keep = np.ones(b.n_rows, bool)
        if q in drop:
            keep[np.asarray(drop[q])] = False
        if keep.all():
            blocks.append(b)
        elif keep.any():
            blocks.append(_subset_block(b, keep, same))
    return Network(network.points, tuple(blocks), network.notes)


def point_keys(b: Block) -> list:
    """The keys of ``b.index`` that refer to points (``from``, ``to``, ``bs``, ``fs``, ``point``)."""
    return [k for k in b.index if k not in b.names and k not in ("axis", "component")]


def _subset_block(b: Block, keep: np.ndarray, new_index: np.ndarray) -> Block:
    """The rows ``keep`` of ``b``, point references renumbered by ``new_index`` (old -> new)."""
    pkeys = point_keys(b)
    index = {k: (new_index[np.asarray(v, int)[keep]] if k in pkeys else np.asarray(v)[keep])
             for k, v in b.index.items()}
    names = {}
    for k, nm in b.names.items():                     # compact sets / instruments / set-ups still used
        ix = np.asarray(index[k], int)
        used = np.unique(ix[ix >= 0])
        index[k] = np.where(ix >= 0, np.searchsorted(used, ix), -1)
        names[k] = tuple(nm[int(o)] for o in used)
    data = {k: np.asarray(v)[keep] for k, v in b.data.items()}
    labels = tuple(np.asarray(b.labels, object)[keep]) if len(b.labels) == b.n_rows else b.labels
    cov = None if b.cov is None else np.asarray(b.cov)[np.ix_(keep, keep)]
    return Block(b.kind, np.asarray(b.value)[keep], np.asarray(b.sigma)[keep], cov, index, data, labels, names,
                 b.options)
