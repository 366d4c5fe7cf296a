"""Approximate coordinates, a step of its own before the adjustment: the distance path's
initial values and minimum search, and the general layer's (:mod:`.general`).
"""
