"""End-to-end Monte Carlo through the self-calibrating adjustment (JCGM 101 / JCGM 102).

Each trial draws every distance of the network from the distance model (non-gaussian telemetric,
head and target errors, :func:`multilat.budget.sample_distance_errors`) — or from a gaussian of the
observations' ``sigma_m`` — re-solves the whole network with the batched solver
(:mod:`multilat.network.montecarlo.batched`, same datum in every trial, each trial started from the nominal
solution) and records station coordinates, offsets, target coordinates and interpoint distances.

The nominal network (the centre of the input distributions) is

* for a built-in configuration (``small_volume()``, ``large_volume()``): the configuration's truth;
  the nominal distances are the exact ``|H - T| + offset``, so the Monte Carlo distributions are
  those of the *errors* of the self-calibrated result;
* for measured observations: the adjustment of the measured distances (:func:`adjust`); the
  nominal distances are the measured ones (JCGM 101: the input PDFs are centred on the measured
  values), and the trials show how the adjusted result scatters for the modelled errors.

Outputs (all from the same trials): per parameter the MC estimate, standard uncertainty, 95 %
probabilistically symmetric and shortest coverage intervals; per point the MC covariance, its 95 %
coverage ellipsoid (JCGM 102 §7.7: ``(x - mean)^T C^-1 (x - mean) <= chi2_3(0.95)``) and the fraction
of trials inside it, and inside the linear ellipsoid; per interpoint distance the same scalar
summaries; and a validation table beside the linear (first-order) covariance of the adjustment,
with the Monte Carlo standard error of each standard deviation.

Seeding, chunking and statistics are the Monte Carlo engine's (:mod:`multilat.montecarlo`): trials are
drawn and solved in fixed blocks of :data:`BLOCK` trials, block ``b`` from
``block_generator(entropy, spawn_key, b)``; a chunk (``chunk_size``, the unit of work handed to
``map=`` from :mod:`multilat.parallel`) is a run of whole blocks, so the numbers are bit-identical
whatever the chunk size, the map or the number of workers. The adaptive run is the engine's
:class:`AdaptiveRule` (JCGM 101 §7.9) and the summaries its :func:`summarize` (§7.6-7.7). Trials that
fail to converge are dropped and counted (``n_failed``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from multilat.errors import MultilatError
from multilat.fast_normal import _fast_std_normal
from multilat.montecarlo import (AdaptiveRule, resolve_map, block_generator, block_trials, chunk_ranges,
                                 resolve_seed)
from multilat.network.montecarlo import batched as bt
from multilat.network.model.parameter_layout import XYZ
from multilat.network.montecarlo.propagate_pairs import default_pairs as _default_pairs  # noqa: F401 (general layer)
from multilat.network.montecarlo.propagate_pairs import pairs_and_refs, parse_pairs
from multilat.network.montecarlo.propagate_result import PropagationResult, chi2_3_95
from multilat.network.montecarlo.propagate_summary import linear_std, summarise
from multilat.network.model.sigma_source import DEFAULT_SIGMA_M
from multilat.parallel import release_map, thread_map

__all__ = ["BLOCK", "NOT_PROPAGATED", "Problem", "noise_choice", "parse_pairs", "problem_from_observations",
           "problem_from_truth", "problem_from_config", "propagate", "PropagationResult", "chi2_3_95"]

#: Trials per seeded block (a constant of the seeding, like :data:`multilat.montecarlo.BLOCK` for
#: ``run_mc``, smaller because every trial solves a whole network): block ``b`` draws from
#: ``montecarlo.block_generator(entropy, spawn_key, b)`` and is solved as one batch.
BLOCK = 1000


# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Problem:
    """The nominal network to propagate through.

    Attributes
    ----------
    station_ids, target_ids : tuple of str
    network : BatchedNetwork
        Structure, weights, nominal solution and datum.
    distance_m : ndarray, shape (m,)
        Nominal distances (centres of the input distributions).
    heads : tuple of str, length s
        Instrument head used for each station's distance errors (``noise="model"``).
    pairs : tuple of (str, str)
        Interpoint distances to report (target or station ids).
    reference_m : ndarray, shape (len(pairs),)
        Reference lengths for the pairs (NaN when none).
    source : str
        Description (configuration name or file).
    sigma0_nominal : float
        A-posteriori sigma0 of the nominal solution: 0 for a known truth (exact nominal distances),
        the adjustment's sigma0 for measured observations (their residuals are in every trial).
    readings : multilat.network.montecarlo.readings.Readings or None
        The readings behind the observations (shared environment sensors, repeated readings): each
        trial draws the readings' and the sensors' errors (:meth:`Readings.draw`); None: one
        independent error per observation.
    instrument : Instrument or None
        The instrument the heads were resolved with: the distance model :func:`propagate` draws from
        with ``noise="model"`` unless it is given one; None: no instrument was named (the errors are
        then drawn gaussian with the observations' σ).
    """

    station_ids: tuple
    target_ids: tuple
    network: bt.BatchedNetwork
    distance_m: np.ndarray
    heads: tuple
    pairs: tuple = ()
    reference_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    source: str = ""
    sigma0_nominal: float = 0.0
    readings: object = None
    instrument: object = None

    def point_xyz(self, ident: str) -> np.ndarray:
        k, i = self.point_index(ident)
        return (self.network.station_xyz_m if k == "station" else self.network.target_xyz_m)[i]

    def point_index(self, ident: str) -> tuple[str, int]:
        if ident in self.station_ids:
            return "station", self.station_ids.index(ident)
        if ident in self.target_ids:
            return "target", self.target_ids.index(ident)
        raise MultilatError(f"unknown point id {ident!r}")

    def param_rows(self, ident: str) -> np.ndarray:
        """Rows of a point's xyz in the :func:`batched.flatten` layout."""
        k, i = self.point_index(ident)
        lay = self.network.reported_layout
        return lay.station_block(XYZ)[i] if k == "station" else lay.target_block()[i]


def _heads_for(head_names, instrument, head: str | None):
    """Each station's instrument head: its head name (the station id without a head column) when the
    instrument resolves it (own block, head type or ``[heads.default]``), else ``head`` ("A")."""
    if instrument is None:
        return tuple(head or "A" for _ in head_names)
    has = getattr(instrument, "has_head", None)
    tracker = getattr(instrument, "is_tracker", lambda _: False)
    names = set(getattr(instrument, "heads", {}) or {})
    return tuple(n if (tracker(n) or (has(n) if has is not None else n in names)) else (head or "A")
                 for n in head_names)


def problem_from_truth(station_ids, target_ids, station_index, target_index, sigma_m, station_xyz_m,
                       offset_m, target_xyz_m, *, datum="free", pairs=None, references=None,
                       instrument=None, head: str | None = None, source: str = "",
                       pairs_option: str = "interpoint distance") -> Problem:
    """A problem whose nominal distances are the exact distances of a known truth.

    With a ``321:A,B,C`` datum the truth is first expressed in that frame (A at the origin, B on +x,
    C in the xy-plane with y > 0), so the fixed coordinates are A.xyz, B.y, B.z and C.z.

    ``references``: optional mapping ``(a, b) -> length_m`` (or :class:`ReferenceLengths`); when
    ``pairs`` is None, the reference pairs are reported if given, else all target pairs (up to 20
    targets) or consecutive ones.
    """
    station_ids = tuple(str(s) for s in station_ids)
    target_ids = tuple(str(t) for t in target_ids)
    dt = bt.TrialDatum.from_datum(datum, station_ids, target_ids)
    h = np.asarray(station_xyz_m, float)
    tg = np.asarray(target_xyz_m, float)
    if dt.kind == "321":   # express the truth in the 3-2-1 frame (as network.adjust does)
        from multilat.network.model.datum import apply_rigid, frame_321

        x = np.concatenate([h, tg])
        a, b, c = dt._stacked(len(h), len(tg))
        rot, shift = frame_321(x[a], x[b], x[c])
        h, tg = apply_rigid(rot, shift, h), apply_rigid(rot, shift, tg)
    net = bt.BatchedNetwork(station_index, target_index, sigma_m, h, offset_m, tg, datum=dt)
    pairs_, ref = pairs_and_refs(pairs, references, target_ids, station_ids, pairs_option)
    return Problem(station_ids, target_ids, net, net.nominal_distance_m(),
                   _heads_for(station_ids, instrument, head), pairs_, ref, source, instrument=instrument)


#: Options of the adjustment a propagation does not take, refused by name when set: its nominal
#: adjustment keeps every observation (no data snooping: every trial solves the same network) and the
#: weighted distance model; the tests judge one adjustment, not the scatter of its trials.
NOT_PROPAGATED = ("cost", "variance_components", "snooping", "max_rejections", "alpha", "power", "alpha_global",
                  "test_method", "alpha_family", "variance_factor", "mdb_limit_sigma", "r_min")


def refuse_not_propagated(opts) -> None:
    """One line naming the first option of :data:`NOT_PROPAGATED` that ``opts`` sets."""
    for f in NOT_PROPAGATED:
        if f in opts.model_fields_set and getattr(opts, f) != type(opts).model_fields[f].default:
            raise MultilatError(f"{opts.name(f)} does not apply to a propagation: its nominal adjustment keeps "
                                "every observation (no data snooping) with the weighted distance model")


def problem_from_observations(obs, options=None, *, pairs=None, references=None, instrument=None,
                              head: str | None = None, source: str = "", adjustment=None,
                              scale_bars=None, points=None, pairs_option: str = "interpoint distance",
                              **option_fields) -> Problem:
    """A problem centred on the adjustment of measured observations.

    ``obs`` is :class:`multilat.network.model.data.Observations`; the network model is ``options`` (a
    :class:`~multilat.network.adjust.distance.options.NetworkOptions`, the one ``adjust`` takes; or its fields as
    keywords: ``datum=``, ``scales=``, ``offsets_m=``, ``levelled=``, ...). The nominal solution is
    ``adjust(obs, options, points=points, scale_bars=..., snooping=False)`` (or ``adjustment`` if
    already computed), the weights are ``obs.sigma_m`` and the nominal distances the measured ones.
    Options that do not apply to a propagation (:data:`NOT_PROPAGATED`) are refused by name.

    What the batched solver (:class:`multilat.network.montecarlo.batched.BatchedNetwork`: one offset per
    station, distances only) cannot hold goes to :class:`multilat.network.montecarlo.batched_coupled.
    CoupledBatchedNetwork`: heads occupying several stations, held offsets (``offsets_m``), scale bars
    (``scale_bars``, or ``references`` with the option ``scale_bars=True``; each drawn from its
    length and ``u_m`` in every trial), control points (``points`` under ``datum="control"``: weighted
    ones drawn from their ``sx_m, sy_m, sz_m``, hard ones held) and per-head scales.

    ``pairs``: the interpoint distances to report ((a, b) point ids; default: the reference pairs,
    else every target pair up to 20 targets, else consecutive ones); ``pairs_option`` names them in
    errors (``--pairs``).
    """
    from multilat.network.model.datum import parse_datum
    from multilat.network.adjust.distance.options import NetworkOptions

    opts = NetworkOptions.of(options, **option_fields)
    refuse_not_propagated(opts)
    if scale_bars is None and opts.scale_bars:
        if references is None:
            raise MultilatError(f"{opts.name('scale_bars')} needs the reference lengths (--references FILE; "
                                "the bars' lengths with u_m)")
        scale_bars = references
    dat = parse_datum(opts.datum)
    if adjustment is None:
        from multilat.network.adjust.distance.adjust import adjust

        adjustment = adjust(obs, opts, points=points, scale_bars=scale_bars, snooping=False)
    res = adjustment
    if res.excluded:
        e = res.excluded[0]
        raise MultilatError(f"propagation: the adjustment left out {e.kind} {e.id!r} ({e.reason}); remove "
                            "it from the file so that every trial solves the same network")
    obs = res.obs
    station_ids = tuple(obs.station_ids)
    target_ids = tuple(obs.target_ids)
    pairs_, ref = pairs_and_refs(pairs, references, target_ids, station_ids, pairs_option)
    heads = _heads_for(obs.head_of_station, instrument, head)
    general = (obs.shares_heads or scale_bars is not None or dat.kind == "control"
               or bool(np.any(res.scale_estimated)) or obs.has_angle_observations
               or not bool(np.all(res.offset_estimated)))
    if general:
        net = _coupled_network(obs, res, dat, scale_bars, points)
    else:
        dt = bt.TrialDatum.from_datum(opts.datum, station_ids, target_ids)
        net = bt.BatchedNetwork(obs.station_index, obs.target_index, obs.sigma_m, res.station_xyz_m,
                                res.offset_m, res.target_xyz_m, datum=dt, covariance=res.covariance)
    return Problem(station_ids, target_ids, net, np.asarray(obs.distance_m, float), heads, pairs_, ref,
                   source, sigma0_nominal=float(res.sigma0), instrument=instrument)


def _coupled_network(obs, res, dat, scale_bars, points):
    """The general batched network of an adjustment (heads, scale bars, control, scales)."""
    from multilat.network.montecarlo.batched_coupled import CoupledBatchedNetwork
    from multilat.network.model.couplings import coupling_spec
    from multilat.network.adjust.distance.fit import control_ids

    s = obs.n_stations
    ids = tuple(obs.station_ids) + tuple(obs.target_ids)
    pos = {p: k for k, p in enumerate(ids)}
    hi = obs.head_index
    first = np.unique(hi, return_index=True)[1]
    held = np.zeros(len(ids), bool)
    if dat.kind == "control":
        for p in control_ids(obs, dat, points):
            held[pos[p]] = points.std(p) is None
        dt = None
    from multilat.network.model.angle_rows import angle_rows

    ar = angle_rows(obs)
    if dat.kind != "control":
        # levelled stations observe the vertical: the trials' datum fit turns about z only
        dt = bt.TrialDatum.from_datum(dat, obs.station_ids, obs.target_ids,
                                      about_z=ar is not None and ar.any_levelled)
    spec = coupling_spec(obs, bars=scale_bars, points=points, control=dat.kind == "control")
    bars = () if spec is None else spec.bars
    ctrl = () if spec is None else spec.control
    ori = np.zeros((s, 3))
    for sid, o in res.orientations.items():
        ori[obs.station_ids.index(sid)] = o["orientation_rad"]
    ang = {} if ar is None else dict(angle_station=ar.station_index, angle_target=ar.target_index,
                                     angle_kind=ar.kind, angle_value_rad=ar.value_rad, angle_sigma_rad=ar.sigma_rad,
                                     orientation_rad=ori, orientation_levelled=ar.levelled)
    return CoupledBatchedNetwork(
        obs.station_index, obs.target_index, obs.sigma_m, hi, res.station_xyz_m, res.offset_m,
        res.scale, res.target_xyz_m, held[:s], held[s:], np.asarray(res.offset_estimated, bool)[first],
        np.asarray(res.scale_estimated, bool)[first],
        bar_a=[pos[b[0]] for b in bars], bar_b=[pos[b[1]] for b in bars],
        bar_length_m=[b[2] for b in bars], bar_sigma_m=[b[3] for b in bars],
        control_point=[pos[c[0]] for c in ctrl for _ in range(3)],
        control_axis=[a for _ in ctrl for a in range(3)],
        control_value_m=[c[1][a] for c in ctrl for a in range(3)],
        control_sigma_m=[c[2][a] for c in ctrl for a in range(3)], datum=dt, covariance=res.covariance, **ang)


def problem_from_config(cfg, *, sigma_m=None, instrument=None, datum="free", pairs=None,
                        source: str = "", pairs_option: str = "interpoint distance") -> Problem:
    """A problem from a built-in configuration (``network.configs.small_volume()`` etc.).

    Every station observes every target. ``sigma_m``: weights' standard uncertainty (scalar or (m,));
    default: the distance model's :func:`multilat.budget.distance_std_m` per distance (or 4.7 um
    without an instrument).
    """
    sid = tuple(cfg.station_ids)
    tid = tuple(cfg.target_ids)
    h = np.asarray(cfg.station_xyz_m, float)
    tg = np.asarray(cfg.target_xyz_m, float)
    off = np.asarray(cfg.offset_m, float)
    si, ti = np.meshgrid(np.arange(len(sid)), np.arange(len(tid)), indexing="ij")
    si, ti = si.ravel(), ti.ravel()
    heads = _heads_for(sid, instrument, None)
    if sigma_m is None:
        d = np.linalg.norm(h[si] - tg[ti], axis=1)
        if instrument is not None:
            from multilat import budget

            sig = np.empty(len(si))
            for i, hd in enumerate(heads):
                sel = si == i
                sig[sel] = budget.distance_std_m(instrument, d[sel], head=hd)
        else:
            sig = np.full(len(si), DEFAULT_SIGMA_M)
    else:
        sig = np.broadcast_to(np.asarray(sigma_m, float), (len(si),)).copy()
    refs = getattr(cfg, "reference_lengths", None)
    return problem_from_truth(sid, tid, si, ti, sig, h, off, tg, datum=datum, pairs=pairs,
                              references=refs, instrument=instrument,
                              source=source or getattr(cfg, "name", ""), pairs_option=pairs_option)


# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _ChunkSpec:
    network: bt.BatchedNetwork
    distance_m: np.ndarray
    heads: tuple
    pair_index: np.ndarray          # (q, 2) indices into the stacked [stations; targets] points
    noise: str
    error_model: object             # distance_errors.ErrorModel (noise="model"), else None
    noise_sigma_m: np.ndarray
    readings: object = None         # network.readings.Readings (raw campaign, repeats) or None


def _draw_errors(spec: _ChunkSpec, n: int, rng: np.random.Generator) -> np.ndarray:
    """Distance errors of n trials, shape (n, m): gaussian, or the distance model in one compiled pass
    (:func:`multilat.distance_errors.draw_errors`, a row of the model per head); a campaign's readings
    (shared sensors, repeats) through :meth:`multilat.network.montecarlo.readings.Readings.draw`."""
    if spec.readings is not None:
        return spec.readings.draw(n, rng, noise=spec.noise, error_model=spec.error_model)
    if spec.noise == "gaussian":    # numpy's draws, faster through numba (multilat.fast_normal)
        return _fast_std_normal(rng, (n, len(spec.distance_m))) * spec.noise_sigma_m
    from multilat.distance_errors import draw_errors

    head_row = spec.network.station_index     # one model row per station, in station order
    return draw_errors(spec.error_model, head_row, spec.distance_m, n, rng)


def _solve_block(spec: _ChunkSpec, entropy, spawn_key: tuple, b: int, n: int) -> dict:
    """Block ``b`` (``n`` trials): draw from the engine's block generator, solve, keep the deviations."""
    g = block_generator(entropy, spawn_key, b)
    e = _draw_errors(spec, n, g)
    d = spec.distance_m + e
    net = spec.network
    q = getattr(net, "n_extra", 0)
    if q:   # scale bars, weighted control, angles: every trial draws their values too (after the distances)
        sol = net.solve(d, extra=net.extra_value + g.standard_normal((n, q)) * net.extra_sigma)
    else:
        sol = net.solve(d)
    ok = sol.converged
    dev = _deviations(spec, sol.station_xyz_m, sol.offset_m, sol.target_xyz_m, np.flatnonzero(ok))
    # the drawn errors' sums: the empirical input std of the linear comparison (model noise, readings)
    sums = spec.noise == "model" or spec.readings is not None
    return dict(dev=dev, n=n, n_failed=int((~ok).sum()),
                n_retried=int(sol.retried.sum()) if sol.retried is not None else 0,
                sigma0=sol.sigma0[ok], e_sum=e.sum(axis=0) if sums else None,
                e2_sum=(e * e).sum(axis=0) if sums else None)


def _deviations(spec: _ChunkSpec, h, o, t, keep) -> np.ndarray:
    """The kept trials' deviations from the nominal (float32): the :func:`batched.flatten` layout, then
    the pairs' distances; one compiled pass when numba is installed, else numpy (the same bits)."""
    net = spec.network
    x0 = bt.flatten(net.station_xyz_m, net.offset_m, net.target_xyz_m)
    p0 = np.concatenate([net.station_xyz_m, net.target_xyz_m])
    pa, pb = (np.ascontiguousarray(spec.pair_index[:, c]) for c in (0, 1))
    dist0 = np.linalg.norm(p0[pa] - p0[pb], axis=1)
    dev = np.empty((len(keep), len(x0) + len(pa)), np.float32)
    if bt.numba_available():
        from multilat.network.montecarlo import _batched_numba as nb

        nb.deviations(*(np.ascontiguousarray(a) for a in (h, o, t)), keep, x0, pa, pb, dist0, dev)
        return dev
    h, o, t = h[keep], o[keep], t[keep]
    pts = np.concatenate([h, t], axis=1)
    dev[:, :len(x0)] = np.concatenate([h.reshape(len(h), -1), o, t.reshape(len(t), -1)], axis=1) - x0
    dev[:, len(x0):] = np.linalg.norm(pts[:, pa] - pts[:, pb], axis=2) - dist0
    return dev


def _run_chunk(args) -> list:
    """One chunk: blocks ``[start, stop)`` of a run of ``trials`` trials, one result per block.
    Module-level so process pools and Dask can pickle it."""
    spec, entropy, spawn_key, start, stop, trials = args
    return [_solve_block(spec, entropy, spawn_key, b, block_trials(b, trials, BLOCK)) for b in range(start, stop)]


def _noise_std(problem: Problem, noise: str, instrument) -> np.ndarray:
    """Standard deviation of the input errors per distance (for the linear sandwich)."""
    if noise == "gaussian":
        return problem.network.sigma_m
    from multilat import budget

    si = problem.network.station_index
    out = np.empty(len(si))
    for i, hd in enumerate(problem.heads):
        sel = si == i
        if sel.any():
            out[sel] = budget.distance_std_m(instrument, problem.distance_m[sel], head=hd)
    return out


def noise_choice(noise: str | None, instrument, *, cli: bool = False) -> tuple[str, object]:
    """``(noise, instrument)`` by the rule of :func:`propagate`: the distance model only when asked
    with an instrument, or when an instrument is given; otherwise gaussian with the σ the
    observations carry. One line naming the option otherwise."""
    n_opt, i_opt = ("--noise", "--instrument") if cli else ("noise", "instrument")
    if noise is None:
        return ("model" if instrument is not None else "gaussian"), instrument
    if noise not in ("model", "gaussian"):
        raise MultilatError(f"{n_opt} must be model or gaussian, got {noise!r}")
    if noise == "model" and instrument is None:
        raise MultilatError(f"{n_opt} model draws from an instrument's distance model: name it with {i_opt} "
                            f"(e.g. seed2020), or draw gaussian with the observations' σ ({n_opt} gaussian)")
    return noise, instrument


def _model_instrument(problem: Problem, instrument):
    """The instrument whose distance model the errors are drawn from (a preset name or path is
    loaded); a laser tracker among the stations is refused (it has no such model)."""
    from multilat import instrument as _instrument

    inst = _instrument.load_instrument(instrument) if isinstance(instrument, str) else instrument
    for sid, hd in zip(problem.station_ids, problem.heads):
        if getattr(inst, "is_tracker", lambda _: False)(hd):
            raise MultilatError(f"--noise model: station {sid!r} is the laser tracker {hd!r}, which has no "
                                "error model to draw from here; use --noise gaussian (its σ from the MPE)")
    return inst


def _pair_columns(problem: Problem) -> np.ndarray:
    """``(n_pairs, 2)`` point columns (stations first, then targets) of the interpoint distances."""
    s = len(problem.station_ids)
    pidx = []
    for a, b in problem.pairs:
        ka, ia = problem.point_index(a)
        kb, ib = problem.point_index(b)
        pidx.append((ia if ka == "station" else s + ia, ib if kb == "station" else s + ib))
    return np.array(pidx, np.int64).reshape(-1, 2)


def _run_adaptive(problem: Problem, items, mapper, noise_std, obs_cov, *, ndigits: int, max_trials: int,
                  progress, batches_per_round: int):
    """The adaptive run (:class:`multilat.montecarlo.AdaptiveRule`): batches of blocks (``items``
    gives the work of a trial range, ``mapper`` runs it) until the watched quantities' estimates are
    stable to ``ndigits`` digits or ``max_trials``. Returns ``(block results, trials done, the
    adaptive record)``."""
    blocks = []
    done = 0
    rule = AdaptiveRule(0.95, ndigits, max_trials, block=BLOCK)
    # the criterion watches the quantities that vary: not those held by the datum (3-2-1), whose
    # samples are rounding noise (same rule as PropagationResult.fixed)
    lin0, _ = linear_std(problem, noise_std, obs_cov)
    watch = lin0 > 1e-9 * np.max(lin0)

    def evaluate_round(h0, h1):
        """Chunks of batches h0..h1-1 submitted together; yields each batch's block results."""
        work, owner = [], []
        for h in range(h0, h1):
            b0, b1 = rule.batch_range(h)
            for it in items(b1 * BLOCK, first_block=b0):
                work.append(it)
                owner.append(h)
        batch, current = [], h0
        for h, res in zip(owner, mapper(_run_chunk, work)):
            if h != current:
                yield batch
                batch, current = [], h
            batch.extend(res)
        yield batch

    for batch in rule.batches(evaluate_round, batches_per_round):
        blocks.extend(batch)
        done += sum(r["n"] for r in batch)
        if progress:
            progress(done)
        dev_b = np.concatenate([r["dev"] for r in batch])
        if dev_b.shape[0] < 2:
            raise MultilatError(f"only {dev_b.shape[0]} trials of adaptive batch {rule.h} converged: the "
                                "network is too weak for a Monte Carlo from its nominal solution")
        if rule.add(dev_b[:, watch]):
            break
    tol = rule.tolerance
    adaptive_info = {"converged": rule.converged, "batches": rule.h, "batch_trials": rule.batch_trials,
                     "tolerance_m_min": None if tol is None else float(np.min(tol)),
                     "n_fixed_by_datum": int((~watch).sum())}
    return blocks, done, adaptive_info


def propagate(problem: Problem, *, trials: int = 100_000, rng=None, noise: str | None = None,
              instrument=None, adaptive: bool = False, ndigits: int = 2,
              max_trials: int = 2_000_000, chunk_size: int = 10_000, map=None,
              progress: Callable[[int], None] | None = None, keep_samples: bool = True,
              max_memory_bytes: int = 1_500_000_000, batches_per_round: int | None = None) -> PropagationResult:
    """Monte Carlo propagation of the distance errors through the adjustment.

    Parameters
    ----------
    problem : Problem
    trials : int
        Number of trials (fixed-size run).
    rng : int, SeedSequence, Generator or None
        Root seed (:func:`multilat.montecarlo.resolve_seed`). Trials are drawn in fixed blocks of
        :data:`BLOCK` trials; block ``b`` draws from :func:`multilat.montecarlo.block_generator`
        ``(entropy, spawn_key, b)`` (the ``b``-th spawn child of the root) and is solved as one batch.
    noise : {"model", "gaussian"} or None
        Distance errors from an instrument's distance model (non-gaussian) or gaussian with the
        observations' ``sigma_m`` (the weights). None: ``model`` when an instrument is known (given
        here, or the one the problem was built with), else ``gaussian``. ``model`` without an
        instrument is refused: a Monte Carlo never draws from an instrument nobody named.
    instrument : Instrument, preset name or TOML path, optional
        For ``noise="model"``; default the problem's (:attr:`Problem.instrument`).
    adaptive : bool
        JCGM 101 §7.9 adaptive procedure, the engine's :class:`multilat.montecarlo.AdaptiveRule`:
        batches of 10^4 trials (10 blocks) until twice the standard deviation of the batch averages
        of every quantity's estimate, standard uncertainty and symmetric interval ends is within the
        numerical tolerance of its standard uncertainty (``ndigits`` significant digits), or
        ``max_trials`` is reached. Quantities held by the datum (3-2-1) are not watched.
    chunk_size : int
        Trials per unit of work handed to ``map``, rounded up to whole blocks. Only distributes the
        work: the numbers do not depend on it.
    map : callable or object with ``.map``, optional
        Ordered map for the chunks (:func:`multilat.parallel.map_from_options`). Default: in-process,
        block by block in numba's threads (:func:`multilat.parallel.thread_map`; one thread per core).
    progress : callable(int), optional
        Called with the number of trials finished after each chunk (each batch when adaptive).
    keep_samples : bool
        Keep the float32 deviation samples in the result (for figures).
    batches_per_round : int, optional
        Adaptive runs: batches submitted to ``map`` together (default 1 in-process, 4 with a
        ``map``); batches computed past the stopping one are discarded (no effect on the numbers).

    Returns
    -------
    PropagationResult
    """
    t0 = time.perf_counter()
    noise, instrument = noise_choice(noise, instrument if instrument is not None else problem.instrument)
    for name, v, lo in (("trials", trials, 2), ("chunk_size", chunk_size, 1), ("max_trials", max_trials, 2)):
        if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < lo:
            raise MultilatError(f"{name} must be an integer >= {lo}, got {v!r}")
    inst = _model_instrument(problem, instrument) if noise == "model" else None
    ss = resolve_seed(rng)
    entropy, key = ss.entropy, tuple(ss.spawn_key)
    net = problem.network
    pidx = _pair_columns(problem)
    obs_cov = None if problem.readings is None else \
        problem.readings.covariance_m2(noise, inst, problem.heads)
    noise_std = _noise_std(problem, noise, inst) if obs_cov is None else np.sqrt(np.diag(obs_cov))
    model = None
    if noise == "model":
        from multilat.distance_errors import error_model

        model = error_model(inst, problem.heads)
    spec = _ChunkSpec(net, problem.distance_m, problem.heads, pidx, noise, model, net.sigma_m, problem.readings)
    k = net.n_params + len(problem.pairs)
    limit = max_trials if adaptive else trials
    if limit * k * 4 > max_memory_bytes:   # float32 samples (statistics are computed per column block)
        raise MultilatError(f"{limit} trials x {k} outputs would need {limit * k * 4 / 2**30:.1f} GiB of "
                            "samples; use fewer trials")
    # in-process: the blocks shared by threads (the kernels release the GIL)
    mapper, unit = (thread_map, BLOCK) if map is None else (resolve_map(map), chunk_size)

    def items(trials_, first_block=0):
        return [(spec, entropy, key, c0, c1, trials_)
                for c0, c1 in chunk_ranges(trials_, unit, BLOCK, first_block=first_block)]

    blocks = []          # per-block results, in block order
    done = 0
    adaptive_info = None
    if not adaptive:
        for res in mapper(_run_chunk, items(trials)):
            blocks.extend(res)
            done += sum(r["n"] for r in res)
            if progress:
                progress(done)
    else:
        if batches_per_round is None:
            batches_per_round = 1 if map is None else 4
        blocks, done, adaptive_info = _run_adaptive(problem, items, mapper, noise_std, obs_cov, ndigits=ndigits,
                                                    max_trials=max_trials, progress=progress,
                                                    batches_per_round=batches_per_round)
    if map is not None:     # every result is in: a single-run Dask map closes its cluster meanwhile
        release_map(map)
    return summarise(problem, blocks, k, noise, noise_std, ss, adaptive_info, t0, keep_samples, done, obs_cov)
