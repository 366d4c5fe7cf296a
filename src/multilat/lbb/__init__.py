"""Laser ball bar (seed 003, Canning et al. 2007): trilateration and its uncertainty.

- :mod:`multilat.lbb.trilateration`: eq. (1), base frame and tool socket from six edges.
- :mod:`multilat.lbb.htm`, :mod:`multilat.lbb.sag`, :mod:`multilat.lbb.model`: the HTM length model.
- :mod:`multilat.lbb.simulate`: the §5 Monte Carlo procedure and the direct propagation.
- :mod:`multilat.lbb.config`: the validated TOML configuration (default: the paper's set-up).

See ``docs/lbb.md`` for frames, units and every interpretation of the paper.
"""

from multilat.lbb.config import LBBConfig, load_config
from multilat.lbb.simulate import LBBSimulation, simulate, volume_points
from multilat.lbb.trilateration import Trilateration, edges_from_points, trilaterate

__all__ = ["LBBConfig", "load_config", "LBBSimulation", "simulate", "volume_points", "Trilateration",
           "edges_from_points", "trilaterate"]
