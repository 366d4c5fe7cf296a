"""JSON Schemas (draft 2020-12) of every command's ``--json`` document, shipped with the package.

``load(command)`` returns the schema of ``multilat <command> --json`` (``lbb-simulate`` for
``multilat lbb simulate``); every document carries ``"schema": "multilat.<command>/<version>"``
(:func:`multilat.vocabulary.stamp`). The files are written by ``tools/schema_infer.py`` (a developer tool) from the
documents of the sample runs listed there and then read by a person before they are committed; the
tests validate every command's output against them (``tests/test_output_schema.py``), so a renamed,
removed or undeclared key fails until the schema (and :data:`multilat.vocabulary.SCHEMA_VERSION`,
when a meaning changes) is updated on purpose.
"""

from __future__ import annotations

import json
from importlib import resources

from multilat.errors import MultilatError

__all__ = ["COMMANDS", "load"]

COMMANDS = ("adjust", "propagate", "simulate", "design", "budget", "air", "correct", "two-face",
            "lbb-trilaterate", "lbb-simulate", "lbb-compare", "export", "import")


def load(command: str) -> dict:
    """The shipped JSON Schema of ``command``'s ``--json`` document."""
    if command not in COMMANDS:
        raise MultilatError(f"no output schema for {command!r} (known: {', '.join(COMMANDS)})")
    return json.loads(resources.files(__package__).joinpath(f"{command}.json").read_text("utf-8"))
