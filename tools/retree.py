#!/usr/bin/env python3
"""Re-tree ``multilat.network`` into packages that show the architecture (issue 27 item 4).

Run from anywhere: ``python tools/retree.py`` (``--dry-run`` prints what it would do and touches
nothing). It is deterministic and idempotent: a second run changes nothing and says so. It

1. ``git mv``\\ s every module of :data:`MAPPING` that is still at its old place, creates the new
   packages with the docstring ``__init__.py`` of :data:`PACKAGE_DOCS`, and removes the emptied old
   package directories;
2. rewrites every reference to a moved module in ``src/``, ``tests/``, ``benchmarks/``, ``tools/``,
   ``docs/``, ``examples/``, ``README.md``, ``BENCHMARKS.md``, ``Makefile``, ``pyproject.toml``,
   ``.ci/run`` (:data:`TEXT_ROOTS`, :data:`TEXT_FILES`): dotted names
   (``multilat.network.model.line_of_sight`` in imports, docstrings, ``mock.patch`` strings,
   ``importlib`` names, numba warm-up lists), ``from multilat.network[.pkg] import module`` (the
   name follows its module; an attribute its module; a renamed module keeps its local name with
   ``as``), paths (``src/multilat/network/fit.py``, ``network/general/``), the ``network.x`` short
   form of the docs, the module tables of the docs (:data:`DOC_RELATIVE`), the network-relative
   keys of ``tests/test_each_concept_once.py``, and the few
   texts no rule can see (:data:`FIXUPS`: a path joined from parts). A name is matched whole
   (``propagate`` never matches inside ``propagate_result``), and one that already names a new
   module is left alone (that is what makes a second run a no-op);
3. writes the network tiers of ``tests/test_layering.py`` (:data:`TIERS`, with the mutation cases),
   the tree, the tiers and the path of one observation in ``docs/architecture.md``, and the
   network part of ``README.md``'s layout (:data:`GENERATED`; the texts are in ``retree_docs.py``);
4. reports the modules of ``network/`` the mapping does not name (added since it was written: place
   them in :data:`MAPPING` and run again) and every import that goes up a tier.

The tree (one idea per package; lowest tier first, a package imports its own tier and those below):

``model/``
    What a network is and how one observation is modelled: the distance path's data, its model
    (``distance``, was ``model.py``), registry of unknowns (``problem``), angle and coupling rows,
    the datum and S-transformation, the σ's record, and the general layer's points, parameter
    layout, observation blocks and ``kinds/`` (one module per kind). No solving: the normal-equation
    assembly (``adjust/solve/normal_equations``, split out of ``distance`` after the re-tree, issue 27)
    and with it ``covariance``, ``statistics`` and the two kernel modules sit in ``adjust/``.
``io/``
    Readers and writers: multilat's CSVs (``files``, ``fastio``, ``screening``, ``result_rows``,
    ``general_files``) and ``interop/`` (GNU Gama XML in and out, JAG3D, Star*Net).
``synthetic/``
    Networks with a known truth: the package's one generator (``generator``, was
    ``synthetic.py``) and the seed's built-in configurations (``configs``). Same tier as ``io/``.
``adjust/``
    The adjustments. ``solve/`` (the distance path's loop, its normal equations and its dense, sparse,
    coupled back ends with the solve's kernels ``_sparse_kernels``), ``covariance`` (Schur form, with
    its kernels) and ``statistics`` (the tests), shared by every path,
    ``approximate/`` (initial values: the distance path's and, in ``approximate/general/``, the
    general layer's), ``distance/`` (the distance path: ``adjust``, ``fit``, snooping,
    reliability, variance components, result, options), ``general/`` (the general layer's
    adjustment, dense and sparse, its statistics, snooping, variance components, JSON document; its
    ``__init__`` is the general layer's facade, ``from multilat.network.adjust.general import
    adjust_network``). ``adjust/general`` is a tier above the rest of ``adjust/``: it calls the
    distance path's cores, never the other way.
``montecarlo/``
    The adjustment's system frozen per trial: ``propagate`` and its summaries, the batched solvers
    and their kernel, the trial datum, ``simulate``, and ``general/`` (the general layer's Monte Carlo).
``design/``
    Pre-analysis and layout search on the same layer, with ``general_preanalysis`` (was
    ``general/preanalysis.py``). Above ``montecarlo/``: ``confirm`` runs ``propagate``.
"""

from __future__ import annotations

import argparse
import ast
import re
import shutil
import subprocess
import sys
from pathlib import Path

from retree_docs import architecture_text, readme_text, tiers_text

ROOT = Path(__file__).resolve().parents[1]
#: this script and its texts: never rewritten (they name the old and the new modules on purpose)
SELF = {Path(__file__).resolve(), Path(__file__).resolve().with_name("retree_docs.py")}
NET = ROOT / "src" / "multilat" / "network"
PREFIX = "multilat.network"

# ---------------------------------------------------------------------------------------------
#: old path under ``src/multilat/network/`` -> new path. Every module of the package, once.
MAPPING: dict[str, str] = {}


def _put(new_dir: str, olds: str, rename: dict[str, str] | None = None) -> None:
    for old in olds.split():
        base = old.rsplit("/", 1)[-1]
        MAPPING[old] = f"{new_dir}/{(rename or {}).get(old, base)}"


_put("model", "data.py model.py angles.py angle_rows.py couplings.py datum.py scale_datum.py problem.py "
              "sigma_source.py "
              "repeats.py frame_words.py parameter_layout.py general/points.py general/observations.py general/layout.py "
              "general/determinability.py", {"model.py": "distance.py"})
_put("model/kinds", " ".join(f"general/kinds/{m}.py" for m in (
    "__init__ columns coordinate_difference direction geometry height_difference horizontal_angle "
    "horizontal_distance observed_coordinates slope_distance tracker_angles zenith_angle").split()))
_put("io", "files.py fastio.py screening.py result_rows.py general/files.py",
     {"general/files.py": "general_files.py"})
_put("io/interop", "interop/__init__.py interop/angles.py interop/common.py interop/gama.py "
                   "interop/gama_adjusted.py interop/jag3d.py interop/starnet.py general/gama_input.py")
_put("synthetic", "synthetic.py configs.py", {"synthetic.py": "generator.py"})
_put("adjust/solve", " ".join(f"solve/{m}.py" for m in
                               "__init__ convergence coupled dense loop normal_equations sparse system".split()))
_put("adjust/solve", "_sparse_kernels.py")
_put("adjust", "covariance.py _covariance_kernels.py statistics.py")
_put("adjust/approximate", "initial.py initial_refine.py large.py starts.py search.py bounds.py")
_put("adjust/approximate/general", " ".join(f"general/approximate/{m}.py" for m in
                                            "__init__ frames place ranging search sights".split()))
_put("adjust/distance", "adjust.py adjust_steps.py fit.py fit_state.py exclusion.py solvability.py ambiguity.py "
                        "unit_slip.py snooping.py reliability.py result.py variance_components.py costs.py "
                        "options.py azimuth_sense.py")
_put("adjust/general", " ".join(f"general/{m}.py" for m in
                                "__init__ adjust sparse run snooping quality reliability variance from_tables "
                                "report".split()))
_put("montecarlo", "propagate.py propagate_pairs.py propagate_result.py propagate_summary.py batched.py "
                   "batched_coupled.py _batched_numba.py trial_datum.py simulate.py readings.py")
_put("montecarlo/general", " ".join(f"general/{m}.py" for m in
                                    "propagate propagate_blocks propagate_result _frozen_numba".split()))
_put("design", " ".join(f"design/{m}.py" for m in
                        "__init__ blocked config confirm couplings evaluate fast paper_study preanalysis search "
                        "targets".split()))
_put("design", "general/preanalysis.py", {"general/preanalysis.py": "general_preanalysis.py"})

#: docstrings of the new packages (an existing ``__init__.py`` is never overwritten)
PACKAGE_DOCS = {
    "model": "The model of a network: what it holds and how one observation is computed from the parameters.\n\n"
             "The distance path's data, model (:mod:`.distance`), registry of unknowns (:mod:`.problem`), angle\n"
             "and coupling rows, datum and S-transformation; the general layer's points, parameter layout,\n"
             "observation blocks and :mod:`.kinds` (one module per kind). No solving here: the normal equations,\n"
             "the covariance and the statistics belong to the adjustment\n"
             "(:mod:`multilat.network.adjust.solve.normal_equations`, :mod:`multilat.network.adjust.covariance`,\n"
             ":mod:`multilat.network.adjust.statistics`).",
    "io": "Readers and writers: multilat's CSV files, large-file readers, and :mod:`.interop` (GNU Gama,\n"
          "JAG3D, Star*Net). Built on :mod:`multilat.network.model` only.",
    "synthetic": "Networks with a known truth: the package's one generator (:mod:`.generator`) and the\n"
                 "seed's built-in configurations (:mod:`.configs`).",
    "adjust": "The adjustments: the solver family (:mod:`.solve`), approximate coordinates (:mod:`.approximate`),\n"
              "the distance path (:mod:`.distance`) and the general layer (:mod:`.general`); shared by them, the\n"
              "covariance in Schur form (:mod:`.covariance`, its kernels :mod:`._covariance_kernels`) and the\n"
              "statistics of the tests (:mod:`.statistics`).",
    "adjust/approximate": "Approximate coordinates, a step of its own before the adjustment: the distance path's\n"
                          "initial values and minimum search, and the general layer's (:mod:`.general`).",
    "adjust/distance": "The distance path's adjustment: self-calibrating multilateration from distances (and\n"
                       "angles, bars, control), its fit, data snooping, reliability, variance components, result.",
    "montecarlo": "The Monte Carlo of a network (JCGM 101/102): the adjustment's system frozen per trial,\n"
                  "batched solvers, ``propagate`` and its summaries, ``simulate``; :mod:`.general` for the\n"
                  "general layer.",
    "montecarlo/general": "The general layer's Monte Carlo: the adjustment's own system frozen at its solution.",
}

#: the network tiers of tests/test_layering.py, lowest first (name, packages)
TIERS = [
    ("network model", ["multilat.network", "multilat.network.model"]),
    ("network io", ["multilat.network.io", "multilat.network.synthetic"]),
    ("network adjust", ["multilat.network.adjust"]),
    ("network adjust general", ["multilat.network.adjust.general"]),
    ("network montecarlo", ["multilat.network.montecarlo"]),
    ("network design", ["multilat.network.design"]),
]

#: where references are rewritten
TEXT_ROOTS = ["src", "tests", "benchmarks", "tools", "docs", "examples"]
TEXT_FILES = ["README.md", "BENCHMARKS.md", "Makefile", "pyproject.toml", ".ci/run"]
TEXT_SUFFIXES = {".py", ".md", ".toml", ".json", ".txt", ".cfg", ".ini", ".yml", ".yaml", ".sh", ".rst"}
#: what the rules above cannot see (a path built from joined parts), as exact text replacements
#: ``file: [(old, new)]``; the old text is gone after the first run, so a second finds nothing
FIXUPS = {
    "tests/test_constants.py": [
        ('(tmp_path / "network").mkdir()\n    (tmp_path / "network" / "sigma_source.py")',
         '(tmp_path / "network" / "model").mkdir(parents=True)\n'
         '    (tmp_path / "network" / "model" / "sigma_source.py")'),
    ],
}
#: docs whose backticked ``x.py`` / ``dir/`` name a module relative to a folder of ``network/``:
#: the bases tried in order (a name is rewritten only when base + name is an old module or package)
DOC_RELATIVE = {"docs/network.md": [""], "docs/general-network.md": ["general/", ""],
                "docs/propagate.md": [""], "docs/design.md": ["design/", ""]}
#: files whose quoted ``"x/y.py"`` keys are relative to ``network/``
NETWORK_RELATIVE_KEYS = ["tests/test_each_concept_once.py"]


# ---------------------------------------------------------------------------------------------
def dotted(rel: str) -> str:
    parts = rel[:-3].split("/")
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join([PREFIX, *parts])


OLD = {dotted(k): dotted(v) for k, v in MAPPING.items()}
OLD[PREFIX] = PREFIX
NEW = set(OLD.values())
for _n in list(NEW):
    while "." in _n:
        _n = _n.rpartition(".")[0]
        NEW.add(_n)
NEW |= {f"{PREFIX}.{p.replace('/', '.')}" for p in PACKAGE_DOCS}
#: old package directories (``general/``) -> their new directory
OLD_DIRS = {k[: -len("__init__.py")]: v[: -len("__init__.py")] for k, v in MAPPING.items()
            if k.endswith("__init__.py")}
OLD_DIRS.setdefault("general/", "adjust/general/")


def _longest(parts: list[str], names: set[str] | dict) -> int:
    for n in range(len(parts), 0, -1):
        if ".".join(parts[:n]) in names:
            return n
    return 0


def resolve(name: str) -> str:
    """The new spelling of a dotted name (unchanged when it already names a new module)."""
    parts = name.split(".")
    o, n = _longest(parts, OLD), _longest(parts, NEW)
    if o == 0 or n > o:
        return name
    return ".".join([OLD[".".join(parts[:o])], *parts[o:]])


_BOUND: dict[str, set[str]] = {}


def bound_names(module: str) -> set[str]:
    """Names an old module (or an old package's ``__init__``) binds at its top level: ``from pkg import
    name`` then means that attribute, not the submodule ``pkg.name``."""
    if module not in _BOUND:
        names: set[str] = set()
        rel = next((k for k in MAPPING if dotted(k) == module), None)
        for path in [NET / rel, NET / MAPPING[rel]] if rel else []:
            if path.is_file():
                for node in ast.parse(path.read_text("utf-8")).body:
                    if isinstance(node, (ast.ImportFrom, ast.Import)):
                        names |= {(a.asname or a.name).split(".")[0] for a in node.names}
                    elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                        names.add(node.name)
                    elif isinstance(node, (ast.Assign, ast.AnnAssign)):
                        targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                        names |= {t.id for t in targets if isinstance(t, ast.Name)}
                break
        _BOUND[module] = names
    return _BOUND[module]


def _import_parts(module: str, name: str):
    """(new module, new name) for ``from module import name``."""
    full = f"{module}.{name}"
    parts = full.split(".")
    o, n = _longest(parts, OLD), _longest(parts, NEW)
    if o == 0 or n > o:
        return module, name
    if full in OLD and name not in bound_names(module):          # a submodule: it moves
        new = OLD[full]
        parent, _, base = new.rpartition(".")
        return parent, base
    return resolve(module), name


def rewrite_import(node: ast.ImportFrom, lines: list[str]) -> list[str] | None:
    """New source lines for one ``from multilat.network... import ...`` statement (None: unchanged)."""
    moved = [_import_parts(node.module, a.name) for a in node.names]
    if all(m == (node.module, a.name) for m, a in zip(moved, node.names)):
        return None
    first, last = node.lineno - 1, node.end_lineno - 1
    text = "\n".join(lines[first:last + 1])
    modules = {m for m, _ in moved}
    if len(modules) == 1 and all(n == a.name for (_, n), a in zip(moved, node.names)):
        # one new module, the same names: change the module only, keep the formatting
        return re.sub(r"^(\s*from\s+)" + re.escape(node.module) + r"(\s+import)",
                      lambda m: m.group(1) + modules.pop() + m.group(2), text, count=1).split("\n")
    groups: dict[str, list[str]] = {}
    for (mod, new), a in zip(moved, node.names):
        local = a.asname or a.name
        groups.setdefault(mod, []).append(new if local == new else f"{new} as {local}")
    indent = lines[first][: node.col_offset]
    tail = lines[last][node.end_col_offset:]
    out = [f"{indent}from {mod} import {', '.join(names)}" for mod, names in groups.items()]
    out[-1] += tail
    return out


DOTTED = re.compile(r"(?<![\w.])multilat\.network(?:\.[A-Za-z_]\w*)*")
SHORT = re.compile(r"(?<![\w./-])network(?:\.[A-Za-z_]\w*)+")
PATH = re.compile(r"(?:(?<=multilat/)|(?<![\w/]))network/((?:[A-Za-z_]\w*/)*(?:[A-Za-z_]\w*\.py|[A-Za-z_]\w*/)?)")
DOC_KEY = re.compile(r"(?<=`)((?:[A-Za-z_]\w*/)*(?:[A-Za-z_]\w*\.py|[A-Za-z_]\w*/))(?=`)")
REL_KEY = re.compile(r"(?<=[\"'])((?:[A-Za-z_]\w*/)*[A-Za-z_]\w*\.py)(?=[:\"'])")


def map_path(rel: str) -> str:
    """The new path of ``rel`` (under network/): a moved file, or a path inside a moved package."""
    if rel in MAPPING:
        return MAPPING[rel]
    best = max((d for d in OLD_DIRS if rel.startswith(d)), key=len, default=None)
    return rel if best is None else OLD_DIRS[best] + rel[len(best):]


def doc_relative(text: str, bases: list[str]) -> str:
    """Backticked module names relative to a folder of network/ (the docs' module tables)."""
    def one(m):
        for base in bases:
            rel = base + m.group(1)
            if rel in MAPPING or rel in OLD_DIRS:
                return map_path(rel)
        return m.group(1)
    return DOC_KEY.sub(one, text)


#: one pass over text: a one-line ``from multilat.network... import a, b as c`` (in a string, a doc
#: block), a regex-escaped dotted name (``multilat\\.network\\.x``), a dotted name; one pass so the
#: first two are never rewritten again by the third
TEXT_RULE = re.compile(r"(?P<imp>^(?P<ind>[ \t]*)from[ \t]+(?P<mod>multilat\.network(?:\.\w+)*)[ \t]+import[ \t]+"
                       r"(?P<names>\w+(?:[ \t]+as[ \t]+\w+)?(?:[ \t]*,[ \t]*\w+(?:[ \t]+as[ \t]+\w+)?)*)[ \t]*$)"
                       r"|(?P<esc>(?<![\w.\\])multilat\\\.network(?:\\\.[A-Za-z_]\w*)*)"
                       r"|(?P<dot>" + DOTTED.pattern + ")", re.M)


def _text_rule(m: re.Match) -> str:
    if m.group("dot"):
        return resolve(m.group("dot"))
    if m.group("esc"):
        return re.escape(resolve(m.group("esc").replace("\\.", ".")))
    aliases = [ast.alias(n.split()[0], n.split()[-1] if " as " in f" {n} " else None)
               for n in re.split(r"\s*,\s*", m.group("names").strip())]
    node = ast.ImportFrom(m.group("mod"), aliases, 0, lineno=1, end_lineno=1, col_offset=len(m.group("ind")),
                          end_col_offset=len(m.group("imp")))
    new = rewrite_import(node, [m.group("imp")])
    return m.group("imp") if new is None else "\n".join(new)


def rewrite_text(text: str, *, markdown: bool, relative_keys: bool) -> str:
    text = TEXT_RULE.sub(_text_rule, text)
    if markdown:
        text = SHORT.sub(lambda m: resolve("multilat." + m.group())[len("multilat."):], text)
    text = PATH.sub(lambda m: "network/" + map_path(m.group(1)), text)
    if relative_keys:
        text = REL_KEY.sub(lambda m: map_path(m.group(1)), text)
    return text


def rewrite_python(text: str, path: Path, *, relative_keys: bool) -> str:
    try:
        tree = ast.parse(text)
    except SyntaxError:
        print(f"  warning: {path.relative_to(ROOT)} does not parse: dotted names only")
        return rewrite_text(text, markdown=False, relative_keys=relative_keys)
    lines = text.split("\n")
    spans = sorted((n for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and not n.level and n.module
                    and (n.module == PREFIX or n.module.startswith(PREFIX + "."))), key=lambda n: n.lineno)
    pieces, i = [], 0
    for node in spans:
        first, last = node.lineno - 1, node.end_lineno - 1
        if first < i:       # two statements on one line: left to the dotted rule
            continue
        if first > i:
            pieces.append(rewrite_text("\n".join(lines[i:first]), markdown=False, relative_keys=relative_keys))
        new = rewrite_import(node, lines)
        pieces.append("\n".join(new if new is not None else lines[first:last + 1]))
        i = last + 1
    if i < len(lines):
        pieces.append(rewrite_text("\n".join(lines[i:]), markdown=False, relative_keys=relative_keys))
    return "\n".join(pieces)


# ---------------------------------------------------------------------------------------------
def git(*args: str, dry: bool) -> None:
    print("  git " + " ".join(args))
    if not dry:
        subprocess.run(["git", "-C", str(ROOT), *args], check=True)


def move_files(dry: bool) -> int:
    moved = 0
    for old, new in MAPPING.items():
        src, dst = NET / old, NET / new
        if old == new or not src.is_file() or dst.exists():
            if src.is_file() and dst.exists() and old != new:
                print(f"  warning: both network/{old} and network/{new} exist: left alone")
            continue
        if not dry:
            dst.parent.mkdir(parents=True, exist_ok=True)
        git("mv", str(src.relative_to(ROOT)), str(dst.relative_to(ROOT)), dry=dry)
        moved += 1
    for pkg, doc in PACKAGE_DOCS.items():
        init = NET / pkg / "__init__.py"
        if not init.exists():
            print(f"  create network/{pkg}/__init__.py")
            if not dry:
                init.parent.mkdir(parents=True, exist_ok=True)
                init.write_text(f'"""{doc}\n"""\n', "utf-8")
                git("add", str(init.relative_to(ROOT)), dry=dry)
            moved += 1
    for d in sorted({(NET / o).parent for o in MAPPING}, key=lambda p: -len(p.parts)):
        if d.is_dir() and d != NET and not any(p for p in d.rglob("*") if p.is_file()
                                                 and "__pycache__" not in p.parts):
            print(f"  remove emptied {d.relative_to(ROOT)}/")
            if not dry:
                shutil.rmtree(d)
    return moved


def text_files():
    for root in TEXT_ROOTS:
        for p in sorted((ROOT / root).rglob("*")):
            if p.is_file() and p.suffix in TEXT_SUFFIXES and "__pycache__" not in p.parts \
                    and p.resolve() not in SELF:
                yield p
    for name in TEXT_FILES:
        if (ROOT / name).is_file():
            yield ROOT / name


def rewrite_all(dry: bool) -> int:
    n = 0
    for p in text_files():
        rel = p.relative_to(ROOT).as_posix()
        try:
            text = p.read_text("utf-8")
        except UnicodeDecodeError:
            continue
        keys = rel in NETWORK_RELATIVE_KEYS
        new = (rewrite_python(text, p, relative_keys=keys) if p.suffix == ".py"
               else rewrite_text(text, markdown=p.suffix == ".md", relative_keys=keys))
        if rel in DOC_RELATIVE:
            new = doc_relative(new, DOC_RELATIVE[rel])
        new = GENERATED.get(rel, lambda t: t)(new)       # sections this script writes whole
        for old, fixed in FIXUPS.get(rel, []):
            new = new.replace(old, fixed)
        if new != text:
            changed = sum(a != b for a, b in zip(text.split("\n"), new.split("\n")))
            print(f"  rewrite {rel} ({changed} lines)")
            n += 1
            if not dry:
                p.write_text(new, "utf-8")
    return n


# ---------------------------------------------------------------------------------------------
GENERATED = {"tests/test_layering.py": lambda t: tiers_text(t, TIERS), "docs/architecture.md": architecture_text,
             "README.md": readme_text}


# ---------------------------------------------------------------------------------------------
def module_of(path: Path) -> str:
    parts = list(path.relative_to(NET.parents[1]).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def unmapped() -> list[str]:
    """Modules of network/ that are neither at an old place the mapping names nor at a new one."""
    old_paths = {NET / k for k in MAPPING} | {NET / "__init__.py"}
    new_paths = {NET / v for v in MAPPING.values()} | {NET / p / "__init__.py" for p in PACKAGE_DOCS}
    return sorted(p.relative_to(NET).as_posix() for p in NET.rglob("*.py")
                  if "__pycache__" not in p.parts and p not in old_paths | new_paths)


def tier_of(module: str) -> int:
    best, best_len = 0, -1
    for i, (_, pkgs) in enumerate(TIERS):
        for p in pkgs:
            if (module == p or module.startswith(p + ".")) and len(p) > best_len:
                best, best_len = i, len(p)
    return best


def upward_imports() -> list[str]:
    """Every import inside network/ that goes up a tier (after the move)."""
    found = []
    for path in sorted(NET.rglob("*.py")):
        me = module_of(path)
        for node in ast.walk(ast.parse(path.read_text("utf-8"))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                names = [f"{node.module}.{a.name}" for a in node.names]
            for name in names:
                if name.startswith(PREFIX + ".") and tier_of(name) > tier_of(me):
                    found.append(f"{me} -> {name} ({path.relative_to(ROOT)}:{node.lineno}: "
                                 f"{TIERS[tier_of(me)][0]} may not import {TIERS[tier_of(name)][0]})")
    return found


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dry-run", action="store_true", help="print what would be done, change nothing")
    args = ap.parse_args(argv)
    dry = args.dry_run
    clash = sorted(f"{n} (new) is also a name {p} (old) binds" for n in NEW for p in [n.rpartition(".")[0]]
                   if p in OLD and n not in OLD and n.rpartition(".")[2] in bound_names(p))
    if clash:
        print("error: new module names that an old module binds:\n  " + "\n  ".join(clash))
        return 2
    print(f"retree: {len(MAPPING)} modules mapped ({sum(k != v for k, v in MAPPING.items())} move)")
    moved = move_files(dry)
    print(f"moved or created: {moved}")
    n = rewrite_all(dry)
    print(f"files rewritten: {n}")
    left = unmapped()
    if left:
        print("modules the mapping does not name (left in place; add them to MAPPING):")
        print("\n".join(f"  network/{m}" for m in left))
    up = [] if dry else upward_imports()
    if up:
        print(f"{len(up)} import(s) up a tier:")
        print("\n".join(f"  {u}" for u in up))
    if not (moved or n):
        print("nothing to do: the tree is already retreed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
