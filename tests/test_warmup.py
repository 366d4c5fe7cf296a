"""``python -m multilat.warmup`` (run by ``make install``) compiles every numba kernel a large
``adjust`` loads, so a user's first command does not compile: after the warm-up in an empty numba
cache, ``multilat adjust`` of a network above every size gate (48 000 distances, 6 000 targets, a
1.3 MB file) with its ``--json`` and ``--out`` outputs saves nothing to the cache
(``NUMBA_DEBUG_CACHE`` reports each compilation it saves). Slow (the warm-up compiles for ~30 s):
``pytest -m slow``."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")


@pytest.mark.slow
def test_first_adjust_after_the_warm_up_compiles_nothing(tmp_path):
    from multilat.network.synthetic.generator import synthetic_network

    net = synthetic_network(4, population="rings", n_stations=20, n_targets=6000, per_target=8)
    rows = [f"S{i},T{j},{d:.9f},5e-06" for i, j, d in zip(net.station_index, net.target_index, net.distance_m)]
    obs = tmp_path / "obs.csv"
    obs.write_text("station,target,distance_m,sigma_m\n" + "\n".join(rows) + "\n")
    assert obs.stat().st_size > 1 << 20                  # the large-file reader's path
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    subprocess.run([sys.executable, "-m", "multilat.warmup"], env=env, check=True, capture_output=True,
                   timeout=1200)
    env["NUMBA_DEBUG_CACHE"] = "1"
    cli = [sys.executable, "-c", "from multilat.cli import run; run()"]
    for extra in (["--json"], ["--out", str(tmp_path / "out")]):
        p = subprocess.run(cli + ["adjust", str(obs), *extra], env=env, capture_output=True, text=True, timeout=600)
        assert p.returncode == 0, p.stderr[-500:]
        saved = [ln for ln in (p.stdout + p.stderr).splitlines() if ln.startswith("[cache]") and "saved" in ln]
        assert not saved, saved
    assert np.isfinite(net.distance_m).all()


_ONE_VARIANT = r"""
import sys
import numpy as np
from numba.core import types
from numba.core.registry import CPUDispatcher

from multilat.network.adjust import covariance as C
from multilat.network.adjust.solve import loop

C.KERNELS_ABOVE_OBS = 0                      # every size gate open: the kernels on a small network
loop.KERNEL_MIN_TARGETS = 0
from multilat.cli import main
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.model.data import Observations
from multilat.network.adjust.approximate.large import multilaterate_targets
from multilat.network.synthetic.generator import synthetic_network

net = synthetic_network(3, population="rings", n_stations=6, n_targets=30,
                        per_target=5)  # arrays made in memory: writeable
obs = Observations(tuple(f"S{i}" for i in range(6)), tuple(f"T{j}" for j in range(30)),
                   net.station_index, net.target_index, net.distance_m, net.sigma_m)
res = adjust(obs, solver="sparse", rng=0)
res.covariance.hat_row(0)
multilaterate_targets(net.station_xyz_m, net.offset_m, net.station_index, net.target_index, net.distance_m,
                      net.sigma_m, 30)
csv = sys.argv[1]                                   # the same kernels on a CSV read from disk
for extra in (["--solver", "sparse"], []):
    assert main(["adjust", csv, "--json", *extra]) == 0
ro = np.frombuffer(net.distance_m.tobytes())        # a read-only array straight into a kernel
assert not ro.flags.writeable
multilaterate_targets(net.station_xyz_m, net.offset_m, net.station_index, net.target_index, ro, net.sigma_m, 30)
for name, mod in sorted(sys.modules.items()):
    if name.startswith("multilat"):
        for k, obj in vars(mod).items():
            d = getattr(obj, "dispatcher", obj)
            if isinstance(d, CPUDispatcher) and d.signatures:
                ro_args = [i for s in d.signatures for i, a in enumerate(s)
                           if isinstance(a, types.Array) and not a.mutable]
                print(f"{name}.{k} {len(d.signatures)} {ro_args}", file=sys.stderr)
"""


def test_one_compiled_variant_per_kernel_for_files_and_memory(tmp_path):
    """Every kernel an adjustment reaches has exactly one compiled signature, with no read-only
    array in it, after adjusting a network built in memory (what the warm-up compiles) and the
    example CSV read from disk (sparse and default solvers, every size gate opened), and a read-only
    array passed straight in. A CSV's arrays are read-only: numba compiled a second variant of each
    kernel for them, so the first ``adjust`` of a CSV after ``make install``'s warm-up compiled again
    (33 s against 6 s). In a subprocess: a fresh process's dispatchers hold only what it compiled or
    loaded."""
    csv = Path(__file__).resolve().parents[1] / "examples" / "network" / "small_volume_obs.csv"
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1] / "src"))
    p = subprocess.run([sys.executable, "-c", _ONE_VARIANT, str(csv)], env=env, capture_output=True, text=True,
                       timeout=900)
    assert p.returncode == 0, p.stderr[-3000:]
    rows = [ln.split(" ", 2) for ln in p.stderr.splitlines() if ln.startswith("multilat.")]
    names = {r[0] for r in rows}
    for must in ("multilat.network.adjust.solve._sparse_kernels.assemble", "multilat.network.adjust.solve._sparse_kernels.multilaterate",
                 "multilat.network.adjust._covariance_kernels._hat_diagonal",
                 "multilat.network.adjust.solve._sparse_kernels.whitened_distances"):
        assert must in names, sorted(names)
    bad = [r for r in rows if r[1] != "1" or r[2] != "[]"]
    assert not bad, bad


_BLAS_THREADS = r"""
import ctypes
import multilat.cli  # noqa: F401  (the command line's entry: sets the BLAS threads before numpy loads)
import numpy  # noqa: F401
libs = sorted({ln.split()[-1] for ln in open("/proc/self/maps") if "openblas" in ln and ln.strip().endswith(".so")})
get = None
for lib in libs:
    for name in ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads", "openblas_get_num_threads"):
        get = get or getattr(ctypes.CDLL(lib), name, None)
print(get() if get is not None else "unknown")
"""


@pytest.mark.parametrize("preset, expect", [(None, "1"), ("2", "2")])
def test_the_command_line_runs_blas_on_one_thread(preset, expect):
    """The CLI's entry sets OpenBLAS to one thread before numpy loads (OpenBLAS's own count, asked
    through its C API in a fresh process); a value the user set wins. Measured: 3 000 small solves
    and products took 44-64 s with OpenBLAS's default threads on 2 busy cores, 1.8 s with one."""
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                                                          "BLIS_NUM_THREADS", "OMP_NUM_THREADS")}
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[1] / "src")
    if preset is not None:
        env["OPENBLAS_NUM_THREADS"] = preset
    p = subprocess.run([sys.executable, "-c", _BLAS_THREADS], env=env, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    if p.stdout.strip() == "unknown":
        pytest.skip("numpy's BLAS is not OpenBLAS")
    if preset is None and os.cpu_count() == 1:
        pytest.skip("one core: OpenBLAS's default is one thread anyway")
    assert p.stdout.strip() == expect


def test_warm_up_writes_the_bytecode_of_every_module(tmp_path):
    """The warm-up's first step writes every module's ``.pyc`` (an editable install writes none, so a
    user's first command compiled each module it imported; with ``PYTHONDONTWRITEBYTECODE`` set, every
    command did; issue 29), on a copy of the package without any ``__pycache__``, and Python then
    reads that bytecode rather than compiling (``importlib``'s loader finds a valid cache)."""
    import importlib.util
    import shutil

    src = Path(__file__).resolve().parents[1] / "src" / "multilat"
    pkg = tmp_path / "multilat"
    shutil.copytree(src, pkg, ignore=shutil.ignore_patterns("__pycache__"))
    modules = sorted(pkg.rglob("*.py"))
    assert len(modules) > 100 and not list(pkg.rglob("*.pyc"))
    env = dict(os.environ, PYTHONPATH=str(tmp_path), PYTHONDONTWRITEBYTECODE="1")
    p = subprocess.run([sys.executable, "-c", "from multilat import warmup; print(warmup.bytecode())"], env=env,
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0 and p.stdout.strip() == "True", p.stderr[-500:]
    missing = [m for m in modules if not Path(importlib.util.cache_from_source(str(m))).exists()]
    assert missing == []
    probe = """
import importlib._bootstrap_external as be
compiled = []
orig = be.SourceLoader.source_to_code
def source_to_code(self, data, path, *a, **k):
    compiled.append(str(path))
    return orig(self, data, path, *a, **k)
be.SourceLoader.source_to_code = source_to_code
import multilat.cli, multilat.network.adjust.distance.adjust, multilat.network.montecarlo.propagate
print(sum("multilat" in c for c in compiled))
"""
    p = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-500:]
    assert p.stdout.strip() == "0"              # every module's code came from its .pyc
    for cache in (pkg / "network").rglob("__pycache__"):      # the probe can see a compilation
        shutil.rmtree(cache)
    p = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, timeout=300)
    assert int(p.stdout.strip()) > 10
