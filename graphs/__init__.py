"""The packaged simulation scenarios (``*.json``, docs/scenarios.md).

This folder is the repository's top-level ``graphs/``; pyproject.toml maps it
into the package as ``vfactor.graphs`` so that wheels and installs carry the
files and :func:`vfactor.sim.load_scenario` finds them from any folder.
"""
