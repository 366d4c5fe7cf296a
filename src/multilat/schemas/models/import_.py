"""``multilat import FORMAT ... --json``: what was read from another program's file; the keys depend on
``format`` (one model per reader, told apart by ``format``)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, RootModel

from multilat.schemas.models.base import Document, Num, Strict

__all__ = ["ImportDocument", "GamaAdjustedImport", "DistanceImport", "GamaImport"]

_SCHEMA = Literal["multilat.import/1"]


class Orientation(Strict):
    orientation_rad: Num
    orientation_std_rad: Num


class GamaAdjustedImport(Document):
    """``import gama-adjusted``: a gama-local adjustment's result; ``n_angles`` and ``stations`` (the
    direction sets' orientations) when it holds angles."""

    schema_: _SCHEMA = Field(alias="schema")
    format: Literal["gama-adjusted"]
    dof: int
    defect: int
    sigma0: Num
    sigma0_apriori: Num
    n_obs: int
    n_points: int
    fixed: list[str]
    n_angles: int | None = None
    stations: dict[str, Orientation] | None = None


class DistanceImport(Document):
    """``import jag3d`` / ``import starnet``: a distance network for the distance path."""

    schema_: _SCHEMA = Field(alias="schema")
    format: Literal["jag3d", "starnet"]
    n_obs: int
    n_stations: int
    n_targets: int
    n_angles: int
    levelled: list[str]
    n_heads: int
    n_points: int
    fixed: list[str]
    notes: list[str]


class GamaImport(Document):
    """``import gama``: a gama-local network as multilat's general files; ``n_stations``, ``n_targets``
    and ``levelled`` when the distance path takes the file too (its distances.csv is written)."""

    schema_: _SCHEMA = Field(alias="schema")
    format: Literal["gama"]
    n_obs: int
    n_points: int
    fixed: list[str]
    n_angles: int
    notes: list[str]
    n_stations: int | None = None
    n_targets: int | None = None
    levelled: list[str] | None = None


class ImportDocument(RootModel[Annotated[GamaAdjustedImport | DistanceImport | GamaImport,
                                         Field(discriminator="format")]]):
    """``multilat import --json`` (and gama-adjusted's ``summary.json``)."""
