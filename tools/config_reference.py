"""Write docs/config-reference.md from the pydantic models of the config files (developer tool,
outside the package: it imports the instrument, design and LBB models, which sit in different layers).

    python tools/config_reference.py            # rewrites docs/config-reference.md
    python tools/config_reference.py --check    # exit 1 if the page differs from the models

Every key of every table: its TOML path, type, unit (from the name's suffix, the package's naming
rule ``quantity_unit``; or the field's ``json_schema_extra["unit"]``), default ("required" when it has
none), constraint (the field's ``json_schema_extra["constraint"]``; tests/test_config_reference.py
checks each numeric bound against the model by feeding it a value just across) and description
(``Field(description=...)``). The page cannot go stale: the test regenerates it and compares.
"""

from __future__ import annotations

import sys
import types
import typing
from pathlib import Path

from pydantic import BaseModel

__all__ = ["UNIT_SUFFIXES", "render", "rows", "unit_of", "type_name", "submodel", "main"]

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "config-reference.md"

#: key suffix -> unit shown (longest match wins; the package's names carry their units)
UNIT_SUFFIXES = {
    "_m": "m", "_um": "µm", "_nm": "nm", "_m2": "m²", "_deg": "degree", "_rad": "rad", "_urad": "µrad",
    "_hz": "Hz", "_db": "dB", "_m_per_db": "m/dB", "_um_per_m": "µm/m", "_pa": "Pa", "_hpa": "hPa",
    "_c": "°C", "_per_c": "1/°C", "_pct": "%", "_ppm": "µmol/mol (ppm)", "_kg": "kg", "_years": "year",
    "_per_year": "1/year", "_m_s2": "m/s²", "_kg_m3": "kg/m³",
}


def _files():
    """(anchor, title, root model, what reads it) of each config file described."""
    from multilat.instrument import Instrument
    from multilat.lbb.config import LBBConfig
    from multilat.network.design.config import DesignConfig

    return [
        ("instrument", "Instrument file", Instrument,
         "`--instrument FILE.toml` of `budget`, `simulate`, `adjust`, `propagate`, ...; the `[instrument] file` "
         "of a design. The shipped preset `seed2020` (`src/multilat/presets/seed2020.toml`) is an example of "
         "every table."),
        ("design", "Design file", DesignConfig,
         "`multilat design FILE.toml` (docs/design.md); example `examples/design/cube.toml`. Files it names "
         "are read relative to its directory."),
        ("lbb", "Laser-ball-bar file", LBBConfig,
         "`multilat lbb ... --config FILE.toml` (docs/lbb.md); the default is "
         "`src/multilat/lbb/canning2007.toml`, which comments every key."),
    ]


def unit_of(name: str, field) -> str:
    """The unit of key ``name``: the field's ``json_schema_extra["unit"]``, else its suffix, else "-"."""
    extra = field.json_schema_extra if isinstance(field.json_schema_extra, dict) else {}
    if "unit" in extra:
        return extra["unit"]
    best = ""
    for suf in UNIT_SUFFIXES:
        if name.endswith(suf) and len(suf) > len(best):
            best = suf
    return UNIT_SUFFIXES[best] if best else "-"


def submodel(ann):
    """``(model, how)`` when an annotation holds a table: ``how`` is "table", "map" (``dict[str, M]``),
    "array" (``list[M]``); else ``(None, None)``."""
    if isinstance(ann, type) and issubclass(ann, BaseModel):
        return ann, "table"
    origin, args = typing.get_origin(ann), typing.get_args(ann)
    if origin is dict and len(args) == 2 and isinstance(args[1], type) and issubclass(args[1], BaseModel):
        return args[1], "map"
    if origin is list and args and isinstance(args[0], type) and issubclass(args[0], BaseModel):
        return args[0], "array"
    return None, None


def type_name(ann) -> str:
    """A TOML reader's name for an annotation."""
    origin, args = typing.get_origin(ann), typing.get_args(ann)
    if ann is type(None):
        return "none"
    if origin is typing.Literal:
        return "one of " + ", ".join(f'"{a}"' for a in args)
    if origin in (typing.Union, types.UnionType):
        opts = [a for a in args if a is not type(None)]
        s = " or ".join(type_name(a) for a in opts)
        return s + (" (optional)" if len(opts) < len(args) else "")
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"array of {type_name(args[0])}"
        return f"array of {len(args)} {type_name(args[0])}" if len(set(args)) == 1 else \
            "array (" + ", ".join(type_name(a) for a in args) + ")"
    if origin is list:
        return f"array of {type_name(args[0])}"
    if origin is dict:
        return f"table of {type_name(args[1])} by name"
    if isinstance(ann, type) and issubclass(ann, BaseModel):
        return "table"
    return {float: "number", int: "integer", bool: "boolean", str: "string"}.get(ann, str(ann))


def _default(field) -> str:
    if field.is_required():
        return "required"
    d = field.get_default(call_default_factory=True)
    if isinstance(d, BaseModel):
        return "the table's defaults" if not d.model_fields_set else "`" + ", ".join(f"{k} = {_toml(v)}" for k, v in d.model_dump(exclude_unset=True).items()) + "`"
    return f"`{_toml(d)}`" if d is not None else "none"


def _toml(v) -> str:
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml(x)}" for k, x in v.items()) + "}"
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def rows(model, prefix: str = ""):
    """``(table path, model, [(key, type, unit, default, constraint, description)])`` for ``model`` and
    every table under it, depth first, in declaration order."""
    out = []
    mine = []
    subs = []
    for name, f in model.model_fields.items():
        sub, how = submodel(f.annotation)
        extra = f.json_schema_extra if isinstance(f.json_schema_extra, dict) else {}
        path = f"{prefix}{name}"
        if sub is not None:
            where = {"table": f"[{path}]", "map": f"[{path}.NAME]", "array": f"[[{path}]]"}[how]
            mine.append((name, {"table": "table", "map": "tables by name", "array": "array of tables"}[how]
                         + f" ({where})", "-", _default(f), extra.get("constraint", ""), f.description or ""))
            subs.append((sub, path + (".NAME" if how == "map" else "") + "."))
        else:
            mine.append((name, type_name(f.annotation), unit_of(name, f), _default(f),
                         extra.get("constraint", ""), f.description or ""))
    out.append((prefix[:-1] if prefix else "", model, mine))
    seen = set()
    for sub, p in subs:
        if (sub, p) in seen:
            continue
        seen.add((sub, p))
        out.extend(rows(sub, p))
    return out


def _cell(s: str) -> str:
    return str(s).replace("|", "\\|").replace("\n", " ")


def render() -> str:
    """The whole page."""
    lines = ["# Config file reference", "",
             "Generated by `python tools/config_reference.py` from the pydantic models; "
             "`tests/test_config_reference.py` fails when this page and the models differ. Do not edit by hand: "
             "edit the `Field(description=...)` in the model and rerun the tool.", "",
             "Units follow each key's suffix (`_m` metres, `_um` micrometres, `_deg` degrees, ...). Unknown keys "
             "are refused (one line naming the file and the key path); so is a value outside its constraint.", ""]
    for anchor, title, model, what in _files():
        lines += [f"<a id=\"{anchor}\"></a>", f"## {title}", "", what, ""]
        doc = (model.__doc__ or "").strip().split("\n\n")[0].replace("\n", " ")
        if doc:
            lines += [doc, ""]
        for path, m, rs in rows(model):
            lines += [f"### {'top level' if not path else '`[' + path + ']`'}" + f" ({m.__name__})", ""]
            lines += ["| key | type | unit | default | constraint | description |",
                      "| --- | --- | --- | --- | --- | --- |"]
            lines += ["| " + " | ".join(_cell(c) for c in (f"`{r[0]}`", *r[1:])) + " |" for r in rs]
            lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    text = render()
    if "--check" in argv:
        same = OUT.is_file() and OUT.read_text(encoding="utf-8") == text
        print("docs/config-reference.md is " + ("up to date" if same else "stale: run tools/config_reference.py"))
        return 0 if same else 1
    OUT.write_text(text, encoding="utf-8")
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
