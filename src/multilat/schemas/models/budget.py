"""``multilat budget --json``: the Monte Carlo budget of one distance and its per-input budget
(:mod:`multilat.budget`, :mod:`multilat.budget_inputs`)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from multilat.schemas.models.base import Document, Interval, Num, Strict

__all__ = ["BudgetDocument"]


class Distribution(Strict):
    """An input's distribution: ``normal`` (mean, std), ``uniform`` (low, high), ``constant`` (value),
    or a misalignment's (half_angle_rad)."""

    type: str
    mean: Num = None
    std: Num = None
    low: Num = None
    high: Num = None
    value: Num = None
    half_angle_rad: Num = None


class InputRow(Strict):
    """One input quantity (``estimate``, ``estimate_std``, ``sensitivity`` in ``unit``; a joint input,
    the misalignment, has one number per component: then they are lists), or a group's bias row
    (no distribution: the null keys)."""

    quantity: str
    symbol: str
    description: str
    group: str
    unit: str
    source: str | None
    distribution: Distribution | None
    estimate: Num | list[Num]
    estimate_std: Num | list[Num]
    sensitivity: Num | list[Num]
    sensitivity_unit: str | None
    contribution_std_lin_m: Num
    contribution_std_mc_m: Num
    share_var_m2: Num
    share_var_se_m2: Num
    share_std_m: Num


class GroupError(Strict):
    error_rms_m: Num
    error_rms_se_m: Num
    error_mean_m: Num
    error_var_m2: Num
    error_mean_square_m2: Num


class Groups(Strict):
    telemetric: GroupError
    head: GroupError
    target: GroupError
    air: GroupError


class InputBudget(Strict):
    method: str
    trials_per_distance: int
    n_batches: int
    include_air: bool
    rows: list[InputRow]
    groups: Groups
    error_rms_m: Num
    error_rms_se_m: Num


class BudgetDocument(Document):
    """``multilat budget --json``; ``plot`` the PNG written by ``--plot`` (null without)."""

    schema_: Literal["multilat.budget/1"] = Field(alias="schema")
    instrument: str
    head: str
    trials: int
    trials_per_distance: int
    distances_m: list[Num]
    components: dict[str, Num]
    component_error_mean_m: dict[str, Num]
    component_error_std_m: dict[str, Num]
    include_air: bool
    error_rms_m: Num
    error_mean_m: Num
    error_std_m: Num
    coverage_95_m: Interval
    coverage_shortest_95_m: Interval
    seed: int
    plot: str | None
    unit: str
    input_budget: InputBudget
    definition: str
