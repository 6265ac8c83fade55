"""Distance bounds factor: point-to-point distances of the wireframe within bounds.

For every pair ``(i, j)`` in :data:`vfactor.shape_model.DISTANCE_PAIRS` (all
66 pairs of keypoints):
``hinge(|p_i - p_j|, d_min, d_max) / sigma`` (one row per pair, metres), zero
inside the bounds: the HWC's "point-to-point distances bounded". Analytic
Jacobian: ``+-u / sigma`` on the two points of an active row (``u`` the unit
vector from ``p_j`` to ``p_i``), zero on inactive rows.
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


def _jacobian(pairs, lo, hi, sigma, points):
    diff = points[pairs[:, 0]] - points[pairs[:, 1]]
    d = np.sqrt(np.sum(diff * diff, axis=1))
    active = (d < lo) | (d > hi)
    u = diff / d[:, None] * (active / sigma)[:, None]
    J = np.zeros((len(pairs), 12, 3))
    rows = np.arange(len(pairs))
    J[rows, pairs[:, 0]] = u
    J[rows, pairs[:, 1]] = -u
    return J.reshape(len(pairs), 36)


def distance_bounds_term(bounds: np.ndarray, pairs: np.ndarray = DISTANCE_PAIRS, sigma: float = 0.01) -> ShapeTerm:
    """Hinge residuals for ``pairs`` (P, 2) with ``bounds`` (P, 2) = ``[min, max]`` metres."""
    bounds, pairs = np.asarray(bounds, float), np.asarray(pairs)
    args = (pairs, bounds[:, 0], bounds[:, 1], sigma)
    return ShapeTerm("distance_bounds", partial(_residual, *args), len(pairs), jacobian=partial(_jacobian, *args))
