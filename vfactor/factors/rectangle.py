"""Wheel-layer factor: the front and back axles are parallel (an isosceles trapezoid with the symmetry).

With ``(lf, rf, lb, rb)`` the four hubs, the residual is the x and z rows of
``((lf - rf) - (lb - rb)) / sigma`` (2 rows, metres): the left-right axle
vectors of the front and back axles have the same forward and vertical
components. The y row, which would make the two axles equally long (a
rectangle), is left out: real vehicles' front and rear tracks differ (by up to
5 cm in the vehicle library), and the shape prior holds that difference.
Linear, so native (see :mod:`vfactor.factors.linear`).
"""

from __future__ import annotations

import numpy as np

from vfactor.factors.linear import linear_vector_factor

__all__ = ["rectangle_factor", "RECTANGLE_MATRIX"]

#: (2, 12) residual matrix on a layer ``[lf, rf, lb, rb]``: the x and z rows of ``(lf - rf) - (lb - rb)``.
RECTANGLE_MATRIX = np.hstack([np.eye(3), -np.eye(3), -np.eye(3), np.eye(3)])[[0, 2]]
RECTANGLE_MATRIX.setflags(write=False)


def rectangle_factor(wheel_key: int, sigma: float = 0.02):
    """Parallel axles of the wheel layer (with the symmetry factor: an isosceles trapezoid, tracks free).

    Args:
        wheel_key: key of the wheel layer 12-vector.
        sigma: standard deviation of the x and z components of the axle-vector difference, metres.
    """
    return linear_vector_factor([wheel_key], [RECTANGLE_MATRIX], np.zeros(2), sigma)
