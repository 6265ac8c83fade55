"""Symmetry factor: each left keypoint mirrors its right partner across the body x-z plane.

For a layer ``[p_lf, p_rf, p_lb, p_rb]`` (12-vector) the residual is, per pair
``(l, r)``: ``(x_l - x_r, y_l + y_r, z_l - z_r) / sigma`` (6 rows per layer).
Linear, so native (see :mod:`vfactor.factors.linear`).
"""

from __future__ import annotations

import numpy as np

from vfactor.factors.linear import linear_vector_factor

__all__ = ["symmetry_factor", "SYMMETRY_MATRIX"]

#: (6, 12) residual matrix of one layer: rows (x, y, z) of the front pair, then the back pair.
SYMMETRY_MATRIX = np.zeros((6, 12))
for _pair, (_l, _r) in enumerate(((0, 1), (2, 3))):
    for _axis, _sign in enumerate((-1.0, 1.0, -1.0)):
        SYMMETRY_MATRIX[3 * _pair + _axis, 3 * _l + _axis] = 1.0
        SYMMETRY_MATRIX[3 * _pair + _axis, 3 * _r + _axis] = _sign
SYMMETRY_MATRIX.setflags(write=False)


def symmetry_factor(layer_key: int, sigma: float = 0.01):
    """Left/right symmetry of one layer.

    Args:
        layer_key: key of the layer 12-vector.
        sigma: standard deviation of each coordinate's asymmetry, metres.
    """
    return linear_vector_factor([layer_key], [SYMMETRY_MATRIX], np.zeros(6), sigma)
