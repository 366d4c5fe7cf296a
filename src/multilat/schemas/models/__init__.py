"""Typed models (pydantic v2) of every command's ``--json`` document: the contract the shipped JSON
Schemas are generated from (:func:`multilat.schemas.generate`).

One module per command; :mod:`.base` holds the pieces they share (the strict base, numbers that may be
null, fixed-length vectors, the id maps, the schema key). :data:`MODELS` maps a command to its
document model (``adjust``: the distance path's document; ``adjust-general``: the general path's).

    >>> from multilat.schemas.models import model
    >>> model("propagate").model_validate(doc)          # raises pydantic.ValidationError when off contract
"""

from __future__ import annotations

from importlib import import_module

__all__ = ["MODELS", "model"]

#: command -> "module:DocumentModel" (imported on first use)
MODELS = {
    "adjust": "adjust:AdjustDocument",
    "propagate": "propagate:PropagateDocument",
    "propagate-general": "propagate_general:PropagateGeneralDocument",
    "adjust-general": "adjust_general:AdjustGeneralDocument",
    "design": "design:DesignDocument",
    "design-general": "design_general:DesignGeneralDocument",
    "simulate": "simulate:SimulateDocument",
    "budget": "budget:BudgetDocument",
    "air": "air:AirDocument",
    "correct": "correct:CorrectDocument",
    "two-face": "two_face:TwoFaceDocument",
    "lbb-trilaterate": "lbb_trilaterate:LbbTrilaterateDocument",
    "lbb-simulate": "lbb_simulate:LbbSimulateDocument",
    "lbb-compare": "lbb_compare:LbbCompareDocument",
    "export": "export:ExportDocument",
    "import": "import_:ImportDocument",
}


def model(command: str):
    """The pydantic model of ``command``'s ``--json`` document."""
    from multilat.errors import MultilatError

    if command not in MODELS:
        raise MultilatError(f"no document model for {command!r} (known: {', '.join(MODELS)})")
    mod, name = MODELS[command].split(":")
    return getattr(import_module(f"{__name__}.{mod}"), name)
