"""The Monte Carlo of a network (JCGM 101/102): the adjustment's system frozen per trial,
batched solvers, ``propagate`` and its summaries, ``simulate``; :mod:`.general` for the
general layer.
"""
