"""Compile every numba kernel and the package's bytecode once, at install: ``python -m multilat.warmup``
(run by ``make install``).

numba compiles a kernel on its first call and keeps the machine code on disk (``cache=True``: in the
package's ``__pycache__`` when writable, else numba's user cache directory, or ``NUMBA_CACHE_DIR``).
Without this step a new user's first ``adjust`` or ``propagate`` would spend ~15-60 s compiling; after
it, the first command only loads the cached code (~0.3 s). Each step is a small real workload through
the public entry points, so kernels reached by those paths are compiled whatever their number.
Prints one line per step; without numba, only the bytecode is written (no kernel to compile).
"""

from __future__ import annotations

import sys
import time
import warnings

import numpy as np

__all__ = ["main"]


def bytecode() -> bool:
    """Write the bytecode (``__pycache__/*.pyc``) of every module of the package, as a regular ``pip
    install`` does and an editable one does not: otherwise a user's first command compiles each module
    it imports (~0.5 s for ``multilat adjust``; every command, when ``PYTHONDONTWRITEBYTECODE`` is set).
    False when the package's directory is not writable (nothing written; the commands still run)."""
    import compileall
    from pathlib import Path

    root = Path(__file__).resolve().parent
    try:
        return bool(compileall.compile_dir(str(root), quiet=2, workers=1))
    except OSError:
        return False


def _propagate_general():
    """The general layer's compiled chord steps (``montecarlo/general/_frozen_numba``), on the distance-only
    network of the package generator adjusted by the general layer (the kernels are the same for every kind)."""
    from multilat.network.adjust.general import adjust_network
    from multilat.network.adjust.general.from_tables import network_from_tables
    from multilat.network.montecarlo.general.propagate import propagate as propagate_general
    from multilat.network.synthetic.generator import synthetic_network

    net, options = network_from_tables(synthetic_network(1, population="well-conditioned").obs, rng=0)
    adj = adjust_network(net, options=options)
    propagate_general(adj.system, adj.result, trials=2000, rng=1)


def _steps():
    def adjust_large():
        """The sparse solver, multilateration, and the statistics kernels (>= 10 000 distances), on a
        network written to a CSV and read back as a user's file is (the kernels' boundary passes
        read-only arrays as writeable copies, :func:`multilat._numba.boundary`; reading a file here
        as well keeps the warm-up's arrays those of a command)."""
        import tempfile
        from pathlib import Path

        from multilat.io import dumps_json
        from multilat.network.adjust.distance.adjust import adjust
        from multilat.network.adjust.covariance import KERNELS_ABOVE_OBS
        from multilat.network.io.files import read_observations
        from multilat.network.synthetic.generator import synthetic_network

        from multilat.network.adjust.solve.loop import KERNEL_MIN_TARGETS

        t = max(KERNELS_ABOVE_OBS // 8, KERNEL_MIN_TARGETS) + 50     # every size-gated kernel runs
        net = synthetic_network(1, population="rings", n_stations=20, n_targets=t, per_target=8)
        with tempfile.TemporaryDirectory(prefix="multilat-warmup-") as tmp:
            path = Path(tmp) / "obs.csv"
            path.write_text("station,target,distance_m,sigma_m\n" + "".join(
                f"S{i},T{j},{float(d)!r},{float(s)!r}\n" for i, j, d, s in
                zip(net.station_index, net.target_index, net.distance_m, net.sigma_m)))
            obs = read_observations(path)
        res = adjust(obs, solver="sparse", snooping=False, rng=0)
        cov = res.covariance
        cov.hat_row(0)
        cov.design_times(cov.internal_times(cov.design_row(0)))      # the downdated snooping rounds
        from multilat.network.adjust.distance.result import result_to_json

        dumps_json(result_to_json(res))

    def propagate_small():
        """The batched Monte Carlo solver and the distance-model draws."""
        from multilat.network.synthetic.configs import small_volume
        from multilat.network.montecarlo.propagate import problem_from_config, propagate
        from multilat.network.model.sigma_source import DEFAULT_SIGMA_M

        propagate(problem_from_config(small_volume(), sigma_m=DEFAULT_SIGMA_M), trials=2000, rng=1,
                  noise="model", instrument="seed2020")      # the draws' kernels: named (never a default)

    def normals():
        """numba's bit-identical standard normal draws (used past a size threshold)."""
        from multilat import fast_normal as D

        D._NUMPY_NORMALS = D.NUMBA_AFTER
        D._fast_std_normal(np.random.default_rng(0), 4096)

    def head_budgets():
        """The distance model's mechanical σ of every head of the shipped instrument presets (a seeded
        Monte Carlo each, kept in the on-disk budget cache: every later command reads it back)."""
        from multilat import budget, instrument

        for name in instrument.presets():
            inst = instrument.load_instrument(name)
            for head in inst.heads:
                budget.distance_std_m(inst, [1.0], head=head)

    def text():
        """The large-file reader's decimal parser (read-only and writable buffers: two signatures)."""
        from multilat import _text_kernels as K

        for buf in (np.frombuffer(b"1.5,2e-3", np.uint8), np.frombuffer(b"1.5,2e-3", np.uint8).copy()):
            K.parse_decimals(buf, np.array([0, 4], np.int64), np.array([3, 8], np.int64), K._POW10,
                             np.empty(2), np.empty(2, bool))

    return [("bytecode of the modules", bytecode), ("adjust, sparse, 10 400 distances", adjust_large), ("decimal reader", text), ("propagate small-volume", propagate_small),
            ("propagate, general layer", _propagate_general),
            ("normal draws", normals), ("heads' budgets of the presets", head_budgets)]


def main(argv=None) -> int:
    t_all = time.perf_counter()
    steps = _steps()
    try:
        import numba  # noqa: F401
    except ImportError:
        steps = steps[:1]
        print("multilat warm-up: numba not installed, no kernel to compile")
    for label, step in steps:
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            step()
        print(f"multilat warm-up: {label}: {time.perf_counter() - t0:.1f} s")
    print(f"multilat warm-up: bytecode and numba kernels compiled and cached in {time.perf_counter() - t_all:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
