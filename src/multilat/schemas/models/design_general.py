"""``multilat design --evaluate NET.xml --json``: the pre-analysis of a planned general network
(:func:`multilat.cli.general_design.document`, docs/design.md)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from multilat.schemas.models.adjust_general import RowReliability
from multilat.schemas.models.base import Cov3, Document, Num, Strict, Vec3, XYZ

__all__ = ["DesignGeneralDocument"]


class Point(Strict):
    xyz_m: XYZ
    status: str
    xyz_std_m: Vec3
    cov_m2: Cov3
    semi_axes_95_m: Vec3


class Parameter(Strict):
    std: Num
    unit: str


class Reliability(Strict):
    redundancy_min: Num
    mdb_sigma_max: Num
    r_min: Num
    mdb_limit_sigma: Num
    n_weak: int


class WeakRow(RowReliability):
    """A row with redundancy below ``r_min`` or MDB above ``mdb_limit_sigma`` σ (no residual: planned)."""


class Undetermined(Strict):
    id: str
    reason: str
    n_obs: int


class DesignGeneralDocument(Document):
    """``multilat design --evaluate NET --json``."""

    schema_: Literal["multilat.design-general/1"] = Field(alias="schema")
    model: Literal["general"]
    input: str
    format: str
    datum: str
    n_points: int
    n_rows: int
    n_free: int
    defect: int
    dof: int
    points: dict[str, Point]
    parameters: dict[str, Parameter]
    reliability: Reliability
    weak_rows: list[WeakRow]
    undetermined: list[Undetermined]
