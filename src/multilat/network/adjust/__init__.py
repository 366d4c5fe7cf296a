"""The adjustments: the solver family (:mod:`.solve`), approximate coordinates (:mod:`.approximate`),
the distance path (:mod:`.distance`) and the general layer (:mod:`.general`); shared by them, the
covariance in Schur form (:mod:`.covariance`, its kernels :mod:`._covariance_kernels`) and the
statistics of the tests (:mod:`.statistics`).
"""
