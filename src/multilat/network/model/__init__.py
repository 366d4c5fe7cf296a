"""The model of a network: what it holds and how one observation is computed from the parameters.

The distance path's data, model (:mod:`.distance`), registry of unknowns (:mod:`.problem`), angle
and coupling rows, datum and S-transformation; the general layer's points, parameter layout,
observation blocks and :mod:`.kinds` (one module per kind). No solving here, except
:func:`.distance.reduced_normal_equations`, which pins :mod:`.covariance` and :mod:`.statistics`
to this package (tools/retree.py).
"""
