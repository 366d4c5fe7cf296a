"""The ``multilat`` command line: a thin shell over the library (no science here).

Each command area lives in its own module and registers its commands on :data:`app`:

- ``air_cmd``       ``multilat air``
- ``budget_cmd``    ``multilat budget``
- ``network_cmd``   ``multilat adjust``
- ``simulate_cmd``  ``multilat simulate``
- ``lbb_cmd``       ``multilat lbb trilaterate|simulate``
- ``campaign_cmd``  ``multilat correct``, ``multilat two-face``
- ``propagate_cmd`` ``multilat propagate``
- ``demo_cmd``      ``multilat demo``
- ``interop_cmd``   ``multilat export``, ``multilat import`` (GNU Gama, JAG3D, Star*Net)

:func:`main` runs the app without sys.exit and turns :class:`multilat.MultilatError` (and other
anticipated input errors) into ``error: <one line>`` on stderr with exit code 2.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

#: BLAS threads of a command: one, set here before numpy is first imported (OpenBLAS reads it when it
#: loads). The compiled kernels and the Monte Carlo already use every core (numba's threads, worker
#: processes); a BLAS that also starts a thread per core on each small product oversubscribes them:
#: 3 000 small solves took 44-64 s with OpenBLAS's default threads on 2 busy cores, 1.8 s with one.
#: Results no longer depend on the machine's core count through BLAS. A value already in the
#: environment wins (``OPENBLAS_NUM_THREADS=4 multilat ...``).
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")
for _name in BLAS_THREAD_VARIABLES:
    os.environ.setdefault(_name, "1")
#: OpenMP's wait policy for numba's threads (the "omp" layer, libgomp, which reads it when numba first
#: starts its threads): passive, a thread that waits for the next parallel region sleeps at once.
#: libgomp's default spins ~300 000 pause loops first in every wait, CPU the command never uses: the
#: 20 x 20 000 ``adjust --json`` took 2.7 s CPU passive against 3.0-3.8 s spinning (load 12-17,
#: interleaved; the same JSON). A value already in the environment wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from multilat.cli.app import app, main, run_and_exit  # noqa: E402,F401

#: The modules that register the commands, in the order ``multilat --help`` lists them. They are
#: imported on demand (:func:`load_commands`): a command loads only its own module, so a small
#: ``multilat adjust`` does not import the demo's report, the campaign commands' readers or the LBB
#: (issue 29: small jobs do not pay for large ones).
COMMAND_MODULES = ("air_cmd", "budget_cmd", "network_cmd", "simulate_cmd", "lbb_cmd", "campaign_cmd",
                   "propagate_cmd", "demo_cmd", "design_cmd", "interop_cmd")
#: command name -> the module that registers it (``tests/test_small_imports.py`` checks it against the
#: registrations); a name not here (``--help``, a typo) loads every module, so help and "No such
#: command" read as before.
COMMANDS = {"air": "air_cmd", "budget": "budget_cmd", "adjust": "network_cmd", "simulate": "simulate_cmd",
            "lbb": "lbb_cmd", "correct": "campaign_cmd", "two-face": "campaign_cmd",
            "propagate": "propagate_cmd", "demo": "demo_cmd", "design": "design_cmd", "export": "interop_cmd",
            "import": "interop_cmd"}


def load_commands(args: Sequence[str] | None = None) -> None:
    """Register the commands ``args`` runs (its first word names the command), or all of them
    (``args`` None, empty, an option such as ``--help``, an unknown word), on :data:`app`, in the
    order of :data:`COMMAND_MODULES` whatever the order of loading."""
    word = next(iter(args), None) if args is not None else None
    wanted = [COMMANDS[word]] if word in COMMANDS else COMMAND_MODULES
    for name in wanted:
        __import__(f"multilat.cli.{name}")          # (not importlib: `python -X importtime` sees it)
    rank = {f"multilat.cli.{m}": i for i, m in enumerate(COMMAND_MODULES)}
    app.registered_commands.sort(key=lambda c: rank.get(getattr(c.callback, "__module__", ""), len(rank)))


def run() -> None:
    """Console-script entry point."""
    run_and_exit()
