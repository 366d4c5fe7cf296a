"""The measurement campaign: raw readings -> corrected distances with their uncertainty (seed 000 §2-4).

Modules: :mod:`~multilat.campaign.raw` (raw-reading files), :mod:`~multilat.campaign.environment`
(sensor log, interpolation in time, vertical gradient), :mod:`~multilat.campaign.correct` (the
pipeline, :func:`correct_file`, :func:`observations_from_raw`, :func:`is_raw_file`),
:mod:`~multilat.campaign.twoface` (double-centering), :mod:`~multilat.campaign.worked` (simulated
campaigns, the gradient study). See ``docs/campaign.md``.
"""

_CORRECT = ("CorrectedObservations", "correct_file", "correct_raw", "is_raw_file", "observations_from_raw")


def __getattr__(name):
    """The pipeline's names, imported on first use (issue 29: ``multilat adjust`` of an observation
    file reads it through :mod:`multilat.campaign.propagation` without the raw-reading pipeline)."""
    if name in _CORRECT:
        from multilat.campaign import correct

        return getattr(correct, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["CorrectedObservations", "correct_file", "correct_raw", "is_raw_file", "observations_from_raw"]
