"""A laser tracker's uncertainty from its maker's specification (distance and two angles per target).

Makers state laser-tracker accuracy as maximum permissible errors (MPE) in the form of ISO 10360-10
and ASME B89.4.19, for example (Leica AT500 user manual, §2.8.2, "Laser Tracker Subsystem
Specifications"):

* absolute distance meter  ``e_ADM = ±(10 µm + 0.3 µm/m · L)``
* transverse (angular)      ``e_T   = ±(15 µm + 6 µm/m · L)``

and the same manual states that "typical measurement results ... are half of the relevant MPE
values". multilat therefore takes a standard uncertainty of ``MPE × std_per_mpe`` with
``std_per_mpe = 0.5`` by default (the MPE read as a k = 2 bound); a user who reads the MPE as the
half-width of a rectangular distribution sets ``std_per_mpe = 1/sqrt(3)``.

The transverse error is a length perpendicular to the beam; the standard uncertainty of each angle
(azimuth, and elevation) is that length over the range, ``u_T(L) / L``, plus an optional constant
angular term ``c`` (µrad) for specifications that give one. The azimuth's error on the sphere is
``cos(elevation)`` times smaller than the transverse length; multilat, like the specification,
uses the same transverse σ for both directions and states it (a tracker used near the zenith is
outside this model).

SI units inside: metres, radians; the specification's µm, µm/m and µrad at the edge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError

__all__ = ["TrackerSpec"]


@dataclass(frozen=True)
class TrackerSpec:
    """A tracker specification in the maker's MPE form (µm, µm/m, µrad).

    Attributes
    ----------
    adm_a_um, adm_b_um_per_m : the distance MPE ``a + b L``
    transverse_a_um, transverse_b_um_per_m : the transverse MPE ``a + b L`` (angles)
    angular_c_urad : a constant angular MPE added in quadrature (0 when the maker gives none)
    std_per_mpe : standard uncertainty per unit of MPE (0.5: MPE read as k = 2)
    """

    adm_a_um: float
    adm_b_um_per_m: float
    transverse_a_um: float
    transverse_b_um_per_m: float
    angular_c_urad: float = 0.0
    std_per_mpe: float = 0.5

    def __post_init__(self):
        for name in ("adm_a_um", "adm_b_um_per_m", "transverse_a_um", "transverse_b_um_per_m", "angular_c_urad"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise MultilatError(f"tracker specification: {name} must be finite and >= 0, got {v!r}")
        if not (np.isfinite(self.std_per_mpe) and 0 < self.std_per_mpe <= 1):
            raise MultilatError(f"tracker specification: std_per_mpe must be in (0, 1], got {self.std_per_mpe!r}")
        if self.adm_a_um + self.adm_b_um_per_m <= 0:
            raise MultilatError("tracker specification: the distance MPE is zero (give adm_a_um or adm_b_um_per_m)")
        if self.transverse_a_um + self.transverse_b_um_per_m + self.angular_c_urad <= 0:
            raise MultilatError("tracker specification: the angular MPE is zero")

    def distance_sigma_m(self, distance_m):
        """Standard uncertainty of a distance reading (m), broadcasting over ``distance_m``."""
        L = np.asarray(distance_m, dtype=float)
        return self.std_per_mpe * (self.adm_a_um + self.adm_b_um_per_m * L) * 1e-6

    def angle_sigma_rad(self, distance_m):
        """Standard uncertainty of each angle (azimuth, elevation) in radians at range ``distance_m``."""
        L = np.asarray(distance_m, dtype=float)
        if np.any(L <= 0):
            raise MultilatError("tracker angle uncertainty: ranges must be > 0")
        transverse = self.std_per_mpe * (self.transverse_a_um + self.transverse_b_um_per_m * L) * 1e-6 / L
        constant = self.std_per_mpe * self.angular_c_urad * 1e-6
        return np.hypot(transverse, constant)
