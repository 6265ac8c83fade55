"""Distance bounds factor: point-to-point distances of the wireframe within bounds.

For every pair ``(i, j)`` in :data:`vfactor.shape_model.DISTANCE_PAIRS` (all
66 pairs of keypoints):
``hinge(|p_i - p_j|, d_min, d_max) / sigma`` (one row per pair, metres), zero
inside the bounds: the HWC's "point-to-point distances bounded". Analytic
Jacobian: ``+-u / sigma`` on the two points of an active row (``u`` the unit
vector from ``p_j`` to ``p_i``), zero on inactive rows. Both in one compiled
call: :func:`kernels.hwc.distance_bounds_kernel`.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from vfactor._kernels import distance_bounds_kernel
from vfactor.errors import check_numbers
from vfactor.factors.shape_terms import ShapeTerm, compiled_term
from vfactor.shape_model import DISTANCE_PAIRS

__all__ = ["distance_bounds_term"]


def distance_bounds_term(bounds: np.ndarray, pairs: np.ndarray = DISTANCE_PAIRS, sigma: float = 0.01) -> ShapeTerm:
    """Hinge residuals for ``pairs`` (P, 2) with ``bounds`` (P, 2) = ``[min, max]`` metres."""
    bounds = np.asarray(bounds, float)
    pairs = np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2)
    check_numbers("distance_bounds_term", SimpleNamespace(sigma=sigma), ("sigma",))
    return compiled_term("distance_bounds", len(pairs), distance_bounds_kernel, pairs,
                         np.ascontiguousarray(bounds[:, 0]), np.ascontiguousarray(bounds[:, 1]), float(sigma))
