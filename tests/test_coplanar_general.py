"""One exactly coplanar target does not sink a general network; a tracker's angles keep it on both
paths (helper coplanar, issue 27's general layer; issue 26, "one weak target sinks a whole network").

The network is ``tests/test_weak_targets.py``'s: 6 stations, 40 targets seen by all, and P403 at
the centroid of stations 1, 2, 3 seen by those 3 only, so its lines of sight are exactly coplanar.
Before: the general layer's distance-only search (approximate coordinates) failed as a whole on
P403 and the run refused every point; the distance path's initial values left P403 out even when
station 1, a tracker, reads its angles (the general layer kept it: two answers to one network).

Independent value: the other path on the same network (the distance path's own initial values,
exclusion rule and solver against the general layer's chain, kinds and solver). Both are converged
Gauss-Newton solutions of the same least-squares problem: σ0 equal to 1e-9 relative (both stop at
steps ~1e-12 of the coordinates; seen: 1.2e-12 and 2.2e-12), dof equal exactly. And the truth
where angles keep P403 (the position it was put at)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.adjust.approximate.general import approximate, reasons
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.adjust.general.from_tables import network_from_tables
from multilat.network.adjust.general.run import adjust_network
from multilat.network.adjust.approximate.starts import LARGE_TARGETS
from multilat.network.model.datum import apply_rigid, rigid_fit
from multilat.network.model.weak_points import COPLANAR_REASON
from p403_network import p403_network

SIGMA0_REL = 1e-9           # two converged solvers of one problem (module docstring)


def _quiet(f, *a, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return f(*a, **kw)


def _coplanar(angles: bool, n_targets: int = 40, truth: bool = False):
    """The network (module docstring); ``angles``: station 1 is a tracker reading azimuth and
    elevation (σ 1 arcsecond) of every target it sees, P403 too; ``truth``: also the true stations
    (6, 3) and P403 (3,)."""
    return p403_network(angles, n_targets=n_targets, truth=truth)


def _p403_error_m(res, H_true, P_true) -> float:
    """|P403 - truth| after the adjusted stations are fitted rigidly onto the true ones (the
    adjustment's frame is its datum's)."""
    R, t = rigid_fit(res.station_xyz_m, H_true)
    j = res.obs.target_ids.index("P403")
    return float(np.linalg.norm(apply_rigid(R, t, res.target_xyz_m[j:j + 1])[0] - P_true))


def test_chain_places_every_point_but_the_coplanar_one_and_names_it():
    net, _ = network_from_tables(_coplanar(angles=False), rng=0)
    assert reasons(net) == {"P403": COPLANAR_REASON}
    ready = approximate(net, partial=True)
    placed = np.all(np.isfinite(ready.points.xyz_m), axis=1)
    assert [p for p, ok in zip(ready.points.ids, placed) if not ok] == ["P403"]
    with pytest.raises(MultilatError, match=r"^point 'P403' is undetermined: its lines of sight are coplanar"):
        approximate(net)


def test_general_leaves_it_out_as_the_distance_path_does():
    obs = _coplanar(angles=False)
    d = _quiet(adjust, obs, rng=0, snooping=False)
    net, opts = network_from_tables(obs, rng=0)
    g = _quiet(adjust_network, net, options=opts)
    assert [(e.id, e.reason) for e in d.excluded] == [("P403", COPLANAR_REASON)]
    assert [(e["id"], e["kind"], e["reason"], e["n_obs"]) for e in g.excluded] == [
        ("P403", "point", COPLANAR_REASON, 3)]
    assert "P403" not in g.network.points.ids and len(g.network.points.ids) == 46
    assert g.result.dof == d.dof == 102       # 240 distances - (6 x 4 + 40 x 3) + datum defect 6
    assert abs(g.result.sigma0 - d.sigma0) <= SIGMA0_REL * d.sigma0


def test_a_tracker_reading_it_keeps_it_on_both_paths():
    obs, H, P = _coplanar(angles=True, truth=True)
    d = _quiet(adjust, obs, rng=0, snooping=False)
    # independent value, the truth: P403 where it was put, within 1e-4 m (about 5 times its σ of
    # 10-20 µm, below; seen 8 µm), not in the mirror image or anywhere along the plane's normal
    assert _p403_error_m(d, H, P) < 1e-4
    net, opts = network_from_tables(obs, rng=0)
    g = _quiet(adjust_network, net, options=opts)
    assert [e.id for e in d.excluded] == [] and g.excluded == ()
    assert "P403" in d.obs.target_ids and "P403" in g.network.points.ids
    # 243 distances + 82 angles (41 targets x 2) - (6 stations x 4 + 41 targets x 3 + 3 orientation
    # angles) + datum defect 6 = 181
    assert g.result.dof == d.dof == 181
    assert abs(g.result.sigma0 - d.sigma0) <= SIGMA0_REL * d.sigma0
    # the angles fix P403 across the sight from station 1 (L σ_angle, L ≈ 2-4 m: 10-20 µm), its
    # distances along it: no direction of mm (the distances alone leave the plane's normal free)
    s = np.sqrt(np.diag(g.result.point_cofactor("P403"))) * g.result.sigma0
    assert s.max() < 1e-4, s


def test_cli_general_adjusts_the_rest_and_lists_it(tmp_path, capsys):
    obs = _coplanar(angles=False)
    rows = ["station,target,distance_m,sigma_m"]
    rows += [f"{obs.station_ids[i]},{obs.target_ids[j]},{float(v):.12f},{float(s):g}" for i, j, v, s in
             zip(obs.station_index, obs.target_index, obs.distance_m, obs.sigma_m)]
    path = tmp_path / "obs.csv"
    path.write_text("\n".join(rows) + "\n")
    rc = main(["adjust", str(path), "--model", "general", "--json"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    doc = json.loads(out.out)
    assert [(e["id"], e["reason"]) for e in doc["excluded"]] == [("P403", COPLANAR_REASON)]
    assert doc["dof"] == 102
    rc = main(["adjust", str(path), "--model", "general", "--strict"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "'P403'" in err[0] and "coplanar" in err[0], err
    assert err[0].endswith("(--strict: refused; without it, it would be left out)"), err


def test_large_distance_path_places_it_by_the_tracker_too():
    """Above 500 targets the initial values come from a seed network and multilateration
    (``approximate/large.py``); P403 read by the tracker is placed by its angles there too and kept,
    where it lies (truth, 1e-4 m as above; seen 8.4 µm); without the angles it is left out."""
    obs, H, P = _coplanar(angles=True, n_targets=LARGE_TARGETS + 10, truth=True)
    d = _quiet(adjust, obs, rng=0, snooping=False)
    assert [e.id for e in d.excluded] == []
    assert _p403_error_m(d, H, P) < 1e-4
    d = _quiet(adjust, _coplanar(angles=False, n_targets=LARGE_TARGETS + 10), rng=0, snooping=False)
    assert [(e.id, e.reason) for e in d.excluded] == [("P403", COPLANAR_REASON)]
