"""``multilat propagate NET.xml --json`` (and ``obs.csv --model general``): the general network's Monte
Carlo (:mod:`multilat.network.montecarlo.general.propagate_result`, keys in docs/general-network.md)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from multilat.schemas.models.base import Cov3, Document, Excluded, Interval, Num, Real, Strict, Vec3

__all__ = ["PropagateGeneralDocument"]


class Row(Strict):
    """One propagated quantity: a parameter (``x:P``, ``offset:I``, ``orientation:S``, ...) or an
    interpoint distance ``A-B``; every number of the row in ``unit`` (m, rad or 1)."""

    label: str
    unit: str
    nominal: Real
    mean_mc: Num
    std_mc: Num
    std_mc_se: Num = Field(description="Monte Carlo standard error of std_mc")
    std_lin: Num
    ratio: Num = Field(description="std_mc / std_lin; null where std_lin is 0")
    agrees: bool
    interval_symmetric: Interval
    interval_shortest: Interval


class Point(Strict):
    """A point with a free coordinate (held coordinates 0)."""

    cov_mc_m2: Cov3
    cov_lin_m2: Cov3
    std_mc_m: Vec3
    std_lin_m: Vec3


class Summary(Strict):
    n_quantities: int
    n_agree: int
    ratio_min: Num
    ratio_max: Num


class PropagateGeneralDocument(Document):
    """``multilat propagate`` on a general network (``--json``, ``--out DIR/result.json``)."""

    schema_: Literal["multilat.propagate-general/2"] = Field(alias="schema")
    model: Literal["general"]
    trials: int
    n_failed: int
    n_retried: int
    chord_steps_mean: Num
    sigma0_mean: Num
    sigma0_rms: Num
    dof: int
    seed: int
    elapsed_s: Real
    parameters: list[Row]
    distances: list[Row]
    points: dict[str, Point]
    summary: Summary
    input: str
    format: str
    noise: str
    noise_source: str
    excluded: list[Excluded]
