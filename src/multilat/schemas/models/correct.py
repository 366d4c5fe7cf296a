"""``multilat correct RAW -e ENV --heights H --json``: raw readings corrected to distances
(:class:`multilat.campaign.correct.CorrectedDistances`, one value per reading in each list)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from multilat.schemas.models.base import Document, Num, Strict

__all__ = ["CorrectDocument"]


class Environment(Strict):
    temperature_c: list[Num]
    pressure_hpa: list[Num]
    humidity_pct: list[Num]
    co2_ppm: list[Num]


class CorrectDocument(Document):
    """``multilat correct --json``; ``azimuth_rad``/``elevation_rad`` when the readings carry them,
    ``head_ids`` when they name the head."""

    schema_: Literal["multilat.correct/1"] = Field(alias="schema")
    station_ids: list[str]
    target_ids: list[str]
    distance_m: list[Num]
    sigma_m: list[Num]
    sigma_air_m: list[Num]
    sigma_model_m: list[Num]
    covariance_m2: list[list[Num]]
    air_jacobian_m: list[list[Num]]
    air_parameters: list[str]
    air_parameter_std: list[Num]
    group_index: list[Num]
    vacuum_path_m: list[Num]
    index_correction_m: list[Num]
    head_transit_correction_m: list[Num]
    target_transit_correction_m: list[Num]
    environment: Environment
    gradient_c_per_m: list[Num]
    time_s: list[Num]
    azimuth_rad: list[Num] | None
    elevation_rad: list[Num] | None
    formula: str
    extrapolated: list[bool]
    notes: list[str]
    head_ids: list[str] | None
