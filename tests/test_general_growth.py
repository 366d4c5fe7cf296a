"""Issue 29: the general layer's statistics and data snooping make no pass over all rows per point.

No timing (this machine is shared): a count. Every numpy call made by :mod:`.snooping` and
:mod:`.quality` (their module's ``np``, wrapped) during ``snoop`` on a distance-only network of
8 stations x 40 targets and on the same network 4x larger (``synthetic_network`` "rings"; one
distance made a 20 σ blunder, so one round of detection, identification, the gross-error gate and
a new adjustment runs). A step with a loop over points or rows (``np.any(ref == p)`` per point: the
gate before commit e686776, 244 of 296 s of ``multilat adjust --model general`` at 8 x 16 000)
makes one call or more per point, 120 more on the 4x network (measured with that gate: 82 and
202 calls); the code without such a loop makes the same number of calls on both (37 and 37). And
the calls of ``GeneralResult.point_cofactor``: the statistics asked it once per point before (144
and 504 over the three ``statistics`` of the run), none now (:func:`.quality.point_cofactors`). The snooping result is checked too (the blunder is the one rejected), so the count is that
of the real path.
"""

from __future__ import annotations

import numpy as np
import pytest

from multilat.network.model.data import Observations, Points
from multilat.network.adjust.general import quality, snooping
from multilat.network.adjust.general.adjust import GeneralResult
from multilat.network.adjust.general.from_tables import network_from_tables
from multilat.network.model.observations import Network
from multilat.network.adjust.general.run import adjust_network
from multilat.network.synthetic.generator import synthetic_network


class _Counting:
    """A stand-in for a module's ``np``: counts the calls of its functions (types and constants pass)."""

    def __init__(self):
        self.calls = 0

    def __getattr__(self, name):
        a = getattr(np, name)
        if not callable(a) or isinstance(a, type):
            return a

        def counted(*args, **kw):
            self.calls += 1
            return a(*args, **kw)
        return counted


def _network(t: int, blunder_row: int = 11):
    s = 8
    syn = synthetic_network(3, population="rings", n_stations=s, n_targets=t, per_target=7)
    d = syn.distance_m.copy()
    d[blunder_row] += 20.0 * syn.sigma_m[blunder_row]
    obs = Observations(tuple(f"S{i}" for i in range(s)), tuple(f"T{j}" for j in range(t)), syn.station_index,
                       syn.target_index, d, syn.sigma_m)
    pts = Points(obs.station_ids + obs.target_ids, np.vstack([syn.station_xyz_m, syn.target_xyz_m]))
    net, opt = network_from_tables(obs, points=pts)
    return net, opt


def _calls(monkeypatch, t: int) -> tuple[int, int, int]:
    net, opt = _network(t)
    assert isinstance(net, Network)
    adj = adjust_network(net, options=opt)
    counters = []
    for mod in (snooping, quality):
        c = _Counting()
        monkeypatch.setattr(mod, "np", c)
        counters.append(c)
    per_point = _Counting()
    one = GeneralResult.point_cofactor

    def point_cofactor(self, pid):
        per_point.calls += 1
        return one(self, pid)
    monkeypatch.setattr(GeneralResult, "point_cofactor", point_cofactor)
    sn = snooping.snoop(net, options=opt, adjustment=adj)
    monkeypatch.undo()
    assert len(sn.rejected) == 1 and sn.rejected[0]["n_rows"] == 1
    b = sn.adjustment.system.blocks[0]
    assert sn.adjustment.system.n_rows == adj.system.n_rows - 1 and b.n_rows == net.blocks[0].n_rows - 1
    return counters[0].calls, counters[1].calls, per_point.calls


@pytest.mark.parametrize("t", [40])
def test_snooping_and_statistics_make_no_pass_per_point(monkeypatch, t):
    small = _calls(monkeypatch, t)
    large = _calls(monkeypatch, 4 * t)
    # the same calls on the 4x network: nothing loops over points or rows (a few calls of slack for a
    # branch taken on one network only, far below the 3 t more points a per-point pass would visit)
    assert large[0] <= small[0] + 8, (small, large)
    assert large[1] <= small[1] + 8, (small, large)
    assert large[2] == small[2], (small, large)            # no point's cofactor asked one by one


@pytest.mark.parametrize("backend", ["dense", "sparse"])
def test_point_cofactors_are_those_of_each_point(backend):
    """quality.point_cofactors (all points at once) against GeneralResult.point_cofactor point by point
    (the dense Q searched by name; the sparse blocks by index): the same numbers, bit for bit."""
    from dataclasses import replace

    from multilat.network.adjust.general.adjust import adjust

    net, opt = _network(30)
    res = adjust(net, options=replace(opt, backend=backend))
    assert res.backend == backend
    every = quality.point_cofactors(res)
    assert every.shape == (len(res.ids), 3, 3)
    one = np.stack([res.point_cofactor(p) for p in res.ids])
    np.testing.assert_array_equal(every, one)
    assert np.all(np.linalg.eigvalsh(every)[:, -1] > 0)
