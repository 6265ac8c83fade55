"""Trapezoid factor: the light and roof layers are trapezoids within a range.

For a layer ``(lf, rf, lb, rb)`` with front edge ``f = lf - rf`` and back edge
``b = lb - rb``:

* parallel sides: ``f/|f| x b/|b|`` (3 rows, unitless) over ``sigma_rad``;
* width ratio within bounds: ``hinge(|f| / |b|, lo, hi)`` (1 row) over ``sigma_ratio``;
  zero inside the bounds.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from vfactor.factors.shape_terms import ShapeTerm, cnorm, cross, hinge
from vfactor.keypoints import LAYER_NAMES, LAYERS

__all__ = ["trapezoid_term"]


def _residual(indices, lo, hi, sigma_rad, sigma_ratio, points):
    quads = points[..., indices, :]  # (..., layers, 4, 3)
    f = quads[..., 0, :] - quads[..., 1, :]
    b = quads[..., 2, :] - quads[..., 3, :]
    nf, nb = cnorm(f), cnorm(b)
    parallel = cross(f / nf[..., None], b / nb[..., None]) / sigma_rad  # (..., layers, 3)
    ratio = hinge(nf / nb, lo, hi)[..., None] / sigma_ratio  # (..., layers, 1)
    return np.concatenate([parallel, ratio], axis=-1).reshape(*points.shape[:-2], -1)


def trapezoid_term(width_ratio: dict, sigma_rad: float = 0.05, sigma_ratio: float = 0.02) -> ShapeTerm:
    """Trapezoid residuals for each layer in ``width_ratio`` (layer -> (min, max) of front/back width)."""
    names = list(width_ratio)
    indices = np.array([LAYERS[name] for name in names])
    lo = np.array([width_ratio[name][0] for name in names], float)
    hi = np.array([width_ratio[name][1] for name in names], float)
    row_layers = np.repeat([LAYER_NAMES.index(name) for name in names], 4)
    return ShapeTerm("trapezoid", partial(_residual, indices, lo, hi, sigma_rad, sigma_ratio), 4 * len(names), row_layers)
