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

from vfactor.factors.shape_terms import ShapeTerm, cnorm, hinge
from vfactor.keypoints import LAYERS

__all__ = ["trapezoid_term"]


def _residual(ranges, sigma_rad, sigma_ratio, points):
    out = []
    for name, (lo, hi) in ranges:
        lf, rf, lb, rb = (points[..., i, :] for i in LAYERS[name])
        f, b = lf - rf, lb - rb
        nf, nb = cnorm(f), cnorm(b)
        out.append(np.cross(f / nf[..., None], b / nb[..., None]) / sigma_rad)
        out.append((hinge(nf / nb, lo, hi) / sigma_ratio)[..., None])
    return np.concatenate(out, axis=-1)


def trapezoid_term(width_ratio: dict, sigma_rad: float = 0.05, sigma_ratio: float = 0.02) -> ShapeTerm:
    """Trapezoid residuals for each layer in ``width_ratio`` (layer -> (min, max) of front/back width)."""
    ranges = tuple((name, (float(lo), float(hi))) for name, (lo, hi) in width_ratio.items())
    return ShapeTerm("trapezoid", partial(_residual, ranges, sigma_rad, sigma_ratio), 4 * len(ranges))
