"""The adjustments: the solver family (:mod:`.solve`), approximate coordinates (:mod:`.approximate`),
the distance path (:mod:`.distance`) and the general layer (:mod:`.general`).
"""
