"""The sections :mod:`retree` writes whole (so a second run writes them identically): the network
tiers and mutation cases of ``tests/test_layering.py``, the tree, the network tiers and the path of one
observation in ``docs/architecture.md``, and the network part of ``README.md``'s layout. Not rewritten
by the script's reference rules (its text names the new modules already)."""

from __future__ import annotations

import re

TIERS_COMMENT = ("#: Inside ``multilat.network``, lowest first (written by tools/retree.py; docs/architecture.md):\n"
                 "#: the model (it solves nothing: the normal equations, the covariance and the statistics are\n"
                 "#: the adjustment's, issue 27), the readers and generated networks, the adjustments (the\n"
                 "#: general layer above the distance path's cores it calls), the Monte Carlo on the adjustment's\n"
                 "#: system, the design.\n"
                 "#: A module of ``network/`` in no package listed here (a new flat module) counts as the model.\n")
MUTATIONS = [
    ("multilat/network/model/datum.py", "multilat.network.adjust.distance.adjust",
     "network model may not import network adjust"),
    ("multilat/network/model/distance.py", "multilat.network.adjust.covariance",
     "network model may not import network adjust"),
    ("multilat/network/adjust/distance/fit.py", "multilat.network.design.fast",
     "network adjust may not import network design"),
    ("multilat/network/io/files.py", "multilat.network.adjust.distance.result",
     "network io may not import network adjust"),
    ("multilat/network/adjust/distance/snooping.py", "multilat.network.adjust.general.quality",
     "network adjust may not import network adjust general"),
]


def tiers_text(text: str, tiers) -> str:
    """tests/test_layering.py with the network tiers ``tiers`` (``(name, packages)``, lowest first) and
    the mutation cases."""
    body = "NETWORK_TIERS = [\n" + "".join(
        f"    ({name!r}, [{', '.join(repr(p) for p in pkgs)}]),\n".replace("'", '"') for name, pkgs in tiers) + "]\n"
    new = re.sub(r"(#: Inside ``multilat\.network``.*?\n)?NETWORK_TIERS = \[\n.*?\n\]\n",
                 lambda m: TIERS_COMMENT + body, text, count=1, flags=re.S)
    mut = "".join(f"    ({a!r}, {b!r}, {c!r}),\n".replace("'", '"') for a, b, c in MUTATIONS)
    return re.sub(r"(?:    \(\"multilat/network/[^\n]*\),\n)+", lambda m: mut, new, count=1)


TREE = """## The tree

```
src/multilat/
  errors.py inputs.py io.py            foundation: one-line errors, bounded inputs, atomic outputs,
  vocabulary.py rows_text.py             the JSON vocabulary, compiled text kernels (_numba, _text_kernels),
  schemas/                               the JSON Schemas, generated from typed models (models/)
  distributions.py fast_normal.py      probability: JCGM 101 distributions, numba normals
  montecarlo/                            the Monte Carlo engine (below)
  parallel.py                            process / Dask maps
  air.py adm.py gimbal.py tracker.py   the distance model of one measurement, and its budget
  instrument.py budget.py                (presets/seed2020.toml)
  distance_errors.py
  network/                             networks of distances, angles and every other kind (tiers, lowest first)
    model/                               what a network is, how one observation is computed: data, distance
                                           (the distance model), problem (registry of unknowns), angles,
                                           angle_rows, couplings (bars, control), datum (S-transformation);
                                           points, layout, observations, kinds/ (one module per observation
                                           kind) of the general layer
    io/                                  readers and writers: files (multilat CSV), fastio, general_files,
                                           interop/ (GNU Gama XML, JAG3D, Star*Net)
    synthetic/                           networks with a known truth: generator, configs (seed 000 §4)
    adjust/                              the adjustments; covariance (Schur form, _covariance_kernels) and
                                           statistics (the tests), shared by every path
      solve/                               one Gauss-Newton loop, normal_equations, dense / sparse / coupled
                                             back ends (_sparse_kernels)
      approximate/                         initial values (distance path), general/ (the general layer's)
      distance/                            the distance path: adjust, fit, snooping, reliability, result
      general/                             the general layer: adjust (dense), sparse, run, quality,
                                             snooping, variance; its __init__ is the layer's facade
    montecarlo/                          the adjustment's system frozen per trial: propagate, batched
                                           solvers, summaries, simulate; general/ (the general layer's)
    design/                              pre-analysis (also general_preanalysis), layout search,
                                           confirmation, the paper study
  campaign/                            raw readings, environment, corrections, two-face, campaigns
  lbb/                                 the laser ball bar: trilateration, bar model, simulation,
                                         outputs and its figures (Figs. 7-9)
  report/                              HTML pages (--report), figures, the demo job's sections
  cli/                                 the typer app, one module per command group; no science
  warmup.py                            compiles the kernels at install time
tools/write_schemas.py                 developer tool: writes the shipped schemas from the models
tools/retree.py                        developer tool: moved network/ into this tree (re-runnable)
tests/ benchmarks/ docs/ examples/
```

"""
NETWORK_TIERS_TEXT = """The Monte Carlo engine sits below the distance model because the distance budget runs it. Inside
`network`, six tiers, each a package (`NETWORK_TIERS`; `tools/retree.py` holds the mapping from the
old flat modules): `model/`; `io/` and `synthetic/`; `adjust/` (`solve/`, `approximate/`,
`distance/`); `adjust/general/` (the general layer calls the distance path's snooping, reliability
and variance cores, never the other way); `montecarlo/`; `design/` (its `confirm` runs
`propagate`). `model/` solves nothing: the normal-equation assembly is
`adjust.solve.normal_equations`, and `covariance`, `statistics` and the two kernel modules sit in
`adjust/` and `adjust/solve/` (issue 27). A module of `network/` outside these packages counts as
the model. A new module must be placed in a layer (the test fails on a module in none)."""
PATH_TEXT = """## One observation, from file to report

`multilat adjust obs.csv --report r.html` (cli/network_cmd.py):

1. **Read.** `campaign.propagation.read_campaign` tells a raw-readings file (corrected first by
   `campaign.correct`) from a distance file, which `network.io.files.read_observations` reads (large
   files through `network.io.fastio`): each row is checked as it comes (`inputs`, one-line
   `error: FILE:LINE`), its σ comes from the file, `--sigma-um` or the instrument's distance model
   (`budget.distance_std_m`; the record is `network.model.sigma_source`). The result is one
   `network.model.data.Observations` (arrays: station and target index, distance, σ, head, optional angles).
2. **Adjust.** `network.adjust.distance.adjust.adjust` checks the geometry (`adjust/distance/ambiguity`,
   `fit.check_network`), finds initial values (`adjust/approximate/`: `starts`, `initial`), and
   `adjust.distance.fit.fit_once` runs the Gauss-Newton loop of `adjust/solve/` on the model of
   `network.model.distance` (residual `d - |H - T| - o`, Jacobian rows `[u, 1, rho]` per distance,
   angle rows from `model/angle_rows`), with the datum of `network.model.datum` (free, 3-2-1,
   control). Data snooping (`adjust/distance/snooping`, `adjust/statistics` w-tests,
   `adjust/distance/reliability`) repeats the fit without rejected observations.
3. **Result.** `network.adjust.distance.result.AdjustmentResult` holds coordinates, offsets,
   covariance (`adjust/covariance`), σ0 and the tests; `result_to_json` makes the `--json` document
   (keys of `vocabulary`, schema in `schemas/adjust.json`); `network.io.files.write_result_tables`
   writes `--out`.
4. **Report.** `cli/report_opt.write_report` hands the document and the result to
   `report.job.build_report`: `report.job_sections` turns the document into sections, `network_figures`
   and `view3d` draw, `report.html.render` writes one escaped page, atomically (`io`).

With `--model general` or a gama-local XML (`cli/general_adjust.py`), step 1 builds a
`network.model.observations.Network` (points and one block per observation kind, `network/model/kinds/`;
read by `network.io.interop.gama_input` or `network.adjust.general.from_tables`) and step 2 is
`network.adjust.general.run.adjust_network`; the report path is the same. `multilat propagate` runs
step 2's system frozen per trial (`network/montecarlo/`), `multilat design` the same layer from the
planned coordinates alone (`network/design/`).
"""
GREP_OLD = ("network/{model,batched,batched_coupled,initial,initial_refine}.py "
            "network/design/{fast,blocked,preanalysis,evaluate}.py")
GREP_NEW = ("network/model/distance.py network/montecarlo/{batched,batched_coupled}.py \\\n"
            "    network/adjust/approximate/{initial,initial_refine}.py network/design/{fast,blocked,preanalysis,evaluate}.py")


def architecture_text(text: str) -> str:
    """docs/architecture.md with the tree, the network tiers and the path of one observation."""
    new = re.sub(r"## The tree\n.*?(?=`montecarlo/` has one idea per module)", lambda m: TREE, text, count=1,
                 flags=re.S)
    new = re.sub(r"The Monte Carlo engine sits below.*?fails on a module in none\)\.",
                 lambda m: NETWORK_TIERS_TEXT, new, count=1, flags=re.S)
    new = re.sub(r"## One observation, from file to report\n.*", lambda m: PATH_TEXT, new, count=1, flags=re.S)
    return new.replace(GREP_OLD, GREP_NEW)


README_NETWORK = """  network/      the network, one package per tier (lowest first; docs/architecture.md):
    model/        data, distance (the distance model), problem, datum (S-transformation), angles,
                  couplings; the general layer's points, layout, kinds/
    io/           files, fastio, general_files, interop/ (GNU Gama, JAG3D, Star*Net files)
    synthetic/    generator (the one random-network generator), configs (seed 000 §4)
    adjust/       covariance, statistics; solve/ (one loop, normal equations; dense, sparse back ends),
                  approximate/ (initial values), distance/ (adjust, fit, snooping, reliability, result),
                  general/ (the general 3D network, issue 26: `adjust NET.xml`, `adjust --model general`)
    montecarlo/   propagate (+ _summary, _result), batched solvers + trial_datum, simulate, general/
    design/       pre-analysis, layout search, confirmation, general_preanalysis
"""


def readme_text(text: str) -> str:
    """README.md with the network part of its layout."""
    return re.sub(r"  network/ +(?:data, files.*?`adjust --model general`\n|the network, one package.*?"
                  r"general_preanalysis\n)", lambda m: README_NETWORK, text, count=1, flags=re.S)
