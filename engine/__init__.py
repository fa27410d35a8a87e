"""Albedit's science: interaction decomposition, recoloring, calibration and acquisition.

Nothing in this package imports Qt, ``devices`` or ``app`` (an import-linter contract in
``pyproject.toml`` enforces it).
"""
