"""Issue 26: the general layer on the distance path's acceptance networks
(``benchmarks/study_general_acceptance.py``, docs/general-network.md "Acceptance on random networks").

Each network ``synthetic_network(default_rng([2024, k]), population="field")`` is adjusted from its distances alone by the
distance path (``adjust``) and by the general layer as ``--model general`` builds it from the CSV
(``network_from_tables`` + ``adjust_network``, no approximate coordinates); the two must reach the
same minimum: σ0 equal to 1e-9 relative and every point within 1 µm after a rigid fit (no mirror).
The reference is an independent method: the distance path's own solver and initial values, which the
general layer shares only through the distance-only search of its approximate chain.
"""

import importlib
import importlib.util
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _study():
    spec = importlib.util.spec_from_file_location("study_general_acceptance",
                                                  ROOT / "benchmarks" / "study_general_acceptance.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_compare_tells_same_mirrored_and_worse():
    """The classifier itself, on solutions made by hand: a rotated copy is the same, a reflected
    copy is mirrored, a copy with another σ0 is worse."""
    s = _study()
    rng = np.random.default_rng(1)
    xyz = rng.uniform(-5, 5, (12, 3))
    ids = tuple(f"P{i}" for i in range(12))
    c, sn = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1]])
    d = {"sigma0": 1.0, "ids": ids, "xyz": xyz}
    assert s.compare({"sigma0": 1.0 + 1e-12, "ids": ids[::-1], "xyz": (xyz @ R.T + 3.0)[::-1]}, d)[0] == "same"
    assert s.compare({"sigma0": 1.0, "ids": ids, "xyz": xyz * [1, 1, -1]}, d)[0] == "mirrored"
    assert s.compare({"sigma0": 1.3, "ids": ids, "xyz": xyz + rng.normal(0, 1e-3, xyz.shape)}, d)[0] == "worse"


def test_first_networks_reach_the_distance_paths_minimum():
    """Networks 0..4 (volume, ring and two-level layouts among them): the same minimum, nothing left out."""
    s = _study()
    for k in range(5):
        row = s.study_one(k)
        assert row["outcome"] == "same", row
        assert row["g_out"] == row["d_out"] == [], row


@pytest.mark.slow
def test_general_acceptance_50_networks():
    """Networks 0..49, measured (see the docs section): 50 of 50 at the distance path's minimum, no
    refusal, no point left out on either side. Asserted: at least 49 of 50 the same (one network of
    slack for a change of either path's initial values), none refused, none silently worse than
    the distance path."""
    s = _study()
    rows = [s.study_one(k) for k in range(50)]
    out = [r["outcome"] for r in rows]
    assert out.count("same") >= 49, [(r["k"], r["outcome"]) for r in rows if r["outcome"] != "same"]
    assert out.count("refused") == 0 and out.count("worse") == 0
    assert all(r["g_out"] == r["d_out"] for r in rows)


@pytest.mark.slow
def test_network_87_reaches_the_minimum_on_the_general_layer():
    """Network 87 (7-station flat ring, 17 floor targets): the distance path's search reaches σ0
    1.047 (the truth-start minimum, mirrored); the general layer converges at σ0 132 from the
    search's start, and now (``run._adjusted``) runs the distance path's minimum search only then,
    from its approximations (``approximate/search.py`` ``minimum_search``): the same minimum.
    Slow (21 s of ``make test``'s 300): both paths' searches run in full. The fast run keeps the two
    halves: the trigger (a fit failing by far, :func:`test_sigma_too_small_is_warned`) and the search
    run from the general layer (:func:`test_start_with_a_mirrored_target_is_rescued_by_the_minimum_search`)."""
    row = _study().study_one(87)
    assert row["outcome"] == "same", row
    assert row["g_vs_truth"] in ("same", "mirrored"), row


@pytest.mark.slow
def test_network_616_diverging_is_refused_in_one_line():
    """Network 616: the general layer's Gauss-Newton diverged from the chain's start (the distance path
    refuses it too) and ended in scipy's "array must not contain infs or NaNs" traceback. Now one line:
    since the one loop (``solve.loop.iterate``) damps the rising steps, it no longer diverges but does
    not converge in 50 iterations either (vTPv 3.0e4 at the end, measured)."""
    from multilat.errors import MultilatError
    from multilat.network.adjust.general import adjust_network
    from multilat.network.adjust.general.from_tables import network_from_tables

    obs = _study().network(616).obs
    net, opts = network_from_tables(obs, rng=0)
    with pytest.raises(MultilatError, match=r"(diverged at iteration \d+|did not converge in \d+ iterations) "
                                            r".*--points") as e:
        adjust_network(net, options=opts)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("backend", ["dense", "sparse"])
def test_a_diverging_step_is_refused_in_one_line(monkeypatch, backend):
    """The guard behind network 616 (slow above), fast: a Gauss-Newton step that overflows is never
    carried into the next linearisation (scipy's NaN traceback). Since the one loop
    (``solve.loop.iterate``) such a step is rejected like any step that raises vTPv and damped; when
    every step, damped too, overflows, the adjustment is refused in one line naming the iteration."""
    from multilat.errors import MultilatError
    general_adjust = importlib.import_module("multilat.network.adjust.general.adjust")     # the package's `adjust` is
    sparse_backend = importlib.import_module("multilat.network.adjust.general.sparse")     # the function
    from multilat.network.adjust.approximate.general import approximate
    from multilat.network.io.interop.gama_input import read_gama_input

    net = approximate(read_gama_input(Path(__file__).parent / "data" / "gama3d" / "two_trackers.xml"))
    if backend == "dense":
        real = general_adjust._step
        monkeypatch.setattr(general_adjust, "_step", lambda *a: (np.full_like(real(*a)[0], np.inf), None))
    else:
        real = sparse_backend.frozen_step
        monkeypatch.setattr(sparse_backend, "frozen_step", lambda *a: (np.full_like(real(*a)[0], np.inf), None))
    opts = general_adjust.AdjustOptions(backend=backend)
    with pytest.raises(MultilatError, match=r"diverged at iteration 1 \(no step lowers vTPv .*--points") as e:
        general_adjust.adjust(net, options=opts)
    assert "\n" not in str(e.value)


def _without_minimum_search(monkeypatch):
    """The general layer as it was before the distance path's minimum search joined it: the search's
    start only (network 87 then converges at σ0 132, a false minimum)."""
    from multilat.network.adjust.approximate.general import search

    monkeypatch.setattr(search, "minimum_search", lambda network, rng=0: None)


@pytest.mark.slow
def test_false_minimum_is_warned_and_a_true_one_is_not(monkeypatch):
    """The distance path's "possible false minimum" warning on the general layer
    (:func:`multilat.network.adjust.general.run.false_minimum_warning`): network 87 left at the search's
    start lands at σ0 ~132 (the distance path's search reaches 1.047 there): warned, naming σ0;
    network 0 (σ0 1.06, the distance path's minimum): no warning."""
    import warnings

    from multilat.network.adjust.general import adjust_network
    from multilat.network.adjust.general.run import false_minimum_warning

    s = _study()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        net, opts = _general_input(s, 0)
        good = adjust_network(net, options=opts)
        _without_minimum_search(monkeypatch)
        net, opts = _general_input(s, 87)
        bad = adjust_network(net, options=opts)
    assert false_minimum_warning(good) is None
    assert bad.result.sigma0 > 100                         # the false minimum of the search's start
    w = false_minimum_warning(bad)
    assert w.startswith("possible false minimum: the global test fails by far") and "sigma0 132" in w, w
    assert "nothing lower found" in bad.network.notes[-1]


def _general_input(s, k):
    from multilat.network.adjust.general.from_tables import network_from_tables

    net, opts = network_from_tables(s.network(k).obs, rng=0)
    return net, opts


@pytest.mark.parametrize("k, warned", [pytest.param(87, True, marks=pytest.mark.slow), (0, False)])
def test_false_minimum_warning_in_json_and_on_stderr(tmp_path, monkeypatch, capsys, k, warned):
    """``multilat adjust obs.csv --model general --json``: the warning once in the JSON's ``warnings``
    and once on stderr (network 87 without the minimum search); none for network 0."""
    import json

    from multilat.cli.app import main
    from multilat.network.io.files import write_observations

    path = tmp_path / "obs.csv"
    write_observations(path, _study().network(k).obs)
    _without_minimum_search(monkeypatch)
    assert main(["adjust", str(path), "--model", "general", "--json", "--no-snooping"]) == 0
    out = capsys.readouterr()
    doc = json.loads(out.out)
    said = [w for w in doc["warnings"] if w.startswith("possible false minimum")]
    assert len(said) == int(warned), doc["warnings"]
    assert out.err.count("possible false minimum") == int(warned), out.err


def _flat_ring(seed=5, ns=5, nt=10, dz_m=0.1, z_m=(0.05, 0.3), sigma_m=5e-6):
    """A flat station ring (radius 5 m, heights within ±``dz_m``) with targets just above it, every
    pair measured (noise ``sigma_m``): the distance path's hard case (issue 10)."""
    from multilat.network.model.data import Observations

    rng = np.random.default_rng(seed)
    a = np.linspace(0, 2 * np.pi, ns, endpoint=False)
    H = np.c_[5 * np.cos(a), 5 * np.sin(a), rng.uniform(-dz_m, dz_m, ns)]
    T = np.c_[rng.uniform(-3, 3, (nt, 2)), rng.uniform(*z_m, nt)]
    si, ti = np.repeat(np.arange(ns), nt), np.tile(np.arange(nt), ns)
    d = np.linalg.norm(H[si] - T[ti], axis=1) + rng.normal(0, sigma_m, si.size)
    return Observations(tuple(f"S{i}" for i in range(ns)), tuple(f"T{j}" for j in range(nt)), si, ti, d,
                        np.full(si.size, sigma_m))


def _ring_adjusted():
    """The ring through ``--model general``'s builder and its adjustment (the search's note kept)."""
    import warnings

    from multilat.network.adjust.general import adjust_network
    from multilat.network.adjust.general.from_tables import network_from_tables

    obs = _flat_ring()
    net, opts = network_from_tables(obs, rng=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return obs, net, opts, adjust_network(net, options=opts)


def test_start_with_a_mirrored_target_is_rescued_by_the_minimum_search():
    """The ring's approximations with target T0 mirrored through the stations' plane (the search's
    notes kept: as if the search had put it there): Gauss-Newton from them diverges; the general
    layer then runs the distance path's minimum search (``run._adjusted``) and reaches the minimum
    of the unmirrored start (σ0 to 1e-9 relative, points to 1 µm). Before, the divergence was the
    answer (and with the search run always, a full distance-path adjustment on every network)."""
    import warnings

    from multilat.network.adjust.general import adjust_network
    from multilat.network.model.observations import Network

    s = _study()
    obs, net, opts, good = _ring_adjusted()
    xyz = good.result.xyz_m.copy()
    H = xyz[:obs.n_stations]
    c, n = H.mean(0), np.linalg.svd(H - H.mean(0))[2][2]
    xyz[obs.n_stations] -= 2 * ((xyz[obs.n_stations] - c) @ n) * n
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = adjust_network(Network(net.points.with_xyz(xyz), net.blocks, net.notes), options=opts)
    assert got.network.notes[-1].startswith("the distance path's minimum search: not converged"), got.network.notes
    row = {"sigma0": float(got.result.sigma0), "ids": got.result.ids, "xyz": got.result.xyz_m}
    ref = {"sigma0": float(good.result.sigma0), "ids": good.result.ids, "xyz": good.result.xyz_m}
    assert s.compare(row, ref)[0] in ("same", "mirrored")


def test_sigma_too_small_is_warned(monkeypatch):
    """σ 30x too small on the ring, started at its minimum: the global test fails by far, the minimum
    search (stubbed here: it finds nothing lower, as the distance path's does on this input, measured
    in 490 s under load) leaves it, and the general layer says "possible false minimum" with σ0
    exactly 30x that of the stated σ (the weights scale, the minimum does not: closed form); at the
    stated σ no warning."""
    import dataclasses
    import warnings

    from multilat.network.adjust.general import adjust_network
    from multilat.network.model.observations import Network
    from multilat.network.adjust.general.run import false_minimum_warning

    obs, net, opts, good = _ring_adjusted()
    assert false_minimum_warning(good) is None
    small = Network(net.points.with_xyz(good.result.xyz_m),
                    tuple(dataclasses.replace(b, sigma=b.sigma / 30) for b in net.blocks), net.notes)
    _without_minimum_search(monkeypatch)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        adj = adjust_network(small, options=opts)
    assert adj.result.sigma0 == pytest.approx(30 * good.result.sigma0, rel=1e-6)
    w = false_minimum_warning(adj)
    assert w is not None and w.startswith("possible false minimum: the global test fails by far"), w
    assert f"sigma0 {adj.result.sigma0:.3g}" in w
