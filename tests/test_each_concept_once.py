"""Each concept once (issue 27): the distance model's Jacobian (the unit vector ``u = (H - T)/rho``
of a difference over its length) has one numpy copy, :func:`multilat.network.model.line_of_sight`,
and one inline copy per compiled kernel; the S-transformation ``S = I - G (EᵀG)⁻¹Eᵀ`` one,
:func:`multilat.network.datum.s_transform` (with its coefficients ``s_coefficients``). A new copy
anywhere in ``network/`` fails here, named ``file:line function``; the places left as they are,
each with its reason, are listed in ``KNOWN`` and may only shrink (docs/architecture.md, "Each
concept once").

The Jacobian is found in the syntax tree, whatever the names: a division whose numerator is a
difference (``a - b``, or a name bound to one in the same function) and whose denominator is a
length (``sqrt``/``norm``/``hypot``/``range_m`` of anything, a name bound to one, indexed or guarded
by ``np.where``). The S-transformation is found in the text: an inverse of ``Xᵀ Y`` or a solve
with it (``solve(E.T @ G, ...)``, ``inv(E.T @ G)``, or of a name bound to ``E.T @ G``)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest

NETWORK = Path(__file__).resolve().parents[1] / "src" / "multilat" / "network"

#: compiled kernels: each @njit function may keep its own inline copy of the Jacobian
KERNEL_FILES = {"_sparse_kernels.py", "_batched_numba.py", "_covariance_kernels.py", "general/_frozen_numba.py"}

#: the homes: ``file:function`` holding the one numpy copy of each concept
HOME = {
    "jacobian": {"model.py:line_of_sight"},
    "s_transform": {"datum.py:s_coefficients"},
}

#: copies found today outside the homes, and why each stays (this list only shrinks)
KNOWN = {
    "jacobian": {
        "datum.py:frame_axes": "the 3-2-1 frame's x axis: a frame, not a distance",
        "angle_rows.py:initial_orientations": "an angle's starting direction (angles, not distances)",
        "costs.py:compare_costs_linear": "a scale bar's direction in the cost study (not the adjustment)",
        "couplings.py:whitened": "the scale bars' rows of the adjustment: a point-to-point length",
        "large.py:refit_point": "the large-network generator's refit (multilat.synthetic, issue 27 item 4)",
        "propagate_summary.py:linear_std": "the gradient of a reported length (a result, not the model)",
        "simulate.py:linear_prediction": "a bar's direction in the length-error prediction",
        "general/approximate/frames.py:orient": "the general layer (issue 26), not in this change",
        "general/approximate/search.py:jac": "the general layer (issue 26), not in this change",
    },
    "s_transform": {
        "angle_rows.py:orientation_covariance": "the orientations' rows (EᵀG)⁻¹ of an S-transform that "
                                                "needs no n x n matrix",
        "trial_datum.py:apply": "the Monte Carlo trials' rigid fit (Gᵀ G)⁻¹ (a projection, per trial)",
    },
}

_LENGTH_CALLS = {"sqrt", "norm", "hypot", "range_m"}
_S_TEXT = re.compile(r"\b(solve|inv)\(\s*\w+\.T\s*@\s*\w+")
_S_NAMED = re.compile(r"\s*(\w+)\s*=\s*\w+\.T\s*@\s*\w+\s*(#.*)?$")


def _called(node, names) -> bool:
    f = node.func if isinstance(node, ast.Call) else None
    return f is not None and (getattr(f, "attr", None) in names or getattr(f, "id", None) in names)


def _functions(tree):
    """(function node, its own nodes) for every function, nested ones apart."""
    for f in ast.walk(tree):
        if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef)):
            own = []
            stack = list(f.body)
            while stack:
                n = stack.pop()
                if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                    continue
                own.append(n)
                stack.extend(ast.iter_child_nodes(n))
            yield f, own


def _jacobian_lines(nodes) -> list[int]:
    """Lines of ``difference / length`` among one function's nodes."""
    lengths, diffs = set(), set()

    def base(n):
        while isinstance(n, ast.Subscript):
            n = n.value
        return n

    def is_diff(n):
        n = base(n)
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute):      # (a - b).transpose(...)
            n = n.func.value
        return (isinstance(n, ast.BinOp) and isinstance(n.op, ast.Sub)) or (isinstance(n, ast.Name)
                                                                             and n.id in diffs)

    def is_length(n):
        n = base(n)
        if _called(n, {"where"}):
            return any(is_length(a) for a in n.args[1:])
        return _called(n, _LENGTH_CALLS) or (isinstance(n, ast.Name) and n.id in lengths)

    def pairs(n):                                        # (target name, value) of one assignment
        for t in n.targets:
            if isinstance(t, ast.Name):
                yield t.id, n.value
            elif isinstance(t, ast.Tuple) and isinstance(n.value, ast.Tuple) and len(t.elts) == len(n.value.elts):
                yield from ((a.id, v) for a, v in zip(t.elts, n.value.elts) if isinstance(a, ast.Name))

    for _ in range(2):                                   # names bound from names bound before
        for n in nodes:
            if isinstance(n, ast.Assign):
                for name, value in pairs(n):
                    if is_length(value):
                        lengths.add(name)
                    if is_diff(value):
                        diffs.add(name)
    return sorted({n.lineno for n in nodes if isinstance(n, ast.BinOp) and isinstance(n.op, ast.Div)
                   and is_diff(n.left) and is_length(n.right)})


def copies(root: Path = NETWORK) -> dict[str, dict[str, list[int]]]:
    """``{concept: {"file:function": [lines]}}`` of every copy under ``root``."""
    found = {"jacobian": {}, "s_transform": {}}
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        text = path.read_text("utf-8")
        lines = text.splitlines()
        for f, own in _functions(ast.parse(text, str(path))):
            key = f"{rel}:{f.name}"
            jl = _jacobian_lines(own)
            if jl:
                found["jacobian"][key] = jl
            inner = [(n.lineno, n.end_lineno) for n in ast.walk(f)
                     if n is not f and isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
            body = [k for k in range(f.lineno, f.end_lineno + 1) if not any(lo <= k <= hi for lo, hi in inner)]
            named = {m.group(1) for k in body for m in [_S_NAMED.match(lines[k - 1])] if m}   # etg = E.T @ G
            sl = [k for k in body if _S_TEXT.search(lines[k - 1])
                  or any(re.search(rf"\b(solve|inv)\(\s*{v}\b", lines[k - 1]) for v in named)]
            if sl:
                found["s_transform"][key] = sl
    return found


def unexpected(found) -> list[str]:
    """The copies outside the homes, the compiled kernels and ``KNOWN``."""
    bad = []
    for concept, where in found.items():
        for key, lines in where.items():
            rel = key.split(":")[0]
            if key in HOME[concept] or key in KNOWN[concept] or (concept == "jacobian" and rel in KERNEL_FILES):
                continue
            bad.append(f"{concept}: network/{key} lines {lines}")
    return bad


def test_no_new_copy_of_the_distance_jacobian_or_the_s_transformation():
    bad = unexpected(copies())
    assert not bad, ("use multilat.network.model.line_of_sight / range_m and "
                     "multilat.network.datum.s_transform / s_coefficients:\n" + "\n".join(bad))


def test_the_known_list_only_shrinks():
    """A ``KNOWN`` entry that no longer holds a copy is removed from the list (it was merged)."""
    found = copies()
    stale = [f"{c}: {k}" for c, keys in KNOWN.items() for k in keys if k not in found[c]]
    assert not stale, "merged, remove from KNOWN:\n" + "\n".join(stale)


def test_one_copy_per_compiled_kernel():
    """Each compiled kernel holds at most one (inline) Jacobian: a function may divide its own
    ``dx, dy, dz`` by ``rho``, the lines of one copy."""
    found = copies()["jacobian"]
    for key, lines in found.items():
        if key.split(":")[0] in KERNEL_FILES:
            assert max(lines) - min(lines) <= 3, (key, lines)


@pytest.mark.parametrize("text, concept", [
    ("def f(H, T, si, ti):\n    d = H[si] - T[ti]\n    r = np.linalg.norm(d, axis=1)\n    return d / r[:, None]\n",
     "jacobian"),
    ("def f(a, b):\n    return (a - b) / np.sqrt(((a - b) ** 2).sum())\n", "jacobian"),
    ("def f(h, t):\n    dx = h[0] - t[0]\n    rho = math.sqrt(dx * dx)\n    return dx / rho\n", "jacobian"),
    ("def f(G, E, n):\n    return np.eye(n) - G @ np.linalg.solve(E.T @ G, E.T)\n", "s_transform"),
    ("def f(g):\n    return g @ np.linalg.inv(g.T @ g)\n", "s_transform"),
    ("def f(G, E):\n    etg = E.T @ G\n    return np.linalg.solve(etg, E.T)\n", "s_transform"),
])
def test_a_new_copy_is_found(tmp_path, text, concept):
    (tmp_path / "x.py").write_text(text)
    found = copies(tmp_path)
    assert list(found[concept]) == ["x.py:f"]
    assert unexpected(found) == [f"{concept}: network/x.py:f lines {found[concept]['x.py:f']}"]


def test_the_homes_are_what_they_say():
    """The one copies against independent values: ``u`` is a unit vector along ``H - T`` with ``rho``
    its length (``np.hypot``, a second method), on random differences with a leading trial axis;
    ``S`` is the projector onto ``Eᵀ dx = 0`` along the rigid motions: ``S² = S``, ``Eᵀ S = 0``,
    ``S G = 0`` (to 1e-12: solved in double precision, conditioned by the 10 m network)."""
    from multilat.network.datum import helmert_basis, s_transform
    from multilat.network.model import line_of_sight

    rng = np.random.default_rng(27)
    d = rng.normal(size=(4, 50, 3)) * 10.0
    rho, u = line_of_sight(d)
    np.testing.assert_allclose(rho, np.hypot(np.hypot(d[..., 0], d[..., 1]), d[..., 2]), rtol=4e-16)
    np.testing.assert_allclose(u * rho[..., None], d, rtol=1e-15, atol=1e-14)
    assert line_of_sight(np.zeros((1, 3)), floor_m=1e-12)[1].tolist() == [[0.0, 0.0, 0.0]]
    x = rng.normal(size=(7, 3)) * 10.0
    G = helmert_basis(x)
    E = np.zeros_like(G)
    E[:9] = G[:9]                                    # inner constraints over the first 3 points
    S = s_transform(G, E)
    assert np.abs(S @ S - S).max() < 1e-12 and np.abs(E.T @ S).max() < 1e-12 and np.abs(S @ G).max() < 1e-12


# ------------------------------------------------------------------------------ one generator (issue 27 item 4)
PACKAGE = NETWORK.parent

#: the one home of generated networks: :func:`multilat.network.synthetic.synthetic_network`
GENERATOR_HOME = "network/synthetic.py"

#: functions outside the home that draw random numbers and build observations, and why each stays
#: (noise on a given configuration, not a generated network; this list only shrinks)
GENERATOR_KNOWN = {
    "network/costs.py:compare_costs_mc": "noise on the given network of the cost study",
    "network/simulate.py:simulate": "the §4.4 study: noise on a fixed configuration",
    "report/network_demo.py:_one_dataset": "the demo's noisy distances of the paper's configuration",
}

_DRAWS = {"uniform", "normal", "random", "integers", "choice", "standard_normal", "permutation"}


def generators(root: Path = PACKAGE) -> dict[str, int]:
    """``{"file:function": line}`` of every function under ``root`` that draws random numbers (a
    Generator method) and builds :class:`Observations` or a ``SyntheticNetwork``: a network generator."""
    found = {}
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        for f in ast.walk(ast.parse(path.read_text("utf-8"), str(path))):
            if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef)):
                called = {getattr(c.func, "attr", getattr(c.func, "id", None))
                          for c in ast.walk(f) if isinstance(c, ast.Call)}
                if called & _DRAWS and called & {"Observations", "from_labels", "SyntheticNetwork"}:
                    found[f"{rel}:{f.name}"] = f.lineno
    return found


def test_the_package_has_one_network_generator():
    found = generators()
    bad = [f"{k} (line {line})" for k, line in found.items()
           if not k.startswith(GENERATOR_HOME + ":") and k not in GENERATOR_KNOWN]
    assert not bad, "generate networks with multilat.network.synthetic.synthetic_network:\n" + "\n".join(bad)
    stale = [k for k in GENERATOR_KNOWN if k not in found]
    assert not stale, "merged, remove from GENERATOR_KNOWN:\n" + "\n".join(stale)
    public = [p.relative_to(PACKAGE).as_posix() for p in PACKAGE.rglob("*.py")
              if any(ln.startswith(("def random_network(", "def synthetic_network(", "def sequential_network(",
                                    "def mixed_network("))
                     for ln in p.read_text("utf-8").splitlines())]
    assert public == [GENERATOR_HOME]


def test_a_new_generator_is_found(tmp_path):
    (tmp_path / "x.py").write_text("def f(g):\n    H = g.uniform(size=(4, 3))\n    return Observations(H)\n"
                                   "def n(g, obs):\n    return g.normal(size=3)\n")
    assert generators(tmp_path) == {"x.py:f": 1}
