"""Run Monte Carlo chunks through any ``map``: in-process, a process pool, or a Dask cluster.

:func:`multilat.montecarlo.run_mc` (and anything built on it) takes ``map=``: a callable
``map(func, iterable)`` or an object with a ``.map`` method (emcee-style), whose results come back
in order. Because every block of trials is seeded from its own ``SeedSequence`` spawn key, the
numbers are identical whichever map runs the chunks and however many workers it has.

Nothing here imports Dask until :func:`dask_map` is entered.

Example
-------
>>> from multilat.distributions import Normal
>>> from multilat.montecarlo import run_mc
>>> from multilat.parallel import map_from_options
>>> def model(a, b):
...     return a + b
>>> with map_from_options(workers=None, scheduler=None) as m:      # in-process: no Dask import
...     res = run_mc(model, {"a": Normal(), "b": Normal()}, trials=100_000, rng=1, map=m)
>>> res.trials
100000

With a local Dask cluster of two worker processes (one thread each), or an existing scheduler::

    with dask_map(workers=2) as m:                       # or dask_map(scheduler="tcp://host:8786")
        res = run_mc(model, inputs, trials=10**8, rng=1, chunk_size=1 << 22, map=m)

The model and the inputs are pickled (cloudpickle under Dask, pickle for process pools): use
module-level functions for process pools; Dask also accepts lambdas and closures.
"""

from __future__ import annotations

import contextlib
import functools
import os
import threading
from collections.abc import Callable, Iterable, Iterator

from multilat.errors import MultilatError

__all__ = ["DaskMap", "dask_map", "process_map", "thread_map", "map_from_options", "parse_scheduler_address",
           "probe_scheduler", "release_map"]

#: Seconds to wait for a TCP connection to a scheduler and for its Dask handshake.
CONNECT_TIMEOUT_S = 5.0
#: Seconds for the Dask client to finish connecting once the handshake was seen.
CLIENT_TIMEOUT_S = 10.0

#: glibc trim and mmap thresholds (bytes) for the local cluster's workers (see :func:`dask_map`).
MALLOC_THRESHOLD = 64 * 2**20


class DaskMap:
    """An ordered, lazily yielding ``map`` over a :class:`distributed.Client`.

    All items are submitted at once (``client.map``, ``pure=False``); results are yielded in
    submission order as they complete, and each future is released once its result is read.
    On a cluster of thread workers (``threads``) each item runs with one numba thread, as in
    :func:`thread_map`'s pool. :meth:`release` ends a single-run map early (see :func:`dask_map`).
    """

    def __init__(self, client, *, threads: bool = False, release: Callable[[], None] | None = None):
        self.client = client
        self.threads = threads
        self._release = release
        self.released = False

    def map(self, func: Callable, iterable: Iterable) -> Iterator:
        if self.released:
            raise MultilatError("this Dask map was released after its run (single_run=True); open another")
        items = list(iterable)
        if not items:
            return
        if self.threads:
            func = functools.partial(_call_with_one_numba_thread, func)
        futures = self.client.map(func, items, pure=False)
        try:
            for i, fut in enumerate(futures):
                yield fut.result()
                futures[i] = None  # release the result on the cluster
        finally:
            live = [f for f in futures if f is not None]
            if live:
                self.client.cancel(live)

    __call__ = map

    def release(self) -> None:
        """The run's last result is in: a single-run map (``dask_map(..., single_run=True)``) closes
        its client and local cluster now, in a background thread, while the caller summarises
        (joined when the context exits); any other map ignores the call."""
        if self._release is not None and not self.released:
            self.released = True
            self._release()

    @property
    def n_workers(self) -> int:
        return len(self.client.scheduler_info().get("workers", {}))


def release_map(map) -> None:
    """Tell ``map`` (any map a run was given) that the run has received its last result:
    :meth:`DaskMap.release`; nothing for other maps."""
    release = getattr(map, "release", None)
    if callable(release):
        release()


class _Closer:
    """Closes a client and its local cluster once: now (:meth:`join`), or in a background thread
    started by :meth:`start` and waited for by :meth:`join`; an error of the close is raised there."""

    def __init__(self, client, cluster):
        self.client, self.cluster = client, cluster
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None

    def _close(self) -> None:
        try:
            try:
                self.client.close()
            finally:
                if self.cluster is not None:
                    self.cluster.close()
        except BaseException as exc:  # noqa: BLE001  handed to join()
            self._error = exc

    def start(self) -> None:
        self._thread = threading.Thread(target=self._close, name="multilat-dask-close")
        self._thread.start()

    def join(self) -> None:
        if self._thread is None:
            self._close()
        else:
            self._thread.join()
        if self._error is not None:
            raise self._error


@contextlib.contextmanager
def dask_map(workers: int | None = None, *, scheduler: str | None = None, memory_limit: str = "auto",
             processes: bool = True, single_run: bool = False):
    """Context manager yielding a :class:`DaskMap`.

    Parameters
    ----------
    workers : int, optional
        Start a ``distributed.LocalCluster`` of this many workers, one thread each. Closed on exit.
    scheduler : str, optional
        Address of an existing scheduler (``"tcp://host:8786"``); the cluster is left running.
    memory_limit : str
        Per-worker memory limit of a local cluster of processes (Dask syntax).
    processes : bool
        Local cluster only: worker *processes* (default; any model, pickled to them), or worker
        *threads* in this process (``False``): no process to start, import into or close, and no
        result serialised back, for work that releases the GIL (numba kernels compiled ``nogil``,
        numpy), each item with one numba thread. Falls back to processes when numba's threading
        layer cannot launch parallel kernels from several threads at once (workqueue).
    single_run : bool
        The map serves one run: :func:`release_map` (which :func:`~multilat.network.montecarlo.
        propagate.propagate` calls once its last result is in) closes the client and the local
        cluster in a background thread while the run summarises; exit waits for that close.

    Exactly one of ``workers`` and ``scheduler`` must be given.
    """
    if (workers is None) == (scheduler is None):
        raise MultilatError("give exactly one of workers (local cluster) and scheduler (address)")
    if workers is not None and (not isinstance(workers, int) or isinstance(workers, bool) or workers < 1):
        raise MultilatError(f"workers must be an integer >= 1, got {workers!r}")
    try:
        import distributed
    except ImportError:  # pragma: no cover - dask is installed in the dev environment
        raise MultilatError("Dask is not installed: pip install 'multilat[dask]'") from None
    threads = workers is not None and not processes and _threads_can_launch_parallel_kernels()
    cluster = None
    saved = None
    try:
        if scheduler is not None:
            client = _connect(distributed, scheduler)
        elif threads:
            cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=False,
                                               dashboard_address=None, memory_limit=0, silence_logs=40)
        else:
            cluster, saved = _process_cluster(distributed, workers, memory_limit)
        if cluster is not None:
            client = distributed.Client(cluster)
        closer, cluster = _Closer(client, cluster), None      # from here on the closer closes the cluster
        try:
            yield DaskMap(client, threads=threads, release=closer.start if single_run else None)
        finally:
            closer.join()
    finally:
        if cluster is not None:          # the client never connected
            cluster.close()
        if saved is not None:
            _restore_environ(saved)      # again: a worker respawned meanwhile set them once more


def _connect(distributed, scheduler: str):
    """A client of the scheduler at ``scheduler`` (probed first); one line naming ``--scheduler``."""
    address = probe_scheduler(scheduler)
    try:
        return distributed.Client(address, timeout=f"{CLIENT_TIMEOUT_S}s")
    except Exception as exc:  # noqa: BLE001  Dask raises many kinds; all are "cannot connect"
        raise MultilatError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler "
                            f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})"
                            ) from None


def _process_cluster(distributed, workers: int, memory_limit: str):
    """A LocalCluster of ``workers`` processes, one thread each, and the saved variables of this
    process that the nanny overwrote (put back here, and again at exit)."""
    import dask

    # Dask sets MALLOC_TRIM_THRESHOLD_=65536 in its workers, which switches off glibc's
    # dynamic mmap threshold: every 0.5 MB block temporary is then mmapped and page-faulted
    # anew, which halves the throughput of this workload. Our workers keep their heap.
    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    environ.update(MALLOC_TRIM_THRESHOLD_=str(MALLOC_THRESHOLD), MALLOC_MMAP_THRESHOLD_=str(MALLOC_THRESHOLD))
    # one thread per worker process: numba's parallel kernels (the distance model's draw) and
    # BLAS would otherwise start a thread per core in every worker, N workers x N threads
    environ.update(NUMBA_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    # the nanny sets these variables in *this* process's os.environ before spawning a worker and
    # leaves them there: NUMBA_NUM_THREADS=1 would make numba's next compilation here raise
    # ("cannot set NUMBA_NUM_THREADS ... once the threads have been launched"). Put them back
    # once the workers are spawned (a respawned worker gets them from the nanny again).
    saved = {k: os.environ.get(k) for k in (*environ, "PYTHONHASHSEED")}
    try:
        with dask.config.set({"distributed.nanny.pre-spawn-environ": environ}):
            cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                               dashboard_address=None, memory_limit=memory_limit,
                                               silence_logs=40)  # logging.ERROR
    finally:
        _restore_environ(saved)
    return cluster, saved


def parse_scheduler_address(text: str) -> tuple[str, str, int]:
    """``tcp://HOST:PORT`` or ``HOST:PORT`` (``tls://`` too) -> (scheme, host, port).

    Raises :class:`MultilatError` naming ``--scheduler`` for anything else: an empty string, another
    scheme (``http://`` is the dashboard, not the scheduler), no port, a port outside 1-65535.
    """
    import re

    s = (text or "").strip()
    m = re.fullmatch(r"(?:(tcp|tls)://)?(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(\d{1,5})/?", s)
    if not m:
        raise MultilatError(f"--scheduler: expected tcp://HOST:PORT (a Dask scheduler, usually port "
                            f"8786), got {text!r}")
    scheme, host, port = m.group(1) or "tcp", m.group(2), int(m.group(3))
    if not 1 <= port <= 65535:
        raise MultilatError(f"--scheduler {text}: port must be in 1-65535, got {port}")
    return scheme, host.strip("[]"), port


def probe_scheduler(text: str, timeout_s: float | None = None) -> str:
    """Check that a Dask scheduler answers at ``text`` before handing it to Dask; return the address.

    Opens a TCP connection (``timeout_s``, default :data:`CONNECT_TIMEOUT_S`) and waits as long for
    the first bytes: a Dask scheduler sends its handshake as soon as a client connects, while a web
    server (the dashboard's port) or another service waits silently — which would otherwise hang Dask.
    Every failure is a one-line :class:`MultilatError` naming ``--scheduler``.
    """
    import socket

    scheme, host, port = parse_scheduler_address(text)
    t = CONNECT_TIMEOUT_S if timeout_s is None else timeout_s
    try:
        sock = socket.create_connection((host, port), timeout=t)
    except socket.timeout:
        raise MultilatError(f"--scheduler {text}: no answer within {t:g} s (unreachable host?)") from None
    except OSError as exc:
        raise MultilatError(f"--scheduler {text}: cannot connect ({exc.strerror or exc})") from None
    try:
        if scheme == "tcp":
            sock.settimeout(t)
            try:
                first = sock.recv(64)
            except socket.timeout:
                raise MultilatError(f"--scheduler {text}: something listens there but it is not a Dask "
                                    f"scheduler (no handshake within {t:g} s; the scheduler's port is "
                                    "usually 8786, the dashboard's 8787)") from None
            except OSError as exc:
                raise MultilatError(f"--scheduler {text}: connection failed ({exc.strerror or exc})") from None
            if not first:
                raise MultilatError(f"--scheduler {text}: the connection was closed at once; not a Dask "
                                    "scheduler")
    finally:
        sock.close()
    return f"{scheme}://{host if ':' not in host else '[' + host + ']'}:{port}"


def _restore_environ(saved: dict) -> None:
    """Set the variables of ``saved`` back to their values (None: unset)."""
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


def _thread_safe_layer() -> bool:
    """True when numba's threading layer (known once a parallel kernel has run) accepts parallel
    kernels launched from several threads at once: OpenMP or TBB, not workqueue (which aborts)."""
    try:
        import numba

        return numba.threading_layer() in ("omp", "tbb")
    except Exception:          # numba missing, or no parallel kernel has run yet
        return False


def _one_numba_thread() -> None:
    from multilat._numba import HAVE_NUMBA

    if HAVE_NUMBA:
        import numba

        numba.set_num_threads(1)      # thread-local: this pool thread's parallel kernels run serially


def _threads_can_launch_parallel_kernels() -> bool:
    """Whether worker threads of this process may run numba's parallel kernels at once: True
    without numba; with numba, its threading layer is chosen now (numba's own start of its thread
    pool, as the first parallel kernel would) and must be OpenMP or TBB."""
    from multilat._numba import HAVE_NUMBA

    if not HAVE_NUMBA:
        return True
    try:
        from numba.np.ufunc.parallel import _launch_threads

        _launch_threads()
    except Exception:          # noqa: BLE001  no threading layer at all: processes then
        return False
    return _thread_safe_layer()


def _call_with_one_numba_thread(func: Callable, item):
    """``func(item)`` in a worker thread whose numba parallel kernels run on one thread."""
    _one_numba_thread()
    return func(item)


def thread_map(func: Callable, iterable: Iterable, threads: int | None = None) -> Iterator:
    """Ordered, lazy ``map`` over a pool of threads, for items whose work releases the GIL (numba
    kernels compiled ``nogil``, numpy's random draws, sorts and reductions).

    The first item runs in the calling thread, where numba's parallel kernels keep their own threads
    (numba loads its cached kernels there, and its threading layer becomes known). The others run in
    ``threads`` pool threads (default: numba's thread count, the cores), each with one numba thread,
    so the cores are shared by items instead of inside each one. Without numba, with a thread-unsafe
    threading layer (workqueue), one thread, or a single item: the builtin ``map``. Results come in
    input order; they do not depend on the threads when each item seeds its own generator.
    """
    from multilat._numba import HAVE_NUMBA, get_num_threads

    items = list(iterable)
    if threads is None:
        threads = get_num_threads() if HAVE_NUMBA else 1
    if not items:
        return
    yield func(items[0])
    if threads < 2 or len(items) < 2 or not _thread_safe_layer():
        yield from map(func, items[1:])
        return
    from concurrent.futures import ThreadPoolExecutor

    pool = ThreadPoolExecutor(min(threads, len(items) - 1), initializer=_one_numba_thread)
    try:
        futures = [pool.submit(func, it) for it in items[1:]]
        for i, f in enumerate(futures):
            yield f.result()
            futures[i] = None          # release each result once read
    finally:
        pool.shutdown(wait=True, cancel_futures=True)   # an error or an interrupt: nothing more starts


@contextlib.contextmanager
def process_map(workers: int):
    """Context manager yielding the ordered, lazy ``map`` of a ``ProcessPoolExecutor`` (no Dask)."""
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
        raise MultilatError(f"workers must be an integer >= 1, got {workers!r}")
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn")) as pool:
        yield pool.map


@contextlib.contextmanager
def map_from_options(workers: int | None = None, scheduler: str | None = None, *, processes: bool = False,
                     single_run: bool = False):
    """The map for CLI options ``--workers N`` / ``--scheduler ADDRESS``.

    Yields None (in-process, builtin ``map``, Dask not imported) when neither is given, else a
    :class:`DaskMap`: a local cluster of ``workers`` worker *threads* (the commands' work is numba
    kernels compiled ``nogil``; ``processes=True`` for worker processes), or the scheduler at
    ``scheduler``; ``single_run``: see :func:`dask_map`.
    """
    if workers is None and scheduler is None:
        yield None
        return
    if workers is not None and scheduler is not None:
        raise MultilatError("--workers and --scheduler are mutually exclusive")
    if scheduler is not None:
        parse_scheduler_address(scheduler)       # a malformed address is refused before Dask loads
    with dask_map(workers=workers, scheduler=scheduler, processes=processes, single_run=single_run) as m:
        yield m
