"""One design criterion, three back ends (as GNU Gama's adjustment algorithms sit behind ``AdjBase``).

A criterion (:data:`CRITERIA`) of a layout is evaluated once, by :func:`criterion`, from what a back
end gives for exact distances: the targets' 3 x 3 covariances in the datum, the redundancy numbers,
and (for ``length_u``) covariance blocks of the points. The back ends
(:class:`DesignBackend`; :func:`make_backend` by name, :func:`choose_backend` for ``auto``):

* ``dense``   (:class:`multilat.network.design.blocked.DenseBackend`): the adjustment's own
  covariance (:func:`multilat.network.design.blocked.blocked_covariance`: the solve's back end, its
  reduced normal equations, :class:`~multilat.network.adjust.covariance.NetworkCovariance` in the datum)
  formed as the whole matrix in the adjustment's parameter layout; every number read from it.
* ``blocked`` (:class:`multilat.network.design.blocked.BlockedBackend`): the same covariance kept in
  its Schur form, per-target blocks and the hat diagonal in ``O(t s²)`` (large layouts).
* ``fast``    (:class:`multilat.network.design.fast.FastBackend`): the search's evaluator, the same
  Schur complement on fixed-shape (targets x heads) arrays; the targets' covariances and the
  redundancy only (not ``length_u``).

They agree to 1e-9 (``tests/test_design.py``); dense and blocked equal ``adjust``'s covariance of the
same exact observations (1e-9).
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError
from multilat.network.adjust import statistics as st
from multilat.network.model.distance import line_of_sight
from multilat.network.model.parameter_layout import ParameterLayout

__all__ = ["CRITERIA", "METHODS", "DENSE_MAX_PARAMS", "DesignBackend", "choose_backend", "make_backend",
           "criterion", "target_criterion", "u95_max_m"]

#: optimisation criteria (docs/design.md): name -> description
CRITERIA = {
    "max_u95": "largest 95 % ellipsoid semi-axis over the targets (m)",
    "rms_u": "RMS over targets of the 3-D standard uncertainty sqrt(trace C_j) (m)",
    "length_u": "largest standard uncertainty of the chosen interpoint lengths (m)",
    "max_mdb": "largest minimal detectable bias over the distances (m)",
}

#: the evaluation methods: ``auto`` and the back ends' names
METHODS = ("auto", "dense", "blocked", "fast")

#: above this many free parameters the pre-analysis (``auto``) keeps the covariance in blocks
#: (``blocked``, O(t s²)) instead of forming the whole matrix (``dense``)
DENSE_MAX_PARAMS = 120


class DesignBackend:
    """What a criterion asks of a back end, for a layout's exact distances.

    ``layout`` the :class:`~multilat.network.design.preanalysis.Layout`; ``sigma_m`` (m,) the
    distances' standard uncertainties in :meth:`~multilat.network.design.preanalysis.Layout.pairs`
    order. Every back end gives :meth:`target_cov_m2` and :meth:`redundancy`; those holding the whole
    parameter covariance give :meth:`station_cov` and :meth:`block` (in the adjustment's layout,
    :meth:`~multilat.network.model.parameter_layout.ParameterLayout.adjustment`) too.
    """

    name = "?"

    def __init__(self, layout, sigma_m):
        self.layout = layout
        self.sigma_m = np.asarray(sigma_m, float)
        self.columns = ParameterLayout.adjustment(layout.n_stations, layout.n_targets)

    def target_cov_m2(self) -> np.ndarray:
        """Every target's 3 x 3 covariance in the datum (t, 3, 3), m²."""
        raise NotImplementedError

    def redundancy(self) -> np.ndarray:
        """Redundancy numbers (m,) (datum-free), ``Layout.pairs`` order."""
        raise NotImplementedError

    def station_cov(self) -> np.ndarray:
        """Covariance of the station parameters (5s, 5s): x, y, z, offset, scale per station."""
        raise MultilatError(f"the {self.name} back end gives the targets' covariances and the redundancy "
                            "only (use dense or blocked)")

    def block(self, rows) -> np.ndarray:
        """Covariance of the parameters ``rows`` (k,) of the adjustment's layout -> (k, k)."""
        raise MultilatError(f"the {self.name} back end gives the targets' covariances and the redundancy "
                            "only (use dense or blocked)")

    def length_u(self, pairs) -> list[tuple[float, float]]:
        """``(length_m, standard uncertainty_m)`` of the distance between each pair of point ids."""
        lay = self.layout
        pos = {p: k for k, p in enumerate(lay.station_ids + lay.target_ids)}
        cols = self.columns.point_columns()                      # (s + t, 3)
        xyz = np.vstack([lay.station_xyz_m, lay.target_xyz_m])
        out = []
        for a, b in pairs:
            L, u = line_of_sight(xyz[pos[a]] - xyz[pos[b]])
            g = np.concatenate([u, -u])
            C = self.block(np.concatenate([cols[pos[a]], cols[pos[b]]]))
            out.append((float(L), float(np.sqrt(max(g @ C @ g, 0.0)))))
        return out


def choose_backend(method: str, layout, name: str | None = None) -> str:
    """The back end for ``method`` (:data:`METHODS`) and criterion ``name`` (None: the whole
    pre-analysis). ``auto``: ``fast`` for a criterion of the targets' covariances or the redundancy,
    ``blocked`` for ``length_u`` (two points' blocks, no whole matrix: 13 ms against dense's 21 ms
    on the small volume), and for the pre-analysis ``dense`` up to :data:`DENSE_MAX_PARAMS` free
    parameters (its ``cov``), ``blocked`` above. ``fast`` asked for ``length_u`` or for no criterion
    falls back to ``auto``."""
    if method not in METHODS:
        raise MultilatError(f"method must be {', '.join(METHODS[:-1])} or {METHODS[-1]}, got {method!r}")
    if method == "fast" and name in (None, "length_u"):
        method = "auto"
    if method != "auto":
        return method
    if name is not None:
        return "blocked" if name == "length_u" else "fast"
    n = ParameterLayout.station_system(layout.n_stations, layout.n_targets).n
    return "dense" if n <= DENSE_MAX_PARAMS else "blocked"


def make_backend(name: str, layout, sigma_m, *, offsets: bool = True, datum="free") -> DesignBackend:
    """The back end ``name`` (``dense``, ``blocked`` or ``fast``) of ``layout`` with the distances'
    standard uncertainties ``sigma_m`` (m,), offsets estimated or known, in ``datum`` (``free``,
    ``free:P,..``, ``321:A,B,C``). Raises :class:`MultilatError` for a singular layout."""
    if name == "fast":
        from multilat.network.design.fast import FastBackend

        return FastBackend(layout, sigma_m, offsets=offsets, datum=datum)
    if name in ("dense", "blocked"):
        from multilat.network.design.blocked import blocked_covariance

        return blocked_covariance(layout, sigma_m, offsets=offsets, datum=datum, dense=name == "dense")
    raise MultilatError(f"back end must be dense, blocked or fast, got {name!r}")


def u95_max_m(cov3) -> np.ndarray:
    """Largest 95 % ellipsoid semi-axis of each 3 x 3 covariance (..., 3, 3) -> (...), m."""
    return np.sqrt(st.CHI2_3_95 * np.clip(np.linalg.eigvalsh(cov3)[..., -1], 0.0, None))


def target_criterion(name: str, target_cov_m2) -> float:
    """``max_u95`` or ``rms_u`` (:data:`CRITERIA`, m) from the targets' covariances (t, 3, 3)."""
    if name == "max_u95":
        return float(u95_max_m(target_cov_m2).max())
    if name == "rms_u":
        return float(np.sqrt(np.trace(target_cov_m2, axis1=1, axis2=2).mean()))
    raise MultilatError(f"target_criterion: {name!r} is not a criterion of the targets' covariances alone")


def criterion(name: str, backend: DesignBackend, *, lengths=(), alpha: float = 0.001,
              power: float = 0.80) -> float:
    """The design criterion ``name`` (:data:`CRITERIA`, metres) from a back end: the one evaluation
    behind :func:`~multilat.network.design.preanalysis.criterion_value`, the search and
    :meth:`~multilat.network.design.preanalysis.PreAnalysis.criterion`. ``lengths`` (pairs of point
    ids) for ``length_u``; ``alpha``, ``power`` of the MDBs (``max_mdb``)."""
    if name in ("max_u95", "rms_u"):
        return target_criterion(name, backend.target_cov_m2())
    if name == "length_u":
        if not lengths:
            raise MultilatError("criterion length_u needs lengths (pairs of point ids)")
        return float(max(u for _, u in backend.length_u(lengths)))
    if name == "max_mdb":
        return float(st.minimal_detectable_bias_m(backend.sigma_m, backend.redundancy(), alpha=alpha,
                                                  power=power).max())
    raise MultilatError(f"criterion must be one of {', '.join(CRITERIA)}, got {name!r}")
