"""Absurd option values on every command: refused before any work starts, one line naming the
option, exit 2, no file written."""

from __future__ import annotations

import pytest

HUGE = "99999999999999999999"

CASES = [
    # seeds
    (["adjust", "{d}/obs.csv", "--seed", "-1"], "--seed"),
    (["simulate", "small-volume", "--seed", "-1"], "--seed"),
    (["propagate", "small-volume", "--seed", "-1"], "--seed"),
    (["budget", "--seed", "-1"], "--seed"),
    (["lbb", "simulate", "--seed", "-1"], "--seed"),
    (["lbb", "compare", "{d}/m60_edges.csv", "{d}/m60_ref.csv", "--seed", "-5"], "--seed"),
    (["budget", "--seed", "1" + "0" * 40], "--seed"),
    # trials
    (["propagate", "small-volume", "--trials", HUGE], "--trials"),
    (["propagate", "small-volume", "--trials", "0"], "--trials"),
    (["propagate", "small-volume", "--trials", "-3"], "--trials"),
    (["simulate", "small-volume", "--trials", HUGE], "--trials"),
    (["simulate", "small-volume", "--trials", "0"], "--trials"),
    (["budget", "--trials", HUGE], "--trials"),
    (["budget", "--trials", "1"], "--trials"),
    (["lbb", "simulate", "--trials", HUGE], "--trials"),
    (["lbb", "simulate", "--trials", "1"], "--trials"),
    (["lbb", "compare", "{d}/m60_edges.csv", "{d}/m60_ref.csv", "--trials", HUGE], "--trials"),
    (["propagate", "small-volume", "--trials", "abc"], "--trials"),
    (["propagate", "small-volume", "--trials", "1e3"], "--trials"),
    # sizes and counts
    (["lbb", "simulate", "--grid", "100000"], "--grid"),
    (["lbb", "simulate", "--grid", "1"], "--grid"),
    (["lbb", "simulate", "--grid", HUGE], "--grid"),
    (["propagate", "small-volume", "--chunk-size", "0"], "--chunk-size"),
    (["propagate", "small-volume", "--workers", "0"], "--workers"),
    (["propagate", "small-volume", "--workers", "100000"], "--workers"),
    # sigma and offsets
    (["adjust", "{d}/obs.csv", "--sigma-um", "1e300"], "--sigma-um"),
    (["adjust", "{d}/obs.csv", "--sigma-um", "1e-300"], "--sigma-um"),
    (["adjust", "{d}/obs.csv", "--sigma-um", "nan"], "--sigma-um"),
    (["adjust", "{d}/obs.csv", "--sigma-um", "-4"], "--sigma-um"),
    (["simulate", "small-volume", "--sigma-um", "1e300"], "--sigma-um"),
    (["simulate", "small-volume", "--sigma-um", "0"], "--sigma-um"),
    (["propagate", "small-volume", "--sigma-um", "inf"], "--sigma-um"),
    (["propagate", "small-volume", "--noise", "gaussian", "--sigma-um", "1e7"], "--sigma-um"),
    (["two-face", "{d}/two_face.csv", "--sigma-um", "1e300"], "--sigma-um"),
    (["two-face", "{d}/two_face.csv", "--sigma-um", "-1"], "--sigma-um"),
    (["adjust", "{d}/obs.csv", "--fix-offsets-um", "1e300"], "--fix-offsets-um"),
    (["adjust", "{d}/obs.csv", "--fix-offsets-um", "A=1e300"], "--fix-offsets-um A"),
    (["adjust", "{d}/obs.csv", "--fix-offsets-um", "Z=0"], "--fix-offsets-um"),
    (["adjust", "{d}/obs.csv", "--fix-offsets-um", "A=x"], "--fix-offsets-um"),
    (["adjust", "{d}/obs.csv", "--fix-offsets-um", "inf"], "--fix-offsets-um"),
    (["correct", "{d}/raw.csv", "-e", "{d}/env.csv", "--max-gap-s", "-1"], "--max-gap-s"),
    (["correct", "{d}/raw.csv", "-e", "{d}/env.csv", "--max-gap-s", "nan"], "--max-gap-s"),
    # choices
    (["adjust", "{d}/obs.csv", "--solver", "magic"], "--solver"),
    (["adjust", "{d}/obs.csv", "--cost", "cubic"], "cost"),
    (["adjust", "{d}/obs.csv", "--datum", "321:A"], "datum"),
    (["adjust", "{d}/obs.csv", "--datum", "nonsense"], "datum"),
    (["simulate", "small-volume", "--noise", "pink"], "--noise"),
    (["simulate", "small-volume", "--start", "random"], "--start"),
    (["propagate", "small-volume", "--noise", "pink"], "--noise"),
    (["lbb", "simulate", "--method", "magic"], "method"),
    (["lbb", "simulate", "--where", "moon"], "--where"),
    (["lbb", "trilaterate", "{d}/edges.csv", "--on-singular", "ignore"], "--on-singular"),
    (["correct", "{d}/raw.csv", "-e", "{d}/env.csv", "--formula", "magic"], "--formula"),
    (["budget", "--head", "Z"], "Z"),
    (["budget", "--instrument", "nosuch"], "nosuch"),
    (["propagate", "small-volume", "--instrument", "{d}/nosuch.toml"], "nosuch.toml"),
    (["simulate", "no-such-volume"], "no-such-volume"),
    (["air", "--temperature-c", "1e300"], "temperature"),
    (["air", "--pressure-hpa", "-5"], "pressure"),
    (["air", "--humidity-pct", "150"], "humidity"),
    (["air", "--wavelength-nm", "0"], "wavelength"),
    (["nosuchcommand"], "nosuchcommand"),
    (["demo", "--seed", "-1"], "--seed"),
    (["demo", "--out", "{d}/obs.csv", "--quick"], "obs.csv"),
    (["budget", "--plot", "{d}"], "--plot"),
    (["adjust", "{d}/obs.csv", "--no-such-option"], "--no-such-option"),
]


@pytest.mark.parametrize("args,needle", CASES, ids=[" ".join(a[:1] + a[2:] if len(a) > 2 else a)[:60]
                                                    for a, _ in CASES])
def test_absurd_option(ws, args, needle):
    ws.fails(args, needle.replace("{d}", str(ws.path)))


def test_scheduler_and_workers_together(ws):
    ws.fails(["propagate", "small-volume", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"],
             "--workers and --scheduler")
