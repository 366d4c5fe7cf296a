"""The solver family of the network adjustment: one Gauss-Newton / Levenberg-Marquardt loop
(:mod:`.loop`) over the Schur-reduced normal equations, with interchangeable linear-algebra back
ends that assemble them:

``dense``   numpy (:mod:`.dense`): every cost, scales, control points.
``sparse``  compiled kernels in one pass over targets (:mod:`.sparse`, :mod:`._sparse_kernels`): large
            networks.

The dense one assembles with :mod:`.normal_equations` (the Schur reduction over the targets).

Both return the same :class:`~.system.Assembly`; the loop, the stopping rule
(:mod:`.convergence`), the datum and every statistic above them are the same whichever ran. The
batched Monte Carlo solver (:mod:`multilat.network.montecarlo.batched`) solves many draws of one network at
once around a converged solution of this loop.
"""

from multilat.network.adjust.solve.convergence import Convergence
from multilat.network.adjust.solve.loop import BACKENDS, choose_backend, gauss_newton, make_backend, solve_reduced

__all__ = ["Convergence", "BACKENDS", "choose_backend", "gauss_newton", "make_backend", "solve_reduced"]
