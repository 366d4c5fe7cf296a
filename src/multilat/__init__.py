"""multilat: large-volume coordinate metrology.

Distance model of an RF-phase absolute distance meter (air index, telemetric and gimbal errors),
self-calibrating multilateration, laser ball bar trilateration, and Monte Carlo uncertainty
evaluation after JCGM 101/102. SI units inside (metres, radians, degrees Celsius where named).
"""

from multilat.errors import MultilatError

__version__ = "0.1.0"
__all__ = ["MultilatError", "__version__"]
