"""``multilat two-face FILE --json``: a head's transit offset and constant from two-face readings
(:mod:`multilat.campaign`)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from multilat.schemas.models.base import Document, Num

__all__ = ["TwoFaceDocument"]


class TwoFaceDocument(Document):
    """``multilat two-face --json``."""

    schema_: Literal["multilat.two-face/1"] = Field(alias="schema")
    head: str
    transit_offset_m: Num
    transit_offset_std_m: Num
    constant_m: Num
    constant_std_m: Num
    target_ids: list[str]
    target_distance_m: list[Num]
    target_distance_std_m: list[Num]
    parameters: list[str]
    covariance: list[list[Num]]
    residuals_m: list[Num]
    chi2: Num
    dof: int
    sigma0: Num
    scaled: bool
