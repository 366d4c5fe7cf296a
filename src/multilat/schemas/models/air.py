"""``multilat air --json``: the refractive index of air and its sensitivities (:mod:`multilat.air`)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from multilat.schemas.models.base import Document, Num, Real, Strict

__all__ = ["AirDocument"]


class AirInputs(Strict):
    """The inputs as given: one of humidity, dew point or water-vapour pressure (the others null);
    ``instrument`` the preset whose wavelength was used (``--instrument``), else null."""

    temperature_c: Real
    pressure_hpa: Real
    humidity_pct: Real | None
    dew_point_c: Real | None
    water_vapour_pa: Real | None
    co2_ppm: Real
    wavelength_nm: Real
    instrument: str | None


class SensitivityUnits(Strict):
    temperature_c: str
    pressure_hpa: str
    humidity_pct: str
    co2_ppm: str


class AirDocument(Document):
    """``multilat air --json``."""

    schema_: Literal["multilat.air/1"] = Field(alias="schema")
    formula: str
    inputs: AirInputs
    phase_index: Real
    group_index: Real
    sensitivity_um_per_m: dict[str, Num]
    sensitivity_units: SensitivityUnits
    sign_convention: str
