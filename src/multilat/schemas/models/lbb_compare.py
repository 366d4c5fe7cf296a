"""``multilat lbb compare EDGES REFERENCE --json``: LBB points against reference coordinates."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from multilat.schemas.models.base import Document, Num, Strict, Vec3

__all__ = ["LbbCompareDocument"]


class Point(Strict):
    point: str
    difference_m: Vec3
    error_mean_mc_m: Vec3
    std_mc_m: Vec3
    inside_2sigma: list[bool] = Field(min_length=3, max_length=3)


class PerAxis(Strict):
    x: Num
    y: Num
    z: Num


class LbbCompareDocument(Document):
    """``multilat lbb compare --json``."""

    schema_: Literal["multilat.lbb-compare/1"] = Field(alias="schema")
    points: list[Point]
    fraction_inside_2sigma: Num
    fraction_inside_2sigma_per_axis: PerAxis
    normalised_rms_per_axis: PerAxis
    method: str
    trials: int
