"""``multilat design CONFIG.toml --json``: the layout search and its pre-analysis
(:func:`multilat.cli.design_cmd.design_document`, docs/design.md)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from multilat.schemas.models.base import Cov3, Document, Num, Strict, Vec3, XYZ

__all__ = ["DesignDocument"]


class Station(Strict):
    head: str
    xyz_m: XYZ
    cov_m2: Cov3
    offset_std_m: Num
    targets: list[str]


class Target(Strict):
    xyz_m: XYZ
    cov_m2: Cov3
    u95_max_m: Num
    seen_by: int


class Length(Strict):
    a: str
    b: str
    length_m: Num
    length_std_m: Num


class Reliability(Strict):
    redundancy_min: Num
    mdb_max_m: Num
    external_max_m: Num


class PoorTarget(Strict):
    id: str
    n_obs: int
    redundancy: Num
    mdb_m: Num
    mdb_sigma: Num


class PoorlyControlled(Strict):
    """The targets owning a distance with redundancy below ``r_min`` or MDB above ``mdb_limit_sigma`` σ."""

    r_min: Num
    mdb_limit_sigma: Num
    n_targets: int
    targets: list[PoorTarget]


class SelectionStep(Strict):
    count: int
    u95_m: Num
    removed: str


class TargetSelection(Strict):
    """The fewest targets keeping the work volume at ``[criterion] target_u95_m``."""

    method: str
    wanted_u95_m: Num
    feasible: bool
    count: int
    candidates: int
    targets: list[str]
    u95_m: Num
    all_candidates_u95_m: Num
    path: list[SelectionStep]
    evaluations: int


class Start(Strict):
    start_criterion_m: Num
    start_unsolvable: bool
    end_criterion_m: Num
    evaluations: int


class StartStation(Strict):
    xyz_m: XYZ


class Search(Strict):
    """The search (absent with ``--evaluate``); ``history_m`` null where a layout was penalised."""

    method: str
    evaluations: int
    starts: list[Start]
    history_m: list[Num]
    start_stations: dict[str, StartStation]


class SimulatedTarget(Strict):
    std_lin_m: Vec3
    std_mc_m: Vec3
    std_mc_se_m: Vec3
    z: Vec3
    u95_max_lin_m: Num
    u95_max_mc_m: Num
    ellipsoid_coverage: Num


class Simulation(Strict):
    """The Monte Carlo confirmation of the layout (``--simulate N``)."""

    noise: str
    trials: int
    n_failed: int
    z_abs_max: Num
    z_mean: Num
    ratio_mean: Num
    u95_max_lin_m: Num
    u95_max_mc_m: Num
    ellipsoid_coverage_mean: Num
    input_std_ratio: Num
    z_drawn_abs_max: Num
    targets: dict[str, SimulatedTarget]


class DesignDocument(Document):
    """``multilat design --json`` and ``--out DIR/design.json``."""

    schema_: Literal["multilat.design/1"] = Field(alias="schema")
    criterion: str
    criterion_m: Num
    start_criterion_m: Num
    sigma: str
    dof: int
    stations: dict[str, Station]
    targets: dict[str, Target]
    lengths: list[Length]
    reliability: Reliability
    poorly_controlled: PoorlyControlled
    target_selection: TargetSelection | None = None
    search: Search | None = None
    simulation: Simulation | None = None
