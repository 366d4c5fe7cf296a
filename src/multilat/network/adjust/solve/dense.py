"""Dense (numpy) back end: the Schur-reduced normal equations assembled with numpy.

General: every cost (``distance``, ``squared``), scales, fixed targets (control points). Memory and
time ``O(t s^2)`` per assembly (chunks of targets bound the memory). With couplings (scale bars,
weighted control) the coupled path :mod:`.coupled` eliminates all targets at once.
"""

from __future__ import annotations

from multilat.network.adjust.solve.normal_equations import back_substitute, reduced_normal_equations
from multilat.network.model.problem import Params, Problem
from multilat.network.adjust.solve.system import Assembly, whitened

__all__ = ["DenseBackend"]


class DenseBackend:
    """Assemble the reduced normal equations of a :class:`Problem` with numpy."""

    name = "dense"

    def __init__(self, problem: Problem, *, chunk_targets: int = 20000):
        self.problem = problem
        self.chunk_targets = int(chunk_targets)

    def assemble(self, p: Params, damping: float = 0.0) -> Assembly:
        if self.problem.couplings is not None or self.problem.angles is not None:
            # scale bars, weighted control, angles (orientation unknowns): targets coupled
            from multilat.network.adjust.solve.coupled import assemble_coupled

            return assemble_coupled(self.problem, p, damping)
        o = self.problem.obs
        r_w, Js_w, Jt_w = whitened(self.problem, p)
        sys_ = reduced_normal_equations(r_w, Js_w, Jt_w, o.station_index, o.target_index, o.n_stations,
                                        o.n_targets, target_free=self.problem.target_free,
                                        damping=damping, chunk_targets=self.chunk_targets)

        def back(dg):
            return back_substitute(sys_, dg, Js_w, Jt_w, o.station_index, o.target_index)

        return Assembly(N=sys_.N, b=sys_.b, Ntt=sys_.Ntt, Ntt_inv=sys_.Ntt_inv,
                        vtpv=float(r_w @ r_w), back_substitute=back)
