"""``multilat air --json``: the refractive index of air and its sensitivities (:mod:`multilat.air`)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from multilat.schemas.models.base import Document, Num, Strict

__all__ = ["AirDocument"]


class SensitivityUnits(Strict):
    temperature_c: str
    pressure_hpa: str
    humidity_pct: str
    co2_ppm: str


class AirDocument(Document):
    """``multilat air --json``."""

    schema_: Literal["multilat.air/1"] = Field(alias="schema")
    formula: str
    inputs: dict[str, Num]
    phase_index: Num
    group_index: Num
    sensitivity_um_per_m: dict[str, Num]
    sensitivity_units: SensitivityUnits
    sign_convention: str
