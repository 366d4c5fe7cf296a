"""JSON Schemas (draft 2020-12) of every command's ``--json`` document, shipped with the package.

``load(command)`` returns the schema of ``multilat <command> --json`` (``lbb-simulate`` for
``multilat lbb simulate``; ``adjust-general``, ``propagate-general`` and ``design-general`` for those
commands on a general network); every document carries ``"schema": "multilat.<command>/<version>"``
(:func:`multilat.vocabulary.stamp`).

The schemas are a contract written as typed models (:mod:`multilat.schemas.models`, pydantic: one
module per command) and generated from them (:func:`generate`; ``python tools/write_schemas.py``
rewrites the shipped files); ``tests/test_output_schema.py`` fails when a shipped file differs from its
model's schema, and validates every command's documents on the shipped examples with the model
(strict: undeclared keys and wrong types refused) and with the shipped file. From Python,
:func:`validate` checks a document against its model. A command's version (its
model's ``schema`` literal and :data:`multilat.vocabulary.SCHEMA_VERSIONS`) is bumped when the shape
of its document changes.
"""

from __future__ import annotations

import json
import typing
from importlib import resources

from multilat.errors import MultilatError

__all__ = ["COMMANDS", "load", "generate", "schema_id", "dumps", "validate"]

COMMANDS = ("adjust", "adjust-general", "propagate", "propagate-general", "simulate", "design", "design-general",
            "budget", "air", "correct", "two-face", "lbb-trilaterate", "lbb-simulate", "lbb-compare", "export",
            "import")


def load(command: str) -> dict:
    """The shipped JSON Schema of ``command``'s ``--json`` document."""
    if command not in COMMANDS:
        raise MultilatError(f"no output schema for {command!r} (known: {', '.join(COMMANDS)})")
    return json.loads(resources.files(__package__).joinpath(f"{command}.json").read_text("utf-8"))


def schema_id(model) -> str:
    """The ``"schema"`` value a document of ``model`` carries (``multilat.<command>/<version>``): the
    literal of its ``schema`` key (of every variant of a union, which must agree)."""
    from pydantic import RootModel

    if isinstance(model, type) and issubclass(model, RootModel):
        variants = typing.get_args(typing.get_args(model.model_fields["root"].annotation)[0]) or \
            typing.get_args(model.model_fields["root"].annotation)
        ids = {schema_id(v) for v in variants}
        if len(ids) != 1:
            raise MultilatError(f"{model.__name__}: its variants carry different schema ids {sorted(ids)}")
        return ids.pop()
    (sid,) = typing.get_args(model.model_fields["schema_"].annotation)
    return sid


def generate(command: str) -> dict:
    """The JSON Schema of ``command``'s document, generated from its model (what the shipped file holds)."""
    from pydantic.json_schema import GenerateJsonSchema

    from multilat.schemas.models import model as model_of

    class _NoFieldTitles(GenerateJsonSchema):
        def field_title_should_be_set(self, schema) -> bool:     # keys are their own titles
            return False

    m = model_of(command)
    body = m.model_json_schema(by_alias=True, schema_generator=_NoFieldTitles)
    body.pop("title", None)
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": schema_id(m),
            "title": f"multilat {command.replace('-', ' ')} --json", **body}


def validate(doc: dict, command: str | None = None) -> None:
    """Check a document against its command's model (``command`` from its ``"schema"`` when not given):
    a :class:`~multilat.errors.MultilatError` names the first key that breaks the contract and why."""
    from pydantic import ValidationError

    from multilat.schemas.models import model as model_of

    if command is None:
        sid = doc.get("schema") if isinstance(doc, dict) else None
        if not isinstance(sid, str) or not sid.startswith("multilat.") or "/" not in sid:
            raise MultilatError(f"schema: {sid!r} is not a multilat document's schema (multilat.<command>/<version>)")
        command = sid[len("multilat."):].rsplit("/", 1)[0]
    try:
        model_of(command).model_validate(doc)
    except ValidationError as e:
        err = e.errors()[0]
        where = ".".join(str(p) for p in err["loc"]) or "(document)"
        more = f" (and {e.error_count() - 1} more)" if e.error_count() > 1 else ""
        raise MultilatError(f"{command} document, key {where}: {err['msg']}{more}") from None


def dumps(schema: dict) -> str:
    """The text of a shipped schema file (one-space indented, a newline at the end)."""
    return json.dumps(schema, indent=1, ensure_ascii=False) + "\n"
