"""The extension module :mod:`vfactor._kernels`: every kernel, compiled ahead of time with ``numba.pycc``.

``setup.py`` calls :func:`extension`; setuptools' ``build_ext`` then compiles
the kernels to native code (numba, generic x86-64 or the platform's baseline
CPU, so that a wheel runs on any machine of its platform) and links them with
numba's small C runtime into a plain CPython extension that needs neither
numba nor LLVM at run time. A C compiler is needed at install time.

Each kernel is exported with one signature: float64 arrays (int64 for indices
and lens codes), any layout (``A``: contiguous or strided, so that views such
as ``Pose3.matrix()[:3, :3]`` pass as they are). The compiled wrapper checks
only the item size of an array argument, not its dtype or number of
dimensions: callers pass exactly these types (:class:`vfactor.factors.projection.KeypointObservations`
makes its tables so). The results are those of numba's JIT of the same
sources: no fast-math, so every operation is IEEE double as written.
"""

from __future__ import annotations

from numba import types
from numba.pycc import CC

from kernels import source_digest
from kernels.ground_plane import ground_plane_kernel
from kernels.hwc import distance_bounds_kernel, layer_offset_kernel, layer_plane_kernel, trapezoid_kernel
from kernels.linalg import symmetric_eigen_kernel
from kernels.motion import acceleration_kernel, nonholonomic_kernel, step_twist_kernel
from kernels.projection import projection_kernel, robust_cost_kernel
from kernels.robust import robust_scale
from kernels.shape_evidence import fit_at_scale_kernel, log_evidence_kernel
from kernels.truncation import truncated_means_kernel

__all__ = ["EXPORTS", "MODULE", "extension"]

#: The extension's import name.
MODULE = "vfactor._kernels"

_F8, _I8, _B1 = types.float64, types.int64, types.boolean
_V1, _V2, _V3 = (types.Array(_F8, ndim, "A") for ndim in (1, 2, 3))
_IDX = types.Array(_I8, 1, "A")
_IDX2 = types.Array(_I8, 2, "A")
_DIGEST = source_digest()

#: Observation tables of the projection kernels: keypoint_index .. sigma (kernels.projection.projection_kernel).
_OBSERVATIONS = (_IDX, _V3, _V2, _V2, _IDX, _V2, _V2, _V3, _V2, _V2, _I8, _F8, _F8)


def _source_digest():
    return _DIGEST


#: Exported name -> (numba function, signature).
EXPORTS = {
    "projection_kernel": (projection_kernel, types.void(_V2, _V1, _V2, *_OBSERVATIONS, _B1, _V1, _V2, _V2)),
    "robust_cost_kernel": (robust_cost_kernel, types.void(_V3, _V2, _V3, *_OBSERVATIONS, _V1)),
    "robust_scale": (robust_scale, types.UniTuple(_F8, 2)(_I8, _F8, _F8)),
    "truncated_means_kernel": (truncated_means_kernel, types.void(_V1, _V1, _V1, _V1, _V1, _V1)),
    "step_twist_kernel": (step_twist_kernel, types.void(_V2, _V2, _B1, _V1, _V2, _V2)),
    "nonholonomic_kernel": (nonholonomic_kernel, types.void(_V2, _V2, _V1, _B1, _V1, _V2, _V2)),
    "acceleration_kernel": (acceleration_kernel, types.void(_V2, _V2, _V2, _V1, _B1, _V1, _V2, _V2, _V2)),
    "ground_plane_kernel": (ground_plane_kernel, types.void(_V2, _V1, _B1, _V1, _V2)),
    "layer_plane_kernel": (layer_plane_kernel, types.void(_V2, _IDX2, _F8, _F8, _B1, _V1, _V2)),
    "trapezoid_kernel": (trapezoid_kernel, types.void(_V2, _IDX2, _V1, _V1, _F8, _F8, _B1, _V1, _V2)),
    "distance_bounds_kernel": (distance_bounds_kernel, types.void(_V2, _IDX2, _V1, _V1, _F8, _B1, _V1, _V2)),
    "layer_offset_kernel": (layer_offset_kernel, types.void(_V2, _IDX2, _V2, _V2, _F8, _B1, _V1, _V2)),
    "fit_at_scale_kernel": (fit_at_scale_kernel, _F8(_V2, _V2, _V1, _V1, _V2, _V1, _F8, _F8, _V1, _V1)),
    "log_evidence_kernel": (log_evidence_kernel, types.void(_V2, _V1, _V3, _V2, _V1, _V1)),
    "symmetric_eigen_kernel": (symmetric_eigen_kernel, _I8(_V2, _V1, _V2)),
    # the digest of the kernels' sources it was built from (tests/test_kernels.py)
    "source_digest": (_source_digest, _I8()),
}


def extension():
    """The setuptools ``Extension`` of :data:`MODULE` (numba's ``CC.distutils_extension``).

    Returns:
        A ``setuptools.Extension`` whose ``build_ext`` runs numba's compiler.
    """
    cc = CC(MODULE.rsplit(".", 1)[1])
    for name, (function, signature) in EXPORTS.items():
        cc.export(name, signature)(getattr(function, "py_func", function))
    ext = cc.distutils_extension()
    ext.name = MODULE
    return ext
