"""The import-layering contract of the package (issue 27 item 5), checked on the source with ``ast``.

The layers, lowest first (docs/architecture.md draws them). A module may import modules of its own
layer and of the layers below, never of a layer above; the groups of one layer are independent (they do
not import each other). Every import counts: at module level, inside a function, or under
``TYPE_CHECKING``. A violation is named ``importer -> imported`` with the file and line.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PKG = SRC / "multilat"

#: Layers, lowest first; each is a list of groups ``(name, module prefixes)``.
LAYERS = [
    [("foundation", ["multilat", "multilat.errors", "multilat.vocabulary", "multilat.inputs", "multilat.io",
                     "multilat.rows_text", "multilat._text_kernels", "multilat._numba", "multilat.schemas"])],
    [("probability", ["multilat.fast_normal", "multilat.distributions", "multilat.montecarlo",
                      "multilat.parallel"])],
    [("distance model", ["multilat.air", "multilat.adm", "multilat.gimbal", "multilat.tracker",
                         "multilat.instrument", "multilat.budget", "multilat.budget_inputs",
                         "multilat.distance_errors"])],
    [("network", ["multilat.network"])],
    [("lbb", ["multilat.lbb"]), ("campaign", ["multilat.campaign"])],
    [("report", ["multilat.report"])],
    [("cli", ["multilat.cli", "multilat.warmup", "multilat.__main__"])],
]

#: Inside ``multilat.network``, lowest first (written by tools/retree.py; docs/architecture.md):
#: the model (it solves nothing: the normal equations, the covariance and the statistics are
#: the adjustment's, issue 27), the readers and generated networks, the adjustments (the
#: general layer above the distance path's cores it calls), the Monte Carlo on the adjustment's
#: system, the design.
#: A module of ``network/`` in no package listed here (a new flat module) counts as the model.
NETWORK_TIERS = [
    ("network model", ["multilat.network", "multilat.network.model"]),
    ("network io", ["multilat.network.io", "multilat.network.synthetic"]),
    ("network adjust", ["multilat.network.adjust"]),
    ("network adjust general", ["multilat.network.adjust.general"]),
    ("network montecarlo", ["multilat.network.montecarlo"]),
    ("network design", ["multilat.network.design"]),
]


def _within(module: str, prefix: str) -> bool:
    return module == prefix or module.startswith(prefix + ".")


def _longest(module: str, table):
    """The entry of ``table`` ((key, prefixes) pairs) whose prefix is the longest match of ``module``."""
    best, best_len = None, -1
    for key, prefixes in table:
        for p in prefixes:
            if _within(module, p) and len(p) > best_len:
                best, best_len = key, len(p)
    return best


_GROUPS = [((i, name), prefixes) for i, layer in enumerate(LAYERS) for name, prefixes in layer]
_TIERS = [((i, name), prefixes) for i, (name, prefixes) in enumerate(NETWORK_TIERS)]


def module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _resolve(name: str) -> str:
    """The module a dotted name refers to: the longest prefix that is a module or package of the tree
    (``multilat.network.montecarlo.batched.flatten`` -> ``multilat.network.montecarlo.batched``)."""
    parts = name.split(".")
    for n in range(len(parts), 0, -1):
        base = SRC.joinpath(*parts[:n])
        if base.with_suffix(".py").is_file() or (base / "__init__.py").is_file():
            return ".".join(parts[:n])
    return name


def imports_of(path: Path):
    """``(line, imported module)`` of every ``multilat`` import in the file at ``path``."""
    me = module_name(path)
    package = me if path.name == "__init__.py" else me.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text("utf-8"), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, _resolve(a.name)) for a in node.names if _within(a.name, "multilat")]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if _within(mod, "multilat"):
                out += [(node.lineno, _resolve(f"{mod}.{a.name}")) for a in node.names]
    return out


def violations():
    """Every import that goes up a layer (or across groups of one layer, or up a network tier)."""
    found = []
    for path in sorted(PKG.rglob("*.py")):
        me = module_name(path)
        g_me = _longest(me, _GROUPS)
        for line, other in imports_of(path):
            g_other = _longest(other, _GROUPS)
            where = f"{path.relative_to(SRC.parent)}:{line}"
            if g_me is None or g_other is None:
                found.append(f"{me} -> {other} ({where}: module in no layer: add it to LAYERS)")
            elif g_other[0] > g_me[0] or (g_other[0] == g_me[0] and g_other != g_me):
                found.append(f"{me} -> {other} ({where}: {g_me[1]} may not import {g_other[1]})")
            elif g_me[1] == g_other[1] == "network":
                t_me, t_other = _longest(me, _TIERS), _longest(other, _TIERS)
                if t_other[0] > t_me[0]:
                    found.append(f"{me} -> {other} ({where}: {t_me[1]} may not import {t_other[1]})")
    return found


def test_no_import_goes_up_a_layer():
    bad = violations()
    assert not bad, f"{len(bad)} layering violation(s):\n" + "\n".join(bad)


def test_every_module_is_in_a_layer():
    missing = [module_name(p) for p in PKG.rglob("*.py") if _longest(module_name(p), _GROUPS) is None]
    assert not missing, missing


@pytest.mark.parametrize("importer,imported,layer", [
    ("multilat/lbb/files.py", "multilat.report.html", "lbb may not import report"),
    ("multilat/montecarlo/engine.py", "multilat.network.montecarlo.batched", "probability may not import network"),
    ("multilat/campaign/raw.py", "multilat.lbb", "campaign may not import lbb"),
    ("multilat/network/model/datum.py", "multilat.network.adjust.distance.adjust", "network model may not import network adjust"),
    ("multilat/network/model/distance.py", "multilat.network.adjust.covariance", "network model may not import network adjust"),
    ("multilat/network/adjust/distance/fit.py", "multilat.network.design.fast", "network adjust may not import network design"),
    ("multilat/network/io/files.py", "multilat.network.adjust.distance.result", "network io may not import network adjust"),
    ("multilat/network/adjust/distance/snooping.py", "multilat.network.adjust.general.quality", "network adjust may not import network adjust general"),
])
def test_a_new_upward_import_is_named(tmp_path, monkeypatch, importer, imported, layer):
    """Mutation: one upward import added to a copy of the tree is reported as ``importer -> imported``."""
    import shutil

    copy = tmp_path / "src"
    shutil.copytree(PKG, copy / "multilat", ignore=shutil.ignore_patterns("__pycache__", "*.json", "*.csv"))
    f = copy / importer
    f.write_text(f.read_text("utf-8") + f"\n\ndef _probe():\n    import {imported}  # noqa\n", "utf-8")
    monkeypatch.setitem(globals(), "SRC", copy)
    monkeypatch.setitem(globals(), "PKG", copy / "multilat")
    me = module_name(f)
    bad = [v for v in violations() if v.startswith(f"{me} -> ")]
    assert len(bad) == 1 and imported.split(".")[1] in bad[0] and layer in bad[0], bad


#: the developers' guide: no module over ~600 lines; no function over ~80 body lines (checked where a
#: package was cut to that size: the Monte Carlo engine)
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 80


def test_no_module_over_600_lines():
    long = [f"{p.relative_to(SRC.parent)}: {n} lines" for p in sorted(PKG.rglob("*.py"))
            if (n := len(p.read_text("utf-8").splitlines())) > MAX_MODULE_LINES]
    assert not long, long


def test_no_montecarlo_function_over_80_body_lines():
    long = []
    for path in sorted((PKG / "montecarlo").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text("utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                body = node.body[1:] if ast.get_docstring(node) is not None else node.body
                if body and body[-1].end_lineno - body[0].lineno + 1 > MAX_FUNCTION_LINES:
                    long.append(f"{path.relative_to(SRC.parent)}:{node.lineno} {node.name}")
    assert not long, long
