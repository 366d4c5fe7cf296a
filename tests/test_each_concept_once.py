"""Each concept once (issue 27): the distance model's Jacobian (the unit vector ``u = (H - T)/rho``
of a difference over its length) has one numpy copy, :func:`multilat.network.model.distance.line_of_sight`,
and one inline copy per compiled kernel; the S-transformation ``S = I - G (EᵀG)⁻¹Eᵀ`` one,
:func:`multilat.network.model.datum.s_transform` (with its coefficients ``s_coefficients``). A new copy
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
KERNEL_FILES = {"adjust/solve/_sparse_kernels.py", "montecarlo/_batched_numba.py", "adjust/_covariance_kernels.py", "montecarlo/general/_frozen_numba.py"}

#: the homes: ``file:function`` holding the one numpy copy of each concept
HOME = {
    "jacobian": {"model/distance.py:line_of_sight"},
    "s_transform": {"model/datum.py:s_coefficients"},
}

#: copies found today outside the homes, and why each stays (this list only shrinks)
KNOWN = {
    "jacobian": {
        "model/datum.py:frame_axes": "the 3-2-1 frame's x axis: a frame, not a distance",
        "model/angle_rows.py:initial_orientations": "an angle's starting direction (angles, not distances)",
    },
    "s_transform": {
        "model/angle_rows.py:orientation_covariance": "the orientations' rows (EᵀG)⁻¹ of an S-transform that "
                                                "needs no n x n matrix",
        "montecarlo/trial_datum.py:apply": "the Monte Carlo trials' rigid fit (Gᵀ G)⁻¹ (a projection, per trial)",
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
    assert not bad, ("use multilat.network.model.distance.line_of_sight / range_m and "
                     "multilat.network.model.datum.s_transform / s_coefficients:\n" + "\n".join(bad))


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
    from multilat.network.model.datum import helmert_basis, s_transform
    from multilat.network.model.distance import line_of_sight

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

#: the one home of generated networks: :func:`multilat.network.synthetic.generator.synthetic_network`
GENERATOR_HOME = "network/synthetic/generator.py"

#: functions outside the home that draw random numbers and build observations, and why each stays
#: (noise on a given configuration, not a generated network; this list only shrinks)
GENERATOR_KNOWN = {
    "network/adjust/distance/costs.py:compare_costs_mc": "noise on the given network of the cost study",
    "network/montecarlo/simulate.py:simulate": "the §4.4 study: noise on a fixed configuration",
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
    assert not bad, "generate networks with multilat.network.synthetic.generator.synthetic_network:\n" + "\n".join(bad)
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


# ------------------------------------------------------------------------------ one parameter layout (issue 27 item 1)
#: the one home of column arithmetic: :class:`multilat.network.model.parameter_layout.ParameterLayout`
LAYOUT_HOME = "model/parameter_layout.py"

#: a parameter's width: 3 (x, y, z), 4 (with the offset), 5 (and the scale), ``Q``
_WIDTHS = {3, 4, 5}
#: what a width multiplies in column arithmetic: a count or an index of stations, targets, heads, points
#: (the distance path's names, then the general layer's: ``m``/``me`` eliminated points, ``lo``/``hi`` a
#: range of them, ``pr`` a row's point, ``order`` points in an order, ``n_points``)
_OWNERS = {"s", "t", "h", "i", "j", "q", "n_stations", "n_targets", "n_heads", "si", "ti", "hs", "il",
           "station_index", "target_index", "head_index", "angle_station", "angle_target", "control_point",
           "slot", "lead_of_head", "bar_a", "bar_b",
           "m", "me", "lo", "hi", "pr", "order", "n_points"}

#: functions outside the one layout (model, batched, batched_coupled, solve/ and its kernels, design/fast,
#: design/blocked, the general layer's model/layout.py and kinds: none left) that still compute a column
#: or a count of columns, and why each stays; this list only shrinks
_ELIMINATED = "the general sparse back end's elimination: 3 rows per eliminated point in its own E system"
LAYOUT_KNOWN = {
    "adjust/general/sparse.py:_reduce": _ELIMINATED,
    "adjust/general/sparse.py:cofactor": _ELIMINATED,
    "adjust/general/sparse.py:row_parts": _ELIMINATED,
    "adjust/general/sparse.py:ginv": _ELIMINATED,
    "adjust/general/reliability.py:__init__": _ELIMINATED + " (external reliability)",
    "adjust/general/reliability.py:shifts": _ELIMINATED + " (external reliability)",
    "adjust/general/reliability.py:_others": _ELIMINATED + " (external reliability)",
    "montecarlo/general/propagate_blocks.py:ginv": _ELIMINATED + " (the Monte Carlo's frozen copy)",
    "adjust/distance/reliability.py:_others": "external reliability on the adjustment's covariance",
    "io/interop/gama_adjusted.py:_covariance": "GNU Gama's covariance rows (its layout)",
    "adjust/distance/adjust_steps.py:coupling_results": "the couplings' prior values per control point (couplings' layout)",
    "adjust/distance/adjust_steps.py:start_as_partial": "a count of unknowns (the redundancy of a start)",
    "model/angle_rows.py:orientation_covariance": "the orientations' rows after the targets (angle_rows)",
    "model/angle_rows.py:angle_results": "the orientations' rows after the targets (angle_rows)",
    "model/angle_rows.py:whitened": "the angles' Jacobian in the adjustment layout (angle_rows)",
    "adjust/distance/costs.py:_design": "the cost study's own Jacobian (not the adjustment)",
    "adjust/distance/costs.py:compare_costs_linear": "the cost study's own Jacobian (not the adjustment)",
    "model/couplings.py:resolve": "the couplings' columns in the adjustment layout",
    "model/datum.py:datum_matrices": "the datum's G and E in the adjustment layout",
    "adjust/approximate/initial_refine.py:refine": "the starting values' own least squares (heads, then targets)",
    "adjust/approximate/initial_refine.py:unpack": "the starting values' own least squares (heads, then targets)",
    "adjust/approximate/initial_refine.py:jac": "the starting values' own least squares (heads, then targets)",
    "io/interop/gama_adjusted.py:interpoint_distance_std_m": "GNU Gama's covariance rows (its layout)",
    "adjust/distance/reliability.py:_shifts_dense": "external reliability on the adjustment's covariance",
    "adjust/distance/reliability.py:shifts": "external reliability on the adjustment's covariance",
    "adjust/distance/reliability.py:__init__": "external reliability on the adjustment's covariance",
    "adjust/distance/result.py:build_result": "the result's covariance blocks (adjustment layout)",
    "adjust/distance/result.py:_param_rows": "the result's covariance blocks (adjustment layout)",
    "adjust/distance/result.py:offset_correlations": "the result's covariance blocks (adjustment layout)",
    "adjust/approximate/search.py:_dof": "a count of unknowns",
    "adjust/distance/solvability.py:count_unknowns": "a count of unknowns",
    "adjust/distance/solvability.py:check_structure": "a count of unknowns",
    "synthetic/generator.py:_well_conditioned": "a count of unknowns (a drawn network's redundancy)",
    "adjust/distance/variance_components.py:_hat": "the variance components' hat matrix (adjustment layout)",
}


def _layout_lines(nodes) -> list[int]:
    """Lines of ``width * owner`` (``5 * i``, ``Q * station_index``, ``3 * s``, ``4 * np.arange(s)``) or
    ``reshape(..., Q)`` among one function's nodes."""
    def owner(n):
        while isinstance(n, ast.Subscript):
            n = n.value
        if isinstance(n, ast.Call) and getattr(n.func, "attr", getattr(n.func, "id", None)) == "arange":
            return bool(n.args) and owner(n.args[0])
        return (isinstance(n, ast.Name) and n.id in _OWNERS) or (isinstance(n, ast.Attribute) and n.attr in _OWNERS)

    def width(n):
        return ((isinstance(n, ast.Constant) and type(n.value) is int and n.value in _WIDTHS)
                or (isinstance(n, ast.Name) and n.id == "Q") or (isinstance(n, ast.Attribute) and n.attr == "Q"))

    out = set()
    for n in nodes:
        if isinstance(n, ast.BinOp) and isinstance(n.op, ast.Mult) and (
                (width(n.left) and owner(n.right)) or (width(n.right) and owner(n.left))):
            out.add(n.lineno)
        if _called(n, {"reshape"}) and any(isinstance(a, ast.Name) and a.id == "Q" for a in n.args):
            out.add(n.lineno)
    return sorted(out)


def layout_copies(root: Path = NETWORK) -> dict[str, list[int]]:
    """``{"file:function": [lines]}`` of column arithmetic under ``root``, every layer (the general one's
    :class:`multilat.network.model.layout.Layout` is built on the one layout)."""
    found = {}
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if rel == LAYOUT_HOME:
            continue
        for f, own in _functions(ast.parse(path.read_text("utf-8"), str(path))):
            lines = _layout_lines(own)
            if lines:
                found[f"{rel}:{f.name}"] = lines
    return found


def test_one_parameter_layout():
    """No column arithmetic outside ``ParameterLayout`` and the known list (which only shrinks)."""
    found = layout_copies()
    bad = [f"network/{k} lines {v}" for k, v in found.items() if k not in LAYOUT_KNOWN]
    assert not bad, ("ask multilat.network.model.parameter_layout.ParameterLayout for the columns:\n" + "\n".join(bad))
    stale = [k for k in LAYOUT_KNOWN if k not in found]
    assert not stale, "merged, remove from LAYOUT_KNOWN:\n" + "\n".join(stale)


@pytest.mark.parametrize("text", [
    "def f(J, si, c):\n    J[0, Q * si + c] = 1.0\n",
    "def f(J, s, ti, c):\n    J[0, 4 * s + 3 * ti + c] = 1.0\n",
    "def f(x, s):\n    return x[:, 3 * s:]\n",
    "def f(dg):\n    return dg.reshape(-1, Q)\n",
    "def f(self, x):\n    return x[4 * np.arange(self.n_stations)]\n",
    "def f(x, lo, hi):\n    return x[3 * lo:3 * hi]\n",                       # the general layer's names
    "def f(m):\n    return np.arange(3 * m).reshape(m, 3)\n",
])
def test_a_new_layout_copy_is_found(tmp_path, text):
    (tmp_path / "x.py").write_text(text)
    assert list(layout_copies(tmp_path)) == ["x.py:f"]


def test_shapes_are_not_layouts(tmp_path):
    (tmp_path / "x.py").write_text("def f(m, n, t):\n    a = np.zeros((m, 3))\n    return a.reshape(t, 3), 3 * n\n")
    assert layout_copies(tmp_path) == {}


def test_the_layout_against_its_definition():
    """The columns against the layouts written out by hand (the docstrings of model, batched and
    batched_coupled): 2 stations of one head and a third, 2 targets, one oriented station."""
    from multilat.network.model.parameter_layout import XYZ, ParameterLayout

    adj = ParameterLayout.adjustment(3, 2)
    assert adj.n == 21 and adj.station_block().tolist() == [[0, 1, 2, 3, 4], [5, 6, 7, 8, 9], [10, 11, 12, 13, 14]]
    assert adj.target_block().tolist() == [[15, 16, 17], [18, 19, 20]]
    assert adj.names(["A", "B", "C"], ["P", "Q"])[8] == "offset:B" and adj.names(["A"] * 3, ["P", "Q"])[19] == "y:Q"
    # a head's offset and scale are named by the head (the general layer's ``offset:I``)
    assert ParameterLayout.adjustment(3).names(["A", "B", "C"], head_ids=["H", "H", "C"])[:10] == [
        "x:A", "y:A", "z:A", "offset:H", "scale:H", "x:B", "y:B", "z:B", "offset:H", "scale:H"]
    bat = ParameterLayout.batched(3, 2)
    assert bat.station_block(XYZ).tolist() == [[0, 1, 2], [3, 4, 5], [6, 7, 8]]
    assert bat.station_columns("offset").tolist() == [9, 10, 11] and bat.target_block()[1].tolist() == [15, 16, 17]
    cpl = ParameterLayout.coupled(3, 2, [0, 0, 1], n_oriented=1)      # [3s, h offsets, h scales, 3t, 3 orientation]
    assert cpl.n == 9 + 2 + 2 + 6 + 3
    assert cpl.station_columns("offset").tolist() == [9, 9, 10] and cpl.station_columns("scale").tolist() == [11, 11, 12]
    assert cpl.block("orientation").tolist() == [[19, 20, 21]]
    assert bat.index_in(cpl).tolist() == list(range(9)) + [9, 9, 10] + list(range(13, 19))
    assert ParameterLayout.station_system(3).index_in(adj).tolist() == [0, 1, 2, 3, 5, 6, 7, 8, 10, 11, 12, 13]
    sys3 = ParameterLayout.station_system(3, 2, offsets=False)
    assert sys3.index_in(adj).tolist() == [0, 1, 2, 5, 6, 7, 10, 11, 12, 15, 16, 17, 18, 19, 20]
    src = adj.tie_source([0, 0, 1])                                   # B's offset and scale read A's
    assert src[8] == 3 and src[9] == 4 and src[13] == 13 and src[5] == 5
    g = np.arange(15.0).reshape(15, 1)                                # rows of the 5 stacked points
    rows = bat.datum_rows(g)
    assert rows[:9, 0].tolist() == list(range(9)) and not rows[9:12].any() and rows[12:, 0].tolist() == list(range(9, 15))
    assert (bat.point_rows(rows) == g).all()
    free = cpl.free_mask(head={"scale": [False, True]}, target={"z": [True, False]})
    assert np.flatnonzero(~free).tolist() == [11, 18]


def test_the_general_layer_is_scanned(tmp_path):
    """The scan reads every layer: a copy under ``adjust/general`` or ``model/kinds`` is found (the old
    scan skipped ``general/``, a path the re-tree emptied)."""
    for sub in ("adjust/general", "model/kinds", "montecarlo/general"):
        (tmp_path / sub).mkdir(parents=True)
        (tmp_path / sub / "x.py").write_text("def f(x, m):\n    return x[:3 * m]\n")
    assert sorted(layout_copies(tmp_path)) == ["adjust/general/x.py:f", "model/kinds/x.py:f",
                                               "montecarlo/general/x.py:f"]


def test_the_general_layout_is_the_one_layout():
    """The general layer's :class:`Layout` against its definition written out by hand: 3 points (P2
    held), then an instrument's offset and scale per registration, a direction set's orientation; its
    blocks are the one layout's (columns, names, reduced columns from ``ParameterLayout``)."""
    from multilat.network.model.layout import Layout
    from multilat.network.model.parameter_layout import ParameterLayout
    from multilat.network.model.points import FIXED, FREE, PointSet

    pts = PointSet.build(["P1", "P2", "P3"], np.arange(9.0).reshape(3, 3), status=[FREE, FIXED, FREE])
    lay = Layout(pts)
    assert lay.point_cols.tolist() == [[0, 1, 2], [3, 4, 5], [6, 7, 8]] and lay.n == 9
    assert lay.columns("offset", ["I1", "I2", "I1"]).tolist() == [9, 10, 9]
    assert lay.columns("scale", ["I2"], free=False).tolist() == [11]
    assert lay.add("orientation:S") == 12 and lay.add("offset:I2") == 10 and lay.column("scale:I2") == 11
    assert lay.names == ["x:P1", "y:P1", "z:P1", "x:P2", "y:P2", "z:P2", "x:P3", "y:P3", "z:P3",
                         "offset:I1", "offset:I2", "scale:I2", "orientation:S"]
    assert lay.reduced.tolist() == [0, 1, 2, -1, -1, -1, 3, 4, 5, 6, 7, -1, 8, -1]
    assert lay.initial().tolist() == list(range(9)) + [0.0] * 4
    # the same columns from the one layout's blocks; a held offset registered free is refused
    pl = ParameterLayout.general(3)
    assert lay.params.n == lay.n and lay.params.point_columns().tolist() == pl.point_columns().tolist()
    assert [(b.kind, b.count, b.start) for b in lay.params.blocks] == [("point", 3, 0), ("offset", 2, 9),
                                                                     ("scale", 1, 11), ("orientation", 1, 12)]
    with pytest.raises(Exception, match="registered both free and held"):
        lay.columns("scale", ["I2"])
