"""Campaign pipeline benchmark: correct a long raw file (air along each beam + full covariance).

Ours: :func:`multilat.campaign.correct.correct_raw` (analytic sensor Jacobian: 8 extra index
evaluations, whatever the number of sensors). Baseline: the same covariance by brute force, i.e.
re-running the whole correction with each sensor parameter bumped up and down (2 x 4 x S runs),
the obvious way to get the sensor-error Jacobian. Both give the same Jacobian (checked).
"""

from __future__ import annotations


import numpy as np

from common import median_time


def _setup(n_targets: int):
    from multilat import instrument
    from multilat.campaign.worked import simulate_campaign

    rng = np.random.default_rng(1)
    sxyz = np.array([[0, 0, 0], [2.736, 0.056, 1.406], [5.289, 0, 0], [2.692, 6.236, 0.793]])
    txyz = np.column_stack([rng.uniform(-0.5, 6, n_targets), rng.uniform(-1, 10, n_targets),
                            rng.uniform(-0.6, 0.5, n_targets)])
    inst = instrument.load_instrument("seed2020")
    camp = simulate_campaign(("A", "B", "C", "D"), sxyz, tuple(f"P{i}" for i in range(n_targets)), txyz,
                             instrument=inst, rng=2, sensor_errors=True)
    return camp, inst


def _brute_jacobian(camp, inst):
    from dataclasses import replace

    from multilat.campaign.correct import FD_STEPS, correct_raw
    from multilat.campaign.environment import QUANTITIES

    cols = []
    for s in range(len(camp.log.sensor_ids)):
        for q in QUANTITIES:
            h = FD_STEPS[q]
            out = []
            for sign in (1, -1):
                rd = tuple({**r, q: r[q] + (sign * h if k == s else 0.0)} for k, r in enumerate(camp.log.readings))
                out.append(correct_raw(camp.raw, environment=replace(camp.log, readings=rd),
                                       instrument=inst).distance_m)
            cols.append((out[0] - out[1]) / (2 * h))
    return np.column_stack(cols)


_median = median_time


def run(quick: bool = False) -> list[dict]:
    from multilat.campaign.correct import correct_raw

    n_targets = 100 if quick else 250
    camp, inst = _setup(n_targets)
    correct_raw(camp.raw, environment=camp.log, instrument=inst)          # warm the budget cache
    reps = 3 if quick else 5
    ours, _ = _median(lambda: correct_raw(camp.raw, environment=camp.log, instrument=inst), reps)
    base, _ = _median(lambda: _brute_jacobian(camp, inst), 1 if quick else 2)
    res = correct_raw(camp.raw, environment=camp.log, instrument=inst)
    jb = _brute_jacobian(camp, inst)
    agree = float(np.max(np.abs(jb - res.air_jacobian_m)) / np.max(np.abs(res.air_jacobian_m)))
    m = camp.raw.size
    return [{"name": f"campaign correct_raw ({m} readings, 4 sensors, full covariance)",
             "median_s": ours, "baseline": "brute-force sensor Jacobian (32 re-corrections)",
             "baseline_median_s": base, "ratio": base / ours,
             "extra": {"readings": m, "readings_per_s": m / ours, "jacobian_rel_diff": agree}}]


if __name__ == "__main__":
    for r in run(quick=True):
        print(r)
