"""Issue 29, "small jobs do not pay for large ones": a network the dense path solves (the small volume,
4 heads x 14 targets) is adjusted by the whole ``multilat adjust --json`` command without importing
numba, scipy.sparse, Dask or matplotlib (their import alone costs ~0.1-0.5 s of a ~0.8 s command).
Not a timed test: it checks which modules the command loaded. The station-target graph's components,
which the structure checks used scipy.sparse.csgraph for, are checked against it."""

import json
import os
import runpy
from types import SimpleNamespace
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from multilat.network.adjust.distance import solvability
from multilat.network.adjust.distance.solvability import graph_components

ROOT = Path(__file__).resolve().parents[1]
SMALL = ROOT / "examples" / "network" / "small_volume_obs.csv"
#: the heavy packages a small dense job must not load (issue 29, "Decisions")
HEAVY = ("numba", "scipy.sparse", "dask", "distributed", "matplotlib")
#: multilat's own modules a small ``adjust`` of an observation file does not need (issue 29): the other
#: commands' modules (registered on demand, ``multilat.cli.load_commands``), the demo's report, the
#: raw-reading pipeline, the LBB, the Monte Carlo engine, the design and the general layer's solvers
UNNEEDED = ("multilat.cli.air_cmd", "multilat.cli.budget_cmd", "multilat.cli.simulate_cmd",
            "multilat.cli.lbb_cmd", "multilat.cli.campaign_cmd", "multilat.cli.propagate_cmd",
            "multilat.cli.demo_cmd", "multilat.cli.design_cmd", "multilat.cli.interop_cmd",
            "multilat.report", "multilat.campaign.correct", "multilat.campaign.environment", "multilat.air",
            "multilat.lbb", "multilat.montecarlo", "multilat.network.design", "multilat.network.adjust.general",
            "multilat.distance_errors", "multilat.budget")

_PROBE = """
import contextlib, io, json, sys
sys.argv = ["multilat", "adjust", sys.argv[1], "--json"]
from multilat.cli import run
out = io.StringIO()
code = 0
with contextlib.redirect_stdout(out):
    try:
        run()
    except SystemExit as e:
        code = e.code or 0
doc = json.loads(out.getvalue())
print(json.dumps({"code": code, "schema": doc.get("schema"), "modules": sorted(sys.modules)}))
"""


def test_small_adjust_imports_no_heavy_package():
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src") + os.pathsep + os.environ.get("PYTHONPATH", ""))
    p = subprocess.run([sys.executable, "-c", _PROBE, str(SMALL)], capture_output=True, text=True, env=env,
                       timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    rep = json.loads(p.stdout.strip().splitlines()[-1])
    assert rep["code"] == 0 and str(rep["schema"]).startswith("multilat.adjust/")   # the command did its work
    mods = rep["modules"]
    assert "multilat.network.adjust.distance.adjust" in mods                                       # the probe sees imports
    loaded = sorted({h for h in HEAVY for m in mods if m == h or m.startswith(h + ".")})
    assert loaded == [], f"a small adjust imported {loaded}"
    unneeded = sorted({u for u in UNNEEDED for m in mods if m == u or m.startswith(u + ".")})
    assert unneeded == [], f"a small adjust imported modules it does not use: {unneeded}"


def test_command_map_names_every_command():
    """``multilat.cli.COMMANDS`` (command -> the module registering it, for loading on demand) matches
    the registrations: each module, imported alone in a fresh process, registers exactly the commands
    the map gives it, and all of them together are every command ``multilat --help`` lists."""
    probe = """
import json, sys
import multilat.cli as cli
app = sys.modules["multilat.cli.app"].app
names = lambda: {c.name or c.callback.__name__.replace("_", "-") for c in app.registered_commands} | {
    g.name for g in app.registered_groups}
__import__("multilat.cli." + sys.argv[1])
print(json.dumps(sorted(names())))
"""
    from multilat import cli

    env = dict(os.environ, PYTHONPATH=str(ROOT / "src") + os.pathsep + os.environ.get("PYTHONPATH", ""))
    every = set()
    for module in cli.COMMAND_MODULES:
        p = subprocess.run([sys.executable, "-c", probe, module], capture_output=True, text=True, env=env,
                           timeout=300)
        assert p.returncode == 0, p.stderr[-2000:]
        own = {c for c, m in cli.COMMANDS.items() if m == module}
        got = set(json.loads(p.stdout.strip().splitlines()[-1]))
        assert own <= got, (module, own, got)        # a module may import another (propagate: adjust's)
        every |= got
    assert every == set(cli.COMMANDS)


def test_commands_loaded_in_help_order(capsys):
    """Loading one command first (as ``multilat adjust`` does) leaves ``--help`` listing the commands
    in the order of :data:`multilat.cli.COMMAND_MODULES`."""
    from multilat import cli

    cli.load_commands(["adjust"])
    cli.load_commands(None)
    mods = [c.callback.__module__ for c in cli.app.registered_commands]
    rank = [cli.COMMAND_MODULES.index(m.rsplit(".", 1)[1]) for m in mods]
    assert rank == sorted(rank) and len(set(mods)) == len(cli.COMMAND_MODULES) - 1   # lbb: a group


def _scipy_components(n, a, b):
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    g = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    return connected_components(g, directed=False)


@pytest.mark.parametrize("numpy_path", [True, False])
@pytest.mark.parametrize("case", ["random", "chain", "isolated", "no_edges", "bipartite"])
def test_graph_components_match_scipy(case, numpy_path, monkeypatch):
    """Same count and the same labels (numbered by each component's lowest node) as scipy's csgraph,
    on both paths (numpy below ``GRAPH_NUMPY_MAX_EDGES`` edges, csgraph above)."""
    monkeypatch.setattr(solvability, "GRAPH_NUMPY_MAX_EDGES", 10**9 if numpy_path else -1)
    rng = np.random.default_rng(29)
    if case == "random":                  # sparse random graph: many components of all sizes
        n = 400
        a, b = rng.integers(0, n, 300), rng.integers(0, n, 300)
    elif case == "chain":                 # long path in shuffled order: the worst case for hooking rounds
        n = 2000
        perm = rng.permutation(n)
        a, b = perm[:-1], perm[1:]
    elif case == "isolated":              # edges among the first half only, a self-loop, repeated edges
        n = 50
        a = np.r_[rng.integers(0, 25, 40), 7, 3, 3]
        b = np.r_[rng.integers(0, 25, 40), 7, 4, 4]
    elif case == "no_edges":
        n = 5
        a = b = np.zeros(0, int)
    else:                                 # station-target graph of two separate networks, interleaved ids
        s, t = 6, 40
        st = np.r_[rng.integers(0, 3, 60), rng.integers(3, 6, 60)]
        tg = np.r_[rng.integers(0, 20, 60), rng.integers(20, 40, 60)]
        n, a, b = s + t, st, s + tg
    n_ref, lab_ref = _scipy_components(n, a, b)
    n_got, lab_got = graph_components(n, a, b)
    assert n_got == n_ref
    np.testing.assert_array_equal(lab_got, lab_ref)


def test_the_test_run_sets_blas_threads_once():
    """tests/conftest.py sets one BLAS thread per test process before numpy loads (issue 29), for at
    least the variables the CLI sets, and OpenBLAS took it (asked through its C API; skipped when
    numpy's BLAS is not OpenBLAS or the user set another value)."""
    from multilat.cli import BLAS_THREAD_VARIABLES as cli_vars

    here = Path(__file__).with_name("conftest.py")
    conf = SimpleNamespace(**runpy.run_path(str(here)))       # the module object's name differs under xdist
    assert set(cli_vars) <= set(conf.BLAS_THREAD_VARIABLES) and "OMP_NUM_THREADS" in conf.BLAS_THREAD_VARIABLES
    assert all(os.environ.get(v) for v in conf.BLAS_THREAD_VARIABLES)
    if os.environ["OPENBLAS_NUM_THREADS"] != "1":
        pytest.skip("OPENBLAS_NUM_THREADS set by the user")
    import ctypes

    if not Path("/proc/self/maps").exists():
        pytest.skip("no /proc/self/maps to find the loaded BLAS")
    libs = sorted({ln.split()[-1] for ln in open("/proc/self/maps") if "openblas" in ln and ln.strip().endswith(".so")})
    get = None
    for lib in libs:
        for name in ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads",
                     "openblas_get_num_threads"):
            get = get or getattr(ctypes.CDLL(lib), name, None)
    if get is None:
        pytest.skip("numpy's BLAS is not OpenBLAS")
    assert get() == 1
