"""The algorithm's own uncertainty by simulation (seed 000 §4.4).

Per simulation: the true head-target distances of a configuration, plus each head's instrument
offset, plus a random error (gaussian of ``sigma_m`` = 4.7 µm as in the paper, or drawn from the
distance model of :mod:`multilat.budget`, which is not gaussian); then the self-calibrating
adjustment (:func:`multilat.network.adjust.distance.adjust.adjust`, from initial values found from the distances
alone); then the errors of the adjusted interpoint distances against the truth for the
configuration's reference-length pairs (the pairs of Tables V-VI: 9 in the small volume, 6 in the
large one), and **their sample standard deviation** (``ddof=1``: this reproduces the paper's 8.0 µm
and 12.8 µm from the differences printed in Tables V and VI). Over simulations: min, mean, max,
beside the paper's 2.0 / 6.6 / 10.7 µm (small) and 2.2 / 5.4 / 9.2 µm (large) over 50 simulations.

With only 6-9 correlated pairs the per-simulation standard deviation is itself noisy (relative
standard deviation 32 % small, 43 % large; ``1/sqrt(2(k-1))`` = 25-32 % if they were independent),
so min and max over 50 simulations scatter widely;
the mean is compared with its standard error, and with the first-order prediction
``E[s^2] = tr(C Sigma_L) / (k - 1)`` (``C`` the centring matrix, ``Sigma_L`` the linear covariance of
the k lengths from the adjustment's covariance), a second method independent of the Monte Carlo.

Each simulation uses its own ``SeedSequence`` child: results do not depend on how the work is split.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from multilat.errors import MultilatError
from multilat.network.synthetic.configs import BUILTIN, NetworkConfig, get_config
from multilat.network.model.data import Observations, ReferenceLengths
from multilat.network.model.sigma_source import DEFAULT_SIGMA_M
from multilat.network.model.distance import line_of_sight

__all__ = ["PaperStudy", "PAPER_STUDY", "SimulationResult", "simulate", "interpoint_error_std",
           "linear_prediction", "load_config", "load_config_file", "NOISES", "perturbed_config"]

NOISES = ("gaussian", "model")


@dataclass(frozen=True)
class PaperStudy:
    """The §4.4 figures of seed 000: per-simulation std of the interpoint-distance errors, metres."""

    min_m: float
    mean_m: float
    max_m: float
    trials: int


#: seed 000 §4.4 ("average value of 6.6 µm over 50 simulations"; 50 assumed for the large one too)
PAPER_STUDY = {
    "small-volume": PaperStudy(2.0e-6, 6.6e-6, 10.7e-6, 50),
    "large-volume": PaperStudy(2.2e-6, 5.4e-6, 9.2e-6, 50),
}


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """Result of :func:`simulate`.

    Attributes
    ----------
    config : str  configuration name
    station_ids : tuple of str
    trials : int  simulations run (converged ones are in the arrays)
    n_failed : int  simulations whose adjustment raised (dropped)
    noise : str  "gaussian" or "model"
    sigma_m : float  gaussian standard deviation (NaN for the distance model)
    pairs : tuple of (str, str)  the compared target pairs (k)
    true_length_m : ndarray (k,)
    errors_m : ndarray (n, k)  adjusted minus true interpoint distance per simulation
    interpoint_std_m : ndarray (n,)  sample std (ddof=1) of each simulation's errors
    offset_error_m : ndarray (n, s)  adjusted minus true offsets
    sigma0 : ndarray (n,)  a-posteriori standard deviation of unit weight per simulation
    predicted_rms_std_m : float  first-order ``sqrt(E[s^2])`` (see module docstring)
    paper : PaperStudy or None
    """

    config: str
    station_ids: tuple
    trials: int
    n_failed: int
    noise: str
    sigma_m: float
    pairs: tuple
    true_length_m: np.ndarray
    errors_m: np.ndarray
    interpoint_std_m: np.ndarray
    offset_error_m: np.ndarray
    sigma0: np.ndarray
    predicted_rms_std_m: float
    paper: PaperStudy | None

    def summary(self) -> dict:
        """``min``, ``mean``, ``max``, ``sem`` (standard error of the mean) of the per-simulation
        std, and ``rms`` (sqrt of the mean of its square, the quantity the linear prediction gives)."""
        s = self.interpoint_std_m
        n = len(s)
        return {"min": float(s.min()), "mean": float(s.mean()), "max": float(s.max()),
                "sem": float(s.std(ddof=1) / np.sqrt(n)) if n > 1 else float("nan"),
                "rms": float(np.sqrt(np.mean(s ** 2)))}


def interpoint_error_std(errors_m, axis: int = -1) -> np.ndarray:
    """The paper's statistic: sample standard deviation (``ddof=1``) of interpoint-distance errors.

    Parameters
    ----------
    errors_m : array_like, shape (..., k), k >= 2
    """
    e = np.asarray(errors_m, float)
    if e.shape[axis] < 2:
        raise MultilatError("the standard deviation of interpoint errors needs at least 2 pairs")
    return np.std(e, axis=axis, ddof=1)


# ------------------------------------------------------------------------------------ helpers


def _complete_pattern(cfg: NetworkConfig):
    si, ti = np.meshgrid(np.arange(cfg.n_stations), np.arange(cfg.n_targets), indexing="ij")
    return si.ravel(), ti.ravel()


def _heads(cfg: NetworkConfig, inst) -> list[str]:
    names = set(getattr(inst, "heads", {}) or {})
    return [s if s in names else "A" for s in cfg.station_ids]


def _instrument(instrument):
    from multilat import instrument as _inst

    if instrument is None:
        return _inst.load_instrument("seed2020")
    if isinstance(instrument, (str, os.PathLike)):
        return _inst.load_instrument(str(instrument))
    return instrument


def _model_sigma(cfg, inst, si, rho):
    from multilat import budget

    heads = _heads(cfg, inst)
    sig = np.empty(len(si))
    for i, h in enumerate(heads):
        sel = si == i
        sig[sel] = budget.distance_std_m(inst, rho[sel], head=h)
    return sig


def linear_prediction(cfg: NetworkConfig, sigma_m, *, pairs=None, cost: str = "distance") -> float:
    """First-order ``sqrt(E[s^2])`` of the per-simulation std of the interpoint errors.

    ``E[s^2] = tr(C Sigma_L) / (k - 1)``, ``C = I - 11^T / k``; ``Sigma_L`` from the covariance of an
    adjustment of the exact (noise-free) distances weighted by ``sigma_m`` (scalar or (m,)).
    """
    from multilat.network.adjust.distance.adjust import adjust

    si, ti = _complete_pattern(cfg)
    rho = cfg.geometric_distances_m()[si, ti]
    sig = np.broadcast_to(np.asarray(sigma_m, float), rho.shape).copy()
    obs = Observations(cfg.station_ids, cfg.target_ids, si, ti, rho + cfg.offset_m[si], sig)
    res = adjust(obs, initial=_truth_start(cfg), snooping=False, cost="distance")
    pairs = _pairs(cfg, pairs)
    ids = sorted({p for ab in pairs for p in ab}, key=cfg.target_ids.index)
    C = res.points_covariance(ids)
    pos = {p: k for k, p in enumerate(ids)}
    T = res.target_xyz_m
    G = np.zeros((len(pairs), 3 * len(ids)))
    for r, (a, b) in enumerate(pairs):
        _, u = line_of_sight(T[cfg.target_ids.index(a)] - T[cfg.target_ids.index(b)])
        G[r, 3 * pos[a]:3 * pos[a] + 3] = u
        G[r, 3 * pos[b]:3 * pos[b] + 3] = -u
    SL = G @ C @ G.T
    k = len(pairs)
    Cc = np.eye(k) - 1.0 / k
    return float(np.sqrt(np.trace(Cc @ SL) / (k - 1)))


def _truth_start(cfg):
    from types import SimpleNamespace

    return SimpleNamespace(station_xyz_m=cfg.station_xyz_m, target_xyz_m=cfg.target_xyz_m,
                           offset_m=cfg.offset_m)


def _pairs(cfg: NetworkConfig, pairs):
    if pairs is None:
        pairs = tuple(zip(cfg.reference_lengths.target_a, cfg.reference_lengths.target_b))
    pairs = tuple((str(a), str(b)) for a, b in pairs)
    for a, b in pairs:
        for p in (a, b):
            if p not in cfg.target_ids:
                raise MultilatError(f"{cfg.name}: interpoint pair names unknown target {p!r}")
    if len(pairs) < 2:
        raise MultilatError(f"{cfg.name}: at least 2 interpoint pairs are needed")
    return pairs


# ------------------------------------------------------------------------------------ simulate


def simulate(cfg: NetworkConfig, *, trials: int = 50, noise: str = "gaussian", sigma_m: float = DEFAULT_SIGMA_M,
             instrument=None, rng=None, pairs=None, cost: str = "distance", initial: str = "distances",
             callback: Callable[[int], None] | None = None) -> SimulationResult:
    """Simulate the §4.4 study of the self-calibrating adjustment's own uncertainty.

    Parameters
    ----------
    cfg : NetworkConfig
        The truth (every station observes every target).
    trials : int
        Number of simulations (the paper: 50).
    noise : "gaussian" or "model"
        Gaussian errors of ``sigma_m``, or one draw per distance from the distance model
        (:func:`multilat.budget.sample_distance_errors`, each station's head when the instrument
        names it, else head A); the weights are then the model's standard uncertainties.
    sigma_m : float
        Gaussian standard deviation, metres (paper: 4.7 µm).
    instrument : Instrument, preset name or TOML path, optional
        For ``noise="model"`` (default preset ``seed2020``).
    rng : numpy Generator, int or None
        Root seed; simulation ``i`` uses the ``i``-th ``SeedSequence`` child.
    pairs : sequence of (str, str), optional
        Target pairs to compare (default: the configuration's reference-length pairs).
    cost : "distance" or "squared"
        Cost of the adjustment (``"squared"``: the paper's eq. 6).
    initial : "distances" or "truth"
        Start each adjustment from :func:`~multilat.network.adjust.approximate.initial.initial_values` (the default,
        as a user would) or from the truth (isolates the adjustment from the initial values).
    callback : callable(int), optional
        Called with 1 after each simulation (progress bars).

    Returns
    -------
    SimulationResult
    """
    from multilat.network.adjust.distance.adjust import adjust
    from multilat.network.adjust.approximate.initial import initial_values

    if isinstance(trials, bool) or int(trials) < 1:
        raise MultilatError(f"trials must be >= 1, got {trials!r}")
    trials = int(trials)
    if noise not in NOISES:
        raise MultilatError(f"noise must be one of {', '.join(NOISES)}, got {noise!r}")
    if initial not in ("distances", "truth"):
        raise MultilatError(f"initial must be 'distances' or 'truth', got {initial!r}")
    pairs = _pairs(cfg, pairs)
    si, ti = _complete_pattern(cfg)
    rho = cfg.geometric_distances_m()[si, ti]
    if noise == "gaussian":
        if not (np.isfinite(sigma_m) and sigma_m > 0):
            raise MultilatError(f"sigma_m must be finite and > 0, got {sigma_m!r}")
        sig = np.full(len(rho), float(sigma_m))
        inst = None
    else:
        from multilat import budget

        inst = _instrument(instrument)
        sig = _model_sigma(cfg, inst, si, rho)
        heads = _heads(cfg, inst)
    ia = np.array([cfg.target_ids.index(a) for a, _ in pairs])
    ib = np.array([cfg.target_ids.index(b) for _, b in pairs])
    true_len = np.linalg.norm(cfg.target_xyz_m[ia] - cfg.target_xyz_m[ib], axis=1)
    seed = rng if isinstance(rng, np.random.SeedSequence) else None
    if seed is None:
        if isinstance(rng, np.random.Generator):
            seed = np.random.SeedSequence(int(rng.integers(2 ** 63)))
        else:
            seed = np.random.SeedSequence(rng)
    children = seed.spawn(trials)
    start = _truth_start(cfg) if initial == "truth" else None
    errs, offs, s0 = [], [], []
    failed = 0
    first_error = None
    for child in children:
        g = np.random.default_rng(child)
        if noise == "gaussian":
            e = g.normal(0.0, sigma_m, len(rho))
        else:
            e = np.empty(len(rho))
            for i, h in enumerate(heads):
                sel = si == i
                e[sel] = budget.sample_distance_errors(inst, rho[sel], rng=g, head=h)
        obs = Observations(cfg.station_ids, cfg.target_ids, si, ti, rho + cfg.offset_m[si] + e, sig)
        try:
            iv = start if start is not None else initial_values(obs, rng=g)
            res = adjust(obs, initial=iv, snooping=False, cost=cost)
        except MultilatError as exc:
            failed += 1
            first_error = first_error or str(exc)
        else:
            T = res.target_xyz_m
            errs.append(np.linalg.norm(T[ia] - T[ib], axis=1) - true_len)
            offs.append(res.offset_m - cfg.offset_m)
            s0.append(res.sigma0)
        if callback is not None:
            callback(1)
    if not errs:
        raise MultilatError(f"{cfg.name}: no simulation converged ({failed} failed; first: {first_error})")
    errors = np.array(errs)
    try:
        pred = linear_prediction(cfg, sig, pairs=pairs)
    except MultilatError:
        pred = float("nan")
    return SimulationResult(
        config=cfg.name, station_ids=tuple(cfg.station_ids), trials=trials, n_failed=failed, noise=noise,
        sigma_m=float(sigma_m) if noise == "gaussian" else float("nan"), pairs=pairs,
        true_length_m=true_len, errors_m=errors, interpoint_std_m=interpoint_error_std(errors),
        offset_error_m=np.array(offs), sigma0=np.array(s0), predicted_rms_std_m=pred,
        paper=PAPER_STUDY.get(cfg.name))


# ------------------------------------------------------------------------------------ files


def load_config(source: str) -> NetworkConfig:
    """A built-in configuration by name, else a configuration file (TOML or CSV)."""
    if source in BUILTIN:
        return get_config(source)
    return load_config_file(source)


_TOML_KEYS = {"name", "vertical_axis", "stations", "targets", "offsets_m", "pairs"}


def _xyz(where: str, v) -> list[float]:
    if not (isinstance(v, list) and len(v) == 3 and all(isinstance(c, (int, float)) and
                                                         not isinstance(c, bool) for c in v)):
        raise MultilatError(f"{where}: expected [x, y, z] in metres, got {v!r}")
    out = [float(c) for c in v]
    if not all(np.isfinite(out)):
        raise MultilatError(f"{where}: coordinates must be finite")
    return out


def load_config_file(path: str | os.PathLike) -> NetworkConfig:
    """Read a network configuration (truth) for ``multilat simulate FILE``.

    TOML::

        name = "my-network"            # optional (default: the file name)
        vertical_axis = 2              # optional, 0/1/2 (default 2)
        pairs = [["1", "2"], ["2", "3"]]   # optional: target pairs to compare (default: all pairs)
        [stations]                     # id = [x, y, z], metres (>= 4)
        A = [0.0, 0.0, 0.0]
        [targets]
        "1" = [1.0, 2.0, 0.5]
        [offsets_m]                    # optional, default 0
        A = 0.002

    CSV (header ``point,kind,x_m,y_m,z_m`` and optional ``offset_m``; ``kind`` is ``station`` or
    ``target``; all target pairs are compared).
    """
    p = Path(path)
    if p.is_dir():
        raise MultilatError(f"{p}: is a directory, not a configuration file")
    if not p.is_file():
        raise MultilatError(f"{p}: no such file (and not a built-in configuration: "
                            f"{', '.join(BUILTIN)})")
    if p.suffix.lower() == ".toml":
        return _load_toml(p)
    if p.suffix.lower() == ".csv":
        return _load_csv(p)
    raise MultilatError(f"{p}: expected a .toml or .csv configuration")


def _build(name, sid, sx, tid, tx, off, pairs, vertical_axis=2) -> NetworkConfig:
    if len(sid) < 4:
        raise MultilatError(f"{name}: at least 4 stations are needed, got {len(sid)}")
    if len(tid) < 2:
        raise MultilatError(f"{name}: at least 2 targets are needed, got {len(tid)}")
    tx = np.array(tx, float)
    if pairs is None:
        pairs = [(a, b) for i, a in enumerate(tid) for b in tid[i + 1:]]
    for a, b in pairs:
        for q in (a, b):
            if q not in tid:
                raise MultilatError(f"{name}: pairs: unknown target {q!r}")
        if a == b:
            raise MultilatError(f"{name}: pairs: pair from {a!r} to itself")
    ix = {t: j for j, t in enumerate(tid)}
    L = np.array([np.linalg.norm(tx[ix[a]] - tx[ix[b]]) for a, b in pairs])
    if np.any(L <= 0):
        raise MultilatError(f"{name}: two targets of a pair coincide")
    refs = ReferenceLengths(tuple(a for a, _ in pairs), tuple(b for _, b in pairs), L,
                            np.full(len(pairs), np.nan))
    return NetworkConfig(name=name, station_ids=tuple(sid), station_xyz_m=np.array(sx, float),
                         target_ids=tuple(tid), target_xyz_m=tx, offset_m=np.array(off, float),
                         reference_lengths=refs, vertical_axis=vertical_axis,
                         description=f"from {name}")


def _load_toml(p: Path) -> NetworkConfig:
    from multilat.inputs import load_toml

    data = load_toml(p)
    unknown = sorted(set(data) - _TOML_KEYS)
    if unknown:
        raise MultilatError(f"{p}: unknown key {unknown[0]!r} (allowed: {', '.join(sorted(_TOML_KEYS))})")
    for k in ("stations", "targets"):
        if not isinstance(data.get(k), dict) or not data[k]:
            raise MultilatError(f"{p}: missing or empty table [{k}]")
    name = str(data.get("name", p.stem))
    sid = list(data["stations"])
    tid = list(data["targets"])
    if set(sid) & set(tid):
        raise MultilatError(f"{p}: id {sorted(set(sid) & set(tid))[0]!r} is both a station and a target")
    sx = [_xyz(f"{p}: stations.{k}", v) for k, v in data["stations"].items()]
    tx = [_xyz(f"{p}: targets.{k}", v) for k, v in data["targets"].items()]
    offd = data.get("offsets_m", {})
    if not isinstance(offd, dict):
        raise MultilatError(f"{p}: offsets_m must be a table station = metres")
    for k, v in offd.items():
        if k not in sid:
            raise MultilatError(f"{p}: offsets_m.{k}: unknown station")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
            raise MultilatError(f"{p}: offsets_m.{k}: expected a finite number of metres, got {v!r}")
    off = [float(offd.get(k, 0.0)) for k in sid]
    pairs = data.get("pairs")
    if pairs is not None:
        if not (isinstance(pairs, list) and all(isinstance(q, list) and len(q) == 2 for q in pairs)):
            raise MultilatError(f"{p}: pairs must be a list of [target_a, target_b]")
        pairs = [(str(a), str(b)) for a, b in pairs]
    va = data.get("vertical_axis", 2)
    if va not in (0, 1, 2) or isinstance(va, bool):
        raise MultilatError(f"{p}: vertical_axis must be 0, 1 or 2, got {va!r}")
    return _build(name, sid, sx, tid, tx, off, pairs, va)


def _load_csv(p: Path) -> NetworkConfig:
    from multilat.io import read_csv_table

    tab = read_csv_table(p, required=["point", "x_m", "y_m", "z_m"], optional=["kind", "offset_m"])
    if not tab.has("kind"):
        hdr = next(n + 1 for n, ln in enumerate(p.read_text(encoding="utf-8-sig").splitlines())
                   if ln.strip() and not ln.lstrip().startswith("#"))
        raise MultilatError(f"{p}:{hdr}: header lacks "
                            "column kind: a configuration CSV is point,kind,x_m,y_m,z_m[,offset_m] "
                            "with kind 'station' or 'target' (a points file has no kind; see "
                            "examples/network/small_volume_config.csv)")
    x, y, z = tab.floats("x_m"), tab.floats("y_m"), tab.floats("z_m")
    off = tab.floats("offset_m", required=False) if tab.has("offset_m") else np.full(len(x), np.nan)
    sid, sx, so, tid, tx = [], [], [], [], []
    seen = set()
    for k, (pt, kind) in enumerate(zip(tab.column("point"), tab.column("kind"))):
        if pt == "":
            raise tab.error(k, "empty point id")
        if pt in seen:
            raise tab.error(k, f"duplicate point {pt!r}")
        seen.add(pt)
        if kind == "station":
            sid.append(pt)
            sx.append((x[k], y[k], z[k]))
            so.append(0.0 if np.isnan(off[k]) else off[k])
        elif kind == "target":
            if not np.isnan(off[k]):
                raise tab.error(k, f"offset_m given for target {pt!r} (offsets belong to stations)")
            tid.append(pt)
            tx.append((x[k], y[k], z[k]))
        else:
            raise tab.error(k, f"kind must be 'station' or 'target', got {kind!r}")
    return _build(p.stem, sid, sx, tid, tx, so, None)


# ------------------------------------------------------------------------------------ layout sensitivity


def perturbed_config(cfg: NetworkConfig, amplitude_m: float, rng=None, *, fixed=()) -> NetworkConfig:
    """The configuration with its targets moved: each rigid group (a connected component of the
    reference-pair graph: a triplet, a couple, a line of pillars; or an isolated target) is shifted
    by one translation uniform in ``±amplitude_m`` per axis, except the groups containing a target of
    ``fixed``. Reference lengths are unchanged (groups move rigidly). Used to ask how much the §4.4
    result depends on the reconstructed layout.
    """
    g = np.random.default_rng(rng)
    t = cfg.n_targets
    parent = list(range(t))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in cfg.reference_pairs():
        parent[find(a)] = find(b)
    fixed_roots = {find(cfg.target_ids.index(str(f))) for f in fixed}
    T = cfg.target_xyz_m.copy()
    roots = sorted({find(i) for i in range(t)})
    for r in roots:
        if r in fixed_roots:
            continue
        members = [i for i in range(t) if find(i) == r]
        T[members] += g.uniform(-amplitude_m, amplitude_m, 3)
    return NetworkConfig(name=cfg.name + "-perturbed", station_ids=cfg.station_ids,
                         station_xyz_m=cfg.station_xyz_m, target_ids=cfg.target_ids, target_xyz_m=T,
                         offset_m=cfg.offset_m, reference_lengths=cfg.reference_lengths,
                         vertical_axis=cfg.vertical_axis, description=cfg.description + " (perturbed)")
