"""``multilat simulate CONFIG --json``: repeated adjustments of a simulated network
(:mod:`multilat.network.montecarlo.simulate`); the maps are keyed by pair (``A-B``) or station id."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from multilat.schemas.models.base import Document, Num, SigmaSource

__all__ = ["SimulateDocument"]


class SimulateDocument(Document):
    """``multilat simulate --json``."""

    schema_: Literal["multilat.simulate/1"] = Field(alias="schema")
    config: str
    trials: int
    converged: int
    n_failed: int
    noise: str
    sigma_m: Num
    cost: str
    start: str
    seed: int
    pairs: list[Annotated[list[str], Field(min_length=2, max_length=2)]]
    interpoint_std_m: dict[str, Num]
    interpoint_std_se_m: Num
    interpoint_std_rms_m: Num
    interpoint_std_lin_rms_m: Num
    paper_m: dict[str, Num]
    pair_error_rms_m: dict[str, Num]
    offset_error_rms_m: dict[str, Num]
    sigma0_mean: Num
    sigma_source: SigmaSource
    per_simulation_std_m: list[Num]
