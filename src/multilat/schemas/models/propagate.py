"""``multilat propagate --json`` (the distance path's Monte Carlo; :mod:`multilat.network.montecarlo.propagate_result`)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from multilat.schemas.models.base import Cov3, Document, Interval, Num, Real, SigmaSource, Strict, Vec3

__all__ = ["PropagateDocument"]


class Row(Strict):
    """One propagated quantity (a parameter, or a distance in :class:`DistanceRow`), in m."""

    label: str
    nominal_m: Real
    mean_mc_m: Num
    std_mc_m: Num
    std_mc_se_m: Num = Field(description="Monte Carlo standard error of std_mc_m")
    std_lin_m: Num = Field(description="first-order standard deviation (from the adjustment's covariance)")
    ratio: Num = Field(description="std_mc_m / std_lin_m; null for a quantity fixed by the datum")
    agrees: bool
    interval_symmetric_m: Interval
    interval_shortest_m: Interval


class DistanceRow(Row):
    """An interpoint distance ``a``-``b``, and its reference length where one was given."""

    a: str
    b: str
    reference_m: Num


class PointRow(Strict):
    """A point's covariances (Monte Carlo and linear), the MC 95 % ellipsoid and the fraction of the
    trials inside each ellipsoid; ``points`` maps the point's id to it (schema /2; a list with ``id``
    under /1)."""

    cov_mc_m2: Cov3
    cov_lin_m2: Cov3
    semi_axes_95_m: Vec3
    ellipsoid_coverage_mc: Num
    ellipsoid_coverage_lin: Num


class Summary(Strict):
    n_quantities: int
    n_fixed_by_datum: int
    n_agree: int
    ratio_min: Num
    ratio_max: Num
    ellipsoid_coverage_mc_min: Num
    ellipsoid_coverage_mc_max: Num
    ellipsoid_coverage_lin_min: Num
    ellipsoid_coverage_lin_max: Num


class Adaptive(Strict):
    """The adaptive run (``--adaptive``): batches until the standard deviations are stable."""

    converged: bool
    batches: int
    batch_trials: int
    tolerance_m_min: Num
    n_fixed_by_datum: int


class NoiseSource(Strict):
    kind: str
    sigma: str | None = None
    instrument: str | None = None


class Repeat(Strict):
    station: str
    target: str
    n: int
    mean_m: Num
    std_m: Num


class Readings(Strict):
    """Raw readings corrected before the run (``-e``/``--heights``)."""

    n_readings: int
    averaged: bool
    n_observations: int
    sensors: list[str]
    n_sensor_errors: int
    air_sensitivity: str
    repeats: list[Repeat]


class PropagateDocument(Document):
    """``multilat propagate --json`` and ``--out DIR/summary.json``."""

    schema_: Literal["multilat.propagate/2"] = Field(alias="schema")
    source: str
    trials: int
    n_failed: int
    n_retried: int
    noise: str
    solver: str
    seed: int
    coverage: Real
    sigma0_mean: Num
    sigma0_rms: Num
    sigma0_nominal: Num
    sigma0_noise_only: Num
    input_std_ratio: Num
    elapsed_s: Real
    adaptive: Adaptive | None
    parameters: list[Row]
    distances: list[DistanceRow]
    points: dict[str, PointRow]
    summary: Summary
    sigma_source: SigmaSource
    noise_source: NoiseSource
    readings: Readings | None = None
