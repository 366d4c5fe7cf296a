"""The paper's volumes against optimised heads (issue 11, docs/design.md): one study, its table.

For a built-in configuration (seed 000's small or large volume): the paper's four heads and heads
optimised for the same targets in the bounding box of the paper's heads and targets (the room),
criterion ``max_u95`` with the instrument's distance model (``seed2020``), minimum range 0.2 m.
For both layouts:

* the criterion predicted by the pre-analysis and its Monte Carlo value (``simulate_design``,
  non-gaussian distance model);
* the §4.4 statistic (per simulation, the standard deviation of the errors of the reference-pair
  interpoint distances): its first-order prediction (``simulate.linear_prediction``) and the root
  mean square over ``sims`` full re-adjustments from initial values found from the distances
  (``simulate.simulate``, as the paper), with its standard error.

Verdicts (confirmed, gain) are computed here, never typed: :func:`markdown_table` writes the rows of
docs/design.md and a slow test checks the page holds exactly this output.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

__all__ = ["paper_volume_study", "markdown_table"]

#: a Monte Carlo value "confirms" a prediction within this many of its standard errors
Z_CONFIRM = 3.0


def paper_volume_study(name: str, *, evaluations: int = 6000, starts: int = 6, mc_trials: int = 20_000,
                       sims: int = 200, seed: int = 1, criteria=("max_u95", "length_u")) -> dict:
    """Run the study for configuration ``name``; a plain dict (metres) of every layout's numbers.

    ``criteria``: one optimised layout per criterion (``length_u`` over the configuration's
    reference pairs, the §4.4 pairs)."""
    from multilat.instrument import load_instrument
    from multilat.network.synthetic import configs
    from multilat.network.design import SigmaModel, optimise_heads, preanalyse
    from multilat.network.design.confirm import simulate_design
    from multilat.network.montecarlo.simulate import simulate

    cfg = configs.get_config(name)
    inst = load_instrument("seed2020")
    sigma = SigmaModel(instrument=inst)
    pts = np.vstack([cfg.station_xyz_m, cfg.target_xyz_m])
    refs = cfg.reference_lengths
    pairs = tuple(zip(refs.target_a, refs.target_b))
    ss = np.random.SeedSequence(seed).spawn(1 + 2 * (1 + len(criteria)))
    layouts = []
    for k, crit in enumerate(criteria):
        r = optimise_heads(cfg.target_xyz_m, count=4, box_min_m=pts.min(0), box_max_m=pts.max(0),
                           sigma=sigma, target_ids=cfg.target_ids, start=cfg.station_xyz_m, criterion=crit,
                           lengths=pairs if crit == "length_u" else (), min_range_m=0.2, starts=starts,
                           max_evaluations=evaluations, rng=np.random.default_rng(ss[0].spawn(len(criteria))[k]))
        if not layouts:
            layouts.append(("paper", r.start_layout, r.evaluations))
        layouts.append((f"optimised ({crit})", r.layout, r.evaluations))
    out = {"name": name, "layouts": {}}
    for k, (label, lay, n_eval) in enumerate(layouts):
        pa = preanalyse(lay, sigma, lengths=pairs)
        mc = simulate_design(pa, trials=mc_trials, rng=ss[1 + 2 * k], noise="model", instrument=inst)
        row = {"heads_xyz_m": lay.station_xyz_m.tolist(), "evaluations": n_eval,
               "max_u95_predicted_m": pa.criterion("max_u95"), "length_u_predicted_m": pa.criterion("length_u"),
               "max_u95_mc_m": float(mc.mc_u95_max_m.max()), "coordinate_max_abs_z": float(np.abs(mc.z).max()),
               "complete": bool(lay.visible.all())}
        row["u95_confirmed"] = row["coordinate_max_abs_z"] < 4.5
        if lay.visible.all():          # simulate's §4.4 pattern: every head sees every target
            sim = simulate(replace(cfg, station_xyz_m=lay.station_xyz_m), trials=sims, noise="model",
                           instrument=inst, rng=ss[2 + 2 * k])
            s2 = sim.interpoint_std_m ** 2
            rms = float(np.sqrt(s2.mean()))
            row.update(s44_predicted_m=sim.predicted_rms_std_m, s44_mc_rms_m=rms,
                       s44_mc_rms_se_m=float(s2.std(ddof=1) / np.sqrt(len(s2)) / (2 * rms)),
                       s44_mc_mean_m=float(sim.interpoint_std_m.mean()), s44_failed=sim.n_failed,
                       s44_sims=sims)
            row["s44_z"] = (rms - row["s44_predicted_m"]) / row["s44_mc_rms_se_m"]
            row["s44_confirmed"] = abs(row["s44_z"]) < Z_CONFIRM
        out["layouts"][label] = row
    p = out["layouts"]["paper"]
    for label, row in out["layouts"].items():
        if label == "paper":
            continue
        row["gain_max_u95"] = p["max_u95_predicted_m"] / row["max_u95_predicted_m"]
        row["gain_length_u"] = p["length_u_predicted_m"] / row["length_u_predicted_m"]
        if "s44_predicted_m" in p and "s44_predicted_m" in row:
            row["gain_s44"] = p["s44_predicted_m"] / row["s44_predicted_m"]
    return out


def markdown_table(studies) -> str:
    """The docs/design.md table of one or more :func:`paper_volume_study` results."""
    um = 1e6
    lines = ["| volume | heads | max_u95 predicted | max_u95 MC | coordinates: MC vs predicted | "
             "length_u predicted | §4.4 predicted | §4.4 MC (rms ± se) | §4.4 confirmed |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    gains = []
    for d in studies:
        for label, r in d["layouts"].items():
            s44 = ("—", "— (a head within 0.2 m of a target)", "—")
            if "s44_predicted_m" in r:
                s44 = (f"{r['s44_predicted_m'] * um:.2f} µm",
                       f"{r['s44_mc_rms_m'] * um:.2f} ± {r['s44_mc_rms_se_m'] * um:.2f} µm",
                       f"{'yes' if r['s44_confirmed'] else 'no'} (z {r['s44_z']:+.1f})")
            lines.append(f"| {d['name']} | {label} | {r['max_u95_predicted_m'] * um:.1f} µm | "
                         f"{r['max_u95_mc_m'] * um:.1f} µm | "
                         f"{'within' if r['u95_confirmed'] else 'NOT within'} 4.5 SE "
                         f"(max \\|z\\| {r['coordinate_max_abs_z']:.1f}) | {r['length_u_predicted_m'] * um:.2f} µm | "
                         f"{s44[0]} | {s44[1]} | {s44[2]} |")
            if label != "paper":
                g = (f"{d['name']}, {label}: gain {r['gain_max_u95']:.2f}x on max_u95, "
                     f"{r['gain_length_u']:.2f}x on length_u")
                if "gain_s44" in r:
                    g += f", {r['gain_s44']:.2f}x on the predicted §4.4 statistic"
                gains.append(g + " (gain = paper / optimised; below 1: worse than the paper's heads).")
    return "\n".join(lines) + "\n\n" + "\n".join(f"- {g}" for g in gains) + "\n"
