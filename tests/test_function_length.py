"""No function over 80 body lines in the package (the developers' guide; issue 27 item 5), checked
on the source with ``ast``.

The body runs from the first statement after the docstring to the last line of the last statement.
Every ``def`` counts on its own (a nested function's lines count for it and for its host). Compiled
kernels are exempt (numba wants one flat loop nest): functions decorated with ``njit``, ``jit`` or
``vectorize``, and every function of a kernel module (``_*numba*``, ``*_kernels*``).

:data:`ALLOWED` names the functions not yet split, each with its body length today. The list only
shrinks: a listed function that grows fails, and so does one that has been split (or removed) and is
still listed.
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
PKG = SRC / "multilat"
MAX_FUNCTION_LINES = 80
KERNEL_DECORATORS = {"njit", "jit", "vectorize", "guvectorize"}

#: ``"path/under/src:qualified.name"`` -> body lines today. Only shrinks (split one, delete its line).
ALLOWED: dict[str, int] = {
    "multilat/cli/budget_cmd.py:budget_command": 84,
}


def _is_kernel_module(path: Path) -> bool:
    return (path.name.startswith("_") and "numba" in path.stem) or "_kernels" in path.stem


def _decorator_name(node: ast.expr) -> str:
    if isinstance(node, ast.Call):
        node = node.func
    if isinstance(node, ast.Attribute):
        return node.attr
    return node.id if isinstance(node, ast.Name) else ""


def body_lines(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """Lines from the first statement after the docstring to the end of the last statement."""
    body = node.body[1:] if ast.get_docstring(node) is not None else node.body
    return body[-1].end_lineno - body[0].lineno + 1 if body else 0


def function_lengths(pkg: Path = PKG):
    """``{"path:qualname": body lines}`` of every function of the package outside compiled kernels."""
    out = {}
    for path in sorted(pkg.rglob("*.py")):
        if _is_kernel_module(path):
            continue
        rel = path.relative_to(pkg.parent).as_posix()

        def visit(node, prefix):
            for child in ast.iter_child_nodes(node):
                if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    name = prefix + child.name
                    if not any(_decorator_name(d) in KERNEL_DECORATORS for d in child.decorator_list):
                        out[f"{rel}:{name}"] = body_lines(child)
                    visit(child, name + ".")
                elif isinstance(child, ast.ClassDef):
                    visit(child, prefix + child.name + ".")
                else:
                    visit(child, prefix)

        visit(ast.parse(path.read_text("utf-8"), str(path)), "")
    return out


def too_long(lengths: dict[str, int], allowed: dict[str, int] = ALLOWED) -> list[str]:
    """Every breach: a function over the limit and not listed, a listed one that grew, a listed one
    that no longer needs the list."""
    bad = []
    for name, n in sorted(lengths.items()):
        if n > MAX_FUNCTION_LINES and name not in allowed:
            bad.append(f"{name}: {n} body lines > {MAX_FUNCTION_LINES} (split it)")
        elif name in allowed and n > allowed[name]:
            bad.append(f"{name}: {n} body lines, grown past its allowance {allowed[name]} (split it)")
    for name, n in sorted(allowed.items()):
        if lengths.get(name, 0) <= MAX_FUNCTION_LINES:
            bad.append(f"{name}: no longer over {MAX_FUNCTION_LINES} lines (or gone): delete it from ALLOWED")
    return bad


def test_no_function_over_80_body_lines():
    bad = too_long(function_lengths())
    assert not bad, f"{len(bad)} function length breach(es):\n" + "\n".join(bad)


def test_the_count_excludes_the_docstring_and_kernels(tmp_path):
    """Mutation: a module with a 81-line function, an 80-line one under a docstring, a compiled kernel
    and a kernel module; only the first is over the limit."""
    pkg = tmp_path / "multilat"
    pkg.mkdir()
    body = "".join(f"    x{i} = {i}\n" for i in range(81))
    (pkg / "m.py").write_text(
        "from numba import njit\n\n"
        f"def long_one():\n{body}\n"
        f"def just_fits():\n    '''doc\n    string'''\n{body[: body.rindex('    x80')]}\n"
        f"class C:\n    def method(self):\n{body.replace('    x', '        x')}\n"
        f"@njit(cache=True)\ndef kernel():\n{body}\n", "utf-8")
    (pkg / "_kernels_x.py").write_text(f"def flat():\n{body}\n", "utf-8")
    lengths = function_lengths(pkg)
    assert lengths == {"multilat/m.py:long_one": 81, "multilat/m.py:just_fits": 80,
                       "multilat/m.py:C.method": 81}, lengths
    assert too_long(lengths, {}) == [
        "multilat/m.py:C.method: 81 body lines > 80 (split it)",
        "multilat/m.py:long_one: 81 body lines > 80 (split it)"]


def test_the_allowance_only_shrinks():
    """A listed function that grows is named; one split below the limit but still listed is named."""
    lengths = {"a.py:f": 95, "b.py:g": 60}
    assert too_long(lengths, {"a.py:f": 95}) == []
    assert too_long(lengths, {"a.py:f": 94}) == [
        "a.py:f: 95 body lines, grown past its allowance 94 (split it)"]
    assert too_long(lengths, {"a.py:f": 95, "b.py:g": 90}) == [
        "b.py:g: no longer over 80 lines (or gone): delete it from ALLOWED"]
    assert too_long(lengths, {"a.py:f": 95, "c.py:h": 90}) == [
        "c.py:h: no longer over 80 lines (or gone): delete it from ALLOWED"]
