"""The laser-ball-bar configuration: a pydantic-validated TOML file.

The default, :data:`DEFAULT_CONFIG` (``src/multilat/lbb/canning2007.toml``), is the set-up of the
seed paper (Canning et al. 2007): a 564 mm equilateral base, the error ranges of §3-4 with each
unit decided from the physics (the file comments every key), a bar geometry and tube materials
chosen by us (the paper gives none), and the 75-point comparison lattice standing in for the lost
Table 2. Every key is required and checked (``extra="forbid"``): a missing or mistyped key raises a
one-line :class:`~multilat.errors.MultilatError` naming the file and the key path.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from multilat.errors import MultilatError, validation_error_line

__all__ = ["DEFAULT_CONFIG", "LBBConfig", "load_config", "parse_config"]

DEFAULT_CONFIG = Path(__file__).with_name("canning2007.toml")


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, strict=False)


def _pos(v, info):
    if not v > 0:
        raise ValueError(f"must be > 0, got {v!r}")
    return v


def _nonneg(v, info):
    if not v >= 0:
        raise ValueError(f"must be >= 0, got {v!r}")
    return v


class Tube(_Model):
    """A round tube: outer diameter and wall (m), Young's modulus (Pa), density (kg/m³)."""

    outer_diameter_m: float = Field(description="outer diameter of the tube", json_schema_extra={"constraint": "> 0"})
    wall_m: float = Field(description="wall thickness", json_schema_extra={"constraint": "> 0; < outer_diameter_m / 2"})
    youngs_modulus_pa: float = Field(json_schema_extra={"constraint": "> 0"},
                                     description="Young's modulus of the material")
    density_kg_m3: float = Field(description="density of the material", json_schema_extra={"constraint": "> 0"})

    _p = field_validator("outer_diameter_m", "wall_m", "youngs_modulus_pa", "density_kg_m3")(_pos)

    @model_validator(mode="after")
    def _wall(self):
        if not 2 * self.wall_m < self.outer_diameter_m:
            raise ValueError("wall_m must be < outer_diameter_m / 2")
        return self


class Bar(_Model):
    """Bar geometry (section lengths along the DMI axis, see :mod:`multilat.lbb.htm`)."""

    la_m: float = Field(json_schema_extra={"constraint": "> 0"},
                        description="length La from the left ball to the outer tube's bearing (fixed; holds the "
                                    "optics)")
    lb_min_m: float = Field(json_schema_extra={"constraint": "> 0"},
                            description="shortest Lb, bearing to CS2 (middle-tube extension)")
    lb_max_m: float = Field(description="longest Lb", json_schema_extra={"constraint": "> lb_min_m"})
    lc_min_m: float = Field(json_schema_extra={"constraint": "> 0"},
                            description="shortest Lc, CS2 to the right ball (inner-tube extension)")
    lc_max_m: float = Field(description="longest Lc", json_schema_extra={"constraint": "> lc_min_m"})
    retroreflector_x_in_cs3_m: float = Field(
        description="retroreflector apex on CS3's x axis (negative: towards the left ball)")
    unsensed_length_m: float = Field(json_schema_extra={"constraint": "> 0"},
                                     description="total unsensed length (left ball to beam splitter, apex to right "
                                                 "ball)")
    optics_mass_kg: float = Field(json_schema_extra={"constraint": ">= 0"},
                                  description="mass of the optics package, spread over La in the sag model")
    gravity_m_s2: float = Field(description="local acceleration of gravity", json_schema_extra={"constraint": "> 0"})
    outer_tube: Tube = Field(description="the outer tube")
    middle_tube: Tube = Field(description="the middle tube")
    inner_tube: Tube = Field(description="the inner tube")

    _p = field_validator("la_m", "lb_min_m", "lb_max_m", "lc_min_m", "lc_max_m",
                         "unsensed_length_m", "gravity_m_s2")(_pos)
    _n = field_validator("optics_mass_kg")(_nonneg)

    @model_validator(mode="after")
    def _ranges(self):
        if not self.lb_max_m > self.lb_min_m:
            raise ValueError("lb_max_m must be > lb_min_m")
        if not self.lc_max_m > self.lc_min_m:
            raise ValueError("lc_max_m must be > lc_min_m")
        return self

    @property
    def min_length_m(self) -> float:
        return self.la_m + self.lb_min_m + self.lc_min_m

    @property
    def max_length_m(self) -> float:
        return self.la_m + self.lb_max_m + self.lc_max_m


class Errors(_Model):
    """Error sources of §3 (SI; see the TOML comments for the unit decisions)."""

    axis_distribution: Literal["normal_2sigma", "uniform"] = Field(
        description="\"normal_2sigma\": a ±bound is 2 σ of a normal; \"uniform\": uniform on ±bound")
    middle_angle_bound_rad: float = Field(json_schema_extra={"constraint": ">= 0"},
                                          description="axis-motion angle bound of the middle tube (Table 1, e_y)")
    middle_straightness_bound_m: float = Field(json_schema_extra={"constraint": ">= 0"},
                                               description="straightness bound of the middle tube (Table 1, d_y)")
    inner_angle_bound_rad: float = Field(json_schema_extra={"constraint": ">= 0"},
                                         description="axis-motion angle bound of the inner tube")
    inner_straightness_bound_m: float = Field(json_schema_extra={"constraint": ">= 0"},
                                              description="straightness bound of the inner tube")
    bearing_compliance_rad: float = Field(json_schema_extra={"constraint": ">= 0"},
                                          description="bearing compliance tilt (§3.1.3), about z at CS2, directed by "
                                                      "gravity")
    cosine_misalignment_std_rad: float = Field(json_schema_extra={"constraint": ">= 0"},
                                               description="standard deviation of the beam's cosine misalignment "
                                                           "(§3.1.4)")
    unsensed_cte_per_c: float = Field(json_schema_extra={"constraint": ">= 0"},
                                      description="thermal expansion coefficient of the unsensed lengths (§3.1.6)")
    unsensed_temperature_bound_c: float = Field(json_schema_extra={"constraint": ">= 0"},
                                                description="± bound of their temperature change")
    thermal_model: Literal["paper_normal", "uniform"] = Field(
        description="\"paper_normal\": the bound is 2 σ of a normal (the paper); \"uniform\": uniform on ±bound")
    interferometer_std_m: float = Field(json_schema_extra={"constraint": ">= 0"},
                                        description="standard deviation of the interferometer's reading (§3.1.7)")

    _n = field_validator("middle_angle_bound_rad", "middle_straightness_bound_m", "inner_angle_bound_rad",
                         "inner_straightness_bound_m", "bearing_compliance_rad",
                         "cosine_misalignment_std_rad", "unsensed_cte_per_c",
                         "unsensed_temperature_bound_c", "interferometer_std_m")(_nonneg)


class Initialization(_Model):
    """Initialization fixture (§4.2, Fig. 2, eq. 6)."""

    enabled: bool = Field(description="simulate the initialization fixture (§4.2, eq. 6); off: L0 known exactly")
    l12_m: float = Field(json_schema_extra={"constraint": "> 0; within the bar's range"},
                         description="distance between fixture sockets 1 and 2")
    l23_m: float = Field(json_schema_extra={"constraint": "> 0; within the bar's range"},
                         description="distance between fixture sockets 2 and 3")
    fixture_offset_std_m: float = Field(json_schema_extra={"constraint": ">= 0"},
                                        description="standard deviation of socket 3's offset from the 1-2 line")

    _p = field_validator("l12_m", "l23_m")(_pos)
    _n = field_validator("fixture_offset_std_m")(_nonneg)


class Base(_Model):
    """Base sockets (base edges in metres) and their thermal drift during the cycle (§4.3)."""

    l12_m: float = Field(json_schema_extra={"constraint": "> 0; within the bar's range"},
                         description="base edge between sockets 1 and 2")
    l13_m: float = Field(json_schema_extra={"constraint": "> 0; within the bar's range"},
                         description="base edge between sockets 1 and 3")
    l23_m: float = Field(json_schema_extra={"constraint": "> 0; triangle inequality"},
                         description="base edge between sockets 2 and 3")
    thermal_cte_per_c: float = Field(json_schema_extra={"constraint": ">= 0"},
                                     description="thermal expansion coefficient of the base")
    thermal_bound_c: float = Field(json_schema_extra={"constraint": ">= 0"},
                                   description="± bound of the base's temperature change during the cycle, uniform")

    _p = field_validator("l12_m", "l13_m", "l23_m")(_pos)
    _n = field_validator("thermal_cte_per_c", "thermal_bound_c")(_nonneg)

    @model_validator(mode="after")
    def _triangle(self):
        a, b, c = self.l12_m, self.l13_m, self.l23_m
        if not (a < b + c and b < a + c and c < a + b):
            raise ValueError("base edges l12_m, l13_m, l23_m violate the triangle inequality")
        return self


class MonteCarlo(_Model):
    """Draw counts of the §5 procedure and of the direct propagation."""

    init_draws: int = Field(description="draws of L0 (§5, step 4)", json_schema_extra={"constraint": ">= 2"})
    side_draws: int = Field(json_schema_extra={"constraint": ">= 2"},
                            description="draws of the six sides per point (§5, step 6)")
    point_draws: int = Field(json_schema_extra={"constraint": ">= 2"},
                             description="points in each point cloud (§5, step 7)")
    direct_trials: int = Field(description="trials of the direct propagation", json_schema_extra={"constraint": ">= 2"})
    min_height_ratio: float = Field(json_schema_extra={"constraint": "> 0"},
                                    description="a point is singular when its height above the base is below this "
                                                "times the largest edge")

    @field_validator("init_draws", "side_draws", "point_draws", "direct_trials")
    @classmethod
    def _ge2(cls, v):
        if v < 2:
            raise ValueError(f"must be >= 2, got {v!r}")
        return v

    _p = field_validator("min_height_ratio")(_pos)


class Grid(_Model):
    """A lattice ``x × y × z`` given by ranges (m) and counts."""

    x_m: tuple[float, float] = Field(description="x range [low, high] of the lattice")
    y_m: tuple[float, float] = Field(description="y range [low, high] of the lattice")
    z_m: tuple[float, float] = Field(json_schema_extra={"constraint": "0 < low <= high"},
                                     description="z range [low, high] of the lattice (above the base)")
    nx: int = Field(description="points along x", json_schema_extra={"constraint": ">= 1"})
    ny: int = Field(description="points along y", json_schema_extra={"constraint": ">= 1"})
    nz: int = Field(description="points along z", json_schema_extra={"constraint": ">= 1"})

    @field_validator("nx", "ny", "nz")
    @classmethod
    def _ge1(cls, v):
        if v < 1:
            raise ValueError(f"must be >= 1, got {v!r}")
        return v

    @field_validator("z_m")
    @classmethod
    def _above(cls, v):
        if not (v[0] > 0 and v[1] >= v[0]):
            raise ValueError(f"must be [low, high] with 0 < low <= high, got {list(v)}")
        return v

    def points(self, n: int | None = None) -> np.ndarray:
        """Lattice points, shape (m, 3), ordered z, then y, then x (x fastest). ``n`` overrides
        every count."""
        nx, ny, nz = (n, n, n) if n is not None else (self.nx, self.ny, self.nz)
        xs = np.linspace(*self.x_m, nx)
        ys = np.linspace(*self.y_m, ny)
        zs = np.linspace(*self.z_m, nz)
        zz, yy, xx = np.meshgrid(zs, ys, xs, indexing="ij")
        return np.stack([xx.ravel(), yy.ravel(), zz.ravel()], axis=-1)


class Volume(_Model):
    """The work volume of Fig. 8: an ``nx × ny`` lattice over ``x_m × y_m`` at each height of
    ``z_levels_m`` (the map slices). Points the bar cannot reach are dropped."""

    x_m: tuple[float, float] = Field(description="x range [low, high] of each map slice")
    y_m: tuple[float, float] = Field(description="y range [low, high] of each map slice")
    nx: int = Field(description="points along x (the CLI's --grid overrides)", json_schema_extra={"constraint": ">= 2"})
    ny: int = Field(description="points along y (the CLI's --grid overrides)", json_schema_extra={"constraint": ">= 2"})
    z_levels_m: tuple[float, ...] = Field(json_schema_extra={"constraint": "non-empty; each > 0"},
                                          description="heights of the map slices")
    inside_base_only: bool = Field(description="keep only the points above the base triangle")

    @field_validator("nx", "ny")
    @classmethod
    def _ge2(cls, v):
        if v < 2:
            raise ValueError(f"must be >= 2, got {v!r}")
        return v

    @field_validator("z_levels_m")
    @classmethod
    def _zpos(cls, v):
        if len(v) < 1 or not all(z > 0 for z in v):
            raise ValueError(f"must be a non-empty list of heights > 0, got {list(v)}")
        return v

    def points(self, n: int | None = None) -> np.ndarray:
        """Lattice points, shape (m, 3), ordered z level, then y, then x (x fastest). ``n``
        overrides ``nx`` and ``ny`` (the CLI's ``--grid``)."""
        nx, ny = (n, n) if n is not None else (self.nx, self.ny)
        xs = np.linspace(*self.x_m, nx)
        ys = np.linspace(*self.y_m, ny)
        zz, yy, xx = np.meshgrid(np.asarray(self.z_levels_m), ys, xs, indexing="ij")
        return np.stack([xx.ravel(), yy.ravel(), zz.ravel()], axis=-1)


class LBBConfig(_Model):
    """The whole configuration (see ``canning2007.toml``)."""

    bar: Bar = Field(description="the bar's geometry and tubes")
    errors: Errors = Field(description="the error sources of §3")
    initialization: Initialization = Field(description="the initialization fixture (§4.2)")
    base: Base = Field(description="the base sockets and their thermal drift (§4.3)")
    monte_carlo: MonteCarlo = Field(description="draw counts")
    volume: Volume = Field(description="the work volume mapped (Fig. 8)")
    comparison: Grid = Field(description="the lattice of the comparison (stand-in for the lost Table 2)")

    @model_validator(mode="after")
    def _reach(self):
        lo, hi = self.bar.min_length_m, self.bar.max_length_m
        for name, v in (("initialization.l12_m", self.initialization.l12_m),
                        ("initialization.l23_m", self.initialization.l23_m),
                        ("initialization.l12_m + l23_m", self.initialization.l12_m + self.initialization.l23_m),
                        ("base.l12_m", self.base.l12_m), ("base.l13_m", self.base.l13_m),
                        ("base.l23_m", self.base.l23_m)):
            if not lo <= v <= hi:
                raise ValueError(f"{name} = {v} m is outside the bar's range [{lo:.4g}, {hi:.4g}] m")
        return self

    def replace(self, **sections) -> "LBBConfig":
        """A copy with whole sections or ``section__key=value`` entries replaced (validated)."""
        data = self.model_dump()
        for k, v in sections.items():
            if "__" in k:
                sec, key = k.split("__", 1)
                data[sec][key] = v
            else:
                data[k] = v
        keys = ", ".join(sorted(sections))
        return parse_config(data, source=f"config with {keys} replaced")


def parse_config(data: dict, *, source: str = "<dict>") -> LBBConfig:
    """Validate a decoded mapping; :class:`MultilatError` names the source and the key path."""
    try:
        return LBBConfig.model_validate(data)
    except ValidationError as err:
        raise MultilatError(validation_error_line(err, source)) from None


def load_config(path: str | Path | None = None) -> LBBConfig:
    """Load a TOML config (default: the seed paper's set-up, :data:`DEFAULT_CONFIG`).

    Raises
    ------
    MultilatError
        Missing/unreadable file, malformed TOML (with its line), a missing, unknown or mistyped key.
    """
    p = Path(path) if path is not None else DEFAULT_CONFIG
    from multilat.inputs import load_toml

    if not p.exists():
        raise MultilatError(f"config file not found: {p}")
    return parse_config(load_toml(p), source=str(p))
