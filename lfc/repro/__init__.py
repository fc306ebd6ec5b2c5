"""Reproduction: executing the notebooks (``reproduce``, ``sweep``), notebook helpers,
figure styling and the command line ``python -m lfc``."""
