"""A target whose lines of sight are coplanar is left out and named, never the network refused
(issue 26, "one weak target sinks a whole network").

Independent value: the adjustment of the same network written without the target. Leaving a
target out removes its 3 unknowns and its 3 observations, which touch nothing else (a target with
3 distances has zero redundancy: its residuals are zero and it adds nothing to the normal equations
of the rest once reduced), so the two adjustments solve the same least-squares problem; both are
converged Gauss-Newton solutions from the same start rule, equal to 1e-12 m (a few hundred ulp of
2 m coordinates; the solver stops at a step far below σ = 5 µm)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from multilat.cli import main
from multilat.errors import MultilatError
from multilat.network.adjust.distance.adjust import adjust
from multilat.network.model.data import Observations
from multilat.network.synthetic.generator import synthetic_network

SIGMA = 5e-6
ON = (1, 2, 3)      # the stations that see the weak target; it lies in their plane


def _networks():
    """(with the weak target 'P403', without it): 6 stations, 40 targets seen by all, plus P403 at
    the centroid of stations 1, 2, 3 seen by those 3 only (its sight lines are exactly coplanar)."""
    tr = synthetic_network(1, population="shell", n_stations=6, n_targets=40, sigma_m=SIGMA)
    o, H = tr.obs, tr.station_xyz_m
    P = H[list(ON)].mean(axis=0)
    rho = (np.linalg.norm(H[list(ON)] - P, axis=1) + tr.offset_m[list(ON)]
           + np.random.default_rng(2).normal(0, SIGMA, 3))
    weak = Observations(o.station_ids, list(o.target_ids) + ["P403"],
                        np.r_[o.station_index, ON], np.r_[o.target_index, [o.n_targets] * 3],
                        np.r_[o.distance_m, rho], np.r_[o.sigma_m, [SIGMA] * 3])
    return weak, o


def test_coplanar_sight_target_is_left_out_and_the_rest_adjusted():
    weak, rest = _networks()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = adjust(weak, rng=0)
    assert [(e.id, e.kind, e.n_obs) for e in res.excluded] == [("P403", "target", 3)]
    assert "lines of sight are coplanar" in res.excluded[0].reason
    assert any("'P403' left out" in str(w.message) for w in caught)
    ref = adjust(rest, rng=0)
    assert res.obs.target_ids == rest.target_ids
    np.testing.assert_allclose(res.target_xyz_m, ref.target_xyz_m, rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.station_xyz_m, ref.station_xyz_m, rtol=0, atol=1e-12)
    assert res.dof == ref.dof


def test_strict_refuses_naming_the_target():
    weak, _ = _networks()
    with pytest.raises(MultilatError, match=r"target 'P403' .*lines of sight are coplanar.*--strict"):
        adjust(weak, rng=0, strict=True)


def test_cli_json_lists_it_as_excluded(tmp_path, capsys):
    weak, _ = _networks()
    rows = ["station,target,distance_m,sigma_m"]
    rows += [f"{weak.station_ids[i]},{weak.target_ids[j]},{float(d):.12f},{float(s):g}" for i, j, d, s in
             zip(weak.station_index, weak.target_index, weak.distance_m, weak.sigma_m)]
    path = tmp_path / "obs.csv"
    path.write_text("\n".join(rows) + "\n")
    rc = main(["adjust", str(path), "--json"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    doc = json.loads(out.out)
    assert [e["id"] for e in doc["excluded"]] == ["P403"], doc["excluded"]
    assert "coplanar" in doc["excluded"][0]["reason"]
    rc = main(["adjust", str(path), "--json", "--strict"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "'P403'" in err[0] and "--strict" in err[0], err


def test_three_stations_off_their_plane_stay():
    """A target seen by 3 stations well off their plane is determined (mirror-ambiguous only): kept."""
    weak, rest = _networks()
    from multilat.network.adjust.distance.exclusion import undetermined_targets

    tr = synthetic_network(1, population="shell", n_stations=6, n_targets=40, sigma_m=SIGMA)
    H = tr.station_xyz_m
    T = np.vstack([tr.target_xyz_m, H[list(ON)].mean(axis=0)])
    n = np.cross(H[2] - H[1], H[3] - H[1])
    n /= np.linalg.norm(n)
    assert list(undetermined_targets(weak, H, T)) == ["P403"]
    T[-1] += 0.3 * n                  # 0.3 m off the plane: σ along the normal ~ σL/(h√3) ≈ 0.02 mm
    assert undetermined_targets(weak, H, T) == {}
    T[-1] -= 0.3 * n - 1e-4 * n       # 0.1 mm off: σ there ≈ 60 mm, undetermined
    assert list(undetermined_targets(weak, H, T)) == ["P403"]
