"""RF-phase absolute distance meter (seed, eq. 1 and Table I).

The telemetric system measures the phase ``Phi`` of an RF modulation (``f_RF``) carried by light
that travelled to the target and back. Eq. (1) of the seed::

    L = (1/2) (Phi / (2 pi) + k) c / (n f_RF)

with ``n`` the air *group* index and ``k`` a non-negative integer (the number of whole synthetic
wavelengths in the round trip). The synthetic wavelength is ``c / f_RF`` (61.2 mm at 4895 MHz in
vacuum); the distance ambiguity (one phase cycle) is half of it in air, ``c / (2 n f_RF)``.

Error sources of Table I, derived from physical parameters (no table value is typed in):

* clock: a relative frequency error ``e`` scales the distance, ``dL = -e L`` (sign irrelevant for a
  centred law); ``std = ageing_rate x calibration interval x L``, gaussian;
* crosstalk: a spurious phasor of relative amplitude ``r = 10^(-SCR/20)`` added to the signal moves
  the phase by ``atan2(r sin psi, 1 + r cos psi)`` (``psi`` the uniform relative phase), at most
  ``asin(r)``: a cyclic distance error of amplitude ``asin(r) / (2 pi) x c / (2 n f)``,
  arcsine-distributed, std ``amplitude / sqrt(2)``;
* phase noise: ``std_L = std_Phi / (2 pi) x c / (2 n f)``, gaussian;
* AM/PM coupling: ``coefficient [m/dB] x power change``, the power uniform over the peak-to-peak
  range: std ``|coefficient| x p2p / sqrt(12)``.

Units: metres, radians, hertz; SCR and powers in dB (names say so).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from multilat.errors import MultilatError, require_finite

__all__ = ["C_M_PER_S", "synthetic_wavelength_m", "ambiguity_m", "distance_from_phase", "phase_from_distance",
           "resolve_integer", "resolve_integer_vernier", "crosstalk_phase_error_rad", "crosstalk_amplitude_m",
           "phase_noise_std_m", "am_pm_std_m", "clock_relative_std", "TelemetricTerms", "telemetric_terms"]

#: Speed of light in vacuum, m/s (exact).
C_M_PER_S = 299_792_458.0


def _check_f_n(frequency_hz, group_index):
    require_finite("frequency_hz", frequency_hz, positive=True)
    require_finite("group_index", group_index, positive=True)


def synthetic_wavelength_m(frequency_hz, group_index=1.0):
    """Synthetic wavelength ``c / (n f)`` (m); vacuum by default (61.24 mm at 4895 MHz).

    Parameters
    ----------
    frequency_hz : float or ndarray
        Modulation frequency (Hz, > 0).
    group_index : float or ndarray
        Group refractive index of the medium (> 0).
    """
    _check_f_n(frequency_hz, group_index)
    return C_M_PER_S / (np.asarray(group_index, dtype=float) * np.asarray(frequency_hz, dtype=float))


def ambiguity_m(frequency_hz, group_index=1.0):
    """Distance per phase cycle (the ADM's non-ambiguity range), ``c / (2 n f)`` (m)."""
    return 0.5 * synthetic_wavelength_m(frequency_hz, group_index)


def distance_from_phase(phase_rad, k, frequency_hz, group_index):
    """Eq. (1): distance (m) from the measured phase, the integer ``k``, ``f_RF`` and ``n``.

    Parameters
    ----------
    phase_rad : float or ndarray
        Measured phase ``Phi`` in [0, 2 pi) (rad); other values are accepted (eq. 1 is linear).
    k : int or ndarray of int
        Number of whole phase cycles (>= 0).
    frequency_hz, group_index : float or ndarray
        Broadcast with ``phase_rad``.

    Returns
    -------
    ndarray
        ``L = (Phi / (2 pi) + k) c / (2 n f)``, metres, broadcast shape.
    """
    require_finite("phase_rad", phase_rad)
    require_finite("k", k, nonnegative=True)
    k_arr = np.asarray(k)
    if not np.all(np.asarray(k_arr, dtype=float) == np.round(np.asarray(k_arr, dtype=float))):
        raise MultilatError(f"k must be an integer, got {k!r}")
    return (np.asarray(phase_rad, dtype=float) / (2 * math.pi) + k_arr) * ambiguity_m(frequency_hz, group_index)


def phase_from_distance(distance_m, frequency_hz, group_index):
    """Inverse of eq. (1): ``(phase_rad in [0, 2 pi), k)`` for a distance (m, >= 0).

    Returns
    -------
    phase_rad : ndarray
        Phase in [0, 2 pi) (rad).
    k : ndarray of int64
        Whole cycles.
    """
    require_finite("distance_m", distance_m, nonnegative=True)
    cycles = np.asarray(distance_m, dtype=float) / ambiguity_m(frequency_hz, group_index)
    k = np.floor(cycles)
    phase = 2 * math.pi * (cycles - k)
    wrap = phase >= 2 * math.pi  # rounding at the cycle boundary
    phase = np.where(wrap, 0.0, phase)
    k = np.where(wrap, k + 1, k)
    return phase, k.astype(np.int64)


def resolve_integer(phase_rad, coarse_distance_m, frequency_hz, group_index):
    """Integer ``k`` from a coarse distance known to better than a quarter ambiguity (int64 ndarray).

    ``k = round(L_coarse / A - Phi / (2 pi))`` with ``A = c / (2 n f)``. The answer is right when
    the coarse distance's error is below ``A / 2`` (15 mm at 4895 MHz); a margin of ``A / 4`` is
    advisable. Raises :class:`MultilatError` for a negative result.
    """
    require_finite("coarse_distance_m", coarse_distance_m, nonnegative=True)
    require_finite("phase_rad", phase_rad)
    a = ambiguity_m(frequency_hz, group_index)
    k = np.round(np.asarray(coarse_distance_m, dtype=float) / a - np.asarray(phase_rad, dtype=float) / (2 * math.pi))
    if np.any(k < 0):
        raise MultilatError("coarse_distance_m is shorter than the phase alone implies (k < 0)")
    return k.astype(np.int64)


def resolve_integer_vernier(phase1_rad, phase2_rad, frequency1_hz, frequency2_hz, group_index):
    """Integer ``k1`` at ``frequency1_hz`` from the phases at two modulation frequencies (vernier).

    The phase difference ``Phi1 - Phi2`` behaves like a phase at the beat frequency
    ``|f1 - f2|``, whose ambiguity ``c / (2 n |f1 - f2|)`` is long: the coarse distance
    ``L_c = wrap(Phi1 - Phi2) / (2 pi) x c / (2 n (f1 - f2))`` (for ``f1 > f2``), valid while the
    true distance is below that beat ambiguity, resolves ``k1`` by :func:`resolve_integer`. The
    phase noise of the difference is magnified by ``f1 / (f1 - f2)``; the result is right when
    that magnified error stays below a quarter of ``c / (2 n f1)``.

    Returns
    -------
    ndarray of int64
        ``k1``.
    """
    require_finite("frequency1_hz", frequency1_hz, positive=True)
    require_finite("frequency2_hz", frequency2_hz, positive=True)
    f1, f2 = float(frequency1_hz), float(frequency2_hz)
    if not f1 > f2:
        raise MultilatError(f"frequency1_hz must exceed frequency2_hz, got {f1!r} <= {f2!r}")
    dphi = np.mod(np.asarray(phase1_rad, dtype=float) - np.asarray(phase2_rad, dtype=float), 2 * math.pi)
    coarse = dphi / (2 * math.pi) * ambiguity_m(f1 - f2, group_index)
    return resolve_integer(phase1_rad, coarse, f1, group_index)


# ------------------------------------------------------------------ Table I error sources
def crosstalk_phase_error_rad(scr_db, relative_phase_rad):
    """Phase error (rad) of a signal plus a spurious phasor of relative amplitude 10^(-SCR/20).

    ``atan2(r sin psi, 1 + r cos psi)``: exact for one crosstalk phasor at relative phase ``psi``.
    """
    require_finite("scr_db", scr_db, positive=True)
    r = 10.0 ** (-np.asarray(scr_db, dtype=float) / 20.0)
    psi = np.asarray(relative_phase_rad, dtype=float)
    return np.arctan2(r * np.sin(psi), 1.0 + r * np.cos(psi))


def crosstalk_amplitude_m(scr_db, frequency_hz, group_index=1.0):
    """Amplitude (m) of the cyclic distance error from crosstalk: ``asin(10^(-SCR/20)) / (2 pi) x c/(2 n f)``.

    65 dB at 4895 MHz: 2.74 um (the seed's 2.7 um); its arcsine std is amplitude / sqrt(2) = 1.94 um.
    """
    require_finite("scr_db", scr_db, positive=True)
    r = 10.0 ** (-np.asarray(scr_db, dtype=float) / 20.0)
    return np.arcsin(r) / (2 * math.pi) * ambiguity_m(frequency_hz, group_index)


def phase_noise_std_m(phase_noise_rad, frequency_hz, group_index=1.0):
    """Distance std (m) of a phase std (rad): ``std / (2 pi) x c / (2 n f)``; 0.17 mrad -> 0.83 um."""
    require_finite("phase_noise_rad", phase_noise_rad, nonnegative=True)
    return np.asarray(phase_noise_rad, dtype=float) / (2 * math.pi) * ambiguity_m(frequency_hz, group_index)


def am_pm_std_m(coefficient_m_per_db, power_p2p_db):
    """Std (m) of the AM/PM error for a power uniform over a peak-to-peak range: ``|k| p2p / sqrt(12)``.

    -0.15 um/dB over 5 dB: 0.22 um (the seed's 0.2 um).
    """
    require_finite("coefficient_m_per_db", coefficient_m_per_db)
    require_finite("power_p2p_db", power_p2p_db, nonnegative=True)
    return abs(float(coefficient_m_per_db)) * float(power_p2p_db) / math.sqrt(12.0)


def clock_relative_std(ageing_per_year, interval_years=1.0):
    """Relative std of the modulation frequency: ageing rate x time since calibration (1.5e-9 per year)."""
    require_finite("ageing_per_year", ageing_per_year, nonnegative=True)
    require_finite("interval_years", interval_years, nonnegative=True)
    return float(ageing_per_year) * float(interval_years)


@dataclass(frozen=True)
class TelemetricTerms:
    """The four telemetric error sources of Table I, derived from physical parameters.

    Attributes
    ----------
    clock_relative_std : float
        Relative std of the scale (gaussian): the distance std is this times the distance.
    crosstalk_scr_db : float
        Signal-to-crosstalk ratio (dB) from which the cyclic error is drawn.
    crosstalk_amplitude_m : float
        Amplitude of the cyclic error (m); arcsine law.
    crosstalk_std_m : float
        Its standard deviation, amplitude / sqrt(2) (m).
    noise_std_m : float
        Phase-noise distance std (m), gaussian.
    am_pm_half_width_m : float
        Half-width of the uniform AM/PM error (m).
    am_pm_std_m : float
        Its std (m).
    ambiguity_m : float
        ``c / (2 n f)`` (m), the distance per phase cycle used in the conversions.
    """

    clock_relative_std: float
    crosstalk_scr_db: float
    crosstalk_amplitude_m: float
    crosstalk_std_m: float
    noise_std_m: float
    am_pm_half_width_m: float
    am_pm_std_m: float
    ambiguity_m: float

    def std_m(self, distance_m):
        """Combined std of the four terms at a distance (m): root sum of squares, ndarray."""
        d = np.asarray(distance_m, dtype=float)
        return np.sqrt((self.clock_relative_std * d) ** 2 + self.crosstalk_std_m ** 2 + self.noise_std_m ** 2
                       + self.am_pm_std_m ** 2)


def telemetric_terms(adm_config, group_index: float = 1.0) -> TelemetricTerms:
    """Table I terms from an :class:`multilat.instrument.ADMConfig` and the air group index."""
    f = adm_config.modulation_frequency_hz
    amp = float(crosstalk_amplitude_m(adm_config.signal_to_crosstalk_db, f, group_index))
    am = am_pm_std_m(adm_config.am_pm_m_per_db, adm_config.power_variation_db)
    return TelemetricTerms(
        clock_relative_std=clock_relative_std(adm_config.clock_ageing_per_year, adm_config.calibration_interval_years),
        crosstalk_scr_db=float(adm_config.signal_to_crosstalk_db),
        crosstalk_amplitude_m=amp,
        crosstalk_std_m=amp / math.sqrt(2.0),
        noise_std_m=float(phase_noise_std_m(adm_config.phase_noise_rad, f, group_index)),
        am_pm_half_width_m=0.5 * abs(adm_config.am_pm_m_per_db) * adm_config.power_variation_db,
        am_pm_std_m=am,
        ambiguity_m=float(ambiguity_m(f, group_index)),
    )
