"""The model of a network: what it holds and how one observation is computed from the parameters.

The distance path's data, model (:mod:`.distance`), registry of unknowns (:mod:`.problem`), angle
and coupling rows, datum and S-transformation; the general layer's points, parameter layout,
observation blocks and :mod:`.kinds` (one module per kind). No solving here: the normal equations,
the covariance and the statistics belong to the adjustment
(:mod:`multilat.network.adjust.solve.normal_equations`, :mod:`multilat.network.adjust.covariance`,
:mod:`multilat.network.adjust.statistics`).
"""
