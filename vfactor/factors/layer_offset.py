"""Layer offset factor: the light and roof layers sit within bounds above the wheels.

For each bounded layer, the offset of its centroid from the wheel-layer
centroid along x (forward) and z (up): ``hinge(offset, min, max) / sigma``
(two rows per layer, metres), zero inside the bounds: the HWC's "relation
between layers free within limits".
"""

from __future__ import annotations

from functools import partial

import numpy as np

from vfactor.factors.shape_terms import ShapeTerm, hinge
from vfactor.keypoints import LAYERS

__all__ = ["layer_offset_term"]


def _residual(bounds, sigma, points):
    wheel = points[..., list(LAYERS["wheel"]), :].mean(axis=-2)
    out = []
    for name, b in bounds:
        off = points[..., list(LAYERS[name]), :].mean(axis=-2) - wheel
        out.append(hinge(off[..., 0], b[0, 0], b[0, 1]) / sigma)
        out.append(hinge(off[..., 2], b[1, 0], b[1, 1]) / sigma)
    return np.stack(out, axis=-1)


def layer_offset_term(layer_offset: dict, sigma: float = 0.01) -> ShapeTerm:
    """Hinge residuals for each layer in ``layer_offset`` (layer -> [[x_min, x_max], [z_min, z_max]])."""
    bounds = tuple((name, np.asarray(b, float)) for name, b in layer_offset.items())
    return ShapeTerm("layer_offset", partial(_residual, bounds, sigma), 2 * len(bounds))
