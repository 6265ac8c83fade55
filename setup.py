"""Builds the compiled kernels into the extension module ``vfactor._kernels`` (everything else: pyproject.toml).

The kernels' numba sources (``kernels/``) are compiled ahead of time
(``numba.pycc``, :mod:`kernels.build`), so that vfactor needs neither numba nor
a compile at run time. Needs numba and a C compiler at build time.
"""

import sys
from pathlib import Path

from setuptools import setup

sys.path.insert(0, str(Path(__file__).resolve().parent))

from kernels.build import extension  # noqa: E402

setup(ext_modules=[extension()])
