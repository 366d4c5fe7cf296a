"""Refractive index of air: phase and group index, and the sensitivity of a distance to the air.

Two formulas, both vectorised (every argument broadcasts against the others):

``"ciddor"``
    P. E. Ciddor, "Refractive index of air: new equations for the visible and near infrared",
    Applied Optics 35 (1996) 1566-1573, with the moist-air density of the CIPM-81/91 equation
    (compressibility ``Z``), exactly as written in the NIST Engineering Metrology Toolbox notes
    (J. A. Stone, J. H. Zimmerman, "Index of refraction of air", section A-III).
``"edlen"``
    The updated Edlén formula of G. Bönsch and E. Potulski, "Measurement of the refractive index of
    air and comparison with modified Edlén's formulae", Metrologia 35 (1998) 133-139, eqs. (6)-(9a)
    (the formula the seed paper uses for its Table II).
``"edlen-nist"``
    The modified Edlén equation of the NIST calculator (Birch & Downs 1993/1994 with NIST's
    ``292.75/T`` water-vapour modification, section A-IV of the NIST notes).  It has no CO2 term
    (its standard air holds 450 ppm) and is here to check the implementation against NIST's
    published check values; ``co2_ppm`` must be 450 with it.

Humidity is given as exactly one of relative humidity (``humidity_pct``), water-vapour partial
pressure (``water_vapour_pa``) or dew point (``dew_point_c``), converted as in section A-II of the
NIST notes: saturation vapour pressure over water (IAPWS-IF97, ``t >= 0 °C``) or over ice
(IAPWS 1993, ``t < 0 °C``); enhancement factor ``f = 1.00062 + 3.14e-8 p + 5.6e-7 t^2``;
partial pressure from RH ``p_v = RH/100 · p_sv(t)``, from dew point ``p_v = p_sv(t_d)``; water
mole fraction (Ciddor) ``x_v = f(p, t) p_v / p``, or ``f(p, t_d) p_sv(t_d) / p`` from a dew point.

The group index is ``n_g = n - λ dn/dλ = n + σ dn/dσ`` (σ = 1/λ, the vacuum wavenumber), with
``dn/dσ`` taken analytically from each dispersion formula (the density factors do not depend on λ).

Validity (NIST calculator ranges, enforced): wavelength 300 nm to 1700 nm, temperature -40 °C to
100 °C, pressure 10 kPa to 140 kPa, CO2 0 to 2000 ppm, humidity 0 % to 100 % RH.  Ciddor states
300 nm to 1690 nm; Edlén-type dispersion terms were fitted to visible data, their use in the near
infrared (1550 nm, as in the seed paper) is an extrapolation (see docs/air.md for its size).

Units: SI inside; temperatures in °C (names ending ``_c``), pressures in Pa (``_pa``), CO2 as a
mole fraction in ppm (µmol/mol), wavelengths in vacuum, metres.
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError

__all__ = [
    "FORMULAS",
    "WAVELENGTH_RANGE_M",
    "TEMPERATURE_RANGE_C",
    "PRESSURE_RANGE_PA",
    "CO2_RANGE_PPM",
    "saturation_vapour_pressure_pa",
    "enhancement_factor",
    "compressibility",
    "water_vapour_pressure_pa",
    "phase_index",
    "group_index",
    "sensitivities",
    "SENSITIVITY_UNITS",
]

FORMULAS = ("ciddor", "edlen", "edlen-nist")
WAVELENGTH_RANGE_M = (300e-9, 1700e-9)
TEMPERATURE_RANGE_C = (-40.0, 100.0)
PRESSURE_RANGE_PA = (10e3, 140e3)
CO2_RANGE_PPM = (0.0, 2000.0)
DEW_POINT_MIN_C = -100.0  # lower end of the ice saturation formula's range

#: The unit each :func:`sensitivities` key is "per".
SENSITIVITY_UNITS = {"temperature_c": "°C", "pressure_hpa": "hPa", "humidity_pct": "%RH",
                     "co2_ppm": "ppm"}

# --------------------------------------------------------------------------------------------
# Humidity (NIST notes, sections A-I and A-II)
# --------------------------------------------------------------------------------------------

_K = (1.16705214528e3, -7.24213167032e5, -1.70738469401e1, 1.20208247025e4, -3.23255503223e6,
      1.49151086135e1, -4.82326573616e3, 4.05113405421e5, -2.38555575678e-1, 6.50175348448e2)


def _psv_water(t_c):
    T = np.asarray(t_c, dtype=float) + 273.15
    k1, k2, k3, k4, k5, k6, k7, k8, k9, k10 = _K
    omega = T + k9 / (T - k10)
    a = omega**2 + k1 * omega + k2
    b = k3 * omega**2 + k4 * omega + k5
    c = k6 * omega**2 + k7 * omega + k8
    x = -b + np.sqrt(b**2 - 4.0 * a * c)
    return 1e6 * (2.0 * c / x) ** 4


def _psv_ice(t_c):
    theta = (np.asarray(t_c, dtype=float) + 273.15) / 273.16
    y = -13.928169 * (1.0 - theta**-1.5) + 34.7078238 * (1.0 - theta**-1.25)
    return 611.657 * np.exp(y)


def saturation_vapour_pressure_pa(temperature_c):
    """Saturation vapour pressure of water, Pa (NIST notes A-I).

    Over liquid water (IAPWS-IF97 saturation equation) for ``t >= 0 °C``, over ice (IAPWS 1993)
    for ``t < 0 °C``.

    Parameters
    ----------
    temperature_c : array_like
        Temperature, °C.

    Returns
    -------
    ndarray, same shape, Pa.
    """
    t = np.asarray(temperature_c, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        return np.where(t >= 0.0, _psv_water(np.maximum(t, 0.0)), _psv_ice(np.minimum(t, 0.0)))


def enhancement_factor(pressure_pa, temperature_c):
    """Enhancement factor of water vapour in air, ``f = 1.00062 + 3.14e-8 p + 5.6e-7 t^2``.

    Parameters
    ----------
    pressure_pa : array_like
        Total pressure, Pa.
    temperature_c : array_like
        Temperature, °C.
    """
    p = np.asarray(pressure_pa, dtype=float)
    t = np.asarray(temperature_c, dtype=float)
    return 1.00062 + 3.14e-8 * p + 5.6e-7 * t**2


def compressibility(temperature_c, pressure_pa, water_mole_fraction):
    """Compressibility factor ``Z`` of moist air (CIPM-81/91, Ciddor 1996 eq. 12).

    Parameters
    ----------
    temperature_c, pressure_pa, water_mole_fraction : array_like
        °C, Pa, and the water-vapour mole fraction ``x_w`` (0..1).
    """
    t = np.asarray(temperature_c, dtype=float)
    p = np.asarray(pressure_pa, dtype=float)
    xw = np.asarray(water_mole_fraction, dtype=float)
    T = t + 273.15
    a0, a1, a2 = 1.58123e-6, -2.9331e-8, 1.1043e-10
    b0, b1 = 5.707e-6, -2.051e-8
    c0, c1 = 1.9898e-4, -2.376e-6
    d, e = 1.83e-11, -0.765e-8
    pt = p / T
    return (1.0 - pt * (a0 + a1 * t + a2 * t**2 + (b0 + b1 * t) * xw + (c0 + c1 * t) * xw**2)
            + pt**2 * (d + e * xw**2))


# --------------------------------------------------------------------------------------------
# Dispersion and density terms: refractivity (n - 1), phase or group
# --------------------------------------------------------------------------------------------

_R = 8.314472          # J/(mol K), as in the NIST notes (Ciddor used 8.314510; R cancels to 1e-12)
_MW = 0.018015         # kg/mol, water
_CIDDOR_K = (238.0185, 5792105.0, 57.362, 167917.0)
_CIDDOR_W = (295.235, 2.6422, -0.032380, 0.004028)


def _ciddor_refractivity(t, p, xv, co2, s2, group):
    k0, k1, k2, k3 = _CIDDOR_K
    w0, w1, w2, w3 = _CIDDOR_W
    # standard dry air (15 °C, 101325 Pa, 450 ppm) and standard water vapour (20 °C, 1333 Pa)
    r_as = 1e-8 * (k1 / (k0 - s2) + k3 / (k2 - s2))
    r_ws = 1.022e-8 * (w0 + w1 * s2 + w2 * s2**2 + w3 * s2**3)
    if group:  # + sigma d/dsigma of each dispersion term
        r_as = r_as + 1e-8 * 2.0 * s2 * (k1 / (k0 - s2) ** 2 + k3 / (k2 - s2) ** 2)
        r_ws = r_ws + 1.022e-8 * (2.0 * w1 * s2 + 4.0 * w2 * s2**2 + 6.0 * w3 * s2**3)
    r_axs = r_as * (1.0 + 0.534e-6 * (co2 - 450.0))
    ma = 1e-3 * (28.9635 + 12.011e-6 * (co2 - 400.0))
    rho_axs = 101325.0 * ma / (compressibility(15.0, 101325.0, 0.0) * _R * 288.15)
    rho_ws = 1333.0 * _MW / (compressibility(20.0, 1333.0, 1.0) * _R * 293.15)
    T = t + 273.15
    z = compressibility(t, p, xv)
    rho_a = p * ma * (1.0 - xv) / (z * _R * T)
    rho_w = p * _MW * xv / (z * _R * T)
    return (rho_a / rho_axs) * r_axs + (rho_w / rho_ws) * r_ws


def _edlen_bp_refractivity(t, p, pv, co2, s2, group):
    # Bönsch & Potulski (1998) eqs. (6)-(9a): standard air 20 °C, 100 kPa, 400 ppm CO2, dry.
    a, b, c = 8091.37, 2333983.0, 15518.0
    r_n = 1e-8 * (a + b / (130.0 - s2) + c / (38.9 - s2))
    w = 3.8020 - 0.0384 * s2
    if group:
        r_n = r_n + 1e-8 * 2.0 * s2 * (b / (130.0 - s2) ** 2 + c / (38.9 - s2) ** 2)
        w = w - 2.0 * 0.0384 * s2
    r_x = r_n * (1.0 + 0.5327 * (co2 * 1e-6 - 0.0004))
    r_tp = p * r_x / 93214.60 * (1.0 + 1e-8 * (0.5953 - 0.009876 * t) * p) / (1.0 + 0.0036610 * t)
    return r_tp - pv * w * 1e-10


def _edlen_nist_refractivity(t, p, pv, co2, s2, group):
    # NIST notes A-IV: Birch & Downs (1993, 1994) with NIST's 292.75/T water-vapour factor.
    a, b, c = 8342.54, 2406147.0, 15998.0
    r_s = 1e-8 * (a + b / (130.0 - s2) + c / (38.9 - s2))
    w = 3.7345 - 0.0401 * s2
    if group:
        r_s = r_s + 1e-8 * 2.0 * s2 * (b / (130.0 - s2) ** 2 + c / (38.9 - s2) ** 2)
        w = w - 2.0 * 0.0401 * s2
    x = (1.0 + 1e-8 * (0.601 - 0.00972 * t) * p) / (1.0 + 0.003661 * t)
    return p * r_s * x / 96095.43 - 1e-10 * (292.75 / (t + 273.15)) * w * pv


# --------------------------------------------------------------------------------------------
# Boundary: validation and humidity resolution
# --------------------------------------------------------------------------------------------

def _arr(name, value):
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise MultilatError(f"{name} must be a number or an array of numbers, got {value!r}") from None
    if not np.all(np.isfinite(a)):
        raise MultilatError(f"{name} must be finite, got {_show(value)}")
    return a


def _show(value):
    a = np.asarray(value, dtype=float) if not isinstance(value, str) else None
    if a is not None and a.ndim == 0:
        return repr(float(a))
    if a is not None:
        bad = a[~np.isfinite(a)] if not np.all(np.isfinite(a)) else a
        return f"array containing {float(bad.flat[0])!r}"
    return repr(value)


def _in_range(name, a, lo, hi, unit, scale=1.0):
    bad = (a < lo) | (a > hi)
    if np.any(bad):
        v = float(a[bad].flat[0]) * scale
        raise MultilatError(f"{name} = {v:g} {unit} is outside the valid range "
                            f"[{lo * scale:g}, {hi * scale:g}] {unit}")


def _resolve(temperature_c, pressure_pa, humidity_pct, water_vapour_pa, dew_point_c, co2_ppm,
             wavelength_m, formula):
    """Validate the inputs; return broadcast arrays (t, p, pv, xv, co2, s2) and the formula."""
    if formula not in FORMULAS:
        raise MultilatError(f"formula must be one of {', '.join(FORMULAS)}, got {formula!r}")
    given = [n for n, v in (("humidity_pct", humidity_pct), ("water_vapour_pa", water_vapour_pa),
                            ("dew_point_c", dew_point_c)) if v is not None]
    if len(given) != 1:
        raise MultilatError("give exactly one of humidity_pct, water_vapour_pa, dew_point_c "
                            f"(got {', '.join(given) if given else 'none'})")
    t = _arr("temperature_c", temperature_c)
    _in_range("temperature_c", t, *TEMPERATURE_RANGE_C, "°C")
    p = _arr("pressure_pa", pressure_pa)
    if np.any(p < 0):
        raise MultilatError(f"pressure_pa must be >= 0, got {float(p[p < 0].flat[0]):g}")
    _in_range("pressure_pa", p, *PRESSURE_RANGE_PA, "Pa")
    co2 = _arr("co2_ppm", co2_ppm)
    if np.any(co2 < 0):
        raise MultilatError(f"co2_ppm must be >= 0, got {float(co2[co2 < 0].flat[0]):g}")
    _in_range("co2_ppm", co2, *CO2_RANGE_PPM, "ppm")
    if formula == "edlen-nist" and np.any(co2 != 450.0):
        raise MultilatError("co2_ppm must be 450 with formula 'edlen-nist' (it has no CO2 term); "
                            "use 'edlen' (Bönsch & Potulski) or 'ciddor' for other CO2 contents")
    lam = _arr("wavelength_m", wavelength_m)
    if np.any(lam <= 0):
        raise MultilatError(f"wavelength_m must be > 0, got {float(lam[lam <= 0].flat[0]):g}")
    _in_range("wavelength_m", lam, *WAVELENGTH_RANGE_M, "nm", scale=1e9)

    if humidity_pct is not None:
        h = _arr("humidity_pct", humidity_pct)
        _in_range("humidity_pct", h, 0.0, 100.0, "%")
        t_b, p_b, h_b = np.broadcast_arrays(t, p, h)
        pv = h_b / 100.0 * saturation_vapour_pressure_pa(t_b)
        xv = enhancement_factor(p_b, t_b) * pv / p_b
    elif water_vapour_pa is not None:
        pv0 = _arr("water_vapour_pa", water_vapour_pa)
        if np.any(pv0 < 0):
            raise MultilatError(f"water_vapour_pa must be >= 0, got {float(pv0[pv0 < 0].flat[0]):g}")
        t_b, p_b, pv = np.broadcast_arrays(t, p, pv0)
        psv = saturation_vapour_pressure_pa(t_b)
        over = pv > psv * (1.0 + 1e-12)
        if np.any(over):
            i = np.flatnonzero(over.ravel())[0]
            raise MultilatError(f"water_vapour_pa = {pv.ravel()[i]:g} Pa exceeds the saturation vapour "
                                f"pressure {psv.ravel()[i]:g} Pa at {t_b.ravel()[i]:g} °C (RH > 100 %)")
        xv = enhancement_factor(p_b, t_b) * pv / p_b
    else:
        td = _arr("dew_point_c", dew_point_c)
        t_b, p_b, td_b = np.broadcast_arrays(t, p, td)
        if np.any(td_b < DEW_POINT_MIN_C):
            raise MultilatError(f"dew_point_c = {float(td_b[td_b < DEW_POINT_MIN_C].flat[0]):g} °C is "
                                f"below {DEW_POINT_MIN_C:g} °C")
        above = td_b > t_b
        if np.any(above):
            i = np.flatnonzero(above.ravel())[0]
            raise MultilatError(f"dew_point_c = {td_b.ravel()[i]:g} °C is above the air temperature "
                                f"{t_b.ravel()[i]:g} °C (RH > 100 %)")
        pv = saturation_vapour_pressure_pa(td_b)
        xv = enhancement_factor(p_b, td_b) * pv / p_b
    s2 = (1e-6 / lam) ** 2  # sigma^2 in µm^-2
    t, p, pv, xv, co2, s2 = np.broadcast_arrays(t_b, p_b, pv, xv, co2, s2)
    return t, p, pv, xv, co2, s2


def _refractivity(formula, t, p, pv, xv, co2, s2, group):
    if formula == "ciddor":
        return _ciddor_refractivity(t, p, xv, co2, s2, group)
    if formula == "edlen":
        return _edlen_bp_refractivity(t, p, pv, co2, s2, group)
    return _edlen_nist_refractivity(t, p, pv, co2, s2, group)


# --------------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------------

def water_vapour_pressure_pa(temperature_c, *, humidity_pct=None, dew_point_c=None):
    """Water-vapour partial pressure, Pa, from relative humidity or dew point (NIST notes A-II).

    ``RH/100 · p_sv(t)`` or ``p_sv(t_d)``; exactly one of ``humidity_pct`` and ``dew_point_c``.
    """
    if (humidity_pct is None) == (dew_point_c is None):
        raise MultilatError("give exactly one of humidity_pct, dew_point_c")
    t = _arr("temperature_c", temperature_c)
    if humidity_pct is not None:
        h = _arr("humidity_pct", humidity_pct)
        _in_range("humidity_pct", h, 0.0, 100.0, "%")
        return h / 100.0 * saturation_vapour_pressure_pa(t)
    td = _arr("dew_point_c", dew_point_c)
    if np.any(td > t):
        raise MultilatError("dew_point_c is above the air temperature (RH > 100 %)")
    return saturation_vapour_pressure_pa(td) + 0.0 * t


def phase_index(temperature_c=20.0, pressure_pa=101325.0, *, humidity_pct=None, water_vapour_pa=None,
                dew_point_c=None, co2_ppm=450.0, wavelength_m=1550e-9, formula="ciddor"):
    """Phase refractive index of air ``n``.

    Parameters
    ----------
    temperature_c : array_like
        Air temperature, °C, in [-40, 100].
    pressure_pa : array_like
        Total air pressure, Pa, in [10e3, 140e3].
    humidity_pct, water_vapour_pa, dew_point_c : array_like, exactly one of them
        Relative humidity in % (0..100), water-vapour partial pressure in Pa (at most the
        saturation pressure), or dew point in °C (at most the air temperature).
    co2_ppm : array_like
        CO2 mole fraction, µmol/mol, in [0, 2000] (450 with ``formula="edlen-nist"``).
    wavelength_m : array_like
        Vacuum wavelength, m, in [300e-9, 1700e-9].
    formula : {"ciddor", "edlen", "edlen-nist"}
        See the module docstring.

    Returns
    -------
    ndarray
        ``n``, shape of the broadcast inputs (0-d for scalars).

    Raises
    ------
    MultilatError
        Non-finite, negative or out-of-range input, naming the parameter.
    """
    t, p, pv, xv, co2, s2 = _resolve(temperature_c, pressure_pa, humidity_pct, water_vapour_pa,
                                     dew_point_c, co2_ppm, wavelength_m, formula)
    return 1.0 + _refractivity(formula, t, p, pv, xv, co2, s2, group=False)


def group_index(temperature_c=20.0, pressure_pa=101325.0, *, humidity_pct=None, water_vapour_pa=None,
                dew_point_c=None, co2_ppm=450.0, wavelength_m=1550e-9, formula="ciddor"):
    """Group refractive index of air ``n_g = n - λ dn/dλ`` (analytic dispersion derivative).

    Same parameters, shapes and errors as :func:`phase_index`.  The group index sets the speed of
    an intensity modulation (the envelope), hence the distance of an RF-phase distance meter.
    """
    t, p, pv, xv, co2, s2 = _resolve(temperature_c, pressure_pa, humidity_pct, water_vapour_pa,
                                     dew_point_c, co2_ppm, wavelength_m, formula)
    return 1.0 + _refractivity(formula, t, p, pv, xv, co2, s2, group=True)


# central-difference steps (the refractivities are smooth; truncation error ~h^2 is < 1e-9 relative)
_STEP = {"temperature_c": 1e-2, "pressure_pa": 10.0, "humidity_pct": 1e-2, "co2_ppm": 1.0}


def sensitivities(temperature_c=20.0, pressure_pa=101325.0, *, humidity_pct=None, water_vapour_pa=None,
                  dew_point_c=None, co2_ppm=450.0, wavelength_m=1550e-9, formula="ciddor",
                  index="group"):
    """Relative sensitivity of a distance to each environmental parameter, m/m per unit.

    Each value is ``s_X = (1/n) ∂n/∂X`` (``n`` the group index, or the phase index with
    ``index="phase"``) at the given state, which is the seed paper's (Table II) sign convention:

    - a distance meter measures the optical path ``L = n D``; the distance reported with an index
      computed from a sensor reading ``X_s`` is ``D_s = L / n(X_s)``, so its relative error is
      ``(D_s - D)/D ≈ s_X · (X_true - X_s)``.  With ``s_T ≈ -0.95e-6 /°C`` (group index, 1550 nm,
      20 °C): a thermometer reading 1 °C too high gives distances 0.95 µm/m too long.
    - equivalently: if the air changes by +1 unit of X and the index is not updated, the reported
      distance changes by ``s_X`` m/m (the air warms by 1 °C: distances read 0.95 µm/m shorter).
    - a Monte Carlo drawing a sensor error ``e_X = X_sensor - X_true`` adds ``-s_X e_X`` to the
      relative distance error.

    Derivatives are partial, holding the other inputs *as given* fixed: with ``humidity_pct`` the
    temperature derivative keeps RH fixed (the water-vapour pressure follows ``p_sv(t)``; this is
    what reproduces Table II's -0.95 µm/m/°C), with ``water_vapour_pa`` or ``dew_point_c`` it keeps
    that fixed.  The humidity derivative is always per %RH at fixed temperature and pressure.

    Parameters
    ----------
    Same as :func:`phase_index`, plus
    index : {"group", "phase"}

    Returns
    -------
    dict
        ``{"temperature_c": m/m per °C, "pressure_hpa": m/m per hPa, "humidity_pct": m/m per %RH,
        "co2_ppm": m/m per ppm}``, each an ndarray of the broadcast shape.  Multiply by 1e6 for
        µm/m.  For ``formula="edlen-nist"`` the CO2 value is 0 (no CO2 term).
    """
    if index not in ("group", "phase"):
        raise MultilatError(f"index must be 'group' or 'phase', got {index!r}")
    t, p, pv, xv, co2, s2 = _resolve(temperature_c, pressure_pa, humidity_pct, water_vapour_pa,
                                     dew_point_c, co2_ppm, wavelength_m, formula)
    group = index == "group"
    # humidity expressed the way it was given (kept fixed when T or p move)
    if humidity_pct is not None:
        mode, hval = "rh", 100.0 * pv / saturation_vapour_pressure_pa(t)
    elif water_vapour_pa is not None:
        mode, hval = "pv", pv
    else:
        mode, hval = "td", np.broadcast_to(np.asarray(dew_point_c, dtype=float), t.shape)

    def refr(t_, p_, co2_, mode_=mode, h_=hval):
        if mode_ == "rh":
            pv_ = h_ / 100.0 * saturation_vapour_pressure_pa(t_)
            xv_ = enhancement_factor(p_, t_) * pv_ / p_
        elif mode_ == "pv":
            pv_ = h_
            xv_ = enhancement_factor(p_, t_) * pv_ / p_
        else:
            pv_ = saturation_vapour_pressure_pa(h_)
            xv_ = enhancement_factor(p_, h_) * pv_ / p_
        return _refractivity(formula, t_, p_, pv_, xv_, co2_, s2, group)

    n = 1.0 + refr(t, p, co2)
    ht, hp, hc, hh = (_STEP[k] for k in ("temperature_c", "pressure_pa", "co2_ppm", "humidity_pct"))
    d_t = (refr(t + ht, p, co2) - refr(t - ht, p, co2)) / (2 * ht)
    d_p = (refr(t, p + hp, co2) - refr(t, p - hp, co2)) / (2 * hp) * 100.0  # per hPa
    d_c = (refr(t, p, co2 + hc) - refr(t, p, co2 - hc)) / (2 * hc)
    rh = 100.0 * pv / saturation_vapour_pressure_pa(t)
    d_h = (refr(t, p, co2, "rh", rh + hh) - refr(t, p, co2, "rh", rh - hh)) / (2 * hh)
    return {"temperature_c": d_t / n, "pressure_hpa": d_p / n, "humidity_pct": d_h / n,
            "co2_ppm": d_c / n}
