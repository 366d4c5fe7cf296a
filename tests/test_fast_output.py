"""Issue 12 items 2-4: the JSON writer (orjson, rows streamed from columns), the compiled statistics
kernels, the quantiles without scipy.stats, the vectorised reader behind ``read_observations``.

Every fast path is compared with the path it replaces (or an independent computation): JSON values
bit for bit (the parsed documents re-serialised by the standard library must be the same text, so
-0.0/0.0 and every last digit count), kernels to 1e-12 relative (another summation order),
quantiles bit for bit (the same scipy.special functions), the reader bit for bit.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from multilat import io as mio
from multilat.io import JsonRows, dumps_json, to_jsonable
from multilat.rows_text import column_tokens
from multilat.network.adjust import covariance as C
from multilat.network.adjust.distance.adjust import Start, adjust
from multilat.network.model.data import Observations
from multilat.network.synthetic.generator import synthetic_network
from multilat.network.adjust.distance.result import result_to_json


def _old(doc) -> str:
    """The writer before issue 12: the standard library on :func:`to_jsonable`."""
    return json.dumps(to_jsonable(doc), indent=2)


def _same_values(a: bytes | str, b: bytes | str) -> bool:
    """Both texts parse to the same values, float bits included (re-serialised by one writer)."""
    return json.dumps(json.loads(a)) == json.dumps(json.loads(b))


@dataclass(frozen=True)
class _Rec:
    x: float
    arr: np.ndarray = field(repr=False)
    _private: int = 7          # to_jsonable writes every field; so must the fast writer


def _awkward_doc():
    rng = np.random.default_rng(3)
    return {
        "nan": float("nan"), "inf": np.inf, "ninf": -np.inf, "neg_zero": -0.0, "np_f64": np.float64(0.1),
        "np_f32": np.float32(0.1), "np_i": np.int64(-3), "np_b": np.bool_(True), "tuple": (1, 2.5, None),
        "path": Path("a/b.csv"), 1: "int key", "unicode": "µm ±σ", "arr": rng.normal(size=(3, 4)) * 1e-7,
        "arr_nan": np.array([1.0, np.nan, np.inf, -np.inf, 5e-324, 1.7976931348623157e308]),
        "arr_f32": np.arange(3, dtype=np.float32) / 3, "arr_int": np.arange(4), "arr_bool": np.array([True, False]),
        "noncontig": np.eye(4)[:, 1], "scalar_arr": np.array(2.5), "rec": _Rec(float("nan"), np.ones(2)),
        "rows": JsonRows({"a": (("x", 'q"', 'z,"","', "µ"), np.array([0, 1, 2, 3, 0])),
                          "v": np.array([1.5, np.nan, -np.inf, -0.0, 1e-310]),
                          "k": np.array([3, -1, 0, 7, 2]), "flag": np.array([True, False, True, True, False])}),
        "nested": [{"rows": JsonRows({"e": np.zeros(0)})}, JsonRows({"f": np.array([0.1, 0.2])})],
    }


def test_fast_json_has_the_values_of_the_old_writer():
    doc = _awkward_doc()
    new = dumps_json(doc)
    assert _same_values(new, _old(doc))
    assert _same_values(dumps_json(doc, indent=False), _old(doc))
    assert new.endswith(b"\n") and json.loads(new)["nan"] is None and json.loads(new)["rec"]["_private"] == 7
    # the stdlib fallback (no orjson) writes the same
    assert mio._orjson() is not None, "orjson is a dependency (pyproject.toml)"


def test_fallback_without_orjson(monkeypatch):
    doc = _awkward_doc()
    fast = dumps_json(doc)
    monkeypatch.setattr(mio, "_orjson", lambda: None)
    assert _same_values(dumps_json(doc), fast)


def test_json_rows_as_a_python_sequence():
    r = JsonRows({"s": (("A", "B"), np.array([1, 0, 1])), "d": np.array([1.0, 2.0, np.nan]),
                  "u": np.array([False, True, False])})
    assert len(r) == 3 and r[0] == {"s": "B", "d": 1.0, "u": False} and r[-1]["s"] == "B"
    assert math.isnan(r[2]["d"]) and [x["s"] for x in r] == ["B", "A", "B"] and len(r[1:]) == 2
    with pytest.raises(IndexError):
        r[3]
    with pytest.raises(ValueError, match="rows"):
        JsonRows({"a": np.zeros(2), "b": np.zeros(3)})


def _network(t=40, s=6, rng=21):
    net = synthetic_network(rng, population="rings", n_stations=s, n_targets=t, per_target=5, size_m=6.0)
    obs = Observations(tuple(f"S{i}" for i in range(s)), tuple(f"T{j}" for j in range(t)),
                       net.station_index, net.target_index, net.distance_m, net.sigma_m)
    return net, obs


def test_adjust_document_same_values_with_nan_and_inf_fields(tmp_path):
    """An adjustment with one offset held (NaN correlations) and a target without redundancy (MDB
    inf): the document through the new writer and the old one, and the CLI's file."""
    net, obs = _network()
    keep = ~((obs.target_index == 3) & (obs.station_index == 0))       # target 3 keeps 4 stations
    sub = Observations(obs.station_ids, obs.target_ids, obs.station_index[keep], obs.target_index[keep],
                       obs.distance_m[keep], obs.sigma_m[keep])
    res = adjust(sub, initial=Start(net.station_xyz_m, net.target_xyz_m, net.offset_m), snooping=False,
                 offsets={"S1": float(net.offset_m[1])})
    doc = result_to_json(res, observations="all")
    old = _old(doc)
    assert "null" in old                          # NaN / inf fields are there
    assert _same_values(dumps_json(doc), old)
    mio.write_json_atomic(tmp_path / "r.json", doc)
    assert _same_values((tmp_path / "r.json").read_bytes(), old)
    rows = json.loads(dumps_json(doc))["observations"]
    assert len(rows) == sub.n_obs and rows[5]["station"] == sub.station_ids[sub.station_index[5]]


def test_cli_json_equals_the_library_document(capsys, tmp_path):
    from multilat.cli.app import main
    from multilat.network.io.files import read_observations

    net, obs = _network(t=30, rng=4)
    p = tmp_path / "obs.csv"
    with open(p, "w") as f:
        f.write("station,target,distance_m,sigma_m\n")
        for k in range(obs.n_obs):
            f.write(f"{obs.station_ids[obs.station_index[k]]},{obs.target_ids[obs.target_index[k]]},"
                    f"{float(obs.distance_m[k])!r},{float(obs.sigma_m[k])!r}\n")
    rc = main(["adjust", str(p), "--json", "--seed", "1"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    out = cap.out
    src = {}      # the CLI records where σ came from; so does the library when asked
    res = adjust(read_observations(p, sigma_source=src), rng=1, sigma_source=src)
    assert src["kind"] == "file column"
    from multilat.vocabulary import stamp

    assert _same_values(out, _old(stamp(result_to_json(res), "adjust")))


# ----------------------------------------------------------------------------- statistics kernels
@pytest.fixture
def kernels_always(monkeypatch):
    from multilat.network.adjust import _covariance_kernels as K

    if not K.HAVE_NUMBA:
        pytest.skip("numba not installed: the numpy path is the only one")
    monkeypatch.setattr(C, "KERNELS_ABOVE_OBS", 0)


@pytest.mark.parametrize("datum", ["free", "321:S0,S1,S2"])
def test_kernels_equal_numpy_and_an_independent_hat_matrix(kernels_always, datum):
    """Hat diagonal, hat rows, target blocks and covariance products from the compiled kernels
    against the numpy path (1e-12 relative), and the hat matrix against the SVD of the whole
    whitened Jacobian (1e-9: its own rounding)."""
    from multilat.network.model.distance import dense_jacobian, residuals_and_jacobian

    net, obs = _network()
    res = adjust(obs, initial=Start(net.station_xyz_m, net.target_xyz_m, net.offset_m), snooping=False,
                 datum=datum, solver="dense")
    cov = res.covariance
    h_k = cov.hat_diagonal()
    h_n = cov.hat_diagonal(kernels=False)
    np.testing.assert_allclose(h_k, h_n, rtol=1e-12, atol=1e-13)
    tb_k, tb_n = cov.target_blocks(), cov.target_blocks(kernels=False)
    assert np.abs(tb_k - tb_n).max() <= 1e-12 * np.abs(tb_n).max()
    V = np.random.default_rng(0).normal(size=(cov.n, 3))
    a = cov.times(V)
    C.KERNELS_ABOVE_OBS = 10**12
    b = cov.times(V)
    assert np.abs(a - b).max() <= 1e-12 * np.abs(b).max()
    C.KERNELS_ABOVE_OBS = 0
    o = obs
    r, Js, Jt = residuals_and_jacobian(o.distance_m, res.station_xyz_m, res.target_xyz_m, res.offset_m,
                                       res.scale, o.station_index, o.target_index)
    A = dense_jacobian(Js, Jt, o.station_index, o.target_index, 6, 40) / o.sigma_m[:, None]
    A = np.delete(A, np.arange(4, 5 * 6, 5), axis=1)
    U, sv, _ = np.linalg.svd(A, full_matrices=False)
    Ur = U[:, : int(np.sum(sv > 1e-10 * sv[0]))]
    np.testing.assert_allclose(h_k, np.sum(Ur ** 2, axis=1), atol=1e-9)
    for k in (0, 17, obs.n_obs - 1):
        row_k = cov.hat_row(k)
        np.testing.assert_allclose(row_k, cov.hat_row(k, kernels=False), rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(row_k, Ur @ Ur[k], atol=1e-9)


def test_sparse_statistics_with_kernels_equal_numpy_and_dense(kernels_always):
    """The whole adjustment (sparse back end) with every statistic by the kernels against the same
    solution with the numpy statistics (1e-12: only the summation order differs), and against the
    dense back end as tests/test_solver_family.py asks of the two back ends (w to 1e-8 absolute: the
    two solutions' residuals differ by ~1e-14 m, 2e-9 sigma)."""
    net = synthetic_network(5, population="rings", n_stations=12, n_targets=300, per_target=8)
    obs = Observations(tuple(f"S{i}" for i in range(12)), tuple(f"T{j}" for j in range(300)),
                       net.station_index, net.target_index, net.distance_m, net.sigma_m)
    start = Start(net.station_xyz_m, net.target_xyz_m, net.offset_m)
    s = adjust(obs, initial=start, solver="sparse", snooping=False)
    C.KERNELS_ABOVE_OBS = 10**12
    n = adjust(obs, initial=start, solver="sparse", snooping=False)
    d = adjust(obs, initial=start, solver="dense", snooping=False)
    np.testing.assert_allclose(s.redundancy, n.redundancy, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(s.w, n.w, rtol=1e-11, atol=1e-13)
    assert np.abs(s.target_cov_m2 - n.target_cov_m2).max() <= 1e-12 * np.abs(n.target_cov_m2).max()
    assert s.w_failure_groups == n.w_failure_groups
    np.testing.assert_allclose(s.redundancy, d.redundancy, atol=1e-9)
    np.testing.assert_allclose(s.target_cov_m2, d.target_cov_m2, rtol=1e-7, atol=1e-20)
    np.testing.assert_allclose(s.w, d.w, rtol=1e-7, atol=1e-8)
    assert s.w_failure_groups == d.w_failure_groups


def test_residual_kernel_equals_numpy(kernels_always):
    """The trial-step residuals from the compiled kernel against the numpy path, on random geometry
    with scales and offsets: the same operations in the same order (bit for bit with numpy 2.4 on
    x86-64, whose einsum sums (x0² + x2²) + x1²); the bound allows a platform whose einsum sums in
    another order: 2 ulp of the distance."""
    from multilat.network.adjust.solve.system import trial_residuals

    rng = np.random.default_rng(4)
    s, t, m = 9, 5000, 40001
    h, tg = rng.normal(size=(s, 3)) * 10, rng.normal(size=(t, 3)) * 10
    off, sc = rng.normal(size=s) * 1e-3, rng.normal(size=s) * 1e-5
    si, ti, d = rng.integers(0, s, m), rng.integers(0, t, m), rng.uniform(1, 30, m)
    a = trial_residuals(d, h, tg, off, sc, si, ti)
    C.KERNELS_ABOVE_OBS = 10**12
    b = trial_residuals(d, h, tg, off, sc, si, ti)
    assert np.all(np.abs(a - b) <= 2 * np.spacing(d))


def test_whitened_jacobian_and_target_gains_kernels_equal_numpy(kernels_always):
    """The fused whitened residuals/Jacobian (distance cost) and the covariance's per-observation
    gains ``P`` from the kernels against the numpy path, with held parameters (an offset, a station's
    coordinates, a control target) and scales: 2 ulp (bit for bit with numpy 2.4 on x86-64)."""
    from multilat.network.model.problem import Params, Problem
    from multilat.network.adjust.solve.system import whitened

    net, obs = _network(t=300, s=7, rng=12)
    rng = np.random.default_rng(3)
    s, t = obs.n_stations, obs.n_targets
    sf = np.ones((s, 5), bool)
    sf[2, 3] = False
    sf[0, :3] = False
    sf[:, 4] = rng.random(s) < 0.5
    tf = np.ones(t, bool)
    tf[[5, 40]] = False
    pb = Problem(obs, "distance", sf, tf)
    p = Params(net.station_xyz_m + rng.normal(0, 1e-3, (s, 3)), net.target_xyz_m + rng.normal(0, 1e-3, (t, 3)),
               net.offset_m + 1e-4, rng.normal(0, 1e-5, s))
    got = whitened(pb, p)
    C.KERNELS_ABOVE_OBS = 10**12
    ref = whitened(pb, p)
    for a, b in zip(got, ref):
        assert a.shape == b.shape
        assert np.all(np.abs(a - b) <= 2 * np.spacing(np.abs(b))), np.abs(a - b).max()
    assert np.all(got[2][tf[obs.target_index] == False] == 0) and np.all(got[1][:, 3][obs.station_index == 2] == 0)  # noqa: E712
    Minv = rng.normal(size=(t, 3, 3))
    C.KERNELS_ABOVE_OBS = 0
    P_k = C.NetworkCovariance(np.eye(5 * s), Minv, got[1], got[2], obs.station_index, obs.target_index).P
    P_n = np.einsum("mij,mj->mi", Minv[obs.target_index], got[2])
    assert np.all(np.abs(P_k - P_n) <= 2 * np.spacing(np.abs(P_n)))


def test_covariance_product_over_the_touched_targets_only_is_the_full_sum(kernels_always):
    """``cov_times`` summing only over the observations of the targets a vector touches (the snooping
    rounds' design rows and generators) gives the bits of the sum over all observations; a vector
    without target part sums over none."""
    from multilat.network.adjust import _covariance_kernels as K

    net, obs = _network(t=200, s=8, rng=6)
    res = adjust(obs, initial=Start(net.station_xyz_m, net.target_xyz_m, net.offset_m), snooping=False,
                 solver="sparse")
    cov = res.covariance
    Qgg, Minv, Js, _, P, si, ti, order, tptr = cov._kernel_args()
    for g in (cov.design_row(3) + 0.5 * cov.design_row(150) - 2.0 * cov.design_row(151),
              np.concatenate([cov.design_row(9)[:5 * cov.s], np.zeros(3 * cov.t)])):
        got = cov.internal_times(g)
        og, ot = np.empty(5 * cov.s), np.empty((cov.t, 3))
        K.cov_times(Qgg, Minv, Js, P, si, ti, order, tptr, g[:5 * cov.s].copy(),
                    g[5 * cov.s:].reshape(cov.t, 3).copy(), og, ot, False, np.zeros(0, np.int64))
        assert np.array_equal(got, np.concatenate([og, ot.ravel()]))


def test_hat_rows_of_combinations_equal_numpy_and_the_dense_hat_matrix(kernels_always):
    """``design_times(internal_times(g))`` for a combination ``g`` of design rows (the downdated
    snooping rounds' hat rows) from the kernels, from numpy, and as the same combination of the
    dense hat matrix's rows (``hat_row``)."""
    net, obs = _network()
    res = adjust(obs, initial=Start(net.station_xyz_m, net.target_xyz_m, net.offset_m), snooping=False,
                 solver="sparse")
    cov = res.covariance
    g = 0.7 * cov.design_row(3) - 1.3 * cov.design_row(50) + 0.2 * cov.design_row(obs.n_obs - 1)
    row_k = cov.design_times(cov.internal_times(g))
    ref = 0.7 * cov.hat_row(3) - 1.3 * cov.hat_row(50) + 0.2 * cov.hat_row(obs.n_obs - 1)
    np.testing.assert_allclose(row_k, ref, rtol=1e-11, atol=1e-13)
    C.KERNELS_ABOVE_OBS = 10**12
    row_n = cov.design_times(cov.internal_times(g))
    np.testing.assert_allclose(row_k, row_n, rtol=1e-12, atol=1e-13)


# ----------------------------------------------------------------------------- quantiles, reader
def test_quantiles_without_scipy_stats_are_bit_identical():
    from scipy import stats

    from multilat.network.adjust import statistics as st

    for a in (0.05, 0.001, 1e-6):
        assert st.norm_ppf(1 - a / 2) == float(stats.norm.ppf(1 - a / 2))
        for dof in (1, 3, 40, 12345, 1_599_934):
            assert st.chi2_ppf(1 - a, dof) == float(stats.chi2.ppf(1 - a, dof))
            assert st.chi2_ppf(a, dof) == float(stats.chi2.ppf(a, dof))
            for x in (0.3, 7.0, 1.2 * dof):
                assert st.chi2_sf(x, dof) == float(stats.chi2.sf(x, dof))


def test_adjust_does_not_import_scipy_stats():
    import subprocess
    import sys

    code = ("import sys; import multilat.cli.network_cmd, multilat.network.adjust.distance.adjust, multilat.network.io.files; "
            "print('scipy.stats' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_small_adjust_does_not_load_numba(tmp_path):
    """A small network's whole ``adjust --json`` (dense back end, no kernels) never imports numba
    (~0.2 s of a 0.6 s command); a large one does (the kernels)."""
    import subprocess
    import sys

    ex = Path(__file__).resolve().parents[1] / "examples" / "network" / "small_volume_obs.csv"
    code = ("import sys, io, contextlib\nfrom multilat.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    rc = main(['adjust', {str(ex)!r}, '--json'])\n"
            "print(rc, 'numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["0", "False"], out.stdout + out.stderr[-300:]


def _big_file(path, rows=40_000, bad_line=None):
    rng = np.random.default_rng(9)
    t = rows // 8
    net = synthetic_network(2, population="rings", n_stations=20, n_targets=t, per_target=8)
    d = net.distance_m * (1 + rng.uniform(-1e-3, 1e-3, net.distance_m.size))     # 17 digits
    lines = [f"S{i},T{j},{x!r},{s!r}" for i, j, x, s in zip(net.station_index.tolist(), net.target_index.tolist(),
                                                            d.tolist(), net.sigma_m.tolist())]
    if bad_line is not None:
        lines[bad_line - 2] = lines[bad_line - 2].rsplit(",", 2)[0] + ",abc,5e-06"
    Path(path).write_text("station,target,distance_m,sigma_m\n" + "\n".join(lines) + "\n")
    return d


def test_large_files_read_vectorised_bit_identical(tmp_path, monkeypatch):
    from multilat.network.io import files

    p = tmp_path / "big.csv"
    d = _big_file(p)
    assert p.stat().st_size >= files.FAST_READ_ABOVE_BYTES
    fast = files.read_observations(p)
    monkeypatch.setattr(files, "FAST_READ_ABOVE_BYTES", 1 << 62)
    slow = files.read_observations(p)
    assert fast.station_ids == slow.station_ids and fast.target_ids == slow.target_ids
    for name in ("station_index", "target_index", "distance_m", "sigma_m"):
        assert np.array_equal(getattr(fast, name), getattr(slow, name)), name
    assert np.array_equal(fast.distance_m, d)


def test_large_file_errors_name_the_line(tmp_path):
    from multilat.errors import MultilatError
    from multilat.network.io import files

    p = tmp_path / "big.csv"
    _big_file(p, bad_line=30_001)
    with pytest.raises(MultilatError, match=r"big.csv:30001: column 'distance_m': not a number: 'abc'"):
        files.read_observations(p)


def test_result_tables_written_from_columns_equal_the_row_writer(tmp_path):
    """targets.csv and observations.csv from the columns: byte for byte the text of the row-by-row csv
    writer they replace (written here row by row), with an id that needs quoting and a rejected row."""
    from multilat.io import write_csv_atomic
    from multilat.network.io.files import write_result_tables

    net, obs = _network(t=25, rng=8)
    tids = tuple(f'T{j}' if j != 4 else 'T,"4"' for j in range(25))
    obs = Observations(obs.station_ids, tids, obs.station_index, obs.target_index, obs.distance_m, obs.sigma_m)
    res = adjust(obs, initial=Start(net.station_xyz_m, net.target_xyz_m, net.offset_m), snooping=False)
    used = res.used.copy()
    used[3] = False
    from dataclasses import replace
    res = replace(res, used=used)
    write_result_tables(res, tmp_path)
    (_, _), (t_ax, _) = res.ellipsoids()
    write_csv_atomic(tmp_path / "old_t.csv", ["target", "x_m", "y_m", "z_m", "x_std_m", "y_std_m", "z_std_m",
                                              "semi_axis_1_95_m", "semi_axis_2_95_m", "semi_axis_3_95_m"],
                     [[tid, *res.target_xyz_m[j], *np.sqrt(np.clip(np.diag(res.target_cov_m2[j]), 0, None)),
                       *t_ax[j][::-1]] for j, tid in enumerate(res.target_ids)])
    o, rel = res.obs, res.reliability
    failed = {int(k) for g in res.w_failure_groups for k in g}
    poor = {int(k) for k in rel.poor_obs}
    write_csv_atomic(tmp_path / "old_r.csv", ["index", "station", "target", "distance_m", "sigma_m", "residual_m",
                                              "redundancy", "w", "mdb_m", "rejected", "w_failed",
                                              "poorly_controlled", "mdb_sigma", "bias_to_noise", "shift_max_m",
                                              "shift_point"],
                     [[k, o.station_ids[o.station_index[k]], o.target_ids[o.target_index[k]], o.distance_m[k],
                       o.sigma_m[k], res.residuals_m[k], res.redundancy[k], res.w[k], res.mdb_m[k],
                       not bool(res.used[k]), k in failed, k in poor, rel.mdb_sigma[k], rel.bnr[k],
                       rel.shift_max_m[k], rel.shift_point[k]] for k in range(o.n_obs)])
    for name, old in (("targets.csv", "old_t.csv"), ("observations.csv", "old_r.csv")):
        assert _csv_cells(tmp_path / name) == _csv_cells(tmp_path / old), name
    new_r = (tmp_path / "observations.csv").read_bytes()
    assert b'"T,""4"""' in new_r and b",True," in new_r


def _csv_cells(path):
    """Every cell of a CSV, numbers as their float64 bits' text (repr), others as written."""
    import csv

    out = []
    with open(path, newline="", encoding="utf-8") as f:
        for row in csv.reader(f):
            cells = []
            for c in row:
                try:
                    cells.append(repr(float(c)))
                except ValueError:
                    cells.append(c)
            out.append(cells)
    return out


def test_float_tokens_parse_to_the_same_floats():
    rng = np.random.default_rng(1)
    v = np.concatenate([rng.normal(size=2000) * 10.0 ** rng.integers(-320, 300, 2000),
                        [0.0, -0.0, np.nan, np.inf, -np.inf, 5e-324, 1e-5, 1e16, 0.1 + 0.2]])
    t = column_tokens(v, mio._orjson(), "csv")
    b = t.buf.tobytes()
    tok = [b[s:s + n] for s, n in zip(t.start.tolist(), t.length.tolist())]
    assert [repr(float(x)) for x in tok] == [repr(x) for x in v.tolist()]
    assert tok[-7:-4] == [b"nan", b"inf", b"-inf"]


def test_decimal_reader_is_correctly_rounded_and_leaves_the_rest_to_numpy():
    """The large-file reader's compiled decimal parser against Python's float() and numpy's cast,
    bit for bit, on 40 000 numbers written in eight formats over 20 decades (the formats of real
    files: fixed, repr, exponent) and on edge cases; what it does not take (too many digits, huge
    exponents, nan, junk) is left to numpy (``fast`` False)."""
    from multilat import _text_kernels as K

    if not K.HAVE_NUMBA:
        pytest.skip("numba not installed")
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 30, 40_000) * 10.0 ** rng.integers(-12, 8, 40_000)
    fmts = ["%.9f", "%r", "%.3e", "%g", "%.17g", "%.15f", "%.1f", "%E"]
    strs = [repr(float(v)) if fmts[i % 8] == "%r" else fmts[i % 8] % v for i, v in enumerate(x)]
    edge = ["5e-06", "1.", ".5", "+1.5", "-0", "1e22", "1e-22", "000012.5", "1e+05", "1E-5"]
    slow = ["1e23", "1e-23", "9007199254740993", "1e", "1.5.2", "nan", "inf", "12a", "",
            "12345678901234567890", "2.2250738585072014e-308", "-", "."]
    strs += edge + slow
    b = ",".join(strs).encode()
    buf = np.frombuffer(b, np.uint8)
    commas = np.flatnonzero(buf == 44)
    starts = np.concatenate([[0], commas + 1]).astype(np.int64)
    ends = np.concatenate([commas, [len(buf)]]).astype(np.int64)
    out, fast = np.empty(len(strs)), np.empty(len(strs), bool)
    K.parse_decimals(buf, starts, ends, K._POW10, out, fast)
    assert not fast[-len(slow):].any() and fast[-len(slow) - len(edge):-len(slow)].all()
    assert fast.sum() > 0.7 * len(x)
    got = out[fast]
    ref = np.array([float(s) for s, f in zip(strs, fast) if f])
    assert np.array_equal(got.view(np.uint64), ref.view(np.uint64))
    cast = np.array([s.encode() for s, f in zip(strs, fast) if f]).astype(np.float64)
    assert np.array_equal(got.view(np.uint64), cast.view(np.uint64))
