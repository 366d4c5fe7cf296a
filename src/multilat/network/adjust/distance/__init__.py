"""The distance path's adjustment: self-calibrating multilateration from distances (and
angles, bars, control), its fit, data snooping, reliability, variance components, result.
"""
