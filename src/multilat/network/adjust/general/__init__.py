"""The general 3D network: one set of points in any role, observation kinds that own their model,
determinability from the design (``docs/general-network.md``).

The usual way in, as ``multilat adjust NET.xml`` does it::

    from multilat.network.adjust.general import read_gama_input, adjust_network, statistics, to_json

    adj = adjust_network(read_gama_input("net.xml"))        # undetermined points left out, named
    adj.excluded, adj.result.xyz_m, adj.result.sigma0
    stats = statistics(adj.system, adj.result, alpha=0.001, variance_factor="known")
    doc = to_json(adj, stats, source="net.xml")              # the documented JSON document
"""

from multilat.network.adjust.general.adjust import AdjustOptions, GeneralResult, System, UndeterminedError, adjust
from multilat.network.adjust.approximate.general import approximate
from multilat.network.io.interop.gama_input import read_gama_input
from multilat.network.model.observations import Block, Network, without_points
from multilat.network.model.points import FIXED, FREE, WEIGHTED, PointSet
from multilat.network.adjust.general.quality import GeneralStatistics, statistics
from multilat.network.adjust.general.report import to_json
from multilat.network.adjust.general.run import NetworkAdjustment, adjust_network

__all__ = ["AdjustOptions", "GeneralResult", "System", "UndeterminedError", "adjust", "approximate",
           "read_gama_input", "Block", "Network", "without_points", "FIXED", "FREE", "WEIGHTED", "PointSet",
           "GeneralStatistics", "statistics", "to_json", "NetworkAdjustment", "adjust_network"]
