"""``multilat lbb simulate --json``: the LBB's Monte Carlo (:mod:`multilat.lbb`)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from multilat.schemas.models.base import Cov3, Document, Num, Strict, Vec3, XYZ

__all__ = ["LbbSimulateDocument"]


class Point(Strict):
    nominal_m: XYZ
    error_mean_m: Vec3
    std_m: Vec3
    cov_m2: Cov3


class LbbSimulateDocument(Document):
    """``multilat lbb simulate --json`` and ``--out DIR/summary.json``."""

    schema_: Literal["multilat.lbb-simulate/1"] = Field(alias="schema")
    method: str
    trials: int
    n_points: int
    std_max_m: Num
    error_mean_max_m: Num
    l0_error_mean_m: Num
    l0_std_m: Num
    seed: int
    points: list[Point]
