"""Data snooping on the general network: Baarda's procedure (variance factor known) or Pope's (unknown),
one rejection per round, each followed by a new adjustment.

Each round, on the last adjustment:

1. **detection** — :func:`multilat.network.adjust.distance.snooping.detection_step`, the distance path's own: the global
   χ² test (B-method, fixed α), the largest |w| against Šidák's critical value (large networks), or
   the largest |τ| (variance factor unknown); the test levels are those of the first round
   (:func:`multilat.network.adjust.statistics.test_levels`, as the distance path fixes them once);
2. **identification** — the row with the largest |w| (|τ|) above its critical value;
3. **adaptation** — that row is removed and the network adjusted again (:func:`.run.adjust_network`,
   from the last solution), unless:

   - another row's w-test is perfectly correlated with it (``|ρ| > 1 - 1e-6``,
     :func:`multilat.network.adjust.statistics.correlated_with` on the row of the hat matrix): the data cannot
     tell which is wrong; snooping stops and names both (``unlocated``);
   - removing it would leave a point it observes without redundancy (every remaining row of the point
     uncontrolled, from the rank-one downdate ``r' = r - c² / r_k``; a point that had none before is not
     counted): snooping stops and says so, as the distance path does for a target's last redundancy.

A **correlated block** (a coordinate-difference vector, observed coordinates, a correlated levelling
line: the rows of a block linked by non-zero covariance) is rejected as a block: the failing row
takes the rows it is correlated with (the record says so: ``block_rows``). Removing a block can leave a
point undetermined (its 3 × 3 vector was all that fixed it): the point is then left out and named by
:func:`.run.adjust_network` (``points_left_out`` of the rejection, and the adjustment's ``excluded``);
with ``strict`` snooping stops instead and says why. A failing weighted coordinate of a control point
(an ``observed_coordinates`` row of the point set) is rejected by making that coordinate free.

**Gross errors are refused, not snooped.** Data snooping looks for a few blunders in a network whose
model fits the rest; it is not a way to make a wrong model fit. Before each rejection the rows
rejected so far and the one identified are checked, and snooping stops with
:class:`SnoopingRefused` (one line naming the rows it would remove; nothing is rejected) when

- the identified row's residual is more than :data:`GROSS_SIGMA` (1000) times its a-priori σ (a
  tracker of 10 µm off by 10 mm: a wrong target, unit or sign, not a blunder among the readings);
- the rejections would take more than half of one point's observation rows, in two rejections or
  more (a point, or a set-up, whose observations disagree with the network as a whole: a control
  point in the wrong frame, a station mirrored, a wrong point number; one blunder per point is what
  snooping is for);
- more than :data:`MAX_SHARE` (5 %) of the network's rows would be rejected, and more than
  :data:`MIN_REFUSED` - 1 rejections (a network where that many observations fail is a wrong model).

``gross=False`` keeps Baarda's procedure alone (what it rejected is still listed). The command line
adds what the refusal may mean: azimuths of the opposite sense (:mod:`multilat.cli.general_adjust`).

Bounded: at most ``max_rejections`` rejections (default: every row) and :data:`SNOOP_SECONDS` of wall
time (:class:`multilat.network.adjust.approximate.bounds.Bound`, a note when it stops the rounds); each round reports
its progress line (:func:`multilat.network.adjust.approximate.bounds.report`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust import statistics as st
from multilat.network.adjust.approximate.bounds import Bound, report
from multilat.network.adjust.general import reliability as rel
from multilat.network.adjust.general.adjust import System, UndeterminedError
from multilat.network.model.observations import Network, point_keys, without_rows
from multilat.network.model.points import FREE, PointSet
from multilat.network.adjust.general.quality import POWER, GeneralStatistics, statistics
from multilat.network.adjust.general.report import row_ends, row_record
from multilat.network.adjust.general.run import NetworkAdjustment, adjust_network
from multilat.network.adjust.distance.snooping import detection_step

__all__ = ["Snooping", "SnoopingRefused", "snoop", "SNOOP_SECONDS", "correlated_rows", "GROSS_SIGMA", "MAX_SHARE",
           "MIN_REFUSED"]

#: wall-time bound of the snooping rounds (each a full adjustment), seconds
SNOOP_SECONDS = 600.0
#: |ρ| above 1 - this: two w-tests the data cannot tell apart (the distance path's tolerance)
TWIN_TOL = 1e-6

#: a residual above this many times the row's a-priori σ is a gross error: snooping refuses (module docstring)
GROSS_SIGMA = 1000.0
#: share of the network's rows beyond which the rejections are refused (with at least MIN_REFUSED of them)
MAX_SHARE = 0.05
#: the fewest rejections the share rule refuses (one or two blunders are snooped in any network)
MIN_REFUSED = 3


class SnoopingRefused(MultilatError):
    """Data snooping would remove gross errors (module docstring): ``rows`` the records of the rows it
    rejected before and would reject now, ``sigma0`` that of the adjustment before snooping."""

    def __init__(self, message: str, *, rows: tuple = (), sigma0: float = float("nan")):
        super().__init__(message)
        self.rows, self.sigma0 = tuple(rows), float(sigma0)


@dataclass(frozen=True, eq=False)
class Snooping:
    """adjustment : the final :class:`~.run.NetworkAdjustment` (without the rejected rows)
    stats : its :class:`~.quality.GeneralStatistics`
    rejected : tuple of dicts, one per rejection in order (JSON-ready: ``index`` (its row in the
        observations table: the final system's rows, then the rejections), ``order``, ``round``, ``label``,
        ``kind``, ``from``/``to``/..., ``w``, ``test``, ``statistic``, ``critical``, ``residual``
        (against the final solution), ``residual_rejected`` (when rejected), ``unit``, ``n_rows``,
        ``block_rows`` (the labels of a correlated block rejected with it), ``points_left_out``)
    unlocated : tuple of dicts (rows not rejected although failing; ``index`` their row in the final
        system, so in the table), ``unlocated_reason`` why
    steps : the detection steps, one per round (:func:`multilat.network.adjust.distance.snooping.detection_step`);
        a step that identified a row names it by ``index`` (in the table) and ``kind``
    snooping : whether data snooping was asked for; ``note``: a bound that stopped it, else ""
    """

    adjustment: NetworkAdjustment
    stats: GeneralStatistics
    rejected: tuple
    unlocated: tuple
    unlocated_reason: str
    steps: tuple
    snooping: bool
    note: str = ""


def snoop(network: Network, *, options=None, strict: bool = False, alpha: float = 0.001,
          variance_factor: str = "known", method: str | None = None, alpha_global: float | None = None,
          alpha_family: float = st.ALPHA_FAMILY, power: float = POWER, snooping: bool = True,
          max_rejections: int | None = None, max_seconds: float = SNOOP_SECONDS,
          adjustment: NetworkAdjustment | None = None, gross: bool = True) -> Snooping:
    """Adjust ``network`` (:func:`.run.adjust_network`, or take ``adjustment``), then data snooping
    (module docstring) unless ``snooping`` is False; the statistics of the final adjustment.
    :class:`SnoopingRefused` when it would remove gross errors (unless ``gross`` is False)."""
    adj = adjustment or adjust_network(network, options=options, strict=strict)
    gate = _Gate(adj) if gross else None
    given, excluded = adj.given, list(adj.excluded)
    tests = dict(alpha=alpha, variance_factor=variance_factor, method=method, alpha_global=alpha_global,
                 alpha_family=alpha_family, power=power)
    stats = statistics(adj.system, adj.result, external=False, **tests)   # the rounds need no shifts
    levels = stats.levels
    unknown = variance_factor == "unknown"
    lam0 = st.noncentrality(levels.alpha0, power)
    crit = st.w_critical(levels.alpha0)
    limit = adj.system.n_rows if max_rejections is None else int(max_rejections)
    bound = Bound("data snooping", max_work=max(limit, 0), max_seconds=max_seconds)
    rejected, steps, unlocated, reason, params_then = [], [], (), "", []
    while snooping and not bound.exhausted():
        res = adj.result
        w = stats.w
        k = int(np.argmax(np.abs(w)))
        core = {"dof": res.dof, "sigma0": res.sigma0, "vtpv": stats.vtpv}
        step = detection_step(core, float(w[k]), unknown, levels.alpha0, levels, lam0, crit)
        steps.append(step)
        if step["detection_passed"] is not False or not step["identified"]:
            break
        system = adj.system
        jw = rel.whitened_jacobian(system, res)
        unit = correlated_rows(system, k)
        step.update(index=k, kind=system.blocks[_block_of(system, k)].kind)   # a rejection's: _finish
        twins = _twins(jw, res.cofactor_times, stats.redundancy, k, unit)
        if twins.size:
            unlocated = tuple(_indexed(system, stats, int(q)) for q in np.concatenate([[k], twins]))
            reason = "perfectly correlated w-tests: the data cannot tell which observation is wrong"
            break
        why = _guard(system, jw, res.cofactor_times, stats.redundancy, unit)
        if why:
            unlocated, reason = (_indexed(system, stats, k),), why
            break
        if gate is not None:
            gate.check(system, stats, unit, [r for r, _, _ in rejected])
        record = dict(row_record(system, stats, k), round=len(steps), order=len(rejected) + 1,
                      test=step["test_k"], statistic=step["statistic_k"], critical=step["critical_k"],
                      residual_rejected=float(stats.residual[k]), n_rows=int(unit.size),
                      block_rows=[_label(system, int(q)) for q in unit if q != k] if unit.size > 1 else [],
                      points_left_out=[])
        report(f"data snooping: round {len(steps)}, rejecting {record['label'] or record['kind']} "
               f"({step['test_k']} = {step['statistic_k']:+.2f})")
        try:
            new = _adjust_without(adj, unit, options=options, strict=strict)
        except UndeterminedError as e:                     # strict, or a defect no point carries
            unlocated = (_indexed(system, stats, k),)
            reason = (f"rejecting it would leave {e}" + ("; --strict leaves no point out" if strict else ""))
            break
        except MultilatError as e:
            unlocated, reason = (_indexed(system, stats, k),), f"rejecting it would leave the network unsolvable ({e})"
            break
        for e in new.excluded:
            record["points_left_out"].append(e["id"])
            excluded.append(dict(e, round=len(steps), reason=f"{e['reason']} once {record['label']} was rejected"))
        params_then.append(dict(zip(res.names, res.parameters)))
        rejected.append((record, _removed_rows(system, unit), system.network.points))
        bound.spend()
        adj = NetworkAdjustment(new.network, new.system, new.result, given, tuple(excluded))
        stats = statistics(adj.system, adj.result, levels=levels, external=False, **tests)
    stats = statistics(adj.system, adj.result, levels=levels, **tests)   # the final one, with external reliability
    return _finish(adj, stats, rejected, params_then, steps, unlocated, reason, snooping, bound, limit, max_seconds)


def _finish(adj, stats, rejected, params_then, steps, unlocated, reason, snooping, bound, limit,
            max_seconds) -> Snooping:
    """The record: the rejections with their residuals at the final solution, the steps' actions, the
    bound's note."""
    if unlocated and steps:
        steps[-1]["action"] = f"not rejected: {reason}"
    out, n_final = [], adj.system.n_rows
    for (record, removed, pts), then in zip(rejected, params_then):
        record["residual"] = _final_residual(removed, pts, adj.result, then)
        record = {"index": n_final + len(out), **record}      # its row in the observations table
        out.append(record)
        steps[record["round"] - 1].update(action="rejected", index=record["index"])
    note = ""
    if snooping and bound.stopped_by:
        note = (f"data snooping stopped at its bound of {limit} rejection(s); the tests are those of the last "
                "adjustment" if bound.stopped_by == "work" else
                f"data snooping stopped at its wall-time bound ({max_seconds:g} s) after {len(out)} rejection(s)")
    return Snooping(adj, stats, tuple(out), unlocated, reason if unlocated else "", tuple(steps), bool(snooping),
                    note)


# ---------------------------------------------------------------- gross errors
class _Gate:
    """The refusal rules of the module docstring, on the network as adjusted before snooping (its rows
    per point and in all) and the rows rejected so far."""

    def __init__(self, adj: NetworkAdjustment):
        ref = _point_rows(adj.system)
        ids = adj.system.network.points.ids
        self.n_rows = adj.system.n_rows
        r = np.sort(ref, axis=1)                     # rows per point, each row once: O(rows), not points x rows
        once = r >= 0
        once[:, 1:] &= r[:, 1:] != r[:, :-1]
        counts = np.bincount(r[once], minlength=len(ids))
        self.per_point = {ids[p]: int(counts[p]) for p in np.flatnonzero(counts)}
        self.sigma0 = float(adj.result.sigma0)

    def check(self, system: System, stats: GeneralStatistics, unit, before: list) -> None:
        """Raise :class:`SnoopingRefused` if rejecting the rows ``unit`` of ``system`` after the
        rejections ``before`` (their records) breaks a rule."""
        now = [row_record(system, stats, int(q)) for q in unit]
        ratio = np.abs(stats.residual[unit]) / stats.sigma[unit]
        j = int(np.argmax(ratio))
        if ratio[j] > GROSS_SIGMA:
            o = now[j]
            self._refuse(f"{_what(o)} has a residual of {o['residual']:+.4g} {o['unit']} = {ratio[j]:.3g} σ (more "
                         f"than {GROSS_SIGMA:g} σ: a gross error, not a blunder among the readings)", before + now)
        items = [(set(row_ends(r)), int(r["n_rows"]), [r]) for r in before]
        items.append((set().union(*(row_ends(o) for o in now)), len(now), now))
        per: dict = {}
        for ends, n, recs in items:
            for p in ends:
                c = per.setdefault(p, [0, 0, []])
                c[0], c[1] = c[0] + 1, c[1] + n
                c[2] += recs
        for p, (n_rej, n_rows, recs) in per.items():
            if n_rej >= 2 and 2 * n_rows > self.per_point.get(p, 0):
                self._refuse(f"it would reject {n_rows} of the {self.per_point.get(p, 0)} observation rows of point "
                             f"{p!r} ({_listed(recs)})", recs)
        n_rows = sum(n for _, n, _ in items)
        if len(items) >= MIN_REFUSED and n_rows > MAX_SHARE * self.n_rows:
            recs = [o for _, _, r in items for o in r]
            self._refuse(f"it would reject {n_rows} of the network's {self.n_rows} observation rows (more than "
                         f"{MAX_SHARE:.0%}: {_listed(recs)})", recs)

    def _refuse(self, why: str, rows) -> None:
        raise SnoopingRefused(f"data snooping refused: {why}; the observations disagree with the network as a "
                              "whole (a wrong point number, unit, frame or sign of an angle?): check them, or adjust "
                              "with --no-snooping to see every residual", rows=tuple(rows), sigma0=self.sigma0)


def _what(o: dict) -> str:
    """A row in words: its label (the file's line) or its kind and ends."""
    kind = o["kind"].replace("_", " ") + (f" ({o['component']})" if o.get("component") else "")
    ends, label = "->".join(row_ends(o)), o.get("label") or ""
    return label if ends in label else f"{kind} {ends}" + (f" ({label})" if label else "")


def _listed(rows, limit: int = 6) -> str:
    words = [_what(o) for o in rows]
    return ", ".join(words[:limit]) + (f" and {len(words) - limit} more" if len(words) > limit else "")


# ---------------------------------------------------------------- rows
def correlated_rows(system: System, k: int) -> np.ndarray:
    """The rows rejected with row ``k``: ``k`` and, in a block with a full covariance, every row linked
    to it by non-zero covariance (directly or through others: a vector's 3 rows, a levelling line)."""
    q = _block_of(system, k)
    b, sl = system.blocks[q], system.rows[q]
    if b.cov is None:
        return np.array([k])
    link = np.asarray(b.cov) != 0
    seen = np.zeros(b.n_rows, bool)
    seen[k - sl.start] = True
    while True:
        nxt = seen | link[seen].any(axis=0)
        if (nxt == seen).all():
            return np.flatnonzero(seen) + sl.start
        seen = nxt


def _block_of(system: System, k: int) -> int:
    return int(np.searchsorted([sl.stop for sl in system.rows], k, side="right"))


def _indexed(system: System, stats, k: int) -> dict:
    """Row ``k`` of the final ``system`` as an ``unlocated`` record: ``index`` (its row in the
    observations table, :func:`.report.observation_table`) and :func:`.report.row_record`."""
    return {"index": k, **row_record(system, stats, k)}


def _label(system: System, k: int) -> str:
    q = _block_of(system, k)
    b = system.blocks[q]
    j = k - system.rows[q].start
    return str(b.labels[j]) if len(b.labels) == b.n_rows else ""


def _twins(jw, Q, red, k: int, unit) -> np.ndarray:
    """Rows outside ``unit`` whose w-test is perfectly correlated with row ``k``'s."""
    c = jw @ Q(rel.dense_rows(jw, k).ravel())              # row k of the hat matrix (Q: Q times)
    out = st.correlated_with(c, np.clip(red, 0.0, None), k, TWIN_TOL)
    return out[~np.isin(out, unit)]


def _guard(system: System, jw, Q, red, unit) -> str:
    """Why the rows ``unit`` must not be rejected ("" when they may). Removing rows that leave the
    design rank-deficient (a point undetermined) is for :func:`.run.adjust_network` to name."""
    C = jw @ Q(rel.dense_rows(jw, unit).T)                 # (R, u): the hat matrix's columns
    Rkk = np.eye(unit.size) - C[unit]
    if np.linalg.eigvalsh(Rkk).min() <= st.R_ZERO:
        return ""
    after = red - np.einsum("ij,ij->i", C, np.linalg.solve(Rkk, C.T).T)
    after[unit] = 0.0
    ref = _point_rows(system)
    pts = system.network.points
    points = np.unique(ref[unit][ref[unit] >= 0])
    near = np.flatnonzero(np.isin(ref, points).any(axis=1))   # one pass over the rows, then only theirs
    for p in points.tolist():
        if not np.any(pts.status[p] == FREE):
            continue
        mine = near[np.any(ref[near] == p, axis=1)]
        rest = mine[~np.isin(mine, unit)]
        if np.any(red[rest] > st.R_ZERO) and not np.any(after[rest] > 1e-6):
            return (f"rejecting it would leave point {pts.ids[p]!r} without redundancy (its {rest.size} other "
                    "observation row(s) would be uncontrolled)")
    return ""


def _point_rows(system: System) -> np.ndarray:
    """(R, 4) point indices of every row (-1 padded)."""
    ref = np.full((system.n_rows, 4), -1)
    for b, sl in zip(system.blocks, system.rows):
        for c, key in enumerate(point_keys(b)[:4]):
            ref[sl, c] = np.asarray(b.index[key], int)
    return ref


def _removed_rows(system: System, unit) -> list:
    """The rejected rows as (block, rows of the block) pairs, for their final residuals."""
    out = []
    for q, sl in enumerate(system.rows):
        mine = unit[(unit >= sl.start) & (unit < sl.stop)] - sl.start
        if mine.size:
            out.append((system.blocks[q], mine))
    return out


def _adjust_without(adj: NetworkAdjustment, unit, *, options, strict) -> NetworkAdjustment:
    """The network without the rows ``unit`` adjusted again from the last solution."""
    net, system = adj.network, adj.system
    n_given = len(net.blocks)
    drop, freed = {}, []
    for q, sl in enumerate(system.rows):
        mine = unit[(unit >= sl.start) & (unit < sl.stop)] - sl.start
        if mine.size and q < n_given:
            drop[q] = mine
        elif mine.size:                                    # the weighted coordinates of the point set
            b = system.blocks[q]
            freed += [(int(b.index["point"][j]), int(b.index["axis"][j])) for j in mine]
    pts = net.points.with_xyz(adj.result.xyz_m)
    if freed:
        status, sigma = pts.status.copy(), pts.sigma_m.copy()
        for i, a in freed:
            status[i, a], sigma[i, a] = FREE, np.nan
        pts = PointSet(pts.ids, pts.xyz_m, status, sigma, pts.constrained)
    reduced = without_rows(Network(pts, net.blocks, net.notes), drop)
    return adjust_network(reduced, options=options, strict=strict)


def _final_residual(removed, pts: PointSet, result, then: dict) -> list | float:
    """Observed minus computed of the rejected rows at the final solution (parameters by name; those
    the final adjustment no longer has, e.g. a direction set left without rows, at their values when
    the rows were rejected; NaN for a point left out since)."""
    from multilat.network.model import kinds as kinds_registry

    final = dict(zip(result.names, result.parameters))
    out = []
    for b, rows in removed:
        mask = np.zeros(b.n_rows, bool)
        mask[rows] = True
        sub = without_rows(Network(pts, (b,), ()), {0: ~mask}).blocks[0]
        sysr = System(Network(pts, (sub,), ()))
        x = np.array([final.get(n, then.get(n, np.nan)) if n[:2] not in ("x:", "y:", "z:") or n in final
                      else np.nan for n in sysr.layout.names])
        computed, _, _ = kinds_registry.kind(sub.kind).evaluate(sub, sysr.layout, sysr.cols[0], x)
        out += [float(v) for v in kinds_registry.residual(sub, computed)]
    return out[0] if len(out) == 1 else out
