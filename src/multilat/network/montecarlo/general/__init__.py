"""The general layer's Monte Carlo: the adjustment's own system frozen at its solution.
"""
