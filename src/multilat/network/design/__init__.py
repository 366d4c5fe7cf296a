"""Network design: pre-analysis of a multilateration layout and optimisation of head positions.

- :mod:`.preanalysis`  predicted covariance, redundancy, MDBs of a layout (no measurements)
- :mod:`.backends`     one criterion over three back ends: dense, blocked (:mod:`.blocked`, the
  adjustment's own covariance) and fast (:mod:`.fast`, the search's evaluator)
- :mod:`.search`       global search for head positions under a criterion; visibility, occluders
- :mod:`.targets`      the fewest targets for a wanted work-volume uncertainty (greedy heuristic)
- :mod:`.confirm`      Monte Carlo confirmation through ``propagate``
- :mod:`.config`       the validated TOML of ``multilat design``
- :mod:`.evaluate`     ``evaluate_layout(design, backend)``: the general layer's pre-analysis and the
  distance-only evaluators behind one call
"""

from multilat.network.design.preanalysis import (CRITERIA, Layout, PreAnalysis, SigmaModel,  # noqa: F401
                                                 covariance, criterion_value, layout_observations,
                                                 preanalyse)
from multilat.network.design.search import (DesignResult, choose_candidates, optimise_heads,  # noqa: F401
                                            visibility)
