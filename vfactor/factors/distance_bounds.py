"""Distance bounds factor: point-to-point distances of the wireframe within bounds.

For every pair ``(i, j)`` in :data:`vfactor.shape_model.DISTANCE_PAIRS`:
``hinge(|p_i - p_j|, d_min, d_max) / sigma`` (one row per pair, metres), zero
inside the bounds: the HWC's "point-to-point distances bounded".
"""

from __future__ import annotations

from functools import partial

import numpy as np

from vfactor.factors.shape_terms import ShapeTerm, cnorm, hinge
from vfactor.shape_model import DISTANCE_PAIRS

__all__ = ["distance_bounds_term"]


def _residual(pairs, lo, hi, sigma, points):
    d = cnorm(points[..., pairs[:, 0], :] - points[..., pairs[:, 1], :])
    return hinge(d, lo, hi) / sigma


def distance_bounds_term(bounds: np.ndarray, pairs: np.ndarray = DISTANCE_PAIRS, sigma: float = 0.01) -> ShapeTerm:
    """Hinge residuals for ``pairs`` (P, 2) with ``bounds`` (P, 2) = ``[min, max]`` metres."""
    bounds = np.asarray(bounds, float)
    return ShapeTerm("distance_bounds", partial(_residual, np.asarray(pairs), bounds[:, 0], bounds[:, 1], sigma), len(pairs))
