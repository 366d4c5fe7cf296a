"""Parallel maps give the same numbers as the in-process run, bit for bit."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from multilat.distributions import Arcsine, Normal, Uniform
from multilat.errors import MultilatError
from multilat.montecarlo import BLOCK, run_mc
from multilat.parallel import dask_map, map_from_options, process_map, thread_map


def eq3_error_m(rf, crosstalk, ampm, noise):
    return 20.0 * rf + crosstalk + ampm + noise


INPUTS = dict(
    rf=Normal(0.0, 1.5e-9),
    crosstalk=Arcsine.from_amplitude(2.7e-6),
    ampm=Uniform.from_std(0.2e-6),
    noise=Normal(0.0, 0.8e-6),
)
TRIALS = 6 * BLOCK + 321


def _same(a, b):
    assert a.estimate == b.estimate and a.std == b.std and a.trials == b.trials
    assert np.array_equal(a.interval_symmetric, b.interval_symmetric)
    assert np.array_equal(a.interval_shortest, b.interval_shortest)


def test_dask_local_cluster_two_workers_identical():
    pytest.importorskip("distributed")
    ref_exact = run_mc(eq3_error_m, INPUTS, trials=TRIALS, rng=2024)
    ref_hist = run_mc(eq3_error_m, INPUTS, trials=TRIALS, rng=2024, quantiles="histogram")
    seen = []
    keys = ("NUMBA_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MALLOC_TRIM_THRESHOLD_",
            "MALLOC_MMAP_THRESHOLD_", "PYTHONHASHSEED")
    before = {k: os.environ.get(k) for k in keys}
    with dask_map(workers=2) as m:
        assert m.n_workers == 2
        # the workers' variables stay theirs: the nanny sets them here before spawning and leaves them
        assert {k: os.environ.get(k) for k in keys} == before
        r_exact = run_mc(eq3_error_m, INPUTS, trials=TRIALS, rng=2024, chunk_size=BLOCK, map=m,
                         progress=lambda d, t: seen.append(d))
        r_hist = run_mc(eq3_error_m, INPUTS, trials=TRIALS, rng=2024, chunk_size=2 * BLOCK, map=m,
                        quantiles="histogram")
        r_lambda = run_mc(lambda rf, crosstalk, ampm, noise: rf + crosstalk + ampm + noise, INPUTS,
                          trials=2 * BLOCK, rng=1, map=m)  # closures travel with cloudpickle
    _same(r_exact, ref_exact)
    assert np.array_equal(r_exact.samples, ref_exact.samples)
    _same(r_hist, ref_hist)
    assert np.array_equal(r_hist._hist_counts, ref_hist._hist_counts)
    assert seen[-1] == TRIALS and seen == sorted(seen)
    assert r_lambda.trials == 2 * BLOCK
    assert {k: os.environ.get(k) for k in keys} == before
    numba = pytest.importorskip("numba")
    assert numba.njit(lambda x: x + 1.0)(1.0) == 2.0      # numba still compiles in this process


def three_outputs(rf, crosstalk, ampm, noise):
    return np.stack([crosstalk + ampm, noise - rf, crosstalk * 1e3 + noise], axis=1)


def test_process_pool_identical():
    ref = run_mc(eq3_error_m, INPUTS, trials=3 * BLOCK, rng=5)
    ref3 = run_mc(three_outputs, INPUTS, trials=3 * BLOCK + 7, rng=6)
    with process_map(2) as m:
        r = run_mc(eq3_error_m, INPUTS, trials=3 * BLOCK, rng=5, chunk_size=BLOCK, map=m)
        r3 = run_mc(three_outputs, INPUTS, trials=3 * BLOCK + 7, rng=6, chunk_size=BLOCK, map=m)
    _same(r, ref)
    # vector output: means, covariance and intervals bit for bit too
    assert np.array_equal(r3.estimate, ref3.estimate) and np.array_equal(r3.cov, ref3.cov)
    assert np.array_equal(r3.interval_shortest, ref3.interval_shortest)


def test_default_map_does_not_import_dask():
    code = (
        "import sys\n"
        "from multilat.parallel import map_from_options\n"
        "from multilat.montecarlo import run_mc\n"
        "from multilat.distributions import Normal\n"
        "with map_from_options() as m:\n"
        "    assert m is None\n"
        "    run_mc(lambda a: a, {'a': Normal()}, trials=1000, rng=1, map=m)\n"
        "assert 'distributed' not in sys.modules and 'dask' not in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_option_errors():
    with pytest.raises(MultilatError, match="exactly one"):
        with dask_map():
            pass
    with pytest.raises(MultilatError, match="workers"):
        with dask_map(workers=0):
            pass
    with pytest.raises(MultilatError, match="mutually exclusive"):
        with map_from_options(workers=2, scheduler="tcp://localhost:1"):
            pass
    with pytest.raises(MultilatError, match="workers"):
        with process_map(0):
            pass


def _slow_square(x):
    import time

    time.sleep(0.002 * (x % 3))        # items finish out of order
    return x * x


def test_thread_map_keeps_order_and_falls_back():
    items = list(range(23))
    assert list(thread_map(_slow_square, items, threads=2)) == [x * x for x in items]
    assert list(thread_map(_slow_square, items, threads=1)) == [x * x for x in items]
    assert list(thread_map(_slow_square, [4], threads=2)) == [16]
    assert list(thread_map(_slow_square, [], threads=2)) == []
    assert list(thread_map(_slow_square, iter(items[:5]))) == [x * x for x in items[:5]]


def test_thread_map_pool_threads_run_one_numba_thread():
    """Item 0 runs in the caller with numba's threads; the pool's threads (when numba's threading layer
    is thread-safe) each with one, so two items do not start a thread per core each."""
    numba = pytest.importorskip("numba")
    from multilat.parallel import _thread_safe_layer

    from multilat.distance_errors import draw_errors, error_model   # runs a parallel kernel: the
    from multilat import instrument                                 # threading layer becomes known
    model = error_model(instrument.load_instrument("seed2020"), ("A",))
    draw_errors(model, np.zeros(3, np.int64), np.ones(3), 4, np.random.default_rng(0))
    seen = list(thread_map(lambda _: numba.get_num_threads(), range(6), threads=2))
    assert seen[0] == numba.get_num_threads()
    assert set(seen[1:]) == ({1} if _thread_safe_layer() else {numba.get_num_threads()})


def test_thread_map_error_stops_the_rest():
    """An item's error reaches the caller; the items not yet started are cancelled."""
    import threading

    started = []
    lock = threading.Lock()

    def work(x):
        with lock:
            started.append(x)
        if x == 1:
            raise ValueError("item 1")
        import time

        time.sleep(0.01)
        return x

    with pytest.raises(ValueError, match="item 1"):
        list(thread_map(work, range(200), threads=2))
    assert len(started) < 200


def _worker_numba_threads(_):
    numba = pytest.importorskip("numba")
    return numba.get_num_threads()


def test_dask_thread_workers_identical_and_single_run_closes_early():
    """Local clusters of 1 and 2 worker *threads* (``map_from_options``'s default; ``dask_map(...,
    processes=False)``) give the propagation's numbers bit for bit (the distance model's draw and the
    solver are numba parallel kernels, run on one numba thread per worker thread); ``single_run``
    closes the client and the cluster once the last result is in, before the summaries, and refuses a
    second run; without it the map serves several runs."""
    pytest.importorskip("distributed")
    from multilat.network.montecarlo import propagate as pr
    from multilat.network.synthetic.configs import small_volume

    problem = pr.problem_from_config(small_volume(), sigma_m=4.7e-6, source="small-volume")
    run = dict(trials=2500, rng=5, noise="model", instrument="seed2020", keep_samples=True)
    ref = pr.propagate(problem, **run)
    summarise, states = pr.summarise, []

    def spy(*args, **kw):          # released (its close started) when the driver starts summarising
        states.append(m.released)
        return summarise(*args, **kw)

    for workers in (1, 2):
        with map_from_options(workers=workers, single_run=True) as m:      # the CLI's: threads
            assert m.threads and m.n_workers == workers
            assert set(m.client.run(os.getpid).values()) == {os.getpid()}      # in this process
            assert set(m.map(_worker_numba_threads, range(4))) == {1}
            pr.summarise = spy
            try:
                b = pr.propagate(problem, chunk_size=1000, map=m, **run)
            finally:
                pr.summarise = summarise
            assert m.released
            with pytest.raises(MultilatError, match="released"):
                list(m.map(abs, [1]))
        assert m.client.status == "closed"
        np.testing.assert_array_equal(b.samples, ref.samples)
        for name in ("mc_mean", "mc_std", "interval_symmetric", "interval_shortest", "point_cov_mc",
                     "ellipsoid_coverage_mc", "input_std_m"):
            np.testing.assert_array_equal(getattr(b, name), getattr(ref, name), err_msg=name)
    assert states == [True, True]
    with dask_map(workers=1, processes=False) as m:       # not single-run: release is ignored
        for _ in range(2):
            b = pr.propagate(problem, chunk_size=2000, map=m, **run)
            assert not m.released and m.client.status == "running"
    np.testing.assert_array_equal(b.samples, ref.samples)


def test_release_of_other_maps_and_close_errors():
    """release_map is a no-op for maps without release (builtin, a pool's map); an error of a background
    close is raised when the context waits for it, not lost in the thread."""
    from multilat.parallel import _Closer, release_map

    release_map(None)
    release_map(map)

    class Failing:
        def close(self):
            raise RuntimeError("close failed")

    closer = _Closer(Failing(), None)
    closer.start()
    with pytest.raises(RuntimeError, match="close failed"):
        closer.join()


def test_thread_workers_fall_back_to_processes_without_a_thread_safe_layer(monkeypatch):
    """Where numba's threading layer would abort on kernels launched from two threads (workqueue),
    ``processes=False`` still starts worker processes (whose kernels run one at a time each)."""
    pytest.importorskip("distributed")
    import multilat.parallel as par

    monkeypatch.setattr(par, "_threads_can_launch_parallel_kernels", lambda: False)
    with dask_map(workers=1, processes=False) as m:
        assert not m.threads and m.n_workers == 1
        assert list(m.map(_slow_square, [3, 4])) == [9, 16]
        assert os.getpid() not in set(m.client.run(os.getpid).values())
