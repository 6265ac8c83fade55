"""The numba sources of vfactor's compiled kernels, used at build time only.

``setup.py`` compiles them ahead of time (``numba.pycc``, :mod:`kernels.build`)
into one C extension module, :mod:`vfactor._kernels`, which vfactor imports; at
run time neither this folder nor numba is needed (nor installed: the folder is
not a package of the wheel, numba is a build requirement only). A fresh
process therefore loads the kernels with the extension (under 1 ms) instead of
numba's JIT set-up and cache (about 0.2 s), and nothing is compiled on a first
solve (docs/performance.md, "Scale-out (issue 15)").

* :mod:`kernels.projection` — keypoint projection: residuals, Jacobians, robust costs of many poses
* :mod:`kernels.truncation` — the mean of a Gaussian truncated to the image
* :mod:`kernels.robust` — the robust losses' scale per residual norm
* :mod:`kernels.motion` — Pose3 between, Logmap and Jacobians of the motion factors
* :mod:`kernels.ground_plane` — the ground-plane factor
* :mod:`kernels.hwc` — the hierarchical wireframe constraint's terms
* :mod:`kernels.shape_evidence` — the noise scale's fixed point and the body types' evidence
* :mod:`kernels.linalg` — the eigen-decomposition of the per-vehicle covariances, single-threaded

After editing a file here, rebuild the extension (``pip install -e .``, or
``python setup.py build_ext --inplace`` where numba is installed);
``tests/test_kernels.py`` fails while the built module is older than these
sources (:func:`source_digest`).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

__all__ = ["source_digest"]

_FOLDER = Path(__file__).resolve().parent


def source_digest() -> int:
    """A 60-bit digest of every ``*.py`` file of this folder (names and contents), as built into the extension.

    Returns:
        A non-negative integer below ``2**60``.
    """
    h = hashlib.sha256()
    for path in sorted(_FOLDER.glob("*.py")):
        h.update(path.name.encode())
        h.update(b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    return int(h.hexdigest()[:15], 16)
