"""The options of the network model and of its adjustment: one typed, validated record shared by
``multilat adjust``, :func:`multilat.network.adjust.distance.adjust.adjust`, ``multilat propagate`` and
:func:`multilat.network.montecarlo.propagate.problem_from_observations`.

:class:`NetworkOptions` (pydantic, frozen, unknown keys refused) holds what the model and the
adjustment take: the datum, the heads' offsets and scales, levelled and distance-only stations, the
scale bars, where the σ come from, the cost, the test procedure (α, power, method, variance factor,
reliability limits), data snooping, variance components and the solver. It depends on no
observation: what needs them (a head id, a levelled station) is resolved by
:meth:`NetworkOptions.prepare` and by ``adjust``, which name the option at fault.

A bad value is one line naming the option: the Python field name (``alpha must be in (0, 1), got 2``)
or, for options built by :meth:`NetworkOptions.from_cli`, the command-line option
(``--alpha must be in (0, 1), got 2``).

Reference: ``docs/network.md`` (options table) and ``docs/cli.md`` (the options every command shares).
"""

from __future__ import annotations

import dataclasses
import math
import re
from typing import Literal, Optional, Union

from pydantic import BaseModel, ConfigDict, PrivateAttr, ValidationError, field_validator, model_validator

from multilat.errors import MultilatError

__all__ = ["NetworkOptions", "CLI_NAMES", "options_from"]

#: The command-line option of each field (the others are ``--`` + the field with dashes).
CLI_NAMES = {"offsets_m": "--fix-offsets-um", "sigma_m": "--sigma-um", "snooping": "--snooping/--no-snooping",
             "max_iter": "max_iter", "chunk_targets": "chunk_targets", "max_rejections": "max_rejections",
             "power": "power", "r_min": "r_min"}

#: The older keyword names of :func:`~multilat.network.adjust.distance.adjust.adjust` (kept as aliases).
ALIASES = {"offsets": "offsets_m"}


def _unit_interval(v, info):
    if v is not None and not (0 < v < 1):
        raise ValueError("must be in (0, 1)")
    return v


def _ids(v):
    """``"A,B"`` or a sequence -> a tuple of non-empty ids (None -> ())."""
    if v is None:
        return ()
    if isinstance(v, str):
        v = v.split(",")
    out = tuple(str(x).strip() for x in v)
    if any(not x for x in out) and len(out) > 1:
        raise ValueError("empty id in the list")
    return tuple(x for x in out if x)


class NetworkOptions(BaseModel):
    """Options of the network model and the adjustment (defaults: ``multilat adjust``'s).

    Network model
        ``datum`` ``free[:P,..]``, ``321:A,B,C`` or ``control[:P,..]``; ``cost`` ``distance`` or
        ``squared``; ``offsets_m`` None (estimate every head's offset), ``"estimate"``, one value for
        every head or ``{head: metres}`` (the others estimated); ``scales`` False, True (every head) or
        head ids; ``fixed_scale`` with ``scales=True``: the head whose scale is held (the scale datum);
        ``levelled``, ``distance_only`` station ids; ``scale_bars`` the reference lengths are
        observations (scale bars).
    σ of the observations (read with the file)
        ``sigma_m`` one σ for every distance without a ``sigma_m`` column; ``instrument`` preset or
        TOML whose distance model gives the σ (and, for ``propagate``, the errors drawn).
    Angles (read with the file)
        ``azimuth_sense`` ``ccw`` or ``cw``: the sense of the file's azimuths (None: the instrument
        file's ``azimuth_sense``, else ``ccw``); converted to counter-clockwise on reading
        (:mod:`multilat.network.adjust.distance.azimuth_sense`).
    Tests
        ``alpha`` (α0 of each observation's test), ``power``, ``alpha_global``, ``test_method``
        (None: ``fixed`` with ``alpha_global``, else ``auto``), ``alpha_family``, ``variance_factor``,
        ``mdb_limit_sigma``, ``r_min``: :func:`multilat.network.adjust.distance.adjust.adjust`.
    Procedure
        ``snooping``, ``max_rejections``, ``strict``, ``variance_components`` (None or a grouping),
        ``max_iter``, ``solver``, ``chunk_targets``.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, strict=False,
                              populate_by_name=True)

    datum: str = "free"
    cost: Literal["distance", "squared"] = "distance"
    offsets_m: Union[None, Literal["estimate"], float, dict[str, float]] = None
    scales: Union[bool, tuple[str, ...]] = False
    fixed_scale: Optional[str] = None
    levelled: tuple[str, ...] = ()
    distance_only: tuple[str, ...] = ()
    scale_bars: bool = False
    sigma_m: Optional[float] = None
    instrument: Optional[str] = None
    azimuth_sense: Optional[Literal["ccw", "cw"]] = None
    alpha: float = 0.001
    power: float = 0.80
    alpha_global: Optional[float] = None
    test_method: Optional[Literal["auto", "b-method", "sidak", "fixed"]] = None
    alpha_family: float = 0.01
    variance_factor: Literal["known", "unknown"] = "known"
    mdb_limit_sigma: float = 10.0
    r_min: float = 0.1
    snooping: bool = True
    max_rejections: Optional[int] = None
    strict: bool = False
    variance_components: Optional[Literal["head", "station", "kind"]] = None
    max_iter: int = 100
    solver: Literal["auto", "dense", "sparse"] = "auto"
    chunk_targets: int = 20000

    _cli: bool = PrivateAttr(default=False)

    _unit = field_validator("alpha", "power", "alpha_global", "alpha_family")(_unit_interval)

    @field_validator("datum", mode="before")
    @classmethod
    def _datum(cls, v):
        from multilat.network.model.datum import Datum, parse_datum

        if v is None:
            return "free"
        if isinstance(v, Datum):
            return v.kind if v.points is None else f"{v.kind}:{','.join(v.points)}"
        try:
            parse_datum(v)
        except MultilatError as exc:
            raise ValueError(str(exc).replace("datum ", "", 1)) from None
        return str(v).strip()

    @field_validator("levelled", "distance_only", mode="before")
    @classmethod
    def _id_list(cls, v):
        return _ids(v)

    @field_validator("scales", mode="before")
    @classmethod
    def _scales(cls, v):
        if v is None:
            return False
        if isinstance(v, bool):
            return v
        return _ids(v)

    @field_validator("offsets_m", mode="before")
    @classmethod
    def _offsets(cls, v):
        from collections.abc import Mapping

        if v is None or (isinstance(v, str) and v == "estimate"):
            return None
        try:
            out = ({str(k): float(x) for k, x in v.items()} if isinstance(v, Mapping)
                   else float(v) if not isinstance(v, (bool, str)) else None)
        except (TypeError, ValueError):
            out = None
        if out is None:
            raise ValueError("must be None/'estimate', a number of metres or a mapping head -> metres")
        for k, x in (out.items() if isinstance(out, dict) else [("", out)]):
            if not math.isfinite(x) or abs(x) > 10.0:
                raise ValueError(f"{'value for ' + repr(k) + ' ' if k else ''}must be finite and at most "
                                 "10 m in magnitude")
        return out

    @field_validator("sigma_m")
    @classmethod
    def _sigma(cls, v):
        if v is not None and not (1e-12 <= v <= 1.0):
            raise ValueError("must be in [1e-12, 1] m")
        return v

    @field_validator("mdb_limit_sigma", "r_min")
    @classmethod
    def _positive(cls, v):
        if not v > 0:
            raise ValueError("must be > 0")
        return v

    @field_validator("max_iter", "chunk_targets")
    @classmethod
    def _count(cls, v):
        if v < 1:
            raise ValueError("must be >= 1")
        return v

    @field_validator("max_rejections")
    @classmethod
    def _rejections(cls, v):
        if v is not None and v < 0:
            raise ValueError("must be >= 0")
        return v

    @model_validator(mode="after")
    def _together(self):
        # messages across fields: "FIELD: text" with {field} names, written as the caller names them
        if self.alpha_global is not None and self.test_method not in (None, "fixed"):
            raise ValueError(f"alpha_global: goes with {{test_method}} fixed ({{test_method}} {self.test_method} "
                             "derives it)")
        if self.fixed_scale is not None and self.scales is not True:
            raise ValueError("fixed_scale: goes with {scales}")
        return self

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_cli(cls, **fields) -> "NetworkOptions":
        """The options of a command (errors name the command-line option)."""
        return _build(cls, fields, cli=True)

    @classmethod
    def of(cls, options: "NetworkOptions | None" = None, **fields) -> "NetworkOptions":
        """``options`` with ``fields`` replaced (keyword options of ``adjust``; aliases accepted), validated."""
        for old, new in ALIASES.items():
            if old in fields:
                fields[new] = fields.pop(old)
        if options is None and not fields:
            return cls()
        if options is not None and not fields:
            return options
        base = {} if options is None else options.model_dump(exclude_unset=True)
        return _build(cls, {**base, **fields}, cli=options is not None and options._cli)

    def name(self, field: str) -> str:
        """How this field is named in messages: the CLI option, or the Python field."""
        return option_name(field, self._cli)

    @property
    def test_method_resolved(self) -> str:
        """``test_method``; None means ``fixed`` when ``alpha_global`` is given, else ``auto``."""
        if self.test_method is None:
            return "fixed" if self.alpha_global is not None else "auto"
        return self.test_method

    @property
    def alpha_global_resolved(self) -> float | None:
        """``alpha_global``; 0.05 under ``fixed`` when not given."""
        if self.alpha_global is None and self.test_method_resolved == "fixed":
            return 0.05
        return self.alpha_global

    def non_default(self) -> tuple[str, ...]:
        """The fields set away from their defaults (for a path that implements only some of them to
        refuse the others by name: every option is applied or refused)."""
        d = type(self)()
        return tuple(f for f in type(self).model_fields if getattr(self, f) != getattr(d, f))

    # ------------------------------------------------------------------ against the observations
    def prepare(self, obs, *, source: str = ""):
        """``obs`` with the ``levelled`` stations levelled; ``distance_only`` stations checked (an
        angle observation on one of them is an error in the file ``source``). One line naming the
        option or the observation."""
        import numpy as np

        where = f"{source}: " if source else ""
        for x in self.distance_only:
            if x not in obs.station_ids:
                raise MultilatError(f"{self.name('distance_only')}: unknown station {x!r} (stations: "
                                    f"{', '.join(obs.station_ids)})")
            i = obs.station_ids.index(x)
            for col in ("sigma_azimuth_rad", "sigma_elevation_rad"):
                sig = getattr(obs, col)
                k = np.flatnonzero((obs.station_index == i) & np.isfinite(sig)) if sig is not None else []
                if len(k):
                    raise MultilatError(f"{where}station {x!r} is declared distance-only "
                                        f"({self.name('distance_only')}) but observation "
                                        f"{obs.label(int(k[0]))} has {col}")
        if not self.levelled:
            return obs
        for x in self.levelled:
            if x not in obs.station_ids:
                raise MultilatError(f"{self.name('levelled')}: unknown station {x!r} (stations: "
                                    f"{', '.join(obs.station_ids)})")
        lev = tuple(dict.fromkeys(tuple(obs.levelled) + self.levelled))
        return obs if lev == tuple(obs.levelled) else dataclasses.replace(obs, levelled=lev)

    def scale_heads(self, obs):
        """``scales`` with ``fixed_scale`` resolved against the observations' heads."""
        if self.fixed_scale is None:
            return self.scales
        if self.fixed_scale not in obs.head_ids:
            what = "station" if obs.station_heads is None else "head"
            raise MultilatError(f"{self.name('fixed_scale')}: unknown {what} id {self.fixed_scale!r} "
                                f"({what}s: {', '.join(obs.head_ids)})")
        return [h for h in obs.head_ids if h != self.fixed_scale]


def option_name(field: str, cli: bool) -> str:
    if not cli:
        return field
    return CLI_NAMES.get(field, "--" + field.replace("_", "-"))


def _build(cls, fields: dict, *, cli: bool) -> NetworkOptions:
    try:
        out = cls(**fields)
    except ValidationError as err:
        raise MultilatError(_line(err, cli)) from None
    out._cli = cli
    return out


def _line(err: ValidationError, cli: bool) -> str:
    """One line naming the option at fault (the first error; the others counted)."""
    errs = sorted(err.errors(), key=lambda x: x.get("type") != "extra_forbidden")
    e = errs[0]
    loc = [str(x) for x in e.get("loc", ()) if not str(x).startswith(("function-", "literal", "float", "dict",
                                                                           "none", "bool", "tuple"))]
    msg = e.get("msg", "invalid").replace("Value error, ", "")
    if not loc and ": " in msg:            # a check across options names its field first
        field, msg = msg.split(": ", 1)
        loc = [field]
        msg = re.sub(r"\{(\w+)\}", lambda m: option_name(m.group(1), cli), msg)
    name = option_name(loc[0], cli) if loc else "options"
    if e.get("type") == "literal_error" and loc and loc[0] in NetworkOptions.model_fields:
        msg = "must be one of " + ", ".join(_literal_values(NetworkOptions.model_fields[loc[0]].annotation))
    more = f" (+{len(err.errors()) - 1} more)" if len(err.errors()) > 1 else ""
    if e.get("type") == "extra_forbidden":
        return f"{name}: unknown option (mistyped?){more}"
    inp = e.get("input")
    got = "" if "got" in msg or (isinstance(inp, dict) and not loc[1:] and e.get("loc") == ()) \
        else f", got {inp!r}"
    if msg.startswith(("must", "goes with")):
        return f"{name} {msg}{got}{more}".replace("\n", " ")
    return f"{name}: {msg}{got}{more}".replace("\n", " ")


def _literal_values(annotation) -> list[str]:
    """The allowed values of a ``Literal`` field (inside Optional/Union)."""
    from typing import get_args, get_origin

    if get_origin(annotation) is Literal:
        return [str(v) for v in get_args(annotation)]
    return [v for a in get_args(annotation) for v in _literal_values(a)]


def options_from(options: NetworkOptions | None, **fields) -> NetworkOptions:
    """Shorthand of :meth:`NetworkOptions.of`."""
    return NetworkOptions.of(options, **fields)
