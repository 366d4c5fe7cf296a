"""``python -m multilat`` is the console script: same help, same exit code on a bad option."""

import subprocess
import sys


def _run(*args):
    return subprocess.run([sys.executable, "-m", "multilat", *args], capture_output=True, text=True, timeout=120)


def test_python_dash_m_runs_the_cli():
    ok = _run("air", "--json")
    assert ok.returncode == 0, ok.stderr
    assert '"schema"' in ok.stdout


def test_python_dash_m_refuses_a_bad_option_with_exit_2():
    bad = _run("adjust", "--no-such-option")
    assert bad.returncode == 2
    assert "--no-such-option" in bad.stderr
