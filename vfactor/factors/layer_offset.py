"""Layer offset factor: the light and roof layers sit within bounds above the wheels.

For each bounded layer, the offset of its centroid from the wheel-layer
centroid along x (forward) and z (up): ``hinge(offset, min, max) / sigma``
(two rows per layer, metres), zero inside the bounds: the HWC's "relation
between layers free within limits". Linear in the points between the bounds'
kinks, so the Jacobian is analytic (both in one compiled call,
:func:`kernels.hwc.layer_offset_kernel`): ``+-1 / (4 sigma)`` on the axis of the
layer's and the wheels' points for an active row.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from vfactor._kernels import layer_offset_kernel
from vfactor.errors import check_numbers
from vfactor.factors.shape_terms import ShapeTerm, compiled_term
from vfactor.keypoints import LAYERS

__all__ = ["layer_offset_term"]


def layer_offset_term(layer_offset: dict, sigma: float = 0.01) -> ShapeTerm:
    """Hinge residuals for each layer in ``layer_offset`` (layer -> [[x_min, x_max], [z_min, z_max]])."""
    names = list(layer_offset)
    indices = np.array([LAYERS["wheel"]] + [LAYERS[name] for name in names], dtype=np.int64)
    b = np.array([np.asarray(layer_offset[name], float) for name in names]).reshape(-1, 2, 2)  # (layers, axes, 2)
    check_numbers("layer_offset_term", SimpleNamespace(sigma=sigma), ("sigma",))
    return compiled_term("layer_offset", 2 * len(names), layer_offset_kernel, indices,
                         np.ascontiguousarray(b[..., 0]), np.ascontiguousarray(b[..., 1]), float(sigma))
