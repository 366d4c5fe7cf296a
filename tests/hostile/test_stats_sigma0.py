"""σ in a wrong unit, and the test procedure's options, from outside (issue 25: the σ0 check both ways)."""

from __future__ import annotations

import json


def _scale_sigma(ws, factor):
    p = ws / "obs.csv"
    lines = p.read_text().splitlines()
    out = []
    for ln in lines:
        if ln.startswith("#") or ln.startswith("station"):
            out.append(ln)
            continue
        c = ln.split(",")
        c[3] = repr(float(c[3]) * factor)
        out.append(",".join(c))
    p.write_text("\n".join(out) + "\n")


def test_sigma_written_in_mm_is_named_everywhere(ws):
    # σ 30x too large: σ0 ~ 0.03 used to say "global test passed" (a unit's factor, >= 100, is stopped
    # before any result: tests/hostile/test_unitslip_cases.py)
    _scale_sigma(ws, 30)
    rc, out, err = ws.run(["adjust", "{d}/obs.csv"])
    assert rc == 0, err
    assert "implausible (too low" in err and "obs.csv" in err and "--variance-factor unknown" in err
    flat = " ".join(out.split())                    # the summary wraps at the terminal's width
    assert "FAILED (lower tail)" in flat and "σ0 too low: IMPLAUSIBLE" in flat
    rc, out, err = ws.run(["adjust", "{d}/obs.csv", "--json"])
    doc = json.loads(out)
    assert doc["sigma0_check"]["verdict"] == "too low" and doc["global_test"]["failed_tail"] == "lower"
    assert any("implausible" in w for w in doc["warnings"])
    # accepted: no warning, the verdict recorded
    rc, out, err = ws.run(["adjust", "{d}/obs.csv", "--variance-factor", "unknown", "--json"])
    doc = json.loads(out)
    assert rc == 0 and "implausible" not in err and doc["sigma0_check"]["accepted"] is True


def test_test_method_options_refused_in_one_line(ws):
    ws.fails(["adjust", "{d}/obs.csv", "--test-method", "bonferroni"], "--test-method", "sidak")
    ws.fails(["adjust", "{d}/obs.csv", "--test-method", "sidak", "--alpha-global", "0.05"], "--alpha-global")
    ws.fails(["adjust", "{d}/obs.csv", "--alpha-family", "1.5"], "--alpha-family")
