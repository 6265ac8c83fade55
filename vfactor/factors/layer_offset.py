"""Layer offset factor: the light and roof layers sit within bounds above the wheels.

For each bounded layer, the offset of its centroid from the wheel-layer
centroid along x (forward) and z (up): ``hinge(offset, min, max) / sigma``
(two rows per layer, metres), zero inside the bounds: the HWC's "relation
between layers free within limits". Linear in the points between the bounds'
kinks, so the Jacobian is analytic: ``+-1 / (4 sigma)`` on the axis of the
layer's and the wheels' points for an active row.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from vfactor.factors.shape_terms import ShapeTerm, hinge
from vfactor.keypoints import LAYERS

__all__ = ["layer_offset_term"]


def _residual(indices, lo, hi, sigma, points):
    centroids = points[..., indices, :].mean(axis=-2)  # (..., 1 + layers, 3), the wheel layer first
    offsets = centroids[..., 1:, :][..., [0, 2]] - centroids[..., :1, :][..., [0, 2]]  # (..., layers, 2): x, z
    return (hinge(offsets, lo, hi) / sigma).reshape(*points.shape[:-2], -1)


def _jacobian(indices, lo, hi, sigma, points):
    centroids = points[indices].mean(axis=1)
    offsets = centroids[1:, [0, 2]] - centroids[:1, [0, 2]]  # (layers, 2)
    active = ((offsets < lo) | (offsets > hi)) / sigma
    J = np.zeros((len(indices) - 1, 2, 12, 3))
    for layer in range(len(indices) - 1):
        for a, axis in enumerate((0, 2)):
            J[layer, a, indices[layer + 1], axis] = 0.25 * active[layer, a]
            J[layer, a, indices[0], axis] = -0.25 * active[layer, a]
    return J.reshape(-1, 36)


def layer_offset_term(layer_offset: dict, sigma: float = 0.01) -> ShapeTerm:
    """Hinge residuals for each layer in ``layer_offset`` (layer -> [[x_min, x_max], [z_min, z_max]])."""
    names = list(layer_offset)
    indices = np.array([LAYERS["wheel"]] + [LAYERS[name] for name in names])
    b = np.array([np.asarray(layer_offset[name], float) for name in names])  # (layers, 2 axes, 2)
    args = (indices, b[..., 0], b[..., 1], sigma)
    return ShapeTerm("layer_offset", partial(_residual, *args), 2 * len(names), jacobian=partial(_jacobian, *args))
