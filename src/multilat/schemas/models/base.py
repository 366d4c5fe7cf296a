"""The pieces every document model is built of (pydantic v2).

* :class:`Strict`: the base of every object of a document: an undeclared key is refused
  (``extra="forbid"``) and types are checked without coercion (``strict=True``: ``"1"`` is not a
  number, ``1.0`` not a count, ``true`` not an integer); an integer is accepted where a number is.
* :data:`Num`: a real number of a document; ``null`` where it is not finite (the JSON writer,
  :func:`multilat.io.write_json`, writes NaN and ±inf as ``null``), so every real number may be null.
  Counts, seeds and trial numbers are ``int`` and never null.
* :data:`Vec3` / :data:`Mat3` (coordinates, standard deviations per axis, 3 x 3 covariances) and
  :data:`Interval` (a 95 % interval: low, high) have their lengths checked.
* The id maps of :data:`multilat.vocabulary.ID_MAPS` (stations, targets, points, ...) are
  ``dict[str, Model]``: their keys are ids, their values are checked.
* A key that only some runs write (it depends on an option or on the network) is ``T | None = None``:
  it may be left out; when it is there its value is checked.
* Every document starts with ``"schema": "multilat.<command>/<version>"``; its model declares it as the
  field ``schema_`` (alias ``schema``) of type ``Literal["multilat.<command>/<version>"]``, so a document
  of another command or version is refused. The version of a command is bumped when its document's
  shape changes (a key renamed, removed or retyped; a new required key), together with
  :data:`multilat.vocabulary.SCHEMA_VERSIONS` (what :func:`multilat.vocabulary.stamp` writes).
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["Strict", "Document", "Num", "Vec3", "Mat3", "Interval", "Excluded", "SigmaSource", "TrackerSigma"]


class Strict(BaseModel):
    """An object of a document: undeclared keys refused, types checked without coercion."""

    model_config = ConfigDict(extra="forbid", strict=True)


class Document(Strict):
    """A command's whole ``--json`` document (its first key ``schema`` is declared by each command)."""


#: a real number; null where not finite
Num = float | None
#: three numbers (x, y, z; or per axis)
Vec3 = Annotated[list[Num], Field(min_length=3, max_length=3)]
#: a 3 x 3 matrix (row by row)
Mat3 = Annotated[list[Vec3], Field(min_length=3, max_length=3)]
#: a 95 % interval: [low, high]
Interval = Annotated[list[Num], Field(min_length=2, max_length=2)]


class Excluded(Strict):
    """A point (or station) left out of the adjustment because it cannot be determined."""

    id: str
    kind: str
    reason: str
    n_obs: int
    round: int | None = None


class TrackerSigma(Strict):
    """A laser tracker's σ of a distance: its maker's MPE a + b L times ``std_per_mpe``."""

    tracker: str
    adm_a_um: Num
    adm_b_um_per_m: Num
    std_per_mpe: Num


class SigmaSource(Strict):
    """Where the distances' a-priori σ came from (:mod:`multilat.network.sigma_source`): ``kind`` is
    ``file column`` (``file``, ``column``), ``--sigma-um`` or another option (``sigma_m``), or
    ``distance model`` (``instrument``, ``defaulted``, ``heads`` per station, ``trackers``)."""

    kind: str
    sigma_m: Num = None
    file: str | None = None
    column: str | None = None
    instrument: str | None = None
    defaulted: bool | None = None
    heads: dict[str, str] | None = None
    trackers: dict[str, TrackerSigma] | None = None
    note: str | None = None
