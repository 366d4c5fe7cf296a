"""The sense of the azimuths in an observation file: ``ccw`` (multilat's, the default: from +x towards
+y, ``atan2(dy, dx)``) or ``cw`` (from +x towards -y, as many laser trackers report them).

A clockwise file read as counter-clockwise is not detected by the data of a free network: the whole
hall mirrored (y -> -y) fits the same distances and the negated azimuths exactly (same σ0, same dof).
The sense is therefore declared (``--azimuth-sense`` or ``azimuth_sense`` in the instrument file) and
converted once, where the file is read (:func:`to_ccw_rad`): inside, every azimuth is counter-clockwise.

Reference: ``docs/conventions.md`` (angles).
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from multilat.errors import MultilatError

__all__ = ["SENSES", "DEFAULT", "HELP", "to_ccw_rad", "resolve", "apply", "record", "as_json", "mirror_hint",
           "hint_text"]

SENSES = ("ccw", "cw")
DEFAULT = "ccw"
#: the source of the sense when nobody declared it
UNDECLARED = "default (counter-clockwise; not declared)"
#: ``--azimuth-sense`` of ``adjust`` and ``propagate``
HELP = ("ccw or cw: the sense of the file's azimuth_rad (ccw, the default: from +x towards +y; cw: from +x "
        "towards -y, as many trackers report). Default: the --instrument file's azimuth_sense, else ccw. A cw "
        "file read as ccw gives the same σ0 and a mirrored hall.")


def to_ccw_rad(azimuth_rad, sense: str):
    """Azimuths (rad) read in ``sense`` as multilat's counter-clockwise azimuths (rad): negated for
    ``cw`` (an azimuth of -θ clockwise is θ counter-clockwise), unchanged for ``ccw``; NaN stays NaN."""
    if sense not in SENSES:
        raise MultilatError(f"azimuth sense must be one of {', '.join(SENSES)}, got {sense!r}")
    if azimuth_rad is None:
        return None
    az = np.asarray(azimuth_rad, float)
    return -az if sense == "cw" else az


def resolve(option: str | None, instrument=None, *, option_name: str = "--azimuth-sense") -> tuple[str, str]:
    """``(sense, where it came from)``: the option, else the instrument file's ``azimuth_sense``, else
    the default ``ccw``. An option that contradicts the file is refused in one line naming both."""
    if option is not None and option not in SENSES:
        raise MultilatError(f"{option_name} must be one of {', '.join(SENSES)}, got {option!r}")
    from_file = None
    if instrument is not None:
        from multilat import instrument as _instr

        inst = _instr.load_instrument(instrument) if isinstance(instrument, (str, os.PathLike)) else instrument
        from_file = getattr(inst, "azimuth_sense", None)
        instrument = instrument if isinstance(instrument, (str, os.PathLike)) else getattr(inst, "name", "")
    if option is not None and from_file is not None and option != from_file:
        raise MultilatError(f"{option_name} {option} contradicts azimuth_sense = \"{from_file}\" of the "
                            f"instrument {instrument} (drop one)")
    if option is not None:
        return option, option_name
    if from_file is not None:
        return from_file, f"instrument {instrument} (azimuth_sense)"
    return DEFAULT, UNDECLARED


def apply(obs, sense: str):
    """``obs`` with its azimuths converted from ``sense`` to counter-clockwise (the same ``obs`` for
    ``ccw`` or without azimuths)."""
    if sense == DEFAULT or obs.azimuth_rad is None:
        to_ccw_rad(None, sense)                    # the sense checked all the same
        return obs
    return dataclasses.replace(obs, azimuth_rad=to_ccw_rad(obs.azimuth_rad, sense))


def record(obs, sense: str, source: str) -> dict | None:
    """The JSON record of the sense used (None when the file has no azimuths)."""
    if obs.azimuth_rad is None or not np.isfinite(obs.azimuth_rad).any():
        return None
    return as_json(sense, source)


def as_json(sense: str, source: str) -> dict:
    """``{"sense", "source", "convention"}``: the sense used, where it came from, and what it means."""
    return {"sense": sense, "source": source,
            "convention": "counter-clockwise from +x towards +y inside (cw readings negated on reading)"}


#: The rule of :func:`mirror_hint`: the azimuths negated must fit at least this many times better (σ0)
#: and pass the global test, before the sense is named as the likely fault.
MIRROR_SIGMA0_RATIO = 10.0


def mirror_hint(obs, sigma0: float | None, options, data: dict) -> str | None:
    """When the azimuths' sense was not declared and the adjustment failed (refused, ``sigma0`` None,
    or its global test failed), whether the same network with its azimuths negated fits: re-adjusted
    (no data snooping), σ0 at least :data:`MIRROR_SIGMA0_RATIO` times smaller and the global test
    passed. Then the text naming ``--azimuth-sense cw`` (else None). A free network cannot tell (the
    mirrored hall fits exactly as well); control points, a 321 datum or levelled stations can."""
    if obs.sigma_azimuth_rad is None or not np.isfinite(obs.sigma_azimuth_rad).any():
        return None
    from multilat.network.adjust.distance.adjust import adjust

    try:
        flipped = adjust(apply(obs, "cw"), options, **{**data, "snooping": False})
    except MultilatError:
        return None
    return hint_text(sigma0, flipped.sigma0, flipped.global_test.passed)


def hint_text(sigma0: float | None, flipped_sigma0: float, passed: bool) -> str | None:
    """The rule of :func:`mirror_hint` on the two fits (the azimuths as read: ``sigma0``, None when
    refused; negated: ``flipped_sigma0`` and whether its global test ``passed``), shared by the
    general path (:mod:`multilat.cli.general_adjust`): the text naming ``--azimuth-sense cw``, or None."""
    if not passed or (sigma0 is not None and np.isfinite(sigma0) and flipped_sigma0 * MIRROR_SIGMA0_RATIO > sigma0):
        return None
    was = "do not fit" if sigma0 is None or not np.isfinite(sigma0) else f"give σ0 = {sigma0:.3g}"
    return (f"the azimuths read counter-clockwise (the default) {was}; negated (clockwise) they fit "
            f"(σ0 = {flipped_sigma0:.3g}, global test passed): clockwise azimuths? give --azimuth-sense cw "
            "(or azimuth_sense = \"cw\" in the instrument file)")
