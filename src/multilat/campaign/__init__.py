"""The measurement campaign: raw readings -> corrected distances with their uncertainty (seed 000 §2-4).

Modules: :mod:`~multilat.campaign.raw` (raw-reading files), :mod:`~multilat.campaign.environment`
(sensor log, interpolation in time, vertical gradient), :mod:`~multilat.campaign.correct` (the
pipeline, :func:`correct_file`, :func:`observations_from_raw`, :func:`is_raw_file`),
:mod:`~multilat.campaign.twoface` (double-centering), :mod:`~multilat.campaign.worked` (simulated
campaigns, the gradient study). See ``docs/campaign.md``.
"""

from multilat.campaign.correct import (CorrectedObservations, correct_file, correct_raw, is_raw_file,
                                       observations_from_raw)

__all__ = ["CorrectedObservations", "correct_file", "correct_raw", "is_raw_file", "observations_from_raw"]
