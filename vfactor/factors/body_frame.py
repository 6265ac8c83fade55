"""Body-frame factor: fixes the gauge of pose and shape.

Pose and shape together have six degrees of freedom too many (move every body
point by a rigid motion and the pose by its inverse). docs/conventions.md fixes the
body frame at the centroid of the four wheel hubs, x forward, z up; with the
symmetry factor (which fixes yaw and roll about x), the wheel layer residual

    ( (p_lf + p_rf + p_lb + p_rb) / 4,  (z_lf + z_rf - z_lb - z_rb) / 2 ) / sigma

fixes the origin (3 rows) and the pitch (1 row). Linear, so native.
"""

from __future__ import annotations

import numpy as np

from vfactor.factors.linear import linear_vector_factor

__all__ = ["body_frame_factor", "BODY_FRAME_MATRIX"]

#: (4, 12) residual matrix on the wheel layer.
BODY_FRAME_MATRIX = np.zeros((4, 12))
for _i in range(4):
    BODY_FRAME_MATRIX[:3, 3 * _i : 3 * _i + 3] = 0.25 * np.eye(3)
BODY_FRAME_MATRIX[3, [2, 5]] = 0.5
BODY_FRAME_MATRIX[3, [8, 11]] = -0.5
BODY_FRAME_MATRIX.setflags(write=False)


def body_frame_factor(wheel_key: int, sigma: float = 1e-3):
    """Gauge factor on the wheel layer (origin at the hub centroid, hubs level).

    Args:
        wheel_key: key of the wheel layer.
        sigma: standard deviation, metres (small: it is a definition, not a measurement).
    """
    return linear_vector_factor([wheel_key], [BODY_FRAME_MATRIX], np.zeros(4), sigma)
