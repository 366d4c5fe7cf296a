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

#: BLAS threads of a command: one, set here before numpy is first imported (OpenBLAS reads it when it
#: loads). The compiled kernels and the Monte Carlo already use every core (numba's threads, worker
#: processes); a BLAS that also starts a thread per core on each small product oversubscribes them:
#: 3 000 small solves took 44-64 s with OpenBLAS's default threads on 2 busy cores, 1.8 s with one.
#: Results no longer depend on the machine's core count through BLAS. A value already in the
#: environment wins (``OPENBLAS_NUM_THREADS=4 multilat ...``).
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")
for _name in BLAS_THREAD_VARIABLES:
    os.environ.setdefault(_name, "1")

from multilat.cli.app import app, main, run_and_exit  # noqa: E402,F401
from multilat.cli import (  # noqa: E402,F401  (registration side effects)
    air_cmd,
    budget_cmd,
    network_cmd,
    simulate_cmd,
    lbb_cmd,
    campaign_cmd,
    propagate_cmd,
    demo_cmd,
    design_cmd,
    interop_cmd,
)


def run() -> None:
    """Console-script entry point."""
    run_and_exit()
