"""Trapezoid factor: the light and roof layers are trapezoids within a range.

For a layer ``(lf, rf, lb, rb)`` with front edge ``f = lf - rf`` and back edge
``b = lb - rb``:

* parallel sides: ``f/|f| x b/|b|`` (3 rows, unitless) over ``sigma_rad``;
* width ratio within bounds: ``hinge(|f| / |b|, lo, hi)`` (1 row) over ``sigma_ratio``;
  zero inside the bounds.

Residual and Jacobian (complex step) in one compiled call: :func:`kernels.hwc.trapezoid_kernel`.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from vfactor._kernels import trapezoid_kernel
from vfactor.errors import check_numbers
from vfactor.factors.shape_terms import ShapeTerm, compiled_term
from vfactor.keypoints import LAYERS

__all__ = ["trapezoid_term"]


def trapezoid_term(width_ratio: dict, sigma_rad: float = 0.05, sigma_ratio: float = 0.02) -> ShapeTerm:
    """Trapezoid residuals for each layer in ``width_ratio`` (layer -> (min, max) of front/back width)."""
    names = list(width_ratio)
    indices = np.array([LAYERS[name] for name in names], dtype=np.int64).reshape(-1, 4)
    lo = np.array([width_ratio[name][0] for name in names], float)
    hi = np.array([width_ratio[name][1] for name in names], float)
    check_numbers("trapezoid_term", SimpleNamespace(sigma_rad=sigma_rad, sigma_ratio=sigma_ratio),
                  ("sigma_rad", "sigma_ratio"))
    return compiled_term("trapezoid", 4 * len(names), trapezoid_kernel, indices, lo, hi, float(sigma_rad),
                         float(sigma_ratio))
