"""The pieces every document model is built of (pydantic v2).

* :class:`Strict`: the base of every object of a document: an undeclared key is refused
  (``extra="forbid"``) and types are checked without coercion (``strict=True``: ``"1"`` is not a
  number, ``1.0`` not a count, ``true`` not an integer); an integer is accepted where a number is.
* :data:`Num`: a statistic of a document (a standard deviation, a ratio, an MDB, a test statistic);
  ``null`` where it is not finite (the JSON writer, :func:`multilat.io.write_json`, writes NaN and ±inf
  as ``null``: an MDB where the redundancy is 0, a ratio over a zero standard deviation).
* :data:`Real`: a number that is finite whenever the command succeeds (a coordinate, a covariance, a
  nominal value, an input echoed, a time); ``null`` is refused. Counts, seeds and trial numbers are
  ``int`` and never null.
* :data:`XYZ` / :data:`Cov3` (coordinates; 3 x 3 covariances, finite), :data:`Vec3` (a statistic per
  axis) and :data:`Interval` (a 95 % interval: low, high) have their lengths checked.
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

__all__ = ["Strict", "Document", "Num", "Real", "XYZ", "Cov3", "Vec3", "Interval", "Excluded", "SigmaSource",
           "TrackerSigma"]


class Strict(BaseModel):
    """An object of a document: undeclared keys refused, types checked without coercion."""

    model_config = ConfigDict(extra="forbid", strict=True)


class Document(Strict):
    """A command's whole ``--json`` document (its first key ``schema`` is declared by each command)."""


#: a statistic; null where not finite
Num = float | None
#: a number that is always finite (null refused)
Real = float
#: coordinates x, y, z (m; finite)
XYZ = Annotated[list[Real], Field(min_length=3, max_length=3)]
#: a 3 x 3 covariance, row by row (finite)
Cov3 = Annotated[list[XYZ], Field(min_length=3, max_length=3)]
#: a statistic per axis (x, y, z)
Vec3 = Annotated[list[Num], Field(min_length=3, max_length=3)]
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
    adm_a_um: Real
    adm_b_um_per_m: Real
    std_per_mpe: Real


class SigmaSource(Strict):
    """Where the distances' a-priori σ came from (:mod:`multilat.network.model.sigma_source`): ``kind`` is
    ``file column`` (``file``, ``column``), ``--sigma-um`` or another option (``sigma_m``), or
    ``distance model`` (``instrument``, ``defaulted``, ``heads`` per station, ``trackers``)."""

    kind: str
    sigma_m: Real | None = None
    file: str | None = None
    column: str | None = None
    instrument: str | None = None
    defaulted: bool | None = None
    heads: dict[str, str] | None = None
    trackers: dict[str, TrackerSigma] | None = None
    note: str | None = None
