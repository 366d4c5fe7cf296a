"""Refinement of initial values: robust least squares of all distances from a first guess
(Levenberg-Marquardt with Marquardt scaling, dense or sparse normal equations), the frame
convention of :mod:`multilat.network.adjust.approximate.initial` (3-2-1 on three stations, mirror fixed), and the
mirror sweep that re-fits targets at their mirror image through the plane of their stations."""

from __future__ import annotations

import itertools
import time

import numpy as np
import scipy  # scipy.sparse loads on first use: only large networks need it (issue 29)

from multilat.network.model.distance import line_of_sight, range_m
from multilat.network.adjust.solve.convergence import Convergence


__all__ = ["refine", "refine_unmirrored", "point_fit", "mirror_sweep", "levenberg_marquardt", "row_scale",
           "to_frame", "choose_frame", "fix_mirror", "SPARSE_FROM"]


def refine(D, W, H, T, o, frame, *, robust=True, max_nfev=200, deadline=None):
    """Weighted least squares over all coordinates and offsets in the 3-2-1 frame ``frame``
    (station indices a, b, c: a fixed, b's y, z fixed, c's z fixed). Returns H, T, o, rms, robust
    scale of the residuals and the solver's convergence record. ``deadline`` (a
    :func:`time.monotonic` value, :mod:`multilat.network.adjust.approximate.bounds`) ends the iterations early."""
    s, t = D.shape
    si, tj = np.nonzero(np.isfinite(D))
    d = D[si, tj]
    w = np.sqrt(W[si, tj])
    fa, fb, fc = frame
    free_h = np.ones((s, 3), bool)
    free_h[fa] = False
    free_h[fb, 1:] = False
    free_h[fc, 2] = False
    nh = int(free_h.sum())

    def unpack(x):
        Hx = H.copy()
        Hx[free_h] = x[:nh]
        Tx = x[nh:nh + 3 * t].reshape(t, 3)
        ox = x[nh + 3 * t:]
        return Hx, Tx, ox

    def fun(x):
        Hx, Tx, ox = unpack(x)
        return w * (d - range_m(Hx[si] - Tx[tj]) - ox[si])

    hcols = -np.ones((s, 3), int)
    hcols[free_h] = np.arange(nh)

    n = nh + 3 * t + s
    rows = np.arange(len(d))
    sparse = n > SPARSE_FROM

    def jac(x):
        Hx, Tx, ox = unpack(x)
        _, u = line_of_sight(Hx[si] - Tx[tj], floor_m=1e-12)
        rr, cc, vv = [], [], []
        for c in range(3):
            hc = hcols[si, c]
            ok = hc >= 0
            rr += [rows[ok], rows]
            cc += [hc[ok], nh + 3 * tj + c]
            vv += [-w[ok] * u[ok, c], w * u[:, c]]
        rr.append(rows)
        cc.append(nh + 3 * t + si)
        vv.append(-w)
        rr, cc, vv = np.concatenate(rr), np.concatenate(cc), np.concatenate(vv)
        if sparse:
            return scipy.sparse.csr_matrix((vv, (rr, cc)), shape=(len(d), n))
        J = np.zeros((len(d), n))
        J[rr, cc] = vv
        return J

    x, conv = levenberg_marquardt(fun, jac, np.concatenate([H[free_h], T.ravel(), o]),
                                   max_iter=max_nfev, deadline=deadline)
    if robust:
        r = fun(x)
        scale = max(1.4826 * np.median(np.abs(r)), 1.0)
        if np.max(np.abs(r)) > 10 * scale:   # gross errors: Huber weights, a few reweightings
            for _ in range(5):
                if deadline is not None and time.monotonic() >= deadline:
                    break
                k = 3 * scale
                hw = np.sqrt(np.minimum(1.0, k / np.maximum(np.abs(fun(x)), 1e-300)))
                x, conv = levenberg_marquardt(lambda z: hw * fun(z), lambda z: row_scale(jac(z), hw), x,  # noqa: B023
                                               max_iter=max_nfev, deadline=deadline)
    Hx, Tx, ox = unpack(x)
    r = d - range_m(Hx[si] - Tx[tj]) - ox[si]
    return Hx, Tx, ox, float(np.sqrt(np.mean(r ** 2))), float(1.4826 * np.median(np.abs(r))), conv


def point_fit(A, d, w, p, *, iters=8):
    """Gauss-Newton for one point ``p`` (3,) from anchors ``A`` (n, 3), offset-corrected distances
    ``d`` (n,) and weights ``w`` (n,); returns the point and its weighted cost ``sum w r^2``."""
    for _ in range(iters):
        rho, J = line_of_sight(p - A, floor_m=1e-12)
        r = d - rho
        sw = np.sqrt(w)
        step, *_ = np.linalg.lstsq(sw[:, None] * J, sw * r, rcond=None)
        p = p + step
        if np.max(np.abs(step)) < 1e-12 * (1.0 + np.max(np.abs(p))):
            break
    r = d - range_m(p - A)
    return p, float(w @ r ** 2)


def mirror_sweep(D, W, H, T, o):
    """Targets whose mirror image through the best-fitting plane of their stations fits their own
    distances better (weighted cost lower by more than 1; stations and offsets held): moved there. Returns the moved indices.

    With (nearly) coplanar stations a target and its mirror image are (nearly) equivalent, and the
    block factorisation or a multilateration from 4 stations can put single targets on the wrong
    side; the refinement cannot bring them back (a wrong local minimum, issue 10). ``T`` is
    modified in place."""
    seen = np.isfinite(D)
    moved = []
    for j in range(T.shape[0]):
        st = np.flatnonzero(seen[:, j])
        if len(st) < 4:       # 3 stations: the two sides fit exactly, nothing to decide
            continue
        A, d, w = H[st], D[st, j] - o[st], W[st, j]
        r0 = d - range_m(T[j] - A)
        c0 = float(w @ r0 ** 2)
        c = A.mean(0)
        n = np.linalg.svd(A - c)[2][2]
        Tm, c1 = point_fit(A, d, w, T[j] - 2.0 * ((T[j] - c) @ n) * n)
        if c1 < c0 - 1.0:   # clearly lower (the cost is a chi-square sum: 1 is its noise scale)
            T[j] = Tm
            moved.append(j)
    return moved


def refine_unmirrored(D, W, H, T, o, frame, *, rounds=4, **kw):
    """:func:`refine`, then :func:`mirror_sweep` and a new refinement while targets move (not after
    ``kw['deadline']``)."""
    out = refine(D, W, H, T, o, frame, **kw)
    deadline = kw.get("deadline")
    for _ in range(rounds):
        if deadline is not None and time.monotonic() >= deadline:
            break
        H, T, o = out[0], out[1].copy(), out[2]
        if not mirror_sweep(D, W, H, T, o):
            break
        out = refine(D, W, H, T, o, frame, **kw)
    return out


#: unknowns from which the refinement uses sparse normal equations (SuperLU) instead of dense ones
SPARSE_FROM = 150


def row_scale(J, w):
    if not isinstance(J, np.ndarray):           # sparse
        return scipy.sparse.diags(w) @ J
    return w[:, None] * J


def levenberg_marquardt(fun, jac, x, *, max_iter=200, tol=1e-10, deadline=None):
    """Minimise ``|fun(x)|^2`` by Levenberg-Marquardt with Marquardt scaling; ``jac`` may return a
    dense array or a scipy sparse matrix (then the normal equations are solved by SuperLU). Bounded
    by ``max_iter`` iterations (work) and, when given, by ``deadline`` (a :func:`time.monotonic`
    value, wall time: checked before each iteration; :mod:`multilat.network.adjust.approximate.bounds`).

    Returns ``(x, convergence)``: the lowest-cost point and a :class:`~multilat.network.adjust.solve.Convergence`
    (``last_step_sigma`` is NaN here: the step is relative to the parameters)."""
    r = fun(x)
    cost = r @ r
    lam = 1e-3
    it = 0
    for it in range(1, max_iter + 1):
        if deadline is not None and time.monotonic() >= deadline:
            return x, Convergence(False, it - 1, float("nan"), "wall-time bound")
        J = jac(x)
        sp = not isinstance(J, np.ndarray)
        A = (J.T @ J).tocsc() if sp else J.T @ J
        g = J.T @ r
        dg = np.maximum(A.diagonal(), 1e-30)
        while True:
            try:
                if sp:
                    step = scipy.sparse.linalg.spsolve(A + scipy.sparse.diags(lam * dg, format="csc"), g)
                    if not np.all(np.isfinite(step)):
                        raise np.linalg.LinAlgError
                else:
                    step = np.linalg.solve(A + lam * np.diag(dg), g)
            except (np.linalg.LinAlgError, RuntimeError):
                step = None
            if step is not None:
                # r = w (d - f): J above is d r / d x, so the Gauss-Newton step is -solve(...)
                xn = x - step
                rn = fun(xn)
                cn = rn @ rn
                if np.isfinite(cn) and cn <= cost:
                    break
            lam *= 10.0
            if lam > 1e12:
                return x, Convergence(False, it, float("nan"), "no decrease of the cost")
        small = np.all(np.abs(step) <= tol * (np.abs(x) + 1e-3))
        x, r, done = xn, rn, (cost - cn) <= 1e-10 * cost or small
        cost = cn
        lam = max(lam / 10.0, 1e-12)
        if done:
            return x, Convergence(True, it, float("nan"), "step or cost change below tolerance")
    return x, Convergence(False, it, float("nan"), "iteration limit")


def to_frame(H, T, frame):
    """Rotate/translate so that frame stations (a, b, c) are at origin, +x, xy-plane y > 0."""
    a, b, c = frame
    e1 = H[b] - H[a]
    e1 /= np.linalg.norm(e1)
    v = H[c] - H[a]
    e2 = v - e1 * (v @ e1)
    e2 /= np.linalg.norm(e2)
    e3 = np.cross(e1, e2)
    R = np.vstack([e1, e2, e3])
    return (H - H[a]) @ R.T, (T - H[a]) @ R.T


def choose_frame(H):
    """First station triple (in id order) with a well-shaped triangle (smallest height >= 20 %
    of its longest side); else the best-shaped triple."""
    s = len(H)
    best, bq = None, -1.0
    for tri in itertools.combinations(range(s), 3):
        P = H[list(tri)]
        sides = [np.linalg.norm(P[1] - P[0]), np.linalg.norm(P[2] - P[1]), np.linalg.norm(P[0] - P[2])]
        area2 = np.linalg.norm(np.cross(P[1] - P[0], P[2] - P[0]))
        q = area2 / max(max(sides) ** 2, 1e-300)  # height / longest side
        if q >= 0.2:
            return tri
        if q > bq:
            best, bq = tri, q
    return best


def fix_mirror(H, T, frame):
    """Reflect z if needed: first non-frame station off the plane (by id) has z > 0."""
    scale = scale_of(np.vstack([H, T]))
    for i in range(len(H)):
        if i in frame:
            continue
        if abs(H[i, 2]) > 0.01 * scale:
            flip = H[i, 2] < 0
            break
    else:
        k = int(np.argmax(np.abs(T[:, 2])))
        flip = T[k, 2] < 0
    if flip:
        H = H * [1, 1, -1]
        T = T * [1, 1, -1]
    return H, T


# ----------------------------------------------------------------------------- public


def scale_of(points):
    p = points[np.all(np.isfinite(points), axis=1)]
    return float(np.sqrt(((p - p.mean(0)) ** 2).sum(1).mean())) if len(p) else 1.0


# ----------------------------------------------------------------------------- algebraic block


