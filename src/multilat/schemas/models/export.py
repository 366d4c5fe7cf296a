"""``multilat export FORMAT ... --json``: what was written for another program (:mod:`multilat.network.io.interop`)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from multilat.schemas.models.base import Document

__all__ = ["ExportDocument"]


class ExportDocument(Document):
    """``multilat export --json``."""

    schema_: Literal["multilat.export/1"] = Field(alias="schema")
    format: str
    files: list[str]
    n_obs: int
    n_stations: int
    n_targets: int
    n_angles: int
    offsets_subtracted: bool
    heads: dict[str, list[str]]
