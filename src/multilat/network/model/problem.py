"""The registry of unknowns of a network adjustment: which parameters exist, which are free, and
how observations are weighted. Every solver back end, the datum and the statistics use it.

Parameter layout (see :mod:`multilat.network.model.distance`)::

    [station 0: x, y, z, offset, scale, station 1: ..., target 0: x, y, z, target 1: ...]

``Q = 5`` global parameters per station (index ``Q i + c``), then 3 per target. A parameter that is
held (a fixed offset, an unestimated scale, a coordinate of the internal minimal constraint, a
control point) keeps its value and its column is zero in every Jacobian.

**Heads** (``obs.station_heads``): offsets and scales belong to heads, and a head may occupy several
stations. The Jacobians, the back ends' assemblies and the covariance keep the per-station layout
above; the tie is one linear map ``g = T g_r`` (:attr:`Problem.tie`) from the *reduced* unknowns
``g_r`` — the same 5s layout in which only the first station of each head (its *lead*) carries the
head's offset and scale — to the per-station globals: ``T`` copies the lead's offset/scale entry
onto every other station of the head. :func:`multilat.network.adjust.solve.loop.solve_reduced` is the one
place that applies it (``T^T N T``, ``T^T b``; returns ``T dg_r`` and ``T Q_r T^T``), so the datum,
the covariance and the statistics see per-station globals whose tied entries are equal and fully
correlated. With one station per head ``T`` is the identity and is never formed.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from multilat.network.model.data import Observations
from multilat.network.model.distance import COSTS, Q
from multilat.network.model.parameter_layout import XYZ, ParameterLayout

__all__ = ["Problem", "Params", "param_names", "head_mean"]


@dataclass(frozen=True, eq=False)
class Params:
    """Values of all parameters, in the order of the observations' ids.

    station_xyz_m (s, 3), target_xyz_m (t, 3), offset_m (s,), scale (s,) (dimensionless).
    """

    station_xyz_m: np.ndarray
    target_xyz_m: np.ndarray
    offset_m: np.ndarray
    scale: np.ndarray
    orientation_rad: np.ndarray = None    # (n_o,) orientation unknowns of stations with angles

    def __post_init__(self):
        if self.orientation_rad is None:
            object.__setattr__(self, "orientation_rad", np.zeros(0))

    def step(self, dg: np.ndarray, dt: np.ndarray, do: np.ndarray | None = None) -> "Params":
        """These parameters plus a global step ``dg`` (5s,), target steps ``dt`` (t, 3) and
        orientation steps ``do`` (n_o,)."""
        lay = ParameterLayout.adjustment(len(self.offset_m))
        return Params(self.station_xyz_m + dg[lay.station_block(XYZ)], self.target_xyz_m + dt,
                      self.offset_m + dg[lay.station_columns("offset")], self.scale + dg[lay.station_columns("scale")],
                      self.orientation_rad if do is None else self.orientation_rad + do)

    def is_finite(self) -> bool:
        return bool(np.isfinite(self.station_xyz_m).all() and np.isfinite(self.target_xyz_m).all()
                    and np.isfinite(self.offset_m).all() and np.isfinite(self.scale).all()
                    and np.isfinite(self.orientation_rad).all())


@dataclass(frozen=True, eq=False)
class Problem:
    """One least-squares problem: observations, cost, and which parameters are free.

    Attributes
    ----------
    obs : Observations
    cost : "distance" (weighted by 1/sigma) or "squared" (the paper's eq. 6, unweighted)
    station_free : ndarray of bool (s, Q)   free station parameters (x, y, z, offset, scale)
    target_free : ndarray of bool (t,)      False for targets held fixed (control points)
    couplings : Couplings or None           observations beside the distances that couple points
        (scale bars, weighted control; :mod:`multilat.network.model.couplings`): solved by the dense back
        end's coupled path
    angles : AngleRows or None              azimuth/elevation observations and the stations'
        orientation unknowns (:mod:`multilat.network.model.angle_rows`): the dense coupled path
    """

    obs: Observations
    cost: str
    station_free: np.ndarray
    target_free: np.ndarray
    couplings: object = None     # multilat.network.model.couplings.Couplings: scale bars, weighted control
    angles: object = None        # multilat.network.model.angle_rows.AngleRows: angle observations, orientations

    def __post_init__(self):
        if self.cost not in COSTS:
            raise ValueError(f"cost must be one of {COSTS}, got {self.cost!r}")
        sf = np.asarray(self.station_free, bool)
        tf = np.asarray(self.target_free, bool)
        if sf.shape != (self.obs.n_stations, Q) or tf.shape != (self.obs.n_targets,):
            raise ValueError("station_free (s, 5) / target_free (t,) shapes disagree with obs")
        object.__setattr__(self, "station_free", sf)
        object.__setattr__(self, "target_free", tf)

    @property
    def weight_sqrt(self) -> np.ndarray:
        """Square roots of the weights (m,): ``1/sigma`` for the distance cost, 1 for squared."""
        return 1.0 / self.obs.sigma_m if self.cost == "distance" else np.ones(self.obs.n_obs)

    @property
    def sigma_ref_m(self) -> float:
        """The length that steps are measured against (the smallest a-priori sigma)."""
        return float(np.min(self.obs.sigma_m))

    @cached_property
    def lead_mask(self) -> np.ndarray:
        """(s, Q) bool: False for the offset and scale entries of a station that is not the first
        (lead) station of its head (those entries are copies of the lead's); all True without ties."""
        o = self.obs
        m = np.ones((o.n_stations, Q), bool)
        if o.station_heads is not None:
            hi = o.head_index
            lead = np.zeros(o.n_stations, bool)
            lead[np.unique(hi, return_index=True)[1]] = True
            m[~lead, 3:] = False
        return m

    @property
    def reduced_free(self) -> np.ndarray:
        """(s, Q) bool: the free reduced unknowns (station coordinates, head offsets and scales
        at their lead stations)."""
        return self.station_free & self.lead_mask

    @cached_property
    def tie(self) -> np.ndarray | None:
        """The tie map ``T`` (5s, 5s) with ``g = T g_r``, or None when every head has one station."""
        o = self.obs
        if o.station_heads is None or not o.shares_heads:
            return None
        layout = ParameterLayout.adjustment(o.n_stations)
        T = np.zeros((layout.n, layout.n))
        T[np.arange(layout.n), layout.tie_source(o.head_index)] = 1.0
        return T

    @property
    def n_free(self) -> int:
        return (int(self.reduced_free.sum()) + 3 * int(self.target_free.sum())
                + (0 if self.angles is None else int(self.angles.orientation_free.sum())))

    @property
    def n_rows(self) -> int:
        """Observations: the distances plus the couplings' rows (scale bars, control coordinates) and
        the angles."""
        return (self.obs.n_obs + (0 if self.couplings is None else self.couplings.n_rows)
                + (0 if self.angles is None else self.angles.n_rows))

    @property
    def dof(self) -> int:
        return self.n_rows - self.n_free

    def with_free(self, station_free=None, target_free=None) -> "Problem":
        return replace(self, station_free=self.station_free if station_free is None else station_free,
                       target_free=self.target_free if target_free is None else target_free)


def param_names(station_ids, head_ids=None) -> list[str]:
    """Names of the global parameters in layout order (for messages); ``head_ids`` (s,) names the
    head of each station whose offset and scale they are (default: the station)."""
    return ParameterLayout.adjustment(len(station_ids)).names(list(station_ids), head_ids=head_ids)


def head_mean(values, obs: Observations) -> np.ndarray:
    """Per-station ``values`` (s,) replaced by their mean over the stations of each head: the tied
    start of an adjustment whose initial values treated the stations independently."""
    v = np.asarray(values, float)
    if obs.station_heads is None or not obs.shares_heads:
        return v.copy()
    hi = obs.head_index
    mean = np.bincount(hi, weights=v) / np.bincount(hi)
    return mean[hi]
