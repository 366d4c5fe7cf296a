"""Campaign files: raw readings, environment log, interpolation in time, vertical gradient."""

import math

import numpy as np
import pytest

from multilat.campaign.environment import beam_environment, read_environment
from multilat.campaign.raw import is_raw_file, parse_time, read_raw
from multilat.errors import MultilatError

C = 299_792_458.0


def _write(p, text):
    p.write_text(text)
    return p


ENV = """time,sensor,height_m,temperature_c,pressure_hpa,humidity_pct
2020-03-10T09:00:00,S1,0.3,19.0,1016.8,40
2020-03-10T10:00:00,S1,0.3,19.6,1016.1,42
2020-03-10T09:00:00,S2,2.4,20.0,1016.8,40
2020-03-10T10:00:00,S2,2.4,20.8,1016.1,42
"""


def test_raw_optical_and_phase_rows(tmp_path):
    f = 4895e6
    half = C / (2 * f)
    L = 7.123456789
    k = math.floor(L / half)
    phase = (L / half - k) * 2 * math.pi
    p = _write(tmp_path / "raw.csv",
               "station,target,time,optical_path_m,phase_rad,frequency_hz,k,approx_distance_m\n"
               f"A,P1,2020-03-10T09:30:00,{L!r},,,,\n"
               f"B,P1,2020-03-10T09:31:00,,{phase!r},{f!r},{k},\n"
               f"C,P1,2020-03-10T09:32:00+01:00,,{phase!r},{f!r},,{L + 0.005!r}\n")
    raw = read_raw(p)
    # eq. (1) with n = 1 gives back the vacuum path; k resolved from a coarse distance 5 mm off
    np.testing.assert_allclose(raw.optical_path_m, [L, L, L], rtol=0, atol=1e-12)
    assert raw.k[2] == k
    assert raw.time_s[1] - raw.time_s[0] == 60.0
    assert raw.time_s[2] - raw.time_s[0] == 120.0 - 3600.0   # +01:00 is one hour earlier in UTC
    assert is_raw_file(p)
    obs = _write(tmp_path / "obs.csv", "station,target,distance_m,sigma_m\nA,P1,1.0,1e-6\n")
    assert not is_raw_file(obs) and not is_raw_file(tmp_path / "missing.csv")


@pytest.mark.parametrize("row,match", [
    ("A,P1,2020-03-10T09:30:00,,6.2832,4895e6,3", r"raw.csv:3: column 'phase_rad': must be in \[0, 2π\), got 6.2832$"),
    ("A,P1,2020-03-10T09:30:00,,-0.1,4895e6,3", r"raw.csv:3: column 'phase_rad'"),
    ("A,P1,2020-03-10T09:30:00,,1.0,0,3", r"raw.csv:3: column 'frequency_hz': must be > 0"),
    ("A,P1,10 March 2020,,1.0,4895e6,3", r"raw.csv:3: column 'time': not an ISO 8601 time"),
    ("A,P1,2020-03-10T09:30:00,,1.0,4895e6,", r"raw.csv:3: k missing and no approx_distance_m"),
    ("A,P1,2020-03-10T09:30:00,,1.0,4895e6,2.5", r"raw.csv:3: column 'k': must be an integer"),
    ("A,P1,2020-03-10T09:30:00,5.0,1.0,4895e6,3", r"raw.csv:3: give optical_path_m or phase_rad"),
    ("A,P1,2020-03-10T09:30:00,,,,", r"raw.csv:3: neither optical_path_m nor phase_rad"),
])
def test_raw_bad_rows_name_the_line(tmp_path, row, match):
    p = _write(tmp_path / "raw.csv", "station,target,time,optical_path_m,phase_rad,frequency_hz,k\n"
               "A,P0,2020-03-10T09:29:00,3.0,,,\n" + row + "\n")
    with pytest.raises(MultilatError, match=match):
        read_raw(p)


def test_raw_humidity_over_100_names_row(tmp_path):
    p = _write(tmp_path / "raw.csv", "station,target,optical_path_m,temperature_c,pressure_hpa,humidity_pct\n"
               "A,P1,3.0,20,1013,50\nA,P2,3.0,20,1013,100.5\n")
    with pytest.raises(MultilatError, match=r"raw.csv:3: column 'humidity_pct': 100.5 outside"):
        read_raw(p)
    e = _write(tmp_path / "env.csv", ENV.replace("19.6,1016.1,42", "19.6,1016.1,101"))
    with pytest.raises(MultilatError, match=r"env.csv:3: column 'humidity_pct'"):
        read_environment(e)


def test_environment_log_errors(tmp_path):
    e = _write(tmp_path / "env.csv", ENV + "2020-03-10T10:00:00,S2,2.4,20.8,1016.1,42\n")
    with pytest.raises(MultilatError, match=r"env.csv:6: sensor 'S2' has two readings"):
        read_environment(e)
    e = _write(tmp_path / "env.csv", ENV + "2020-03-10T11:00:00,S2,2.0,20.8,1016.1,42\n")
    with pytest.raises(MultilatError, match=r"env.csv:6: sensor 'S2' changes height"):
        read_environment(e)
    e = _write(tmp_path / "env.csv", ENV.replace(",S2,2.4,", ",S2,,"))
    with pytest.raises(MultilatError, match=r"env.csv:4: sensor 'S2' has no height_m; with several sensors"):
        read_environment(e)
    e = _write(tmp_path / "env.csv", ENV.replace("2020-03-10T10:00:00,S1", "10h,S1"))
    with pytest.raises(MultilatError, match=r"env.csv:3: column 'time'"):
        read_environment(e)


def test_interpolation_in_time_and_refusal_outside_span(tmp_path):
    log = read_environment(_write(tmp_path / "env.csv", ENV))
    t0 = parse_time("2020-03-10T09:00:00")
    times = t0 + np.array([0.0, 900.0, 1800.0, 3600.0])
    # one quarter, half-way: linear interpolation between the two readings of each sensor
    be = beam_environment(log, times, mid_height_m=np.full(4, 0.3))
    np.testing.assert_allclose(be.sensor_values["temperature_c"][:, 0], [19.0, 19.15, 19.3, 19.6], atol=1e-12)
    np.testing.assert_allclose(be.sensor_values["temperature_c"][:, 1], [20.0, 20.2, 20.4, 20.8], atol=1e-12)
    np.testing.assert_allclose(be.values["pressure_hpa"], 1016.8 - 0.7 * times.__sub__(t0) / 3600, atol=1e-9)
    # a beam at the height of sensor 1 gets sensor 1's temperature (two sensors: the line through them)
    np.testing.assert_allclose(be.values["temperature_c"], be.sensor_values["temperature_c"][:, 0], atol=1e-12)
    late = times.copy()
    late[2] = t0 + 3601.0
    with pytest.raises(MultilatError, match=r"observation 3: time 2020-03-10T10:00:01Z has no reading of "
                                            r"sensor 'S1'"):
        beam_environment(log, late, mid_height_m=np.full(4, 0.3))
    with pytest.warns(UserWarning, match="extrapolated"):
        be = beam_environment(log, late, mid_height_m=np.full(4, 0.3), extrapolate=True)
    assert be.extrapolated.tolist() == [False, False, True, False]
    np.testing.assert_allclose(be.sensor_values["temperature_c"][2, 0], 19.6 + 0.6 / 3600, atol=1e-12)
    with pytest.raises(MultilatError, match="observation 1: .*heights are needed"):
        beam_environment(log, times)
    with pytest.raises(MultilatError, match="observation 2: station or target height missing"):
        beam_environment(log, times, mid_height_m=np.array([1.0, np.nan, 1.0, 1.0]))


def test_gradient_fit_is_least_squares_and_beam_average(tmp_path):
    # four sensors on a non-linear profile: the weights must give the least-squares line (np.polyfit)
    z = np.array([0.3, 0.7, 1.4, 2.4])
    temp = np.array([19.0, 19.05, 19.1, 20.0])
    text = "time,sensor,height_m,temperature_c,pressure_hpa,humidity_pct\n" + "".join(
        f"2020-03-10T09:00:00,S{i},{z[i]},{temp[i]},{1016 + i * 0.1},{40 + i}\n" for i in range(4))
    log = read_environment(_write(tmp_path / "env.csv", text))
    mids = np.array([0.5, 1.0, 1.75, 3.0])
    be = beam_environment(log, None, mid_height_m=mids, size=4)
    slope, icpt = np.polyfit(z, temp, 1)
    np.testing.assert_allclose(be.values["temperature_c"], icpt + slope * mids, atol=1e-12)
    np.testing.assert_allclose(be.gradient_c_per_m, slope, atol=1e-12)
    np.testing.assert_allclose(be.weights[:, :, 0].sum(axis=1), 1.0, atol=1e-12)
    # pressure and humidity: the mean of the sensors
    np.testing.assert_allclose(be.values["pressure_hpa"], 1016.15, atol=1e-12)
    # a beam from z=0.2 to z=2.0 sees the average of the fitted line along it (numerical quadrature)
    zz = np.linspace(0.2, 2.0, 100001)
    np.testing.assert_allclose(be.values["temperature_c"][1] - (icpt + slope * 1.0), 0, atol=1e-12)
    assert abs(np.trapezoid(icpt + slope * zz, zz) / 1.8 - (icpt + slope * 1.1)) < 1e-9


def test_single_height_needs_no_heights(tmp_path):
    text = ("time,sensor,height_m,temperature_c,pressure_hpa,humidity_pct,co2_ppm\n"
            "2020-03-10T09:00:00,S1,,20.0,1013.25,50,400\n2020-03-10T09:10:00,S1,,21.0,1013.25,50,420\n")
    log = read_environment(_write(tmp_path / "env.csv", text))
    be = beam_environment(log, np.array([parse_time("2020-03-10T09:05:00")]))
    assert be.values["temperature_c"][0] == pytest.approx(20.5, abs=1e-12)
    assert be.values["co2_ppm"][0] == pytest.approx(410.0, abs=1e-12)


def test_readings_reproduced_at_their_own_times(tmp_path):
    # at a log time the interpolation must return the reading itself (no off-by-one at the ends)
    log = read_environment(_write(tmp_path / "env.csv", ENV))
    t = np.array([parse_time("2020-03-10T09:00:00"), parse_time("2020-03-10T10:00:00")])
    be = beam_environment(log, t, mid_height_m=np.array([0.3, 2.4]))
    np.testing.assert_allclose(be.sensor_values["temperature_c"], [[19.0, 20.0], [19.6, 20.8]], atol=0)
    np.testing.assert_allclose(be.sensor_values["humidity_pct"], [[40, 40], [42, 42]], atol=0)
    # beams at the sensor heights: each sensor's own temperature (two sensors: the line through them)
    np.testing.assert_allclose(be.values["temperature_c"], [19.0, 20.8], atol=1e-12)
    assert not be.extrapolated.any()


def test_a_long_gap_in_a_sensor_log_is_refused_not_bridged(tmp_path):
    """S1 logs every 5 min but is silent 09:30-11:00: an observation at 10:15 would get a value
    interpolated over 90 min (stale); it is refused naming the row, the sensor and the gap, and with
    --extrapolate (or a larger max_gap_s) interpolated with a warning. Readings at the gap's ends and
    times in regular intervals are untouched."""
    rows = ["time,sensor,height_m,temperature_c,pressure_hpa,humidity_pct"]
    for minute in list(range(0, 31, 5)) + list(range(120, 181, 5)):
        t = f"2020-03-10T{9 + minute // 60:02d}:{minute % 60:02d}:00"
        rows.append(f"{t},S1,0.3,{19.0 + 0.01 * minute:.3f},1016.5,40")
    log = read_environment(_write(tmp_path / "env.csv", "\n".join(rows) + "\n"))
    t0 = parse_time("2020-03-10T09:00:00")
    ok = t0 + np.array([120.0, 1800.0, 7200.0, 7500.0])         # in regular intervals / at the gap's ends
    be = beam_environment(log, ok)
    np.testing.assert_allclose(be.values["temperature_c"], 19.0 + 0.01 * (ok - t0) / 60, atol=1e-12)
    stale = t0 + np.array([120.0, 4500.0])
    with pytest.raises(MultilatError, match=r"observation 2: time 2020-03-10T10:15:00Z falls in a 90.0 min "
                                            r"gap of sensor 'S1'"):
        beam_environment(log, stale)
    with pytest.warns(UserWarning, match="gap"):
        be = beam_environment(log, stale, extrapolate=True)
    assert be.extrapolated.tolist() == [False, True]
    be = beam_environment(log, stale, max_gap_s=5400.0)       # the user accepts 90 min
    assert not be.extrapolated.any()
    with pytest.raises(MultilatError, match="max_gap_s must be > 0"):
        beam_environment(log, stale, max_gap_s=0.0)


@pytest.mark.parametrize("column, first, second, expect", [
    ("humidity_pct", "60", "90", r"humidity_pct of sensor 'S1' extrapolated to 120 .*\[0, 100\]"),
    ("co2_ppm", "1200", "1900", r"co2_ppm of sensor 'S1' extrapolated to 2600 .*\[0, 2000\]"),
    ("humidity_pct", "30", "10", r"humidity_pct of sensor 'S1' extrapolated to -10 .*\[0, 100\]"),
])
def test_extrapolated_air_outside_the_formula_range_is_refused(tmp_path, column, first, second, expect):
    """``--extrapolate`` past the log's end: a humidity or CO2 carried outside the air formula's
    range (0-100 %RH, 0-2000 ppm; :mod:`multilat.air`) is refused naming the observation, the
    sensor and the value (it was clipped silently to the range's end). Linear extrapolation one
    more hour: 60 -> 90 -> 120 %RH; 1200 -> 1900 -> 2600 ppm; 30 -> 10 -> -10 %RH."""
    other = "humidity_pct" if column == "co2_ppm" else "co2_ppm"
    base = {"humidity_pct": "40", "co2_ppm": "450"}[other]
    p = _write(tmp_path / "env.csv", f"time,sensor,height_m,temperature_c,pressure_hpa,{column},{other}\n"
               f"2020-03-10T09:00:00,S1,,19.0,1016.8,{first},{base}\n"
               f"2020-03-10T10:00:00,S1,,19.2,1016.7,{second},{base}\n")
    log = read_environment(p)
    t0 = parse_time("2020-03-10T09:00:00")
    times = t0 + np.array([1800.0, 3600.0, 7200.0])
    with pytest.raises(MultilatError, match=r"^observation 3: " + expect + r" \(1 observation\(s\)\)"), \
            pytest.warns(UserWarning, match="extrapolated"):
        beam_environment(log, times, extrapolate=True)
    with pytest.warns(UserWarning, match="extrapolated"):        # inside the range: extrapolated, kept
        be = beam_environment(log, t0 + np.array([1800.0, 4000.0]), extrapolate=True)
    slope = (float(second) - float(first)) / 3600
    np.testing.assert_allclose(be.values[column], [float(first) + 1800 * slope, float(first) + 4000 * slope],
                               rtol=1e-12)
