"""Constants typed once (issue 27): χ²₃(0.95) comes from ``network.statistics`` (scipy), the default
distance σ of 4.7 µm from ``network.sigma_source``; a numeric literal copy of either anywhere else in the
package fails here, named ``file:line``."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "src" / "multilat"

#: value -> (what it is, the one module allowed to hold it as a literal, or None: computed, never typed)
WATCHED = {
    "chi2_3_95": (7.814727903251178, None),
    "sqrt_chi2_3_95": (math.sqrt(7.814727903251178), None),
    "default_sigma_m": (4.7e-6, "network/model/sigma_source.py"),
}


def literal_copies(root: Path = PKG) -> list[str]:
    """``file:line name value`` of every float literal within 1e-9 (relative) of a watched value,
    outside its home module."""
    found = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        for node in ast.walk(ast.parse(path.read_text("utf-8"), str(path))):
            if isinstance(node, ast.Constant) and isinstance(node.value, float):
                for name, (value, home) in WATCHED.items():
                    if math.isclose(node.value, value, rel_tol=1e-9) and rel != home:
                        found.append(f"{rel}:{node.lineno} {name} {node.value!r}")
    return found


def test_no_literal_copy_of_a_shared_constant():
    bad = literal_copies()
    assert not bad, "use multilat.network.adjust.statistics.CHI2_3_95 / sigma_source.DEFAULT_SIGMA_M:\n" + "\n".join(bad)


@pytest.mark.parametrize("text", ["K = 7.814727903251178\n", "k = 2.7954834829151074\n",
                                  "def f(sigma_m=4.7e-06):\n    return sigma_m\n"])
def test_a_new_copy_is_found(tmp_path, text):
    (tmp_path / "network" / "model").mkdir(parents=True)
    (tmp_path / "network" / "model" / "sigma_source.py").write_text("DEFAULT_SIGMA_M = 4.7e-6\n")
    (tmp_path / "x.py").write_text(text)
    assert [s.split()[0] for s in literal_copies(tmp_path)] == ["x.py:1"]


def test_the_constants_are_the_published_values():
    """χ²₃(0.95) against scipy.stats (the independent value, to 2 ulp: gammaincinv and the chi2
    quantile may round differently); the default σ is the seed paper's 4.7 µm (§3.4, §4.4)."""
    from scipy import stats

    from multilat.network.montecarlo.propagate import chi2_3_95
    from multilat.network.model.sigma_source import DEFAULT_SIGMA_M
    from multilat.network.adjust.statistics import CHI2_3_95

    assert CHI2_3_95 == pytest.approx(stats.chi2.ppf(0.95, 3), rel=4e-16)
    assert chi2_3_95 == CHI2_3_95
    assert DEFAULT_SIGMA_M == 4.7e-6
