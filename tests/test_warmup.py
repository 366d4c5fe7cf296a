"""``python -m multilat.warmup`` (run by ``make install``) compiles every numba kernel a large
``adjust`` loads, so a user's first command does not compile: after the warm-up in an empty numba
cache, ``multilat adjust`` of a network above every size gate (48 000 distances, 6 000 targets, a
1.3 MB file) with its ``--json`` and ``--out`` outputs saves nothing to the cache
(``NUMBA_DEBUG_CACHE`` reports each compilation it saves). Slow (the warm-up compiles for ~30 s):
``pytest -m slow``."""

import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("numba")


@pytest.mark.slow
def test_first_adjust_after_the_warm_up_compiles_nothing(tmp_path):
    from multilat.network.large import synthetic_network

    net = synthetic_network(20, 6000, 8, rng=4)
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
