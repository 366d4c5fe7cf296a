"""``multilat adjust NET.xml --json`` (and ``DIR``, ``obs.csv --model general``): the general network's
adjustment (:mod:`multilat.network.adjust.general.report`, keys in docs/general-network.md)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from multilat.schemas.models.base import Cov3, Document, Excluded, Num, Strict, Vec3, XYZ

__all__ = ["AdjustGeneralDocument", "RowRef", "RowReliability", "ListedObservation", "ObservationCounts",
           "TableRecord"]


class RowRef(Strict):
    """Which observation row: its kind, the points it references (``from``/``to``; ``bs``/``fs`` of a
    horizontal angle; ``point`` of an observed coordinate), ``axis``, ``component``, direction ``set``,
    and ``label`` (``FILE:LINE``)."""

    kind: str
    from_: str | None = Field(None, alias="from")
    to: str | None = None
    bs: str | None = None
    fs: str | None = None
    point: str | None = None
    axis: str | None = None
    component: str | None = None
    set: str | None = None
    label: str


class RowReliability(RowRef):
    """A row's internal and external reliability (MDB null where the redundancy is 0); ``unit`` (m or
    rad) is that of its value, σ, residual and MDB."""

    unit: str
    sigma: Num
    redundancy: Num
    mdb: Num
    mdb_sigma: Num
    shift_max_m: Num
    shift_point: str


class Observation(RowReliability):
    """An adjusted observation row with its residual test."""

    value: Num
    residual: Num
    w: Num
    statistic: Num
    passed: bool
    bias_to_noise: Num


class ListedObservation(Observation):
    """A row of the ``observations`` listing (schema /2): its ``index`` in the ``observations`` table and
    the flags that make it matter (the distance path's ``multilat.adjust/2`` rule). A rejected row's
    ``residual`` is null for a correlated block rejected whole (the outlier's list)."""

    index: int
    residual: Num
    rejected: bool
    w_failed: bool
    poorly_controlled: bool


class ObservationCounts(Strict):
    """The counts beside the listed rows (the keys of ``multilat.adjust/2``): ``n_obs`` rows adjusted and
    rejected, ``n_used`` adjusted, each flag, any flag, the rows of points left out, the rows listed and
    the ``listing`` (``flagged`` or ``all``: ``--observations``)."""

    n_obs: int
    n_used: int
    n_rejected: int
    n_w_failed: int
    n_poorly_controlled: int
    n_flagged: int
    n_excluded: int
    n_listed: int
    listing: Literal["flagged", "all"]


class TableRecord(Strict):
    """A table written under ``--out`` (every observation row: ``observations``)."""

    name: str
    file: str
    format: Literal["csv", "parquet"]
    n_rows: int
    sha256: str = Field(pattern="^[0-9a-f]{64}$")


class Outlier(Observation):
    """A row rejected by data snooping (in ``order``, found in ``round``); a correlated block is rejected
    whole (``block_rows``: its other rows), then ``residual`` holds one number per row of the block.
    ``index``: its row in the observations table (the key of ``observations[]``; adjust-general/3)."""

    index: int
    residual: Num | list[Num]
    round: int
    order: int
    test: str
    critical: Num
    residual_rejected: Num
    n_rows: int
    block_rows: list[str]
    points_left_out: list[str]


class Unlocated(Observation):
    """A row that failed its test but was not rejected (``unlocated_reason`` says why); ``index`` its
    row in the observations table (adjust-general/3)."""

    index: int


class LargestShift(RowRef):
    """A row of the external reliability's largest shifts."""

    redundancy: Num
    mdb: Num
    mdb_sigma: Num
    bias_to_noise: Num
    shift_max_m: Num
    shift_point: str


class Point(Strict):
    xyz_m: XYZ
    xyz_std_m: Vec3
    cov_m2: Cov3
    semi_axes_95_m: Vec3
    roles: list[str]
    status: str
    status_xyz: list[str] = Field(min_length=3, max_length=3)


class Parameter(Strict):
    """An unknown other than a coordinate (``orientation:S#1``, ``offset:I``, ``scale:I``, ``omega:U``...)."""

    value: Num
    std: Num
    unit: str


class Frame(Strict):
    kind: str
    axes: str
    scale: str


class GlobalTest(Strict):
    statistic: Num
    critical: Num
    passed: bool
    alpha: Num
    dof: int
    power: Num
    lambda0: Num
    decides: bool
    method: str


class TestRound(Strict):
    """One round of detection and identification (both paths' snooping records)."""

    dof: int
    test: str
    statistic: Num
    critical: Num
    alpha: Num
    power: Num = None
    sigma0: Num
    detection_passed: bool | None
    identified: bool
    statistic_k: Num
    critical_k: Num
    test_k: str
    action: str


class SnoopingStep(TestRound):
    """A round; ``index`` (the row of the observations table, the key of ``observations[]`` and
    ``outliers[]``) and ``kind`` (the row's, e.g. ``slope_distance``) name the row identified
    (adjust-general/3; ``row``, its label, under /2)."""

    index: int | None = None
    kind: str | None = None


class Tests(Strict):
    test: str
    alpha0: Num
    critical: Num
    lambda0: Num
    n_failed: int
    snooping: bool
    rule: str
    steps: list[SnoopingStep]
    snooping_note: str


class ExternalReliability(Strict):
    computed: bool
    n_uncontrolled: int
    shift_max_m: Num
    largest: list[LargestShift]


class Component(Strict):
    group: str
    n: int
    redundancy: Num
    variance_factor: Num
    variance_factor_std: Num
    sigma_scale: Num
    z: Num
    p_value: Num
    differs_from_1: bool


class VarianceComponents(Strict):
    grouping: str
    method: str
    standard_error_method: str
    iterations: int
    converged: bool
    alpha: Num
    components: list[Component]


class GeneralSigmaSource(Strict):
    """Where the a-priori σ came from: ``kind`` (``file`` for gama-local's ``stdev=``; on a CSV ``file
    column``, ``--sigma-um`` or ``distance model``), the input ``file``, and the sentence of the summary."""

    kind: str
    file: str
    description: str


class Iteration(Strict):
    step_max: Num
    vtpv: Num


class AzimuthSense(Strict):
    sense: str
    source: str
    convention: str


class AdjustGeneralDocument(Document):
    """``multilat adjust`` on a general network (``--json``, ``--out DIR/result.json``)."""

    schema_: Literal["multilat.adjust-general/3"] = Field(alias="schema")
    model: Literal["general"]
    input: str
    format: str
    datum: str
    frame: Frame
    defect: int
    n_points: int
    n_obs: int
    excluded: list[Excluded]
    points: dict[str, Point]
    parameters: dict[str, Parameter]
    sigma0: Num
    dof: int
    vtpv: Num
    variance_factor: str
    global_test: GlobalTest
    tests: Tests
    snooping: bool
    outliers: list[Outlier]
    unlocated: list[Unlocated]
    unlocated_reason: str
    external_reliability: ExternalReliability
    backend: Literal["dense", "sparse"] = Field(description="the back end that ran (--backend)")
    not_computed: list[str] = Field(description="statistics the back end left out on a large network "
                                                "(their fields null), e.g. external reliability")
    variance_components: VarianceComponents | None
    sigma_source: GeneralSigmaSource
    observations: list[ListedObservation] = Field(
        description="the rows that matter (rejected, failing w-tests, poorly controlled), every row with "
                    "--observations; all of them in the observations table under --out")
    observation_counts: ObservationCounts
    tables: list[TableRecord] | None = Field(None, description="the tables written (--out, result.json)")
    iterations: list[Iteration]
    notes: list[str]
    warnings: list[str] = Field(description="the warnings printed (e.g. σ defaulted), one line each")
    azimuth_sense: AzimuthSense | None = None
