"""Experiments built on the core: the paper's figure scenarios, attack-surface maps and
readings, the red team, cost-of-safety runs, and the E12 limits."""
