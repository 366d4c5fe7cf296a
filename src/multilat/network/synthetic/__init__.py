"""Networks with a known truth: the package's one generator (:mod:`.generator`) and the
seed's built-in configurations (:mod:`.configs`).
"""
