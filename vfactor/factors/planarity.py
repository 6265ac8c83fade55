"""Layer plane factor: each layer planar and perpendicular to the medial plane.

For a layer ``(lf, rf, lb, rb)``: the diagonals ``d1 = rb - lf`` and
``d2 = lb - rf`` span the layer's plane; with ``n = d1 x d2 / |d1 x d2|``

* planarity: ``n . (rf - lf)``, the distance between the two diagonal lines
  (zero iff the four points are coplanar), metres, over ``sigma_m``;
* perpendicularity: ``n_y``, the sine of the angle between the layer's plane
  and the direction normal to the medial (x-z) plane, over ``sigma_rad``.

Residual and Jacobian (complex step) in one compiled call: :func:`kernels.hwc.layer_plane_kernel`.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from vfactor._kernels import layer_plane_kernel
from vfactor.errors import check_numbers
from vfactor.factors.shape_terms import ShapeTerm, compiled_term
from vfactor.keypoints import LAYER_NAMES, LAYERS

__all__ = ["layer_plane_term"]


def layer_plane_term(layers=LAYER_NAMES, sigma_m: float = 0.02, sigma_rad: float = 0.05) -> ShapeTerm:
    """Planarity and perpendicularity of ``layers`` (two rows each)."""
    indices = np.array([LAYERS[name] for name in layers], dtype=np.int64).reshape(-1, 4)
    check_numbers("layer_plane_term", SimpleNamespace(sigma_m=sigma_m, sigma_rad=sigma_rad), ("sigma_m", "sigma_rad"))
    return compiled_term("layer_plane", 2 * len(layers), layer_plane_kernel, indices, float(sigma_m), float(sigma_rad))
