"""Issue 29, the 20 x 20 000 ``adjust --json``'s CPU: what the command sets up so that its threads and
its start do not cost CPU it never uses. Not timed tests: each checks the setting or the path taken."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _cli_environ(**env) -> str:
    """OMP_WAIT_POLICY as a fresh process sees it after importing ``multilat.cli`` with ``env``."""
    base = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    code = "import os, multilat.cli; print(os.environ.get('OMP_WAIT_POLICY'))"
    out = subprocess.run([sys.executable, "-c", code], env=dict(base, **env), capture_output=True,
                         text=True, check=True, timeout=120)
    return out.stdout.strip()


def test_cli_sets_passive_openmp_wait_and_a_user_value_wins():
    """The CLI asks libgomp (numba's "omp" threads) to sleep between parallel regions instead of
    spinning (cli/__init__.py); a value in the environment wins, as for the BLAS threads."""
    assert _cli_environ() == "PASSIVE"
    assert _cli_environ(OMP_WAIT_POLICY="active") == "active"
