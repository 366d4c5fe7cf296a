"""The state of one adjustment of the self-calibrating network: :class:`Fit`, what
:func:`multilat.network.adjust.distance.fit.fit_once` returns and :func:`multilat.network.adjust.distance.adjust.adjust` carries from
one round of data snooping to the next (it replaced a dict of 22 keys).

A *partial* fit (``partial=True``) is the lowest-cost point a first solve reached without converging:
only ``sx, tx, off, vtpv, dof, convergence`` (and ``error``, the refusal of a start) are set; it is a
start for the minimum search (:mod:`multilat.network.adjust.approximate.search`), never a result.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["Fit"]


@dataclass(eq=False)
class Fit:
    """One adjustment, in the order of the observations it adjusted (``sub``).

    sx, tx : (s, 3), (t, 3) adjusted station and target coordinates, in the datum's frame
    off, sc : (s,) offsets (m) and scales per station (a head's value on each of its stations)
    vtpv : float  weighted sum of squared residuals (distances, couplings, angles); dof : int
    convergence : :class:`multilat.network.adjust.solve.Convergence`
    smap, tmap : indices of ``sub``'s stations and targets in the full observations
    off_free, sc_free : (s,) bool  which offsets and scales were estimated
    residual_w : (m,) whitened distance residuals; redundancy : (m,) redundancy numbers
    sigma0 : a-posteriori σ0; iterations : Gauss-Newton iterations; cond : condition estimate
    cov : the covariance (:class:`multilat.network.adjust.covariance.NetworkCovariance` or coupled)
    solver : back end name; chunk_targets : targets per assembly chunk
    angles : the angle observations' part (dict: rows, residual_rad, redundancy, orientation_rad,
        orientation_cov, station_ids, target_ids, design_w) or None
    coupled : scale bars' and weighted control's part (dict: couplings, residual_m, redundancy) or None
    partial : True for the lowest-cost point of a solve that did not converge; error : its refusal
    """

    sx: np.ndarray
    tx: np.ndarray
    off: np.ndarray
    vtpv: float
    dof: int
    convergence: Any
    partial: bool = False
    error: Exception | None = None
    smap: np.ndarray | None = None
    tmap: np.ndarray | None = None
    sc: np.ndarray | None = None
    off_free: np.ndarray | None = None
    sc_free: np.ndarray | None = None
    residual_w: np.ndarray | None = None
    redundancy: np.ndarray | None = None
    sigma0: float = float("nan")
    iterations: int = 0
    cond: float = float("nan")
    cov: Any = None
    solver: str = ""
    chunk_targets: int = 20000
    angles: dict | None = None
    coupled: dict | None = None
