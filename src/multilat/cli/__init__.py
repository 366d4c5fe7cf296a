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

import sys

from multilat.cli.app import app, main, run_and_exit  # noqa: F401
from multilat.cli import (  # noqa: F401  (registration side effects)
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
