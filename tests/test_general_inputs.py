"""Every input and option of ``multilat adjust`` on the general path applied, or refused by name
(issue 26): ``--datum 321`` (the distance path's frame and cofactors, by minimal constraints), raw
readings (the distance path's reader), the sparse back end's size refused before the approximate
chain, and ``--model auto`` deciding on the tables whether polar points take the general layer (the
network adjusted once)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from multilat.cli.app import main
from multilat.errors import MultilatError

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import test_general_csv as gcsv  # noqa: E402  (its known networks and their simulation)

SMALL = ROOT / "examples" / "network" / "small_volume_obs.csv"
MIXED = ROOT / "examples" / "network" / "mixed" / "obs.csv"
CAMPAIGN = ROOT / "examples" / "campaign"


def _run(capsys, *args):
    code = main(["adjust", *map(str, args)])
    out = capsys.readouterr()
    return code, out.out, out.err


def _points(doc):
    """{id: (xyz, cov)} of either document (distance path: stations and targets; general: points)."""
    if "points" in doc:
        return {p: (np.array(v["xyz_m"]), np.array(v["cov_m2"])) for p, v in doc["points"].items()}
    both = {**doc["stations"], **doc["targets"]}
    return {p: (np.array(v["xyz_m"]), np.array(v["cov_m2"])) for p, v in both.items()}


# ----------------------------------------------------------------------------- --datum 321


@pytest.mark.parametrize("backend", ["dense", "sparse"])
def test_datum_321_equals_the_distance_path(capsys, backend):
    """A distance-only network: the general layer's 3-2-1 (approximate coordinates moved into the
    frame of A, B, C, 6 coordinates held) gives the distance path's coordinates and point covariances
    (its 3-2-1 frame and S-transformed covariance), with either back end. Tolerances: 1e-9 m and 1e-9
    of the largest covariance (measured 3e-15 m, 2e-11): two solvers of one least-squares problem."""
    code, out, err = _run(capsys, SMALL, "--datum", "321:A,B,C", "--json", "--no-snooping")
    assert code == 0, err
    old = json.loads(out)
    code, out, err = _run(capsys, SMALL, "--datum", "321:A,B,C", "--json", "--no-snooping", "--model", "general",
                          "--backend", backend)
    assert code == 0, err
    gen = json.loads(out)
    assert gen["model"] == "general" and gen["dof"] == old["dof"] and gen["defect"] == 0
    assert gen["backend"] == backend
    assert gen["sigma0"] == pytest.approx(old["sigma0"], rel=1e-9)
    assert gen["frame"]["kind"] == "321" and gen["datum"].startswith("3-2-1: A at origin")
    a, g = _points(old), _points(gen)
    assert set(a) == set(g)
    cmax = max(np.abs(c).max() for _, c in a.values())
    for p in a:
        assert np.abs(a[p][0] - g[p][0]).max() < 1e-9, p
        assert np.abs(a[p][1] - g[p][1]).max() < 1e-9 * cmax, p
    assert g["A"][0].tolist() == [0.0, 0.0, 0.0] and g["B"][0][1:].tolist() == [0.0, 0.0] and g["C"][0][2] == 0.0


def _unlevelled_polar_case():
    """heads_tracker_polar's network with the tracker unlevelled (ω, φ estimated): datum defect 6,
    5 polar points the distance path would leave out; noise-free readings of the truth."""
    case = gcsv.heads_tracker_polar(np.random.default_rng(11))
    case.frames = {"AT": (0.004, -0.003, 1.3)}
    case.levelled = ()
    case.rows = [(s, t, *gcsv._reading(case.stations[s], case.frames.get(s), case.targets[t], case.offsets[s]))
                 for s, t in case.pairs]
    return case


def _adjusted(obs, datum):
    from multilat.network.adjust.general import adjust_network
    from multilat.network.adjust.general.from_tables import network_from_tables

    net, options = network_from_tables(obs, datum=datum)
    return adjust_network(net, options=options).result


def _distance_variance(res, p, q):
    """The cofactor of |q - p| from the full cofactor matrix (held coordinates contribute 0)."""
    col = {n: k for k, n in enumerate(res.free_names)}
    xp, xq = res.xyz_m[res.ids.index(p)], res.xyz_m[res.ids.index(q)]
    u = (xq - xp) / np.linalg.norm(xq - xp)
    g = np.zeros(len(res.free_names))
    for a, c in enumerate("xyz"):
        for pid, sign in ((p, -1.0), (q, 1.0)):
            if f"{c}:{pid}" in col:
                g[col[f"{c}:{pid}"]] += sign * u[a]
    return g @ res.cofactor @ g


def test_datum_321_on_a_general_network_closed_form(tmp_path):
    """Heads, an unlevelled tracker and polar points, noise-free: under 3-2-1 on H1, H2, H3 every
    point is the truth in the frame built here (H1 origin, H2 on +x, H3 in the xy-plane) to 1e-9 m;
    the 6 held coordinates have zero cofactor; the cofactors of interpoint distances, invariant
    under a change of datum, equal the free network's (1e-9 relative; both from one linearisation
    of an exact solution)."""
    from multilat.network.io.files import read_observations

    case = _unlevelled_polar_case()
    obs = read_observations(case.write(tmp_path)[0])
    res = _adjusted(obs, "321:H1,H2,H3")
    free = _adjusted(obs, "free")
    assert res.defect == 0 and free.defect == 6 and res.dof == free.dof
    a, b, c = (case.stations[k] for k in ("H1", "H2", "H3"))
    ex = (b - a) / np.linalg.norm(b - a)
    ez = np.cross(ex, c - a)
    ez /= np.linalg.norm(ez)
    rot = np.vstack([ex, np.cross(ez, ex), ez])
    truth = {**case.stations, **case.targets}
    worst = max(np.abs(res.xyz_m[res.ids.index(p)] - rot @ (x - a)).max() for p, x in truth.items())
    assert worst < 1e-9
    held = [("H1", 0), ("H1", 1), ("H1", 2), ("H2", 1), ("H2", 2), ("H3", 2)]
    for p, k in held:
        assert not np.any(res.point_cofactor(p)[k]), (p, k)
    for p, q in [("H1", "Q0"), ("H2", "P03"), ("Q1", "Q4"), ("AT", "H3"), ("P00", "P11")]:
        v321, vfree = _distance_variance(res, p, q), _distance_variance(free, p, q)
        assert v321 == pytest.approx(vfree, rel=1e-9), (p, q)


def test_datum_321_refused_where_the_vertical_is_observed(capsys, tmp_path):
    """Levelled trackers' angles fix the vertical: 3-2-1 cannot mean a rigid motion there. One line,
    exit 2, nothing written; --model auto (the distance path refuses two stations) says the same."""
    ex = ROOT / "examples" / "general" / "two_trackers_csv" / "obs.csv"
    for model in ("general", "auto"):
        out = tmp_path / model
        code, _, err = _run(capsys, ex, "--levelled", "T1,T2", "--datum", "321:T1,T2,P01", "--model", model,
                            "--out", out)
        line = err.strip().splitlines()[-1]
        assert code == 2 and line.startswith("error: --datum 321:T1,T2,P01 does not apply"), err
        assert "levelled station(s) T1, T2" in line and not out.exists()


# ----------------------------------------------------------------------------- raw readings


def test_raw_readings_on_the_general_path_equal_the_distance_path(capsys):
    """The campaign's raw readings, corrected by the distance path's reader (read_campaign): the
    general path's σ0, dof and interpoint distances are the distance path's (``adjust`` on the same
    reader's observations; 1e-9 relative and 1e-9 m: one least-squares problem, two solvers;
    measured σ0 5e-12 relative), with the distance path's default-instrument warning and the
    correction noted."""
    from multilat.campaign.propagation import read_campaign
    from multilat.network.adjust.distance.adjust import adjust

    raw = dict(environment=CAMPAIGN / "environment.csv", heights=CAMPAIGN / "heights.csv")
    obs, corrected = read_campaign(CAMPAIGN / "raw.csv", instrument=None, **raw)
    old = adjust(obs, snooping=False)
    code, out, err = _run(capsys, CAMPAIGN / "raw.csv", "-e", raw["environment"], "--heights", raw["heights"],
                          "--json", "--no-snooping", "--model", "general")
    assert code == 0 and corrected is not None, err
    gen = json.loads(out)
    assert gen["dof"] == old.dof and gen["sigma0"] == pytest.approx(old.sigma0, rel=1e-9)
    assert "no --instrument: the raw readings are corrected and weighted by the distance model" in gen["warnings"][0]
    assert gen["sigma_source"]["kind"] == "raw readings"
    assert any(n.startswith("raw readings corrected") for n in gen["notes"])
    ids = list(old.station_ids) + list(old.target_ids)
    xa = np.vstack([old.station_xyz_m, old.target_xyz_m])
    xg = np.array([gen["points"][p]["xyz_m"] for p in ids])
    da = np.linalg.norm(xa[:, None] - xa[None], axis=-1)
    dg = np.linalg.norm(xg[:, None] - xg[None], axis=-1)
    assert np.abs(da - dg).max() < 1e-9


def test_raw_reading_options_on_an_observation_file_are_refused_as_on_the_distance_path(capsys):
    code, _, err = _run(capsys, MIXED, "--model", "general", "--heights", CAMPAIGN / "heights.csv")
    assert code == 2 and "--environment/--heights/--extrapolate/--max-gap-s apply to raw readings" in err


# ----------------------------------------------------------------------------- sparse size, up front


def test_sparse_size_refused_before_the_approximate_chain(monkeypatch):
    """Over the sparse back end's limit (lowered here to 5): refused from the design alone, the
    approximate chain never run, in the elimination's words with the bound (30 here, which the
    elimination reaches: the bound is never above the reduced system it forms)."""
    import multilat.network.adjust.general.from_tables as ft
    import multilat.network.adjust.general.sparse as sparse
    from multilat.network.io.files import read_observations
    from multilat.network.adjust.general import adjust_network

    obs = read_observations(MIXED)
    monkeypatch.setattr(sparse, "MAX_REDUCED", 5)

    def chain(*_, **__):
        raise AssertionError("approximate coordinates computed before the size check")

    import multilat.network.adjust.general.run as general_run
    from multilat.network.adjust.general import read_gama_input
    from multilat.network.adjust.general.adjust import AdjustOptions

    monkeypatch.setattr(general_run, "approximate", chain)            # a gama-local input: adjust_network
    with pytest.raises(MultilatError, match="sparse back end takes a reduced system of at most 5 parameters"):
        general_run.adjust_network(read_gama_input(ROOT / "tests" / "data" / "gama3d" / "two_trackers.xml"),
                                   options=AdjustOptions(backend="sparse"))
    monkeypatch.setattr(ft, "_with_approximations", chain)            # a CSV network: network_from_tables
    with pytest.raises(MultilatError, match=r"^the general model's sparse back end takes a reduced system of at "
                                            r"most 5 parameters; this network leaves at least (\d+) after") as e:
        ft.network_from_tables(obs, backend="sparse")
    bound = int(str(e.value).split("at least ")[1].split()[0])
    monkeypatch.undo()
    net, options = ft.network_from_tables(obs, backend="sparse")
    k = adjust_network(net, options=options).result.blocks.ck.size   # the reduced system formed
    assert 5 < bound <= k
    monkeypatch.setattr(sparse, "MAX_REDUCED", k)                      # at the limit: taken
    general_run.check_sizes(net, options)


# ----------------------------------------------------------------------------- --model auto, polar points


def test_auto_decides_polar_points_before_adjusting(capsys, monkeypatch, tmp_path):
    """Polar points the distance path would leave out: the general layer adjusts the network and the
    distance path never runs (patched to fail); the document is the one --model general gives, with
    the --model auto note first."""
    import multilat.network.adjust.distance.adjust as distance_path

    case = gcsv.heads_tracker_polar(np.random.default_rng(11)).simulate(np.random.default_rng(12))
    args = case.write(tmp_path)

    def adjust(*_, **__):
        raise AssertionError("the distance path ran")

    monkeypatch.setattr(distance_path, "adjust", adjust)
    code, out, err = _run(capsys, *args, "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["model"] == "general" and doc["notes"][0].startswith("--model auto: the self-calibrating model "
                                                                    "would leave out 5 polar point(s)")
    code, out2, _ = _run(capsys, *args, "--json", "--model", "general")
    gen = json.loads(out2)
    assert code == 0 and doc["points"] == gen["points"] and doc["notes"][1:] == gen["notes"]


def test_parquet_observations_are_refused_alike_by_both_paths(capsys, tmp_path):
    """Neither path reads observations as Parquet (the distance path has no such reader to share):
    the same one-line refusal naming the file, exit 2, on both."""
    pq = pytest.importorskip("pyarrow.parquet")
    import pyarrow as pa

    rows = [ln.split(",") for ln in SMALL.read_text().splitlines() if ln and not ln.startswith("#")]
    table = pa.table({c: [r[k] for r in rows[1:]] for k, c in enumerate(rows[0])})
    path = tmp_path / "obs.parquet"
    pq.write_table(table, path)
    said = []
    for model in ("auto", "general"):
        code, _, err = _run(capsys, path, "--model", model)
        assert code == 2 and len(err.strip().splitlines()) == 1, err
        said.append(err.strip())
    assert said[0] == said[1] and said[0].startswith(f"error: {path}") and "not a text file" in said[0]


def test_point_sigmas_outside_control_are_said_as_on_the_distance_path():
    """--points with sx_m, sy_m, sz_m under a datum other than control: approximate coordinates, said
    in the distance path's words (the σ were dropped without a word before)."""
    from multilat.network.model.data import Points
    from multilat.network.io.files import read_observations
    from multilat.network.adjust.general.from_tables import network_from_tables

    pts = Points(("A",), np.zeros((1, 3)), np.full((1, 3), 1e-5))
    with pytest.warns(UserWarning, match=r"make weighted control under --datum control only; here the points "
                                         r"are approximate coordinates"):
        network_from_tables(read_observations(SMALL), points=pts)


def test_unused_instrument_is_refused_as_on_the_distance_path(capsys):
    """--instrument with a file that gives sigma_m for every distance and no angles is used for
    nothing: refused in one line on both paths (the general path ignored it before)."""
    said = []
    for model in ("multilateration", "general"):
        code, _, err = _run(capsys, SMALL, "--instrument", "seed2020", "--model", model)
        assert code == 2 and len(err.strip().splitlines()) == 1, err
        said.append(err.strip())
    assert said[0] == said[1] and "--instrument seed2020: not used" in said[0]
