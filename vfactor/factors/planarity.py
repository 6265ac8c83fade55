"""Layer plane factor: each layer planar and perpendicular to the medial plane.

For a layer ``(lf, rf, lb, rb)``: the diagonals ``d1 = rb - lf`` and
``d2 = lb - rf`` span the layer's plane; with ``n = d1 x d2 / |d1 x d2|``

* planarity: ``n . (rf - lf)``, the distance between the two diagonal lines
  (zero iff the four points are coplanar), metres, over ``sigma_m``;
* perpendicularity: ``n_y``, the sine of the angle between the layer's plane
  and the direction normal to the medial (x-z) plane, over ``sigma_rad``.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from vfactor.factors.shape_terms import ShapeTerm, cnorm, cross
from vfactor.keypoints import LAYER_NAMES, LAYERS

__all__ = ["layer_plane_term"]


def _residual(indices, sigma_m, sigma_rad, points):
    quads = points[..., indices, :]  # (..., layers, 4, 3), corners (lf, rf, lb, rb)
    lf, rf, lb, rb = quads[..., 0, :], quads[..., 1, :], quads[..., 2, :], quads[..., 3, :]
    n = cross(rb - lf, lb - rf)
    n = n / cnorm(n)[..., None]
    planar = np.sum(n * (rf - lf), axis=-1) / sigma_m  # (..., layers)
    perpendicular = n[..., 1] / sigma_rad
    return np.stack([planar, perpendicular], axis=-1).reshape(*points.shape[:-2], -1)


def layer_plane_term(layers=LAYER_NAMES, sigma_m: float = 0.02, sigma_rad: float = 0.05) -> ShapeTerm:
    """Planarity and perpendicularity of ``layers`` (two rows each)."""
    indices = np.array([LAYERS[name] for name in layers])
    row_layers = np.repeat([LAYER_NAMES.index(name) for name in layers], 2)
    return ShapeTerm("layer_plane", partial(_residual, indices, sigma_m, sigma_rad), 2 * len(layers), row_layers)
