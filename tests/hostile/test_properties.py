"""Property tests: whatever the observation file or the options, a result or a one-line error,
never a traceback, and the inputs untouched."""

from __future__ import annotations

import string

from hypothesis import HealthCheck, given, settings, strategies as st

from multilat.errors import MultilatError
from multilat.network.io.fastio import read_observations_fast
from multilat.network.io.files import read_observations

from conftest import assert_one_line_error

ID = st.one_of(st.sampled_from(["A", "B", "C", "T1", "T2", "#X", " A", "[/b]", "\x1b[1m", "é", ""]),
               st.text(string.printable, max_size=6))
NUM = st.one_of(st.sampled_from(["1.0", "2.5", "-1", "0", "nan", "inf", "1e300", "1e-300", "abc", "", "1_0",
                                 "0x10", " 3 "]),
                st.floats(allow_nan=True, allow_infinity=True).map(repr))
ROW = st.tuples(ID, ID, NUM, NUM).map(lambda r: ",".join(r))
HEADERS = st.sampled_from(["station,target,distance_m,sigma_m", "station,target,distance_m",
                           "target,station,distance_m,sigma_m", "station,target", "", "# c\nstation,target,distance_m,sigma_m",
                           "station,target,distance_m,sigma_m,elevation_rad"])
FILES = st.builds(lambda h, rows, tail: (h + "\n" + "\n".join(rows) + tail).encode("utf-8", "surrogatepass"),
                  HEADERS, st.lists(ROW, max_size=12), st.sampled_from(["", "\n", "\n\n", "\r\n", "\xff"]))
SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@SETTINGS
@given(data=FILES)
def test_readers_give_a_result_or_one_line_error(tmp_path, data):
    p = tmp_path / "obs.csv"
    try:
        p.write_bytes(data)
    except UnicodeEncodeError:
        return
    outcomes = []
    for fn in (read_observations, read_observations_fast):
        try:
            o = fn(p, sigma_m=5e-6)
            outcomes.append(("ok", o.station_ids, o.target_ids, o.distance_m.tolist()))
        except MultilatError as exc:
            assert "\n" not in str(exc)
            outcomes.append(("error",))
    # the fast reader refuses other headers by design (the CLI then takes the general reader)
    if not data.lstrip(b"# c\n").startswith(b"station,target,distance_m") or b",elevation_rad" in data:
        return
    assert outcomes[0][0] == outcomes[1][0]
    assert p.read_bytes() == data


@SETTINGS
@given(data=FILES)
def test_adjust_cli_never_tracebacks(ws, data):
    p = ws / "h.csv"
    p.write_bytes(data)
    rc, out, err = ws.run(["adjust", str(p), "--sigma-um", "5", "--no-snooping"])
    assert rc in (0, 2), err
    if rc == 2:
        assert_one_line_error(err)
    assert p.read_bytes() == data


OPTS = st.lists(st.sampled_from([
    ["--trials", "-1"], ["--trials", "0"], ["--trials", "3"], ["--trials", "99999999999999999999"],
    ["--seed", "-7"], ["--seed", "2"], ["--sigma-um", "1e300"], ["--sigma-um", "nan"], ["--sigma-um", "-0"],
    ["--chunk-size", "0"], ["--noise", "x"], ["--datum", "321:Q,R,S"], ["--workers", "0"],
    ["--scheduler", "junk"], ["--json"], ["--instrument", "nope"]]), max_size=3, unique_by=lambda o: o[0])


@SETTINGS
@given(opts=OPTS, cmd=st.sampled_from(["propagate", "simulate", "budget", "lbb simulate"]))
def test_options_never_traceback(ws, opts, cmd):
    """Absurd options only (a valid set would start a long run): each gives an error line."""
    flat = [x for o in opts for x in o]
    valid_only = all(o in (["--seed", "2"], ["--json"], ["--trials", "3"]) for o in opts)
    if valid_only:
        return
    args = cmd.split() + (["small-volume"] if cmd in ("propagate", "simulate") else []) + flat
    rc, out, err = ws.run(args)
    assert rc == 2, (args, err)
    assert_one_line_error(err)
