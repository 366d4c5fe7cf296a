"""CI that cannot turn checks into skips: ``.ci/run`` fails when Chromium cannot be installed (it
ended in ``|| true``, so the browser tests skipped and CI stayed green), and under ``CI=true`` a
browser test that would skip for want of Chromium or playwright fails (``tests/conftest.py``)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_ci_run_fails_when_chromium_cannot_be_installed(tmp_path):
    """``.ci/run`` in a copy of the repository's layout whose ``make test`` only says it ran, on a
    PATH with no ``chromium`` and an ``apt-get`` that fails: the script exits non-zero before the
    tests (before: exit 0 with the tests run, and the browser tests skipped)."""
    (tmp_path / ".ci").mkdir()
    shutil.copy(ROOT / ".ci" / "run", tmp_path / ".ci" / "run")
    (tmp_path / "Makefile").write_text("test:\n\t@echo TESTS RAN\n")
    bin_ = tmp_path / "bin"
    bin_.mkdir()
    for tool in ("bash", "sh", "dirname", "make", "env", "cat", "echo"):
        found = shutil.which(tool)
        if found:
            (bin_ / tool).symlink_to(found)
    fake = bin_ / "apt-get"
    fake.write_text("#!/bin/sh\necho 'E: Unable to locate package chromium' >&2\nexit 100\n")
    fake.chmod(0o755)
    p = subprocess.run([str(bin_ / "bash"), str(tmp_path / ".ci" / "run")], env={"PATH": str(bin_)},
                       capture_output=True, text=True, timeout=60)
    assert p.returncode != 0, p.stdout + p.stderr
    assert "TESTS RAN" not in p.stdout


_CASES = '''
import pytest


def test_needs_the_browser():
    pytest.skip("/usr/bin/chromium not installed (apt-get install chromium; .ci/run installs it)")


def test_needs_playwright():
    pytest.skip("playwright (the 'test' extra) not installed")


def test_skips_for_another_reason():
    pytest.skip("the dask extra is not installed")
'''


def _run_pytest(tmp_path, ci):
    shutil.copy(ROOT / "tests" / "conftest.py", tmp_path / "conftest.py")
    (tmp_path / "test_cases.py").write_text(_CASES)
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    env["MULTILAT_CACHE_DIR"] = str(tmp_path / "cache")
    if ci is not None:
        env["CI"] = ci
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rfs", str(tmp_path)],
                          env=env, capture_output=True, text=True, timeout=300, cwd=tmp_path)


def test_browser_skips_fail_under_ci(tmp_path):
    p = _run_pytest(tmp_path, "true")
    assert p.returncode == 1, p.stdout
    assert "2 failed, 1 skipped" in p.stdout, p.stdout
    assert "CI=true: a browser test may not skip" in p.stdout


def test_browser_skips_stay_skips_outside_ci(tmp_path):
    p = _run_pytest(tmp_path, None)
    assert p.returncode == 0, p.stdout
    assert "3 skipped" in p.stdout, p.stdout
