"""``multilat adjust OBS.csv --json`` (and ``--out DIR``'s ``result.json``): the distance path's
adjustment, schema ``multilat.adjust/3`` (:func:`multilat.network.adjust.distance.result.result_to_json`,
:func:`multilat.cli.adjust_output.adjust_document`; keys in docs/cli.md "adjust/3").

The keys every run writes are required; the ones written only with an option or a network are
optional: ``azimuth_sense`` (azimuths in the file), ``variance_components`` (``--variance-components``),
``with_correlations`` and ``repeats`` (raw readings, ``--average-repeats``), ``tables`` (``--out``).
The unweighted ``--cost squared`` leaves the tests' statistics null (no global test, no MDB), its
``observation_extremes`` empty and ``reliability`` null.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from multilat.schemas.models.adjust_general import AzimuthSense, Frame, ObservationCounts, TestRound
from multilat.schemas.models.base import Cov3, Document, Excluded, Num, Real, SigmaSource, Strict, Vec3, XYZ

__all__ = ["AdjustDocument", "ObservationRow", "Station", "Target", "Tests", "Initial"]


class Convergence(Strict):
    """How a solver ended (:class:`multilat.network.adjust.solve.convergence.Convergence`)."""

    converged: bool
    iterations: int
    last_step_sigma: Num
    reason: str


class Ambiguous(Strict):
    """A point the distances place only up to a mirror image (:mod:`multilat.network.adjust.distance.ambiguity`)."""

    id: str
    kind: str
    cause: str
    reason: str
    delta_vtpv: Num


class Station(Strict):
    """A station: coordinates, additive offset (with its σ and correlations with x, y, z: null where
    the offset is not estimated), its head; ``scale`` where estimated; an orientation (ω, φ, κ) where
    the station observed angles."""

    xyz_m: XYZ
    offset_m: Real
    offset_std_m: Num
    offset_estimated: bool
    cov_m2: Cov3
    offset_corr_xyz: Vec3
    head: str
    scale: Real | None = None
    scale_std: Num = None
    orientation_rad: XYZ | None = None
    orientation_std_rad: Vec3 | None = None
    parameters: list[str] | None = None


class Head(Strict):
    """An instrument head's offset and scale (its stations carry the same values)."""

    offset_m: Real
    offset_std_m: Num
    offset_estimated: bool
    scale: Real
    scale_std: Num
    scale_estimated: bool
    stations: list[str]


class Target(Strict):
    """A target: coordinates, covariance, the distances used and the sum of their redundancy numbers."""

    xyz_m: XYZ
    cov_m2: Cov3
    n_obs: int
    redundancy: Num


class ScaleBar(Strict):
    """A reference length used as an observation (``--scale-bars``)."""

    target_a: str
    target_b: str
    length_m: Real
    sigma_m: Real
    adjusted_m: Num
    residual_m: Num
    redundancy: Num
    w: Num


class WeightedControl(Strict):
    """A control point observed with its σ: per axis its residual, redundancy number and w."""

    point: str
    xyz_m: XYZ
    std_m: XYZ
    residual_m: Vec3
    redundancy: Vec3
    w: Vec3


class Angle(Strict):
    """An angle observation used (azimuth or elevation) and its test."""

    station: str
    target: str
    kind: str
    value_rad: Real
    sigma_rad: Real
    residual_rad: Num
    redundancy: Num
    w: Num
    mdb_rad: Num
    w_test_passed: bool


class AngleOutlier(Strict):
    """An angle rejected by data snooping (in ``order``, in snooping round ``step``); ``index`` the row
    of the observations table that holds it."""

    index: int
    station: str
    target: str
    kind: str
    w: Num
    residual_rad: Num
    test: str
    statistic: Num
    critical: Num
    step: int
    order: int


class GlobalTest(Strict):
    """The χ² test of the variance factor (statistics null where it does not apply: no redundancy,
    ``--cost squared``); ``decides`` false with an unknown variance factor."""

    statistic: Num
    critical: Num
    passed: bool | None
    alpha: Num
    dof: int
    power: Num
    lambda0: Num
    critical_low: Num
    alpha_low: Num
    failed_tail: Literal["upper", "lower"] | None
    decides: bool


class Sigma0Check(Strict):
    """Is σ0 plausible (:func:`multilat.network.adjust.statistics.sigma0_check`)."""

    sigma0: Num
    dof: int
    factor: Real
    alpha: Real
    p_lower: Num
    p_upper: Num
    verdict: str
    accepted: bool
    message: str


class Step(TestRound):
    """One round of detection and identification; ``index`` (the row of the observations table, the
    key of ``observations[]`` and ``outliers[]``) and ``kind`` (``distance``, ``azimuth`` or
    ``elevation``) name the observation identified (adjust/3; ``observation`` / ``angle`` under /2)."""

    index: int | None = None
    kind: Literal["distance", "azimuth", "elevation"] | None = None


class Tests(Strict):
    """The test procedure (method, levels, critical values) and its rounds."""

    method: str
    variance_factor: Literal["known", "unknown"]
    alpha0: Real
    power: Real
    lambda0: Num
    lambda0_w: Num
    w_critical: Num
    tau_critical: Num
    alpha_global: Num
    requested: str
    alpha0_given: Real
    alpha_family: Real
    n_tests: int
    detection: str
    rule: str
    steps: list[Step]


class AdjustSigmaSource(SigmaSource):
    """:class:`~.base.SigmaSource` with what the distance path adds: the angles' σ from the trackers'
    MPE (``angles``) and the grouping of variance components that re-weighted them."""

    angles: str | None = None
    variance_components: str | None = None


class Outlier(Strict):
    """A distance rejected by data snooping (``residual_m`` against the final solution); ``index`` its
    row in the observations table (the key of ``observations[]``)."""

    index: int
    station: str
    target: str
    w: Num
    residual_m: Num
    test: str
    statistic: Num
    critical: Num
    order: int


class Unlocated(Strict):
    """A w-test failure not rejected (``unlocated_reason`` says why); ``index`` its row in the
    observations table."""

    index: int
    station: str
    target: str
    w: Num
    residual_m: Num


class Pair(Strict):
    station: str
    target: str


class WFailure(Strict):
    """The failing w-tests at the end, grouped: perfectly correlated tests form one group."""

    observations: list[Pair]
    w: Num
    located: bool


class ObservationRow(Strict):
    """A row of the observations table (:func:`multilat.network.io.result_rows.observation_columns`);
    the reliability columns are there with the distance cost."""

    index: int
    station: str
    target: str
    distance_m: Real
    sigma_m: Real
    residual_m: Num
    redundancy: Num
    w: Num
    mdb_m: Num
    rejected: bool
    w_failed: bool
    poorly_controlled: bool
    mdb_sigma: Num = None
    bias_to_noise: Num = None
    shift_max_m: Num = None
    shift_point: str | None = None


class ExcludedObservation(Strict):
    """An observation of a point left out before solving (not a row of the table)."""

    station: str
    target: str
    distance_m: Real
    sigma_m: Real
    reason: str


class End(Strict):
    value: Real
    index: int
    station: str
    target: str


class Extremes(Strict):
    smallest: End
    largest: End


class ObservationExtremes(Strict):
    """Over the distances kept; a quantity without a finite value is left out (all of them with
    ``--cost squared``)."""

    redundancy: Extremes | None = None
    mdb_m: Extremes | None = None
    mdb_sigma: Extremes | None = None
    shift_max_m: Extremes | None = None


class Tried(Strict):
    label: str
    cost: Num
    sigma0: Num
    accepted: bool
    note: str | None = None


class Search(Strict):
    """The search for a false minimum (:meth:`multilat.network.adjust.approximate.search.MinimumSearch.as_dict`)."""

    search_triggered: bool
    bounded: str | None = None
    first_cost: Num
    cost: Num
    dof: int
    p_value: Num
    tried: list[Tried]
    warning: str | None


class Handedness(Strict):
    """Which hand of the distances' solution the given points chose (:func:`multilat.network.adjust.approximate.starts.onto_points`)."""

    decided: bool
    mirrored: bool
    points: list[str]
    misfit_rms_m: Num
    mirror_misfit_rms_m: Num
    ratio_needed: Real
    plane_spread_rms_m: Num
    plane_normal: Vec3
    plane_point_m: Vec3


class ScaleDatum(Strict):
    kind: str
    n_bars: int
    points: list[str] = Field(min_length=2, max_length=2)


class Initial(Strict):
    """How the initial values were found (:mod:`multilat.network.adjust.approximate.starts`) and the minimum search."""

    method: str
    residual_rms_m: Num = None
    seed_targets: int | None = None
    multilateration_rms_m: Num = None
    far_minimum_again: bool | None = None
    bounded: str | None = None
    refinement: Convergence | None = None
    flat_restarts: int | None = None
    handedness: Handedness | None = None
    search: Search | None = None
    scale_datum: ScaleDatum | None = None


class PoorObservation(Pair):
    redundancy: Num
    mdb_m: Num
    mdb_sigma: Num
    shift_max_m: Num
    shift_point: str


class PoorTarget(Strict):
    id: str
    n_obs: int
    redundancy_min: Num
    mdb_max_m: Num
    mdb_max_sigma: Num
    shift_max_m: Num


class Reliability(Strict):
    """Internal and external reliability: the poorly controlled observations and targets."""

    r_min: Real
    mdb_limit_sigma: Real
    shifts_computed: bool
    poor_observations: list[PoorObservation]
    poor_targets: list[PoorTarget]


class ReferenceLength(Strict):
    """An interpoint distance beside its reference length (``--references``)."""

    target_a: str
    target_b: str
    length_m: Real
    length_std_m: Num
    reference_m: Real
    reference_std_m: Num
    difference_m: Num


class Component(Strict):
    group: str
    n: int
    redundancy: Num
    variance_factor: Num
    variance_factor_std: Num
    sigma_scale: Num


class VarianceComponents(Strict):
    """``--variance-components``: Förstner's estimate per group (the distance path's record; the
    general path's adds a test per group)."""

    grouping: str
    method: str
    standard_error_method: str
    iterations: int
    converged: bool
    components: list[Component]


class CorrelatedStation(Strict):
    offset_std_m: Num
    cov_m2: Cov3


class CorrelatedTarget(Strict):
    cov_m2: Cov3


class WithCorrelations(Strict):
    """Raw readings: the covariance with the corrected distances' full covariance (shared sensors)."""

    note: str
    stations: dict[str, CorrelatedStation]
    targets: dict[str, CorrelatedTarget]
    target_std_max_m: Num
    target_std_diagonal_max_m: Num
    reference_lengths_u_m: dict[str, Num] | None = None


class Repeat(Strict):
    """``--average-repeats``: a pair's readings (``std_m`` null for one reading)."""

    station: str
    target: str
    n: int
    mean_m: Real
    std_m: Num


class TableRecord(Strict):
    """A table file of ``--out`` (its row count and the sha256 of the file as written)."""

    name: str
    file: str
    format: Literal["csv", "parquet"]
    n_rows: int
    sha256: Annotated[str, Field(pattern=r"^[0-9a-f]{64}$")]


class AdjustDocument(Document):
    """``multilat adjust`` on the distance path (``--json``, ``--out DIR/result.json``)."""

    schema_: Literal["multilat.adjust/3"] = Field(alias="schema")
    datum: str
    frame: Frame
    cost: Literal["distance", "squared"]
    solver: str
    convergence: Convergence | None
    n_obs: int
    n_used: int
    excluded: list[Excluded]
    warnings: list[str] = Field(description="the warnings printed (e.g. σ defaulted), one line each")
    ambiguous: list[Ambiguous]
    stations: dict[str, Station]
    heads: dict[str, Head]
    scale_bars: list[ScaleBar]
    weighted_control: list[WeightedControl]
    angles: list[Angle]
    angle_outliers: list[AngleOutlier]
    targets: dict[str, Target]
    sigma0: Num
    sigma0_unit: Literal["1", "m^2"]
    dof: int
    global_test: GlobalTest
    sigma0_check: Sigma0Check
    alpha: Real
    snooping: bool
    tests: Tests
    sigma_source: AdjustSigmaSource
    variance_factor: Literal["known", "unknown"]
    outliers: list[Outlier]
    unlocated: list[Unlocated]
    unlocated_reason: str
    w_failures: list[WFailure]
    observation_counts: ObservationCounts
    observations: list[ObservationRow]
    excluded_observations: list[ExcludedObservation]
    observation_extremes: ObservationExtremes
    largest_w: list[ObservationRow]
    initial: Initial
    reliability: Reliability | None
    reference_lengths: list[ReferenceLength]
    iterations: int
    condition: Num
    azimuth_sense: AzimuthSense | None = None
    variance_components: VarianceComponents | None = None
    with_correlations: WithCorrelations | None = None
    repeats: list[Repeat] | None = None
    tables: list[TableRecord] | None = None
