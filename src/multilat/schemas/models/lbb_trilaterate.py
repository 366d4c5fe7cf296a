"""``multilat lbb trilaterate EDGES --json``: points from the LBB's edge lengths (:mod:`multilat.lbb`)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from multilat.schemas.models.base import Document, Num, Strict, XYZ

__all__ = ["LbbTrilaterateDocument"]


class Point(Strict):
    """A trilaterated point; ``xyz_m`` null and ``reason`` said where it is not valid."""

    point: str
    xyz_m: XYZ | None
    valid: bool
    z_squared_m2: Num
    reason: str | None


class LbbTrilaterateDocument(Document):
    """``multilat lbb trilaterate --json``."""

    schema_: Literal["multilat.lbb-trilaterate/1"] = Field(alias="schema")
    frame: str
    points: list[Point]
    n_singular: int
