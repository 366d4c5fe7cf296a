"""docs/design.md's table of the paper's volumes: paper heads against optimised heads, predicted and
confirmed by Monte Carlo (multilat.network.design.paper_study). A few minutes of CPU.

    PYTHONPATH=src python examples/design/paper_volumes.py > table.md
"""

from multilat.network.design.paper_study import markdown_table, paper_volume_study

#: the settings of the docs table (tests/test_design.py::test_docs_paper_volume_table re-runs them)
SETTINGS = dict(evaluations=4000, starts=4, mc_trials=20_000, sims=200, seed=1)

if __name__ == "__main__":
    print(markdown_table([paper_volume_study(n, **SETTINGS) for n in ("small-volume", "large-volume")]), end="")
