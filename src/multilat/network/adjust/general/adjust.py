"""Least-squares adjustment of a general network: Gauss-Newton on the whitened system; the dense back
end here, the sparse one (points eliminated by Schur complement) in :mod:`.sparse`, chosen by
``AdjustOptions.backend`` (``auto``: dense up to :data:`SPARSE_ABOVE` free parameters).

Every block of observations is whitened by the Cholesky factor of its covariance (``C = L L^T``:
``r_w = L^-1 r``, ``J_w = L^-1 J``), so correlated blocks (vectors, levelling lines, observed
coordinates) and independent ones are one least-squares problem ``min |r_w - J_w dx|^2``. The kinds
give the residuals and the Jacobian rows (:mod:`.kinds`); the :class:`~.layout.Layout` gives the
columns; only the free parameters are solved for.

**Datum.** The defect and the undetermined parameters come from the observations at each iterate
(:mod:`.determinability`). With fixed points only (no datum points) a non-zero defect names the
undetermined points in one line. A free network carries its datum by inner constraints on its datum
points' free coordinates (minimum trace over them): each step solves the bordered system
``[[N, B], [B^T, 0]]`` with ``B`` the null space restricted to those coordinates, and the cofactor
matrix is the top-left block of its inverse (the minimum-trace covariance over the datum points).

**Results** (:class:`GeneralResult`): adjusted parameters and point coordinates, the cofactor
matrix ``Q`` of the free parameters (a-priori σ0 = 1: covariance ``Q``, or ``sigma0**2 Q`` a
posteriori), σ0 = sqrt(vᵀPv / dof), dof = observations - free parameters + defect, residuals per
row (observed - adjusted, SI), redundancy numbers ``r_i = 1 - (J_w Q J_w^T)_ii`` of the whitened rows
(for a correlated block: its rows decorrelated by the Cholesky factor in the block's row order, as
gama-local does; they sum to dof), and the record of iterations. Non-convergence is a one-line :class:`~multilat.errors.MultilatError`.

**Iteration** by the one loop of the adjustments (:func:`multilat.network.adjust.solve.loop.iterate`):
Levenberg-Marquardt damping when a step raises vᵀPv, the stopping rule in units of σ
(:mod:`multilat.network.adjust.solve.convergence`: the step's largest predicted change of an
observation, ``max |J_w dx|``); this module and :mod:`.sparse` give the step (:class:`_Steps`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from multilat.errors import MultilatError
from multilat.network.adjust.solve.convergence import Convergence
from multilat.network.adjust.solve.loop import iterate
from multilat.network.model import kinds as kinds_registry
from multilat.network.model.determinability import Determinability, analyse
from multilat.network.model.layout import Layout
from multilat.network.model.observations import Block, Network

__all__ = ["AdjustOptions", "GeneralResult", "System", "UndeterminedError", "adjust", "backend_for", "check_size",
           "MAX_DENSE_UNKNOWNS", "SPARSE_ABOVE", "EXTERNAL_MAX_WORK"]


class UndeterminedError(MultilatError):
    """Points (or other parameters) the observations and the datum leave undetermined: the one-line
    message, and ``points`` {id: the undetermined coordinates, e.g. "z" or "xyz"} so that a caller
    can leave them out (:func:`multilat.network.adjust.general.run.adjust_network`)."""

    def __init__(self, message: str, points: dict, others: tuple):
        super().__init__(message)
        self.points = points
        self.others = others


@dataclass(frozen=True)
class AdjustOptions:
    """max_iterations : int  accepted Gauss-Newton (Levenberg-Marquardt) steps before giving up (one-line
        error); the loop stops by the rule of :mod:`multilat.network.adjust.solve.convergence`
    datum : "auto" | "free" | "fixed"  ``auto``: inner constraints on the points flagged
        ``constrained`` if any, else the fixed points alone; ``free``: on every point's free
        coordinates; ``fixed``: no inner constraints (a defect is an error)
    backend : "auto" | "dense" | "sparse"  ``auto``: dense up to :data:`SPARSE_ABOVE` free
        parameters, sparse above (:mod:`.sparse`); the others force one (tests, comparisons)
    """

    max_iterations: int = 50
    datum: str = "auto"
    backend: str = "auto"

    def __post_init__(self):
        if self.datum not in ("auto", "free", "fixed"):
            raise MultilatError(f"datum={self.datum!r} must be 'auto', 'free' or 'fixed'")
        if self.backend not in ("auto", "dense", "sparse"):
            raise MultilatError(f"backend={self.backend!r} must be 'auto', 'dense' or 'sparse'")
        if self.max_iterations < 1:
            raise MultilatError("max_iterations must be >= 1")


@dataclass(frozen=True, eq=False)
class GeneralResult:
    """ids : point ids; xyz_m : (n, 3) adjusted coordinates (held ones as given)
    parameters : (n_full,) adjusted full parameter vector; names : its parameter names
    free_names : names of the free parameters, the order of ``cofactor``
    cofactor : (n_free, n_free) Q (covariance with σ0 a priori = 1); None from the sparse back end,
        which keeps Q in blocks (``blocks``): use :meth:`point_cofactor`, :meth:`cofactor_diagonal`,
        :meth:`cofactor_times`, :meth:`cofactor_block`, which serve both back ends
    sigma0 : a-posteriori standard deviation of unit weight; dof : degrees of freedom; defect : datum defect
    residuals : (R,) observed - adjusted per row, in network order of the blocks; redundancy : (R,)
    block_rows : per block the slice of its rows; iterations : tuple of (max |step|, vᵀPv) per iteration
    determinability : the analysis at the solution
    backend : "dense" or "sparse";  blocks : the sparse back end's :class:`.sparse.SparseCofactor` (None if dense)
    not_computed : names of the statistics this result cannot serve (the sparse back end: the
        external reliability, which needs ``Q`` times every row)
    convergence : how the loop ended (:class:`~multilat.network.adjust.solve.convergence.Convergence`)
    """

    ids: tuple
    xyz_m: np.ndarray
    parameters: np.ndarray
    names: tuple
    free_names: tuple
    cofactor: np.ndarray
    sigma0: float
    dof: int
    defect: int
    residuals: np.ndarray
    redundancy: np.ndarray
    block_rows: tuple
    iterations: tuple
    determinability: Determinability
    backend: str = "dense"
    blocks: object = None
    not_computed: tuple = ()
    convergence: Convergence | None = None

    def cofactor_diagonal(self) -> np.ndarray:
        """(n_free,) the cofactors of the free parameters (variances with σ0 a priori = 1)."""
        return np.diag(self.cofactor).copy() if self.blocks is None else self.blocks.diagonal()

    def cofactor_times(self, m: np.ndarray) -> np.ndarray:
        """``Q m`` for m (n_free,) or (n_free, c) (the sparse back end: one solve, no Q formed)."""
        return self.cofactor @ m if self.blocks is None else self.blocks.times(np.asarray(m, float))

    def cofactor_block(self, cols) -> np.ndarray:
        """(c, c) cofactor of a few free columns ``cols``."""
        cols = np.asarray(cols, int)
        if self.blocks is None:
            return self.cofactor[np.ix_(cols, cols)]
        e = np.zeros((len(self.free_names), cols.size))
        e[cols, np.arange(cols.size)] = 1.0
        return self.blocks.times(e)[cols]

    def point_cofactor(self, pid: str) -> np.ndarray:
        """(3, 3) cofactor of a point's coordinates (zero rows/columns for held coordinates)."""
        if self.blocks is not None:
            ix = self.__dict__.get("_ix")
            if ix is None:
                ix = {p: k for k, p in enumerate(self.ids)}
                object.__setattr__(self, "_ix", ix)
            return self.blocks.point[ix[pid]].copy()
        idx = {n: k for k, n in enumerate(self.free_names)}
        cols = [idx.get(f"{c}:{pid}", -1) for c in "xyz"]
        q = np.zeros((3, 3))
        for a, ca in enumerate(cols):
            for b, cb in enumerate(cols):
                if ca >= 0 and cb >= 0:
                    q[a, b] = self.cofactor[ca, cb]
        return q


class System:
    """The network's least-squares system: layout, the kinds' columns, the whiteners."""

    def __init__(self, network: Network):
        self.network = network
        self.layout = Layout(network.points)
        blocks = list(network.blocks) + _weighted_block(network.points)
        self.blocks = tuple(blocks)
        self.cols = [kinds_registry.kind(b.kind).register(b, self.layout) for b in blocks]
        # the Cholesky factor of a correlated block; None for independent rows (no (R, R) diagonal)
        self.chol = [b.whitener() if b.cov is not None else None for b in blocks]
        bounds = np.cumsum([0] + [b.n_rows for b in blocks])
        self.rows = tuple(slice(int(a), int(c)) for a, c in zip(bounds[:-1], bounds[1:]))
        self.n_rows = int(bounds[-1])
        self.reduced = self.layout.reduced
        self.n_free = int(self.layout.free.sum())

    def evaluate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residuals (R,) observed - computed and the dense Jacobian (R, n_free), unwhitened."""
        r = np.empty(self.n_rows)
        jac = np.zeros((self.n_rows, self.n_free))
        for b, cols, sl in zip(self.blocks, self.cols, self.rows):
            mod = kinds_registry.kind(b.kind)
            computed, values, columns = mod.evaluate(b, self.layout, cols, x)
            r[sl] = kinds_registry.residual(b, computed)
            red = self.reduced[columns]                     # -1 (column -1 maps to the extra entry)
            rows = np.broadcast_to(np.arange(sl.start, sl.stop)[:, None], red.shape)
            keep = red >= 0
            np.add.at(jac, (rows[keep], red[keep]), values[keep])
        return r, jac

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """Residuals (R,) observed - computed at ``x``, without the Jacobian (the loop's cost)."""
        r = np.empty(self.n_rows)
        for b, cols, sl in zip(self.blocks, self.cols, self.rows):
            computed, _, _ = kinds_registry.kind(b.kind).evaluate(b, self.layout, cols, x, jacobian=False)
            r[sl] = kinds_registry.residual(b, computed)
        return r

    def whiten(self, a: np.ndarray) -> np.ndarray:
        """``L^-1 a`` block by block (rows of ``a``)."""
        out = np.empty_like(a)
        for L, sl, b in zip(self.chol, self.rows, self.blocks):
            if b.cov is None:
                out[sl] = a[sl] / (b.sigma if a.ndim == 1 else b.sigma[:, None])
            else:
                out[sl] = scipy.linalg.solve_triangular(L, a[sl], lower=True)
        return out

    def linearise(self, x: np.ndarray, mask: np.ndarray):
        """At parameters ``x``: whitened residuals and Jacobian, the determinability analysis, the
        constrained Gauss-Newton step and the cofactor matrix (undetermined parameters named)."""
        r, jac = self.evaluate(x)
        rw, jw = self.whiten(r), self.whiten(jac)
        det = analyse(jw, mask)
        if det.undetermined.size:
            raise UndeterminedError(_undetermined_line(self, det), *_undetermined(self, det))
        dx, q = _step(jw, rw, det)
        return r, rw, jw, det, dx, q

    def redundancy(self, jw: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Redundancy numbers ``1 - diag(J_w Q J_w^T)`` of the whitened rows."""
        return 1.0 - np.einsum("ij,jk,ik->i", jw, q, jw)

    def datum_mask(self, datum: str) -> np.ndarray:
        """(n_free,) bool: the free coordinates of the datum points (inner constraints)."""
        pts = self.network.points
        use = pts.constrained if datum == "auto" else np.full(pts.n, datum == "free")
        mask = np.zeros(self.layout.n, bool)
        mask[self.layout.point_cols[use].ravel()] = True
        return mask[self.layout.free]


def _weighted_block(points) -> list:
    i, c, v, s = points.weighted_rows()
    if len(i) == 0:
        return []
    labels = tuple(f"weighted coordinate {'xyz'[a]} of {points.ids[p]}" for p, a in zip(i, c))
    return [Block("observed_coordinates", v, s, None, {"point": i, "axis": c}, labels=labels)]


def _undetermined(system: System, det: Determinability) -> tuple[dict, tuple]:
    """{point id: its undetermined coordinates ("z", "xyz", ...)} and the other undetermined parameters."""
    names = [n for k, n in enumerate(np.array(system.layout.names)[system.layout.free]) if k in set(det.undetermined)]
    points: dict = {}
    for n in names:
        if n[:2] in ("x:", "y:", "z:"):
            points[n[2:]] = points.get(n[2:], "") + n[0]
    return points, tuple(n for n in names if n[:2] not in ("x:", "y:", "z:"))


def _undetermined_line(system: System, det: Determinability) -> str:
    pts, others = _undetermined(system, det)
    points = list(pts)
    what = (f"point {points[0]!r}" + (f" (and {len(points) - 1} more: {', '.join(points[1:4])}"
                                       f"{', ...' if len(points) > 4 else ''})" if len(points) > 1 else "")
            if points else f"parameter {others[0]!r}")
    return (f"{what} not determined by the observations (datum defect {det.defect}, "
            f"{'not removed by the datum points' if det.constraints is not None else 'no datum points to remove it'})")


def _step(jw, rw, det: Determinability, lam: float = 0.0):
    """Gauss-Newton step and the cofactor matrix, under the datum constraints ``B^T dx = 0``; with
    ``lam`` > 0 the Levenberg-Marquardt step (``N_ii`` times ``1 + lam``; the matrix returned is then
    not the cofactor matrix)."""
    n = jw.shape[1]
    N = jw.T @ jw
    if lam:
        N[np.diag_indices(n)] *= 1.0 + lam
    b = det.constraints
    k = 0 if b is None else b.shape[1]
    M = np.zeros((n + k, n + k))
    M[:n, :n] = N
    if k:
        M[:n, n:] = b
        M[n:, :n] = b.T
    try:
        Minv = np.linalg.inv(M)
    except np.linalg.LinAlgError:
        raise MultilatError("the normal equations are singular although the datum removes the defect") from None
    rhs = np.zeros(n + k)
    rhs[:n] = jw.T @ rw
    return (Minv @ rhs)[:n], Minv[:n, :n]


#: the dense back end's largest problem: its SVD of the (R, n) whitened Jacobian costs O(R n²) per
#: iteration (measured under load here: n = 1000, R = 3000: 4.3 s; n = 2000, R = 6000: 39 s)
MAX_DENSE_UNKNOWNS = 2000
#: ``backend="auto"`` takes the sparse back end above this many free parameters (measured in CPU
#: time, benchmarks/bench_general_sparse.py --crossover: sparse 1.35x faster at 107 unknowns, 3.7x at
#: 182, 39x at 632; below, the dense one spares small networks the import of scipy.sparse)
SPARSE_ABOVE = 200
#: the sparse back end leaves the external reliability out (NaN, ``not_computed``) above this many
#: rows x unknowns; none since issue 29: it costs O(R k²) through the Schur blocks
#: (:class:`.reliability.SchurShifts`), as the redundancy numbers do
EXTERNAL_MAX_WORK = float("inf")


def backend_for(system: "System", options: AdjustOptions | None = None) -> str:
    """"dense" or "sparse": the option, or by size for ``auto``."""
    b = (options or AdjustOptions()).backend
    return b if b != "auto" else ("sparse" if system.n_free > SPARSE_ABOVE else "dense")


def check_size(system: "System", options: AdjustOptions | None = None) -> None:
    """Refuse, in one line, a network larger than the dense back end takes when it is the one chosen
    (never a silent hour); the sparse back end bounds its reduced system itself (:mod:`.sparse`)."""
    if backend_for(system, options) == "dense" and system.n_free > MAX_DENSE_UNKNOWNS:
        n_pts = len(system.network.points.ids)
        raise MultilatError(
            f"the general model's dense back end takes at most {MAX_DENSE_UNKNOWNS} unknowns; this network has "
            f"{system.n_free} ({n_pts} points, {system.n_rows} observation rows): use the sparse back end "
            "(backend='sparse' or 'auto')")


def adjust(network: Network, *, options: AdjustOptions | None = None) -> GeneralResult:
    """Adjust ``network`` (approximate coordinates of every free point must be given, e.g. by
    :func:`multilat.network.adjust.approximate.general.approximate`)."""
    opt = options or AdjustOptions()
    system = System(network)
    check_size(system, opt)
    sparse = backend_for(system, opt) == "sparse"
    pts = network.points
    if np.any(~np.isfinite(pts.xyz_m)):
        i = int(np.argwhere(~np.isfinite(pts.xyz_m))[0][0])
        raise MultilatError(f"point {pts.ids[i]!r} has no approximate coordinates (compute them with "
                            "approximate())")
    x = system.layout.initial()
    mask = system.datum_mask(opt.datum)
    record = []
    steps = _Steps(system, mask, sparse)
    x, cost, conv = iterate(steps, x, max_iter=opt.max_iterations,
                            on_accept=lambda x0, dx, c: record.append((float(np.abs(dx).max(initial=0.0)), c)))
    if not conv.converged:
        hint = ("give approximate coordinates of the points (--points) or check the observations for gross "
                "errors")
        if conv.reason == "iteration limit":
            raise MultilatError(f"the adjustment did not converge in {opt.max_iterations} iterations (last step "
                                f"{record[-1][0]:.3g}, vTPv {record[-1][1]:.6g}): {hint}")
        raise MultilatError(
            f"the adjustment diverged at iteration {conv.iterations} (no step lowers vTPv {cost:.6g}, even "
            f"damped; last step {conv.last_step_sigma:.3g} sigma): the approximate coordinates are too far "
            f"from a solution; {hint}")
    # the result at the point the converged step started from, whose linearisation the loop made: that
    # step is below the stopping rule's tolerance (rounding), and one linearisation is spared
    at, lin = steps.linearisation()
    build = _sparse_result if sparse else _result
    return dataclasses.replace(build(system, at, mask, tuple(record), lin=lin), convergence=conv)


class _Steps:
    """The general layer's step for :func:`~multilat.network.adjust.solve.loop.iterate`: the
    linearisation at ``x`` (dense: :meth:`System.linearise`; sparse: :func:`.sparse.linearise`), kept
    while the loop damps; the damped step by :func:`_step` or :func:`.sparse.damped_step`; its length
    ``max |J_w dx|`` (the largest change of an observation it predicts, in units of its sigma). The
    rounding of a whitened residual: 4 eps times the sum of its parameters' magnitudes weighted by
    ``|J_w|``, plus the observed value over its sigma."""

    def __init__(self, system: System, mask: np.ndarray, sparse: bool):
        self.system, self.mask, self.sparse = system, mask, sparse
        self.free = system.layout.free
        self.n_rows = system.n_rows
        self.rounding = 0.0
        self._at = self._lin = self._full = None

    def cost(self, x: np.ndarray) -> float:
        if not np.all(np.isfinite(x)):
            return np.inf
        with np.errstate(over="ignore", invalid="ignore"):
            r = self.system.residuals(x)
            rw = self.system.whiten(r) if np.all(np.isfinite(r)) else None
            c = float(rw @ rw) if rw is not None else np.inf
        return c if np.isfinite(c) else np.inf

    def _linearised(self, x: np.ndarray):
        """(jw, rw, det, dx, the sparse back end's Linearised or None) at ``x``, once per point."""
        if self._at is not x:
            with np.errstate(over="ignore", invalid="ignore"):
                if self.sparse:
                    self._full = lin = _sparse_linearise(self.system, x, self.mask)
                    self._lin = (lin.jw, lin.rw, lin.det, lin.dx, lin)
                else:
                    self._full = self.system.linearise(x, self.mask)
                    _, rw, jw, det, dx, _ = self._full
                    self._lin = (jw, rw, det, dx, None)
            if self._at is None:
                self.rounding = self._rounding(self._lin[0], x)
            self._at = x
        return self._lin

    def linearisation(self) -> tuple:
        """``(x, linearisation)``: the last point linearised and :meth:`System.linearise`'s tuple (dense)
        or :func:`.sparse.linearise`'s ``Linearised`` there."""
        return self._at, self._full

    def _rounding(self, jw, x) -> float:
        obs = np.concatenate([np.abs(b.value) / b.sigma for b in self.system.blocks]) if self.n_rows else np.zeros(0)
        delta = 4 * np.finfo(float).eps * (abs(jw) @ np.abs(x[self.free]) + obs)
        return float(np.sqrt(np.mean(delta ** 2))) if delta.size else 0.0

    def step(self, x: np.ndarray, lam: float):
        jw, rw, det, dx, lin = self._linearised(x)
        with np.errstate(over="ignore", invalid="ignore"):
            if lam:
                if self.sparse:
                    from multilat.network.adjust.general import sparse as sparse_backend

                    dx = sparse_backend.damped_step(self.system, lin, lam)
                else:
                    dx = _step(jw, rw, det, lam)[0]
            return dx, float(np.max(np.abs(jw @ dx), initial=0.0))

    def apply(self, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        y = x.copy()
        y[self.free] += dx
        return y


def _sparse_linearise(system: System, x, mask):
    from multilat.network.adjust.general import sparse as sparse_backend      # scipy.sparse only when used

    def undetermined(det):
        raise UndeterminedError(_undetermined_line(system, det), *_undetermined(system, det))

    return sparse_backend.linearise(system, x, mask, undetermined)


def _sparse_result(system: System, x, mask, record, *, lin=None) -> GeneralResult:
    """The result at ``x`` (``lin``: its linearisation, made here if None)."""
    from multilat.network.adjust.general import sparse as sparse_backend

    lin = lin if lin is not None else _sparse_linearise(system, x, mask)
    det = lin.det
    blocks = sparse_backend.cofactor(system, lin)
    n = system.n_free                        # the dense Q its consumers read, only where it is small
    q = blocks.times(np.eye(n)) if n <= MAX_DENSE_UNKNOWNS else None
    heavy = system.n_rows * n > EXTERNAL_MAX_WORK
    dof = system.n_rows - system.n_free + det.defect
    vtpv = float(lin.rw @ lin.rw)
    lay = system.layout
    names = np.array(lay.names)
    return GeneralResult(
        ids=system.network.points.ids, xyz_m=x[lay.point_cols].copy(), parameters=x.copy(),
        names=tuple(lay.names), free_names=tuple(names[lay.free]), cofactor=None if q is None else 0.5 * (q + q.T),
        sigma0=float(np.sqrt(vtpv / dof)) if dof > 0 else float("nan"), dof=int(dof), defect=det.defect,
        residuals=lin.r, redundancy=sparse_backend.redundancy(lin), block_rows=system.rows, iterations=record,
        determinability=det, backend="sparse", blocks=blocks,
        not_computed=("external reliability",) if heavy else ())


def _result(system: System, x, mask, record, *, lin=None) -> GeneralResult:
    """The result at ``x`` (``lin``: its :meth:`System.linearise` tuple, made here if None)."""
    r, rw, jw, det, _, Q = lin if lin is not None else system.linearise(x, mask)
    dof = system.n_rows - system.n_free + det.defect
    vtpv = float(rw @ rw)
    sigma0 = float(np.sqrt(vtpv / dof)) if dof > 0 else float("nan")
    lay = system.layout
    names = np.array(lay.names)
    return GeneralResult(
        ids=system.network.points.ids, xyz_m=x[lay.point_cols].copy(), parameters=x.copy(),
        names=tuple(lay.names), free_names=tuple(names[lay.free]), cofactor=Q, sigma0=sigma0, dof=int(dof),
        defect=det.defect, residuals=r, redundancy=system.redundancy(jw, Q), block_rows=system.rows, iterations=record,
        determinability=det)
