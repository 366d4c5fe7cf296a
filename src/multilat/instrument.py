"""Instrument description: a validated TOML config of an RF-phase multilateration system.

An instrument is what the distance budget (:mod:`multilat.budget`) needs to know: the absolute
distance meter's physical parameters (Table I of the seed), the misalignment parameters of each
measurement head (Table III) and of the target (Table IV), the environmental sensors, the angle
ranges over which sightings are spread, and the Monte Carlo set-up of section 3.4.

The seed paper's instrument ships as the preset ``seed2020`` (``src/multilat/presets/seed2020.toml``,
commented key by key). A user writes their own file with the same keys; every key is checked
(``extra="forbid"``: a mistyped key is an error, not a silently ignored line) and every value must be
finite and, where physical, non-negative. Errors are one-line :class:`~multilat.errors.MultilatError`
messages naming the file and the key path, e.g. ``my.toml: heads.A.toh_std_m: must be >= 0``.

Units: SI unless a key's suffix says otherwise (``_deg``, ``_db``, ``_hpa``, ``_pct``, ``_ppm``,
``_nm``); angles are converted to radians by the properties that consume them. The offsets of heads
and targets, their bounds and standard uncertainties (metres keys of ``head_common``, ``heads``,
``target``) must lie within ±``SMALL_LENGTH_MAX_M`` (0.1 m), ``am_pm_m_per_db`` within ±1e-3 m/dB:
a larger value is a unit slip (µm written in a metres key), named with its file, key and the value
it likely meant, e.g. ``my.toml: head_common.beam_offset_m: must lie within ±0.1 m, got -320 m;
-320 µm written in a metres key? (-0.00032 m)``.

Example
-------
>>> from multilat.instrument import load_instrument
>>> inst = load_instrument("seed2020")
>>> sorted(inst.heads)
['A', 'B', 'C', 'D']
>>> inst.adm.modulation_frequency_hz
4895000000.0
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path
from typing import Literal, Optional

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from multilat.errors import MultilatError, validation_error_line

__all__ = ["ADMConfig", "Environment", "HeadCommon", "HeadConfig", "TargetConfig", "BudgetConfig",
           "Instrument", "load_instrument", "parse_instrument", "presets"]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


#: largest magnitude of a head's or target's offset, offset bound or its uncertainty, metres: the
#: seed's are a few hundred µm; a value above this is a unit slip (µm or mm written in a metres key)
SMALL_LENGTH_MAX_M = 0.1
#: largest magnitude of the amplitude-to-phase coupling, metres per dB (the seed: 0.15 µm/dB)
AM_PM_MAX_M_PER_DB = 1e-3


def _small_length(v, limit=SMALL_LENGTH_MAX_M, unit="m"):
    """``v`` (a float or an interval) unless a magnitude exceeds ``limit``: then the one-line reason,
    naming the unit the value was likely written in."""
    for x in (v if isinstance(v, tuple) else (v,)):
        if abs(x) > limit:
            key = "metres" if unit == "m" else unit
            guess = next((f"; {x:g} {u}{unit[1:]} written in a {key} key? ({x * f:g} {unit})"
                          for f, u in ((1e-3, "mm"), (1e-6, "µm")) if abs(x) * f <= limit / 100), "")
            raise ValueError(f"must lie within ±{limit:g} {unit}, got {x:g} {unit}{guess}")
    return v


def _interval(v, name="interval"):
    lo, hi = v
    if not hi >= lo:
        raise ValueError(f"must be [low, high] with low <= high, got {list(v)}")
    return v


class ADMConfig(_Model):
    """Absolute distance meter (Table I).

    Attributes
    ----------
    modulation_frequency_hz : float
        RF modulation frequency f_RF (> 0).
    wavelength_nm : float
        Vacuum wavelength of the optical carrier (> 0), for the air group index.
    signal_to_crosstalk_db : float
        Worst accepted signal-to-crosstalk ratio (dB, > 0).
    phase_noise_rad : float
        Standard deviation of a phase measurement (rad, >= 0).
    am_pm_m_per_db : float
        Amplitude-to-phase coupling: distance change per dB of received power (m/dB, any sign).
    power_variation_db : float
        Peak-to-peak received-power variation, uniformly distributed (dB, >= 0).
    clock_ageing_per_year : float
        Relative ageing rate of the reference clock (1/year, >= 0).
    calibration_interval_years : float
        Time between clock calibrations (years, >= 0).
    """

    modulation_frequency_hz: float = Field(json_schema_extra={"constraint": "> 0"},
                                           description="RF modulation frequency f_RF of the ADM (Table I)")
    wavelength_nm: float = Field(1550.0, json_schema_extra={"constraint": "> 0"},
                                 description="vacuum wavelength of the optical carrier, for the air group index")
    signal_to_crosstalk_db: float = Field(json_schema_extra={"constraint": "> 0"},
                                          description="worst accepted signal-to-crosstalk ratio")
    phase_noise_rad: float = Field(json_schema_extra={"constraint": ">= 0"},
                                   description="standard deviation of one phase measurement")
    am_pm_m_per_db: float = Field(0.0, json_schema_extra={"constraint": "within ±0.001 m/dB"},
                                  description="amplitude-to-phase coupling: distance change per dB of received power "
                                              "(any sign)")
    power_variation_db: float = Field(0.0, json_schema_extra={"constraint": ">= 0"},
                                      description="peak-to-peak received-power variation, uniformly distributed")
    clock_ageing_per_year: float = Field(0.0, json_schema_extra={"constraint": ">= 0"},
                                         description="relative ageing rate of the reference clock")
    calibration_interval_years: float = Field(1.0, json_schema_extra={"constraint": ">= 0"},
                                              description="time between clock calibrations")

    @field_validator("modulation_frequency_hz", "wavelength_nm", "signal_to_crosstalk_db")
    @classmethod
    def _pos(cls, v):
        if not v > 0:
            raise ValueError(f"must be > 0, got {v}")
        return v

    _len = field_validator("am_pm_m_per_db")(
        classmethod(lambda cls, v: _small_length(v, AM_PM_MAX_M_PER_DB, "m/dB")))

    @field_validator("phase_noise_rad", "power_variation_db", "clock_ageing_per_year",
                     "calibration_interval_years")
    @classmethod
    def _nonneg(cls, v):
        if not v >= 0:
            raise ValueError(f"must be >= 0, got {v}")
        return v


class Environment(_Model):
    """Nominal air and the standard uncertainties of the environmental sensors."""

    temperature_c: float = Field(20.0, json_schema_extra={"constraint": "within [-40, 100] (the air formulas' range)"},
                                 description="nominal air temperature")
    pressure_hpa: float = Field(
        1013.25, json_schema_extra={"constraint": "within [100, 1400] (the air formulas' range)"},
        description="nominal air pressure")
    humidity_pct: float = Field(50.0, json_schema_extra={"constraint": "within [0, 100]"},
                                description="nominal relative humidity")
    co2_ppm: float = Field(450.0, json_schema_extra={"constraint": "within [0, 2000] (the air formulas' range)"},
                           description="nominal CO2 mole fraction")
    u_temperature_c: float = Field(0.0, json_schema_extra={"constraint": ">= 0"},
                                   description="standard uncertainty of the temperature sensor")
    u_pressure_hpa: float = Field(0.0, json_schema_extra={"constraint": ">= 0"},
                                  description="standard uncertainty of the pressure sensor")
    u_humidity_pct: float = Field(0.0, json_schema_extra={"constraint": ">= 0"},
                                  description="standard uncertainty of the humidity sensor")
    u_co2_ppm: float = Field(0.0, json_schema_extra={"constraint": ">= 0"},
                             description="standard uncertainty of the CO2 value")

    @field_validator("pressure_hpa")
    @classmethod
    def _p(cls, v):
        if not v > 0:
            raise ValueError(f"must be > 0, got {v}")
        from multilat.air import PRESSURE_RANGE_PA

        lo, hi = (x / 100 for x in PRESSURE_RANGE_PA)
        if not lo <= v <= hi:
            raise ValueError(f"must lie in [{lo:g}, {hi:g}] hPa (the air formulas' range), got {v}")
        return v

    @field_validator("temperature_c", "co2_ppm")
    @classmethod
    def _air_range(cls, v, info):
        from multilat.air import CO2_RANGE_PPM, TEMPERATURE_RANGE_C

        lo, hi = TEMPERATURE_RANGE_C if info.field_name == "temperature_c" else CO2_RANGE_PPM
        if not lo <= v <= hi:
            raise ValueError(f"must lie in [{lo:g}, {hi:g}] (the air formulas' range), got {v}")
        return v

    @field_validator("humidity_pct")
    @classmethod
    def _rh(cls, v):
        if not 0 <= v <= 100:
            raise ValueError(f"must lie in [0, 100], got {v}")
        return v

    @field_validator("co2_ppm", "u_temperature_c", "u_pressure_hpa", "u_humidity_pct", "u_co2_ppm")
    @classmethod
    def _nonneg(cls, v):
        if not v >= 0:
            raise ValueError(f"must be >= 0, got {v}")
        return v


class HeadCommon(_Model):
    """What all heads share: the common beam-offset law and the elevation range of sightings.

    ``beam_offset_m`` is the uniform interval of the beam offsets a and c of every head (the seed:
    +-320 um); ``elevation_deg`` the uniform range of the head elevation angle phi, measured from the
    horizontal (the convention that makes eq. 2's ``cos(phi)`` right, see :mod:`multilat.gimbal`).
    """

    beam_offset_m: tuple[float, float] = Field(
        (-320e-6, 320e-6), json_schema_extra={"constraint": "[low, high], low <= high; within ±0.1 m"},
        description="uniform interval of the beam offsets a and c of every head (the seed: ±320 µm)")
    elevation_deg: tuple[float, float] = Field(
        (-90.0, 90.0), json_schema_extra={"constraint": "[low, high], low <= high; within [-180, 180]"},
        description="uniform range of the head elevation angle φ, measured from the horizontal")

    _iv = field_validator("beam_offset_m", "elevation_deg")(classmethod(lambda cls, v: _interval(v)))
    _len = field_validator("beam_offset_m")(classmethod(lambda cls, v: _small_length(v)))

    @field_validator("elevation_deg")
    @classmethod
    def _el(cls, v):
        if not (-180 <= v[0] and v[1] <= 180):
            raise ValueError(f"must lie within [-180, 180] degrees, got {list(v)}")
        return v


class HeadConfig(_Model):
    """One measurement head (Table III).

    Attributes
    ----------
    a_limit_m, c_limit_m : float
        Observed bounds of |a| and |c| for this head (m, >= 0); used when the budget's
        ``beam_offset_model`` is ``"per_head"``.
    alpha_deg, gamma_deg : (float, float)
        Beam-tilt intervals (degrees), uniform.
    toh_m, toh_std_m : float
        Transit-offset estimate and its standard uncertainty (m; eq. 2/4 convention: positive
        lengthens the measured distance at horizontal sight).
    """

    a_limit_m: float = Field(json_schema_extra={"constraint": ">= 0; within ±0.1 m"},
                             description="observed bound of |a| for this head (used when budget.beam_offset_model = "
                                         "\"per_head\")")
    c_limit_m: float = Field(json_schema_extra={"constraint": ">= 0; within ±0.1 m"},
                             description="observed bound of |c| for this head (used when budget.beam_offset_model = "
                                         "\"per_head\")")
    alpha_deg: tuple[float, float] = Field(
        json_schema_extra={"constraint": "[low, high], low <= high; within (-90, 90)"},
        description="beam-tilt interval α, uniform")
    gamma_deg: tuple[float, float] = Field(
        json_schema_extra={"constraint": "[low, high], low <= high; within (-90, 90)"},
        description="beam-tilt interval γ, uniform")
    toh_m: float = Field(json_schema_extra={"constraint": "within ±0.1 m"},
                         description="transit-offset estimate Toh (eq. 2/4: positive lengthens the measured distance "
                                     "at horizontal sight)")
    toh_std_m: float = Field(json_schema_extra={"constraint": ">= 0; within ±0.1 m"},
                             description="standard uncertainty of Toh")

    _iv = field_validator("alpha_deg", "gamma_deg")(classmethod(lambda cls, v: _interval(v)))
    _len = field_validator("a_limit_m", "c_limit_m", "toh_m", "toh_std_m")(
        classmethod(lambda cls, v: _small_length(v)))

    @field_validator("a_limit_m", "c_limit_m", "toh_std_m")
    @classmethod
    def _nonneg(cls, v):
        if not v >= 0:
            raise ValueError(f"must be >= 0, got {v}")
        return v

    @field_validator("alpha_deg", "gamma_deg")
    @classmethod
    def _small(cls, v):
        if not (abs(v[0]) < 90 and abs(v[1]) < 90):
            raise ValueError(f"beam tilts must lie within (-90, 90) degrees, got {list(v)}")
        return v


class TargetConfig(_Model):
    """The target (Table IV) and the angles at which it is used.

    Offsets follow eq. (5)'s convention: a', b', c' in the corner-cube frame (b' along the cube
    axis, positive towards the head), ``tot_m`` positive when the transit axis is displaced
    towards the head. ``misalignment_half_angle_deg`` bounds the angle between the cube axis and
    the line of sight (default: half of the 30 deg aperture); ``misalignment_shape`` = ``"cone"``
    draws that direction uniformly over the cone's solid angle, ``"square"`` draws theta'' and
    phi'' as independent uniforms on [-h, h]. ``transit_correction`` says how the estimated Tot is
    corrected: ``"model"`` (eq. 5's Tot term at the sighting's angles phi', theta'', phi''),
    ``"line_of_sight"`` (eq. 2 form with the elevation of the line of sight seen from the target)
    or ``"target_axis"`` (eq. 2 form with the target's own elevation phi').
    ``constant_calibrated``: b' at perfect alignment is a constant of the target, calibrated with
    the ADM zero and removed from the error.
    """

    a_m: float = Field(json_schema_extra={"constraint": "within ±0.1 m"},
                       description="target offset a′ in the corner-cube frame (eq. 5)")
    b_m: float = Field(json_schema_extra={"constraint": "within ±0.1 m"},
                       description="target offset b′ along the cube axis, positive towards the head (eq. 5)")
    c_m: float = Field(json_schema_extra={"constraint": "within ±0.1 m"},
                       description="target offset c′ in the corner-cube frame (eq. 5)")
    offset_std_m: float = Field(json_schema_extra={"constraint": ">= 0; within ±0.1 m"},
                                description="standard uncertainty of each target offset")
    tot_m: float = Field(json_schema_extra={"constraint": "within ±0.1 m"},
                         description="target transit offset Tot, positive when the transit axis is displaced towards "
                                     "the head")
    tot_std_m: float = Field(json_schema_extra={"constraint": ">= 0; within ±0.1 m"},
                             description="standard uncertainty of Tot")
    aperture_deg: float = Field(30.0, json_schema_extra={"constraint": "within (0, 180)"},
                                description="full acceptance angle of the corner cube")
    elevation_deg: tuple[float, float] = Field(
        (-90.0, 90.0), json_schema_extra={"constraint": "[low, high], low <= high"},
        description="range of the target's elevation angle φ′ in use")
    misalignment_half_angle_deg: float = Field(15.0, json_schema_extra={"constraint": ">= 0; < 90"},
                                               description="largest angle between the cube axis and the line of sight")
    misalignment_shape: Literal["cone", "square"] = Field("cone",
                                                          description="\"cone\": the axis direction uniform over the "
                                                                      "cone's solid angle; \"square\": θ″ and φ″ "
                                                                      "independent uniforms on [-h, h]")
    transit_correction: Literal["model", "line_of_sight", "target_axis"] = Field(
        "model",
        description="how the estimated Tot is corrected: \"model\" (eq. 5's Tot term), \"line_of_sight\" (eq. 2 form, "
                    "elevation of the line of sight seen from the target), \"target_axis\" (eq. 2 form, the target's "
                    "own elevation)")
    constant_calibrated: bool = Field(True,
                                      description="b′ at perfect alignment is a constant of the target, calibrated "
                                                  "with the ADM zero and removed from the error")

    _iv = field_validator("elevation_deg")(classmethod(lambda cls, v: _interval(v)))
    _len = field_validator("a_m", "b_m", "c_m", "offset_std_m", "tot_m", "tot_std_m")(
        classmethod(lambda cls, v: _small_length(v)))

    @field_validator("offset_std_m", "tot_std_m", "misalignment_half_angle_deg")
    @classmethod
    def _nonneg(cls, v):
        if not v >= 0:
            raise ValueError(f"must be >= 0, got {v}")
        return v

    @field_validator("aperture_deg")
    @classmethod
    def _ap(cls, v):
        if not 0 < v < 180:
            raise ValueError(f"must lie in (0, 180) degrees, got {v}")
        return v

    @model_validator(mode="after")
    def _inside(self):
        if self.misalignment_half_angle_deg >= 90:
            raise ValueError("misalignment_half_angle_deg must be < 90")
        return self


class BudgetConfig(_Model):
    """Monte Carlo set-up of the distance budget (section 3.4)."""

    distance_start_m: float = Field(0.2, json_schema_extra={"constraint": "> 0"},
                                    description="first distance of the budget's grid")
    distance_stop_m: float = Field(20.2, json_schema_extra={"constraint": ">= distance_start_m"},
                                   description="last distance of the grid (included)")
    distance_step_m: float = Field(0.8, description="step of the grid", json_schema_extra={"constraint": "> 0"})
    trials_per_distance: int = Field(200_000, json_schema_extra={"constraint": ">= 2"},
                                     description="Monte Carlo trials per distance")
    include_air: bool = Field(False,
                              description="add the air group-index uncertainty (environment's u_*) to the budget")
    beam_offset_model: Literal["common", "per_head"] = Field(
        "common",
        description="\"common\": head_common.beam_offset_m for every head; \"per_head\": each head's a_limit_m and "
                    "c_limit_m")

    @field_validator("distance_start_m", "distance_step_m")
    @classmethod
    def _pos(cls, v):
        if not v > 0:
            raise ValueError(f"must be > 0, got {v}")
        return v

    @field_validator("trials_per_distance")
    @classmethod
    def _trials(cls, v):
        if v < 2:
            raise ValueError(f"must be >= 2, got {v}")
        return v

    @model_validator(mode="after")
    def _order(self):
        if not self.distance_stop_m >= self.distance_start_m:
            raise ValueError("distance_stop_m must be >= distance_start_m")
        return self

    @property
    def distances_m(self):
        """The budget's distance grid, ndarray (m,) in metres (stop included)."""
        import numpy as np

        n = int(math.floor((self.distance_stop_m - self.distance_start_m) / self.distance_step_m + 1e-9)) + 1
        return np.round(self.distance_start_m + self.distance_step_m * np.arange(n), 12)


class TrackerConfig(_Model):
    """A laser tracker beside the heads, in its maker's MPE form (:class:`multilat.tracker.TrackerSpec`):
    distance MPE ``adm_a_um + adm_b_um_per_m · L``, transverse MPE ``transverse_a_um +
    transverse_b_um_per_m · L`` (angles: over the range), an optional constant angular MPE
    ``angular_c_urad``, ``std_per_mpe`` (0.5: the MPE read as k = 2), and ``levelled`` (its vertical is
    the world's: one orientation angle instead of three when angles are adjusted)."""

    adm_a_um: float = Field(json_schema_extra={"constraint": ">= 0"},
                            description="constant term of the tracker's distance MPE a + b·L")
    adm_b_um_per_m: float = Field(json_schema_extra={"constraint": ">= 0; a + b > 0"},
                                  description="length term of the distance MPE")
    transverse_a_um: float = Field(json_schema_extra={"constraint": ">= 0"},
                                   description="constant term of the transverse (angle) MPE over the range")
    transverse_b_um_per_m: float = Field(json_schema_extra={"constraint": ">= 0"},
                                         description="length term of the transverse MPE")
    angular_c_urad: float = Field(0.0, json_schema_extra={"constraint": ">= 0; some angular MPE > 0"},
                                  description="constant angular MPE")
    std_per_mpe: float = Field(0.5, json_schema_extra={"constraint": "within (0, 1]"},
                               description="standard uncertainty per MPE (0.5: the MPE read as k = 2)")
    levelled: bool = Field(False,
                           description="the tracker's vertical is the world's: one orientation angle instead of three"
                                       " when angles are adjusted")

    @model_validator(mode="after")
    def _spec(self):
        try:
            self.spec()
        except MultilatError as exc:
            raise ValueError(str(exc).replace("tracker specification: ", "")) from None
        return self

    def spec(self):
        """The :class:`multilat.tracker.TrackerSpec` of this tracker."""
        from multilat.tracker import TrackerSpec

        return TrackerSpec(self.adm_a_um, self.adm_b_um_per_m, self.transverse_a_um, self.transverse_b_um_per_m,
                           self.angular_c_urad, self.std_per_mpe)


class Instrument(_Model):
    """A whole instrument: ADM, environment, heads, target, budget set-up.

    Heads of one design are described once: ``[heads.default]`` applies to every head name not
    listed under ``heads``; ``[head_types.X]`` blocks with a ``[head_map]`` table (``H1 = "X"``)
    give named designs to named heads. :meth:`head` resolves a name: ``heads``, then ``head_map``,
    then ``heads.default``.
    """

    name: str = Field("custom", description="the instrument's name, shown in outputs")
    description: str = Field("", description="free text")
    adm: ADMConfig = Field(description="the absolute distance meter (Table I)")
    environment: Environment = Field(Environment(),
                                     description="nominal air and the environmental sensors' uncertainties")
    head_common: HeadCommon = Field(HeadCommon(),
                                    description="what all heads share: the beam-offset law and the elevation range")
    heads: dict[str, HeadConfig] = Field({}, json_schema_extra={"constraint": "heads or head_types non-empty"},
                                         description="one table per head, by name; [heads.default] applies to any "
                                                     "head not listed")
    head_types: dict[str, HeadConfig] = Field({}, description="named head designs, given to heads by head_map")
    head_map: dict[str, str] = Field({}, json_schema_extra={"constraint": "a known type; not a head of [heads]"},
                                     description="head name -> head type (a key of head_types)")
    trackers: dict[str, TrackerConfig] = Field({}, json_schema_extra={"constraint": "not also a head"},
                                               description="laser trackers beside the heads, by name")
    target: TargetConfig = Field(description="the target (Table IV)")
    budget: BudgetConfig = Field(BudgetConfig(), description="Monte Carlo set-up of the distance budget (section 3.4)")
    azimuth_sense: Optional[Literal["ccw", "cw"]] = Field(
        None, description="sense of the azimuths its observation files give: ccw (from +x towards +y, multilat's) "
                          "or cw (from +x towards -y, as many trackers report); unset: ccw; --azimuth-sense "
                          "must agree with it (a contradiction is refused)")

    @model_validator(mode="after")
    def _some(self):
        if not self.heads and not self.head_types:
            raise ValueError("at least one head (or head type) is required")
        for h, ty in self.head_map.items():
            if ty not in self.head_types:
                raise ValueError(f"head_map.{h}: unknown head type {ty!r}; head types: "
                                 f"{', '.join(sorted(self.head_types)) or 'none'}")
            if h in self.heads:
                raise ValueError(f"head_map.{h}: head {h!r} also has its own block under heads")
        for t in self.trackers:
            if t in self.heads or t in self.head_map:
                raise ValueError(f"trackers.{t}: {t!r} is also a head")
        return self

    def is_tracker(self, name: str) -> bool:
        """Whether ``name`` is one of the instrument's laser trackers (``[trackers.NAME]``)."""
        return name in self.trackers

    def has_head(self, name: str) -> bool:
        """Whether :meth:`head` resolves ``name`` (own block, mapped type or the default head; a tracker
        is not a head)."""
        if name in self.trackers:
            return False
        return name in self.heads or name in self.head_map or "default" in self.heads

    def head(self, name: str) -> HeadConfig:
        """The head called ``name`` (its own block, its type in ``head_map``, or ``heads.default``);
        :class:`MultilatError` listing the heads if unknown."""
        if name in self.heads:
            return self.heads[name]
        if name in self.head_map:
            return self.head_types[self.head_map[name]]
        if "default" in self.heads:
            return self.heads["default"]
        known = sorted(self.heads) + sorted(self.head_map)
        raise MultilatError(f"unknown head {name!r} in instrument {self.name!r}; "
                            f"heads: {', '.join(known)} (a [heads.default] block applies to any head)")


def presets() -> list[str]:
    """Names of the shipped instrument presets."""
    files = resources.files("multilat").joinpath("presets")
    return sorted(p.name[:-5] for p in files.iterdir() if p.name.endswith(".toml"))


def parse_instrument(data: dict, *, source: str = "<dict>") -> Instrument:
    """Validate a decoded config mapping; :class:`MultilatError` names the key and the source."""
    try:
        return Instrument.model_validate(data)
    except ValidationError as err:
        raise MultilatError(validation_error_line(err, source)) from None


def load_instrument(name_or_path: str | Path = "seed2020") -> Instrument:
    """Load a preset by name (e.g. ``"seed2020"``) or a TOML file by path.

    Raises
    ------
    MultilatError
        Unknown preset (the message lists the presets), unreadable file, malformed TOML (with the
        line), or an invalid/mistyped key (named with its path in the file).
    """
    s = str(name_or_path)
    path = Path(s)
    if path.suffix == ".toml" or path.exists() or "/" in s or "\\" in s:
        from multilat.inputs import read_text_input

        if not path.exists():
            raise MultilatError(f"instrument file not found: {s}")
        text = read_text_input(path, "config")
        source = s
    else:
        if s not in presets():
            raise MultilatError(f"unknown instrument preset {s!r}; presets: {', '.join(presets())} "
                                f"(or give a path to a .toml file)")
        text = resources.files("multilat").joinpath("presets", f"{s}.toml").read_text(encoding="utf-8")
        source = f"preset {s}"
    from multilat.inputs import parse_toml

    return parse_instrument(parse_toml(text, source), source=source)
