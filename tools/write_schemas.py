"""Write the shipped JSON Schemas from the typed document models (developer tool).

    python tools/write_schemas.py            # rewrites src/multilat/schemas/<command>.json

Every command has a model (:data:`multilat.schemas.models.MODELS`) and gets the schema of
:func:`multilat.schemas.generate`. The tests fail while a shipped file differs from its model
(tests/test_output_schema.py); read the diff before committing.
"""

from __future__ import annotations

from pathlib import Path

from multilat.schemas import dumps, generate
from multilat.schemas.models import MODELS

HERE = Path(__file__).resolve().parents[1] / "src" / "multilat" / "schemas"


def main() -> None:
    for command in MODELS:
        path = HERE / f"{command}.json"
        text = dumps(generate(command))
        old = path.read_text("utf-8") if path.exists() else None
        if text != old:
            path.write_text(text, "utf-8")
        print(f"{command}: {'unchanged' if text == old else 'written'}")


if __name__ == "__main__":
    main()
