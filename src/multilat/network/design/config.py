"""The ``multilat design`` configuration: a pydantic-validated TOML, and the one call that runs it.

Example (docs/design.md lists every key)::

    [targets]                      # or: file = "targets.csv" (point,x_m,y_m,z_m)
    box_min_m = [0, 0, 0]
    box_max_m = [1, 1, 1]
    grid = [3, 3, 3]
    [heads]                        # or: file = "candidates.csv", or fixed = "heads.csv"
    count = 4
    box_min_m = [-1.5, -1.5, 0]
    box_max_m = [2.5, 2.5, 2.0]
    min_range_m = 0.2              # optional range limits of a head
    max_range_m = 20.0
    hidden = { A = ["T3", "T7"] }  # optional: targets a head (id; candidate id) cannot see
    [[occluders]]                  # optional, repeatable: a box blocking the line of sight
    box_min_m = [0.4, -1, 0]
    box_max_m = [0.6, 2, 1.5]
    [instrument]                   # or: sigma_um = 4.7
    preset = "seed2020"
    [criterion]
    name = "max_u95"               # rms_u, length_u (with lengths = [["1", "27"], ...]), max_mdb
    target_u95_m = 30e-6           # optional: the fewest targets keeping the work volume at this
    [network]                      # optional
    offsets = true
    datum = "free"
    [search]                       # optional
    method = "multistart"          # or differential_evolution
    starts = 8
    max_evaluations = 20000
    evaluation = "auto"            # fast / dense / blocked: how a criterion is computed (docs/design.md)

Files named in the config are read relative to the config file's directory. Every error is one
line naming the file and the key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from multilat.errors import MultilatError, validation_error_line
from multilat.network.design.preanalysis import (CRITERIA, Layout, PreAnalysis, SigmaModel, design_head_names,
                                                 preanalyse)
from multilat.network.design.search import (PENALTY_M, DesignResult, choose_candidates, head_ids, min_heads,
                                            optimise_heads, visibility)
from multilat.network.model.parameter_layout import ParameterLayout

__all__ = ["DesignConfig", "parse_design_config", "load_design_config", "run_design", "DesignRun",
           "poorly_controlled_targets",
           "MAX_DESIGN_TARGETS", "MAX_DESIGN_HEADS", "design_memory_bytes"]


#: The most targets a design may hold (a grid's product or a targets file's rows): the 20 x 200 000
#: benchmark network's size; beyond it a search of thousands of evaluations takes days.
MAX_DESIGN_TARGETS = 200_000
#: The most heads (or candidate positions) a design may place.
MAX_DESIGN_HEADS = 200


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


def _box(lo, hi, what):
    if (lo is None) != (hi is None):
        raise ValueError(f"{what}: give both box_min_m and box_max_m")
    if lo is not None:
        if len(lo) != 3 or len(hi) != 3:
            raise ValueError("box_min_m and box_max_m need 3 values (x, y, z)")
        if not all(b > a for a, b in zip(lo, hi)):
            raise ValueError(f"box_max_m must exceed box_min_m in every axis (empty or inside-out box: "
                             f"{list(lo)} .. {list(hi)})")


class TargetsCfg(_Model):
    file: str | None = Field(None, json_schema_extra={"constraint": "either file or box_min_m/box_max_m/grid"},
                             description="CSV of the targets (point,x_m,y_m,z_m), relative to the config")
    box_min_m: list[float] | None = Field(None, json_schema_extra={"constraint": "3 values, below box_max_m"},
                                          description="lower corner (x, y, z) of the targets' grid box")
    box_max_m: list[float] | None = Field(None, json_schema_extra={"constraint": "3 values, above box_min_m"},
                                          description="upper corner (x, y, z) of the targets' grid box")
    grid: list[int] | None = Field(None, json_schema_extra={"constraint": "3 counts >= 1; product <= 200 000"},
                                   description="points per axis (x, y, z) of the grid")

    @model_validator(mode="after")
    def _one(self):
        _box(self.box_min_m, self.box_max_m, "targets")
        has_box = self.box_min_m is not None
        if (self.file is None) == (not has_box):
            raise ValueError("give either file or box_min_m/box_max_m/grid")
        if has_box:
            if self.grid is None or len(self.grid) != 3 or min(self.grid) < 1:
                raise ValueError("grid: need 3 counts >= 1 (points per axis)")
            if math.prod(self.grid) > MAX_DESIGN_TARGETS:
                raise ValueError(f"grid: {' x '.join(map(str, self.grid))} = {math.prod(self.grid):,} targets, "
                                 f"more than the {MAX_DESIGN_TARGETS:,} a design may hold")
        return self


class HeadsCfg(_Model):
    count: int | None = Field(None, json_schema_extra={"constraint": ">= 4; <= 200"},
                              description="number of heads to place (box or candidates)")
    box_min_m: list[float] | None = Field(None, json_schema_extra={"constraint": "exactly one of box, file, fixed"},
                                          description="lower corner (x, y, z) of the box heads may stand in")
    box_max_m: list[float] | None = Field(None, json_schema_extra={"constraint": "3 values, above box_min_m"},
                                          description="upper corner (x, y, z) of the box heads may stand in")
    file: str | None = Field(None,
                             description="CSV of candidate positions (point,x_m,y_m,z_m): the search chooses count of"
                                         " them")
    fixed: str | None = Field(None,
                              description="CSV of given heads (point,x_m,y_m,z_m): score this layout only, as "
                                          "--evaluate")
    start: str | None = Field(None,
                              description="CSV of the box search's start layout (count rows; default: alternate box "
                                          "corners)")
    min_range_m: float = Field(0.0, json_schema_extra={"constraint": ">= 0"},
                               description="shortest distance a head measures")
    max_range_m: float | None = Field(None, json_schema_extra={"constraint": "> min_range_m"},
                                      description="longest distance a head measures (none: unlimited)")
    hidden: dict[str, list[str]] = Field({}, json_schema_extra={"constraint": "known ids"},
                                         description="targets a head cannot see: head id (or candidate id) -> list of"
                                                     " target ids")

    @model_validator(mode="after")
    def _one(self):
        _box(self.box_min_m, self.box_max_m, "heads")
        modes = [self.box_min_m is not None, self.file is not None, self.fixed is not None]
        if sum(modes) != 1:
            raise ValueError("give exactly one of box_min_m/box_max_m, file (candidates) or fixed")
        if self.fixed is None and self.count is None:
            raise ValueError("count: number of heads is required with a box or candidates")
        if self.count is not None and self.count < min_heads(True):
            raise ValueError(f"count: self-calibration needs at least {min_heads(True)} heads, "
                             f"got {self.count}")
        if self.count is not None and self.count > MAX_DESIGN_HEADS:
            raise ValueError(f"count: at most {MAX_DESIGN_HEADS} heads, got {self.count:,}")
        if self.min_range_m < 0:
            raise ValueError("min_range_m must be >= 0")
        if self.max_range_m is not None and not self.max_range_m > self.min_range_m:
            raise ValueError("max_range_m must exceed min_range_m")
        return self


class InstrumentCfg(_Model):
    preset: str | None = Field(None, json_schema_extra={"constraint": "exactly one of preset, file, sigma_um"},
                               description="a shipped instrument preset (seed2020)")
    file: str | None = Field(None, description="an instrument TOML (the instrument file above), relative to the config")
    sigma_um: float | None = Field(None, json_schema_extra={"constraint": "> 0"},
                                   description="one standard uncertainty for every distance, instead of a distance "
                                               "model")

    @model_validator(mode="after")
    def _one(self):
        if sum(x is not None for x in (self.preset, self.file, self.sigma_um)) != 1:
            raise ValueError("give exactly one of preset, file or sigma_um")
        if self.sigma_um is not None and not self.sigma_um > 0:
            raise ValueError("sigma_um must be > 0")
        return self


class CriterionCfg(_Model):
    name: str = Field("max_u95", json_schema_extra={"constraint": "one of the four"},
                      description="what the search minimises: max_u95, rms_u, length_u or max_mdb (docs/design.md)")
    lengths: list[tuple[str, str]] = Field([], json_schema_extra={"constraint": "needed by length_u"},
                                           description="interpoint lengths for length_u, as pairs of point ids")
    target_u95_m: float | None = Field(None, json_schema_extra={"constraint": "> 0"},
                                       description="keep the fewest targets whose work-volume 95 % semi-axis stays at"
                                                   " or below this")

    @field_validator("target_u95_m")
    @classmethod
    def _pos(cls, v):
        if v is not None and not v > 0:
            raise ValueError("must be > 0 (metres)")
        return v

    @field_validator("name")
    @classmethod
    def _name(cls, v):
        if v not in CRITERIA:
            raise ValueError(f"unknown criterion {v!r} (one of {', '.join(CRITERIA)})")
        return v

    @model_validator(mode="after")
    def _lengths(self):
        if self.name == "length_u" and not self.lengths:
            raise ValueError("criterion length_u needs lengths = [[id, id], ...]")
        return self


class ScaleBarCfg(_Model):
    a: str = Field(description="point id of one end of the bar")
    b: str = Field(description="point id of the other end")
    u_um: float = Field(description="standard uncertainty of the bar's length", json_schema_extra={"constraint": "> 0"})

    @field_validator("u_um")
    @classmethod
    def _u(cls, v):
        if not (math.isfinite(v) and v > 0):
            raise ValueError("must be > 0")
        return v


class ControlCfg(_Model):
    point: str = Field(description="the control point's id (a target)")
    s_um: list[float] = Field(json_schema_extra={"constraint": "3 values > 0"},
                              description="standard uncertainties of its x, y, z")

    @field_validator("s_um")
    @classmethod
    def _s(cls, v):
        if len(v) != 3 or not all(math.isfinite(x) and x > 0 for x in v):
            raise ValueError("three standard uncertainties > 0 (x, y, z) in um")
        return v


class NetworkCfg(_Model):
    offsets: bool = Field(True, description="estimate one additive offset per head (self-calibration)")
    datum: str | None = Field(None,
                              description="free, free:P,.., 321:A,B,C or control (default: control with control "
                                          "points, else free)")
    scale_bars: list[ScaleBarCfg] = Field([],
                                          description="reference lengths between two targets (pre-analysis of given "
                                                      "heads only)")
    control: list[ControlCfg] = Field([],
                                      description="control points observed with standard uncertainties (given heads "
                                                  "only)")


class SearchCfg(_Model):
    method: str = Field("multistart", description="multistart (Powell from several starts) or differential_evolution")
    starts: int = Field(8, description="local searches of multistart", json_schema_extra={"constraint": ">= 1"})
    max_evaluations: int = Field(20_000, json_schema_extra={"constraint": ">= 1"},
                                 description="criterion evaluations in all")
    evaluation: str = Field("auto",
                            description="how a criterion is computed: auto, fast, dense or blocked (docs/design.md)")

    @field_validator("evaluation")
    @classmethod
    def _e(cls, v):
        if v not in ("auto", "dense", "blocked", "fast"):
            raise ValueError(f"unknown evaluation {v!r} (auto, dense, blocked or fast)")
        return v

    @field_validator("method")
    @classmethod
    def _m(cls, v):
        if v not in ("multistart", "differential_evolution"):
            raise ValueError(f"unknown method {v!r} (multistart or differential_evolution)")
        return v

    @field_validator("starts", "max_evaluations")
    @classmethod
    def _pos(cls, v):
        if v < 1:
            raise ValueError("must be >= 1")
        return v


class OccluderCfg(_Model):
    box_min_m: list[float] = Field(json_schema_extra={"constraint": "3 values, below box_max_m"},
                                   description="lower corner (x, y, z) of a box blocking the line of sight")
    box_max_m: list[float] = Field(json_schema_extra={"constraint": "3 values, above box_min_m"},
                                   description="upper corner (x, y, z) of the box")

    @model_validator(mode="after")
    def _b(self):
        _box(self.box_min_m, self.box_max_m, "occluders")
        return self


class DesignConfig(_Model):
    targets: TargetsCfg = Field(description="the targets to measure: a file, or a grid in a box")
    heads: HeadsCfg = Field(description="where the heads go: a box to search, candidate positions, or fixed heads")
    occluders: list[OccluderCfg] = Field([],
                                         description="boxes blocking lines of sight (a blocked target is not observed"
                                                     " from that head)")
    instrument: InstrumentCfg = Field(InstrumentCfg(preset="seed2020"),
                                      description="the distance model: a preset, an instrument file or a constant σ")
    criterion: CriterionCfg = Field(CriterionCfg(), description="what the search minimises")
    network: NetworkCfg = Field(NetworkCfg(), description="the adjustment's model: offsets, datum, scale bars, control")
    search: SearchCfg = Field(SearchCfg(), description="the global search's method and budget")


def parse_design_config(data: dict, *, source: str = "<dict>") -> DesignConfig:
    """Validate a decoded mapping; :class:`MultilatError` names the source and the key path."""
    try:
        return DesignConfig.model_validate(data)
    except ValidationError as err:
        raise MultilatError(validation_error_line(err, source)) from None


def load_design_config(path: str | Path) -> DesignConfig:
    from multilat.inputs import load_toml

    p = Path(path)
    if not p.is_file():
        raise MultilatError(f"config file not found: {p}")
    return parse_design_config(load_toml(p), source=str(p))


# ---------------------------------------------------------------------------------------------
def _read_points(base: Path, name: str):
    from multilat.network.io.files import read_points

    return read_points(base / name)


def _targets(cfg: TargetsCfg, base: Path):
    if cfg.file is not None:
        pts = _read_points(base, cfg.file)
        return pts.ids, pts.xyz_m
    axes = [np.linspace(a, b, n) if n > 1 else np.array([(a + b) / 2])
            for a, b, n in zip(cfg.box_min_m, cfg.box_max_m, cfg.grid)]
    g = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return tuple(f"T{k + 1}" for k in range(len(g))), g


def _check_reach(tid, tx, heads_pts, box, rmin, rmax, source, hidden=None, occluders=(), head_names=()):
    """Every target must be within range of some admissible head position."""
    if box is not None:
        lo, hi = np.asarray(box[0]), np.asarray(box[1])
        near = np.linalg.norm(tx - np.clip(tx, lo, hi), axis=1)
        corners = lo + np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)]) * (hi - lo)
        far = np.linalg.norm(tx[:, None] - corners[None], axis=2).max(axis=1)
        bad = (near > rmax) | (far < rmin)
    else:
        vis = visibility(heads_pts, tx, min_range_m=rmin, max_range_m=rmax, hidden=hidden,
                         occluders=occluders)
        bad = vis.sum(axis=0) < 3
        few = vis.sum(axis=1) < 4
        if few.any() and not bad.any():
            i = int(np.flatnonzero(few)[0])
            raise MultilatError(f"{source}: heads: head {head_names[i]!r} sees {int(vis[i].sum())} targets "
                                "(range limits, hidden targets, occluders): a head needs at least 4")
    if bad.any():
        j = int(np.flatnonzero(bad)[0])
        why = "seen by fewer than 3 heads" if box is None else "out of range of every head position"
        raise MultilatError(f"{source}: heads: target {tid[j]!r} is {why} (min_range_m {rmin:g}, "
                            f"max_range_m {rmax:g}); {int(bad.sum())} target(s)")


def _hidden(cfg, head_ids_, tid, source):
    """The ``[heads] hidden`` table as a bool (s, t) matrix over ``head_ids_`` (None when empty)."""
    if not cfg.heads.hidden:
        return None
    pos = {t: j for j, t in enumerate(tid)}
    hpos = {h: i for i, h in enumerate(head_ids_)}
    out = np.zeros((len(head_ids_), len(tid)), bool)
    for h, ts in cfg.heads.hidden.items():
        if h not in hpos:
            raise MultilatError(f"{source}: heads.hidden: unknown head {h!r} (heads: {', '.join(head_ids_)})")
        for t in ts:
            if t not in pos:
                raise MultilatError(f"{source}: heads.hidden.{h}: unknown target {t!r}")
            out[hpos[h], pos[t]] = True
    return out


def _check_sizes(n_targets: int, n_fixed: int | None, source: str) -> None:
    """Refuse a targets or heads file beyond :data:`MAX_DESIGN_TARGETS` / :data:`MAX_DESIGN_HEADS`
    (a grid and a head count are refused when the config is read)."""
    if n_targets > MAX_DESIGN_TARGETS:
        raise MultilatError(f"{source}: targets: {n_targets:,} targets, more than the "
                            f"{MAX_DESIGN_TARGETS:,} a design may hold")
    if n_fixed is not None and n_fixed > MAX_DESIGN_HEADS:
        raise MultilatError(f"{source}: heads: {n_fixed:,} heads, at most {MAX_DESIGN_HEADS}")


def _check_datum(datum: str, known: set, source: str) -> None:
    """``network.datum`` parsed, each point it names a target or head of the design."""
    from multilat.network.model.datum import parse_datum

    try:
        d = parse_datum(datum)
    except MultilatError as exc:
        raise MultilatError(f"{source}: network.datum: {exc}") from None
    for p in d.points or ():
        if p not in known:
            raise MultilatError(f"{source}: network.datum: unknown point id {p!r} (not a target or head "
                                "of the design)")


def design_memory_bytes(cfg: DesignConfig) -> float | None:
    """A rough estimate of the memory a design needs (~200 bytes per head-target pair, as ``lbb
    simulate --grid`` counts per point), None when the targets or heads come from files."""
    t, h = cfg.targets, cfg.heads
    if t.grid is None or h.count is None:
        return None
    return 200.0 * math.prod(t.grid) * h.count


@dataclass(frozen=True, eq=False)
class DesignRun:
    """What ``multilat design`` computed: the search (None with fixed or evaluated heads), the
    pre-analysis of the returned layout and of the start (or given) layout; ``selection``: the
    fewest targets for ``[criterion] target_u95_m`` (:class:`~.targets.TargetSelection`) or None;
    ``heads``: the instrument head measuring from each station of ``best``; ``poorly_controlled``:
    :func:`poorly_controlled_targets` of ``best``; ``occluders``: the declared obstruction boxes
    ``(box_min_m, box_max_m)``, for the figures."""

    criterion: str
    search: DesignResult | None
    best: PreAnalysis
    start: PreAnalysis
    sigma: SigmaModel
    selection: object = None
    heads: tuple = ()
    poorly_controlled: tuple = ()
    occluders: tuple = ()


def run_design(cfg: DesignConfig, *, base_dir: str | Path = ".", evaluate=None, rng=None,
               source: str = "config") -> DesignRun:
    """Run a validated config: optimise (box or candidates) or, with fixed heads or ``evaluate``
    (a :class:`~multilat.network.model.data.Points` of heads), score the given layout only."""
    import dataclasses

    run = _run_design(cfg, base_dir=base_dir, evaluate=evaluate, rng=rng, source=source)
    return dataclasses.replace(run, occluders=tuple((o.box_min_m, o.box_max_m) for o in cfg.occluders))


def _run_design(cfg: DesignConfig, *, base_dir, evaluate, rng, source) -> DesignRun:
    base = Path(base_dir)
    tid, tx = _targets(cfg.targets, base)
    h = cfg.heads
    rmin, rmax = h.min_range_m, (math.inf if h.max_range_m is None else h.max_range_m)
    sigma = _sigma_model(cfg.instrument, base, rmax)
    c = cfg.criterion
    net = cfg.network
    coupled = bool(net.scale_bars or net.control)
    datum = net.datum if net.datum is not None else ("control" if net.control else "free")
    kw = dict(offsets=net.offsets, datum=datum, lengths=tuple(c.lengths))
    skw = dict(kw, evaluation=cfg.search.evaluation)
    known = set(tid)
    fixed = evaluate if evaluate is not None else (_read_points(base, h.fixed) if h.fixed else None)
    _check_sizes(len(tid), None if fixed is None else len(fixed.ids), source)
    if fixed is not None:
        if len(fixed.ids) < min_heads(cfg.network.offsets):
            raise MultilatError(f"{source}: heads: self-calibration needs at least "
                                f"{min_heads(cfg.network.offsets)} heads, got {len(fixed.ids)}")
        ids = tuple(fixed.ids)
        _check_heads(sigma, ids, f"{source}: " + ("--evaluate" if evaluate is not None else "heads.fixed"))
    else:
        ids = head_ids(h.count, design_head_names(sigma.instrument))
        _check_heads(sigma, ids, f"{source}: heads.count")
    known |= set(ids)
    _check_counts(len(ids), len(tid), cfg.network.offsets, source)
    for a, b in c.lengths:
        for p in (a, b):
            if p not in known:
                raise MultilatError(f"{source}: criterion.lengths: unknown point id {p!r}")
    _check_datum(datum, known, source)
    search = None
    occ = tuple((o.box_min_m, o.box_max_m) for o in cfg.occluders)
    if fixed is not None:
        hid = _hidden(cfg, ids, tid, source)
        _check_reach(tid, tx, fixed.xyz_m, None, rmin, rmax, source, hid, occ, ids)
        lay = Layout(fixed.ids, fixed.xyz_m, tid, tx,
                     visibility(fixed.xyz_m, tx, min_range_m=rmin, max_range_m=rmax, hidden=hid,
                                occluders=occ))
        return _evaluate(cfg, lay, sigma, kw, source)
    if coupled:
        raise MultilatError(f"{source}: network.scale_bars / network.control are used in the pre-analysis of "
                            "given heads (heads.fixed or --evaluate); the optimisation does not model them yet")
    s = cfg.search
    if h.file is not None:
        cand = _read_points(base, h.file)
        hid = _hidden(cfg, tuple(cand.ids), tid, source)
        _check_reach(tid, tx, cand.xyz_m, None, rmin, rmax, source, hid, occ, tuple(cand.ids))
        search = choose_candidates(tx, cand.xyz_m, count=h.count, sigma=sigma, target_ids=tid,
                                   candidate_ids=cand.ids, criterion=c.name, min_range_m=rmin,
                                   hidden=hid, occluders=occ, head_names=ids,
                                   max_range_m=rmax, max_evaluations=s.max_evaluations, rng=rng, **skw)
    else:
        _check_reach(tid, tx, None, (h.box_min_m, h.box_max_m), rmin, rmax, source)
        start = None
        if h.start is not None:
            sp = _read_points(base, h.start)
            if len(sp.ids) != h.count:
                raise MultilatError(f"{source}: heads.start: {len(sp.ids)} heads, count is {h.count}")
            start = sp.xyz_m
        search = optimise_heads(tx, count=h.count, box_min_m=h.box_min_m, box_max_m=h.box_max_m,
                                sigma=sigma, target_ids=tid, criterion=c.name, start=start,
                                hidden=_hidden(cfg, ids, tid, source), occluders=occ, head_names=ids,
                                min_range_m=rmin, max_range_m=rmax, method=s.method, starts=s.starts,
                                max_evaluations=s.max_evaluations, rng=rng, **skw)
    if search.criterion_m >= PENALTY_M:
        raise MultilatError(f"{source}: no solvable layout found (every head layout tried leaves a "
                            "target seen by too few heads): widen the heads box or the range limits")
    if h.file is not None:      # the i-th chosen candidate holds the i-th design head
        sigma = sigma.with_station_heads({**dict(zip(search.start_layout.station_ids, ids)),
                                          **dict(zip(search.layout.station_ids, ids))})
    try:
        start_pa = preanalyse(search.start_layout, sigma, **kw)
    except MultilatError:
        start_pa = None
    best = preanalyse(search.layout, sigma, **kw)
    return _run(c.name, search, best, start_pa, sigma, _select(c, best, sigma, kw))


def _sigma_model(ic: InstrumentCfg, base: Path, rmax: float) -> SigmaModel:
    """The distance model of ``[instrument]``: a constant σ, or a preset's or file's model tabulated up
    to twice the heads' range (at least 100 m)."""
    from multilat import instrument as _inst

    if ic.sigma_um is not None:
        return SigmaModel(ic.sigma_um * 1e-6)
    return SigmaModel(instrument=_inst.load_instrument(ic.preset or str(base / ic.file)),
                      max_distance_m=max(100.0, 2 * rmax if np.isfinite(rmax) else 100.0))


def _check_counts(n_heads: int, n_targets: int, offsets: bool, source: str) -> None:
    """Enough distances for the unknowns (one line naming the fewest targets if not)."""
    heads = ParameterLayout.station_system(n_heads, offsets=offsets).n          # the heads' unknowns
    n_unknown = ParameterLayout.station_system(n_heads, n_targets, offsets=offsets).n - 6
    if n_heads * n_targets < n_unknown:
        t_min = -(-(heads - 6) // (n_heads - 3))
        raise MultilatError(f"{source}: targets: {n_targets} targets and {n_heads} heads give at most "
                            f"{n_heads * n_targets} distances for {n_unknown} unknowns: need at least "
                            f"{t_min} targets")


def _evaluate(cfg: DesignConfig, lay: Layout, sigma: SigmaModel, kw: dict, source: str) -> DesignRun:
    """The pre-analysis of given heads (with the config's scale bars and control, if any)."""
    c, net = cfg.criterion, cfg.network
    if net.scale_bars or net.control:
        from multilat.network.design.couplings import preanalyse_coupled

        if c.target_u95_m is not None:
            raise MultilatError(f"{source}: criterion.target_u95_m (fewest targets) does not use scale "
                                "bars or control points yet: leave them out for that search")
        pa = preanalyse_coupled(lay, sigma, scale_bars=[(b.a, b.b, b.u_um * 1e-6) for b in net.scale_bars],
                                control=[(k.point, *(v * 1e-6 for v in k.s_um)) for k in net.control], **kw)
        return _run(c.name, None, pa, pa, sigma, None)
    pa = preanalyse(lay, sigma, **kw)
    return _run(c.name, None, pa, pa, sigma, _select(c, pa, sigma, kw))


def _check_heads(sigma: SigmaModel, ids, where: str) -> None:
    """Every design station resolves to a head of the instrument (one line naming ``where`` if not)."""
    for sid in ids:
        try:
            sigma.head_of(sid)
        except MultilatError as exc:
            raise MultilatError(f"{where}: {exc}") from None


def _run(criterion, search, best, start, sigma, selection) -> DesignRun:
    return DesignRun(criterion, search, best, start, sigma, selection,
                     tuple(sigma.head_of(sid) for sid in best.station_ids), poorly_controlled_targets(best))


def poorly_controlled_targets(pa: PreAnalysis, *, r_min: float | None = None,
                              mdb_limit_sigma: float | None = None) -> tuple:
    """The targets owning a poorly controlled distance (redundancy number below ``r_min`` or MDB
    above ``mdb_limit_sigma`` σ; the adjustment's defaults :data:`~multilat.network.adjust.distance.reliability.R_MIN`
    and :data:`~multilat.network.adjust.distance.reliability.MDB_LIMIT_SIGMA`): a blunder in such a distance would
    not show in the residuals. One dict per target (``id``, ``n_obs`` poorly controlled, smallest
    ``redundancy``, largest ``mdb_m`` and ``mdb_sigma``), smallest redundancy first."""
    from multilat.network.adjust.distance.reliability import MDB_LIMIT_SIGMA, R_MIN

    r_min = R_MIN if r_min is None else r_min
    lim = MDB_LIMIT_SIGMA if mdb_limit_sigma is None else mdb_limit_sigma
    red, mdb = pa.redundancy, pa.mdb_m
    mdb_sig = mdb / pa.sigma_m
    poor = (red < r_min) | ~(mdb_sig <= lim)
    out = []
    for j in np.unique(pa.target_index[poor]):
        k = poor & (pa.target_index == j)
        out.append({"id": pa.target_ids[j], "n_obs": int(k.sum()), "redundancy": float(red[k].min()),
                    "mdb_m": float(mdb[k].max()), "mdb_sigma": float(mdb_sig[k].max())})
    return tuple(sorted(out, key=lambda d: d["redundancy"]))


def _select(c: CriterionCfg, pa: PreAnalysis, sigma, kw):
    if c.target_u95_m is None:
        return None
    from multilat.network.design.targets import select_targets

    sel = select_targets(pa.layout, sigma, c.target_u95_m, offsets=kw["offsets"], datum=kw["datum"])
    if not sel.feasible:
        import warnings

        warnings.warn(f"criterion.target_u95_m: even all {len(sel.target_ids)} candidate targets give "
                      f"{sel.all_u95_m * 1e6:.2f} um > wanted {sel.wanted_u95_m * 1e6:.2f} um (all kept)",
                      stacklevel=2)
    return sel
