"""Write ``adjust.json``, the one shipped JSON Schema without a typed model yet, from the documents of
sample runs (developer tool, outside the package: it runs the CLI and reads the repository's examples).

    python tools/schema_infer.py            # rewrites src/multilat/schemas/adjust.json

Every other command's schema is generated from its model (:mod:`multilat.schemas.models`,
``python tools/write_schemas.py``); this tool goes once ``adjust`` has its model (with schema adjust/2).
It can still serve as a cross-check of a model: ``infer(command, docs)`` of any command's documents.

Each command is run on the shipped examples with the options in :data:`SAMPLES` (several runs per
command, so that keys that appear only with some options are declared); the schema of a command is
the merge of its documents' shapes:

* objects: ``properties`` of every key seen, ``required`` the keys present in every document,
  ``additionalProperties: false`` — except the id maps of :data:`multilat.vocabulary.ID_MAPS`, whose
  keys are ids (any key, every value of the merged shape);
* numbers may be ``null`` (non-finite values are written as null); a key only ever seen as null
  accepts anything;
* arrays: the merged shape of their items.

The result is a contract, not a proof: read the diff before committing it.
"""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

from multilat.vocabulary import ID_MAPS, schema_id

__all__ = ["SAMPLES", "run_sample", "infer", "merge"]

_ROOT = Path(__file__).resolve().parents[1]
_EX = _ROOT / "examples"
_N = _EX / "network"
_TESTDATA = _ROOT / "tests" / "data"

#: command -> list of argument lists (the commands without a model; tests/test_output_schema.py holds every
#: command's samples)
SAMPLES = {
    "adjust": [["adjust", f"{_N}/small_volume_obs.csv", "--references", f"{_N}/small_volume_refs.csv"],
               ["adjust", f"{_N}/small_volume_obs.csv", "--observations", "-o", "{tmp}/adj"],
               ["adjust", str(_TESTDATA / "network" / "weak_target.csv")],
               ["adjust", f"{_N}/sequential/obs.csv", "--variance-components", "head"],
               ["adjust", f"{_N}/mixed/obs.csv", "--variance-components", "kind"],
               ["adjust", str(_TESTDATA / "angles" / "mixed_azimuth_blunder.csv")],
               ["adjust", f"{_EX}/campaign/raw.csv", "-e", f"{_EX}/campaign/environment.csv", "--heights",
                f"{_EX}/campaign/heights.csv", "--average-repeats"]],
}


def run_sample(args, tmp: Path) -> dict:
    """Run ``multilat ARGS --json`` in-process and return its document."""
    from multilat.cli import main

    args = [a.replace("{tmp}", str(tmp)) for a in args] + ["--json"]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(args)
    if rc != 0:
        raise RuntimeError(f"multilat {' '.join(args)} exited {rc}: {err.getvalue().strip()[-300:]}")
    return json.loads(out.getvalue())


def _shape(v):
    if v is None:
        return {}
    if isinstance(v, bool):
        return {"type": "boolean"}
    if isinstance(v, (int, float)):
        return {"type": ["number", "null"]}
    if isinstance(v, str):
        return {"type": "string"}
    if isinstance(v, list):
        items = None
        for x in v:
            items = _shape(x) if items is None else merge(items, _shape(x))
        return {"type": "array", "items": items if items is not None else {}}
    props = {}
    req = None
    for k, x in v.items():
        props[k] = _shape(x)
    req = sorted(v)
    return {"type": "object", "properties": props, "required": req, "additionalProperties": False}


def merge(a: dict, b: dict) -> dict:
    """The shape that accepts what ``a`` and what ``b`` accept."""
    if a == {} or b == {}:
        return {}
    ta, tb = a.get("type"), b.get("type")
    if ta == tb == "object":
        props = dict(a["properties"])
        for k, v in b["properties"].items():
            props[k] = merge(props[k], v) if k in props else v
        req = sorted(set(a["required"]) & set(b["required"]))
        return {"type": "object", "properties": props, "required": req, "additionalProperties": False}
    if ta == tb == "array":
        return {"type": "array", "items": merge(a["items"], b["items"])}
    if a == b:
        return a
    types = set()
    for t in (ta, tb):
        types.update(t if isinstance(t, list) else [t])
    if "object" in types or "array" in types:
        return {"anyOf": [a, b]}
    return {"type": sorted(types)}


def _id_maps(shape: dict, key: str | None = None) -> dict:
    """Turn the objects under :data:`ID_MAPS` keys into maps of any id to the merged value shape."""
    if shape.get("type") == "object":
        props = {k: _id_maps(v, k) for k, v in shape["properties"].items()}
        if key in ID_MAPS:
            vals = list(props.values())
            m = vals[0] if vals else {}
            for v in vals[1:]:
                m = merge(m, v)
            return {"type": "object", "additionalProperties": m}
        return dict(shape, properties=props)
    if shape.get("type") == "array":
        return dict(shape, items=_id_maps(shape["items"]))
    if "anyOf" in shape:
        return {"anyOf": [_id_maps(s, key) for s in shape["anyOf"]]}
    return shape


def infer(command: str, docs: list) -> dict:
    shape = None
    for d in docs:
        shape = _shape(d) if shape is None else merge(shape, _shape(d))
    shape = _id_maps(shape)
    sid = schema_id(command)
    shape["properties"]["schema"] = {"const": sid}
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": sid,
            "title": f"multilat {command.replace('-', ' ')} --json", **shape}


def main() -> None:  # pragma: no cover - developer tool
    import tempfile

    from multilat.schemas.models import MODELS

    here = _ROOT / "src" / "multilat" / "schemas"
    with tempfile.TemporaryDirectory() as t:
        for cmd, runs in SAMPLES.items():
            if cmd in MODELS:            # written from its model (tools/write_schemas.py)
                continue
            docs = []
            for i, args in enumerate(runs):
                tmp = Path(t) / f"{cmd}-{i}"
                tmp.mkdir()
                docs.append(run_sample(args, tmp))
            (here / f"{cmd}.json").write_text(json.dumps(infer(cmd, docs), indent=1, sort_keys=False) + "\n")
            print(f"{cmd}: {len(docs)} documents")


if __name__ == "__main__":  # pragma: no cover
    main()
