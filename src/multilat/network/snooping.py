"""Data-snooping rounds between two adjustments: the rejection of one observation as a rank-one
downdate of the last adjustment (for large networks).

Data snooping rejects one observation per round and, in :func:`multilat.network.adjust.adjust`,
adjusts the network again each time. On a network of 10⁵ distances the B-method's global test fails
most of the time even without a blunder (``alpha_global`` near 0.8 at that redundancy), and the
w-tests' own false alarms are then rejected one by one: dozens of rounds, each a full adjustment.

Between two adjustments the rounds here use the Sherman-Morrison downdate of the linearised model
(whitened design ``A``, hat matrix ``H = A Q Aᵀ``, residuals ``v``, redundancy numbers ``r = 1 -
diag H``). Leaving out observation ``k``, with ``c = H e_k`` (one row of the hat matrix)::

    v'   = v + c v_k / r_k            (the solution moves by -Q a_k v_k / r_k)
    r'   = r - c² / r_k
    vᵀPv' = vᵀPv - v_k² / r_k,   dof' = dof - 1
    H'   = H + c cᵀ / r_k             (the next round's hat row: the stored c's)

exact for the linearised model (Cook & Weisberg 1982, *Residuals and Influence in Regression*, §2.2;
the w-test's correlation ``rho_kl = -H_kl / sqrt(r_k r_l)`` as in Baarda's procedure). The network's
curvature changes the downdated vᵀPv by about 1e-8 relative after a marginal rejection (a move of
about one σ; ``tests/test_snooping_rounds.py``). The adjustment
is re-run after a bounded number of downdates (memory: one hat row of ``m`` floats each), after the
rejection of a gross error (|w| > :data:`LINEAR_W_MAX`: its removal moves the solution far enough
for the curvature to show, 1e-6 relative in vᵀPv at 50σ) and whenever the procedure would stop, so the decision to stop and every reported number come from a
full adjustment; only the statistics recorded for the intermediate rounds are the downdated ones.
"""

from __future__ import annotations

import numpy as np

from multilat.network import statistics as st
from multilat.network.data import distinct_pair_codes

__all__ = ["LinearRounds", "LINEAR_MIN_OBS", "LINEAR_W_MAX"]

#: networks with at least this many distances use the downdated rounds (smaller ones are re-adjusted
#: after every rejection: fast anyway, and the exact path)
LINEAR_MIN_OBS = 20_000
#: a rejection with a larger |w| (a gross error, whose removal moves the solution by many σ) is
#: followed by a new adjustment; the downdate serves the marginal rejections (|w| a little above the
#: critical value: the w-tests' false alarms on large networks), where the model is linear to ~1e-8
LINEAR_W_MAX = 10.0
#: memory for the stored hat rows (bytes): the number of downdates before the next adjustment
ROW_MEMORY_BYTES = 256 * 2 ** 20


class LinearRounds:
    """The state of the rounds since the last adjustment ``core`` (a dict of
    :func:`multilat.network.fit.fit_once`) of the observations ``global_index`` (their rows in the
    caller's observations). Indices ``k`` below are positions in that adjustment's observations."""

    def __init__(self, core: dict, global_index: np.ndarray, station_index, target_index,
                 n_stations: int, n_targets: int):
        self.cov = core["cov"]
        self.v = np.array(core["residual_w"], float, copy=True)
        self.red = np.array(core["redundancy"], float, copy=True)
        self.vtpv = float(core["vtpv"])
        self.dof = int(core["dof"])
        self.gidx = np.asarray(global_index)
        self.si = np.asarray(station_index)
        self.ti = np.asarray(target_index)
        m = self.v.size
        self.alive = np.ones(m, bool)
        self.rows: list[tuple[np.ndarray, float]] = []
        self.cap = int(max(4, min(64, ROW_MEMORY_BYTES // (8 * max(m, 1)))))
        inc = np.zeros((n_stations, n_targets), bool)
        inc[self.si, self.ti] = True
        self.incidence = inc

    @staticmethod
    def applies(core: dict, sub, datum) -> bool:
        """Distances only (no angles, bars or weighted control), one reading per pair, a free or 3-2-1
        datum, and a network large enough to need it."""
        if sub.n_obs < LINEAR_MIN_OBS or core.get("angles") is not None or core.get("coupled") is not None:
            return False
        if datum.kind == "control":
            return False
        return distinct_pair_codes(sub.station_index, sub.target_index, sub.n_targets).size == sub.n_obs

    @property
    def pending(self) -> int:
        """Rejections since the last adjustment."""
        return len(self.rows)

    @property
    def full(self) -> bool:
        return len(self.rows) >= self.cap

    def stats(self) -> dict:
        """What the detection step reads: residual_w, redundancy (0 for the left-out), vtpv, dof, sigma0."""
        sigma0 = float(np.sqrt(self.vtpv / self.dof)) if self.dof > 0 else float("nan")
        return {"residual_w": self.v, "redundancy": self.red, "vtpv": self.vtpv, "dof": self.dof,
                "sigma0": sigma0}

    def w(self) -> np.ndarray:
        return st.w_statistics(self.v, np.ones_like(self.v), self.red)

    def hat_row(self, k: int) -> np.ndarray:
        """Row ``k`` of the current hat matrix (the last adjustment's plus the stored downdates)."""
        c = np.array(self.cov.hat_row(int(k)), float, copy=True)
        for row, rho in self.rows:
            c += row * (row[k] / rho)
        c[~self.alive] = 0.0
        return c

    def twins(self, k: int, c: np.ndarray, tol: float = 1e-6) -> np.ndarray:
        """Observations other than ``k`` whose w-test is perfectly correlated with ``k``'s (as
        :meth:`multilat.network.covariance.NetworkCovariance.perfectly_correlated`)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            q = np.abs(c) / np.sqrt(self.red[k] * self.red)
        q[~self.alive] = 0.0
        out = np.flatnonzero(q > 1.0 - tol)
        return out[out != k]

    def keeps_structure(self, k: int, need_per_station: int = 7) -> bool:
        """Whether leaving out ``k`` surely keeps the network solvable: its station keeps at least
        ``need_per_station`` distances (more than any station's unknowns + 1), the redundancy stays
        positive, and the distance lies on a 4-cycle (station–target–station–target), so the network
        stays connected. False means "not sure": the caller checks the whole structure."""
        i, j = int(self.si[k]), int(self.ti[k])
        inc = self.incidence
        if int(inc[i].sum()) - 1 < need_per_station or self.dof - 1 < 1:
            return False
        others = np.flatnonzero(inc[:, j])
        others = others[others != i]
        if others.size == 0:
            return False
        common = inc[others] & inc[i]
        common[:, j] = False
        return bool(common.any())

    def reject(self, k: int, c: np.ndarray) -> None:
        """Leave out observation ``k`` (``c`` its current hat row)."""
        rho = float(self.red[k])
        vk = float(self.v[k])
        self.v += c * (vk / rho)
        self.red -= c * c / rho
        np.clip(self.red, 0.0, 1.0, out=self.red)
        self.vtpv -= vk * vk / rho
        self.dof -= 1
        self.alive[k] = False
        self.v[k] = 0.0
        self.red[k] = 0.0
        self.incidence[self.si[k], self.ti[k]] = False
        self.rows.append((c, rho))
