"""Geometry that distances cannot fix, through the CLI (issue 25, item 12): coplanar targets leave each
station's side of their plane open (named: a warning, the summary, the JSON 'ambiguous'; --strict
refuses), a network with every point in one plane is refused; a nearly coplanar but determined
network and the shipped example are not flagged."""

from __future__ import annotations

import json

import numpy as np
import pytest


def _write(path, *, heights, target_spread_m=0.0, seed=2):
    """6 stations on a 2 m circle at ``heights``, 20 targets in x, y ∈ [-1, 1], z ∈ ±spread/2, 5 µm."""
    rng = np.random.default_rng(seed)
    ang = np.arange(6) * np.pi / 3 + 0.2
    H = np.c_[2.0 * np.cos(ang), 2.0 * np.sin(ang), heights]
    T = np.c_[rng.uniform(-1, 1, (20, 2)), rng.uniform(-0.5, 0.5, 20) * target_spread_m]
    off = rng.uniform(-3e-3, 3e-3, 6)
    rows = ["station,target,distance_m,sigma_m"]
    for i in range(6):
        for j in range(20):
            d = np.linalg.norm(H[i] - T[j]) + off[i] + rng.normal(0, 5e-6)
            rows.append(f"S{i + 1},T{j + 1:02d},{d:.7f},5e-6")
    path.write_text("\n".join(rows) + "\n")
    return path


HEIGHTS = [0.5, 0.7, 0.6, 0.4, 0.8, 0.6]


def test_coplanar_targets_are_named_in_warning_summary_and_json(ws):
    """Before the fix: exit 0, no warning, 3 of the 6 stations mirrored through the target plane."""
    p = _write(ws / "plane.csv", heights=HEIGHTS)
    rc, out, err = ws.run(["adjust", str(p)])
    assert rc == 0, err
    assert "warning: ambiguous geometry: the side of 6 station(s) (S1, S2, S3, S4, S5, S6)" in err
    assert "ambiguous geometry, 6 point(s) placed only up to a mirror" in " ".join(out.split())
    rc, out, err = ws.run(["adjust", str(p), "--json"])
    doc = json.loads(out)
    assert [a["id"] for a in doc["ambiguous"]] == [f"S{i}" for i in range(1, 7)]
    assert {a["cause"] for a in doc["ambiguous"]} == {"mirror"}
    assert any(w.startswith("ambiguous geometry") for w in doc["warnings"])


def test_coplanar_targets_strict_is_one_line(ws):
    p = _write(ws / "plane.csv", heights=HEIGHTS)
    ws.fails(["adjust", str(p), "--strict"], "ambiguous geometry", "S1", "--strict: refused")


@pytest.mark.parametrize("seed", [8, 2])
def test_everything_in_one_plane_is_refused(ws, seed):
    """Before the fix (seed 8): exit 0, global test passed, points mm off the plane with σ ≈ 1 mm."""
    p = _write(ws / "flat.csv", heights=np.zeros(6), seed=seed)
    ws.fails(["adjust", str(p)], "near-degenerate geometry", "all 26 points (6 stations, 20 targets)",
             "in one plane", "span a volume")


def test_nearly_coplanar_but_determined_is_not_flagged(ws):
    """Targets spread 0.3 m off their plane: no false alarm."""
    p = _write(ws / "near.csv", heights=HEIGHTS, target_spread_m=0.3)
    rc, out, err = ws.run(["adjust", str(p), "--json"])
    assert rc == 0, err
    assert "ambiguous" not in err and json.loads(out)["ambiguous"] == []


def test_the_example_network_is_not_flagged(ws):
    rc, out, err = ws.run(["adjust", "{d}/obs.csv", "--json"])
    assert rc == 0, err
    assert "ambiguous" not in err and json.loads(out)["ambiguous"] == []
