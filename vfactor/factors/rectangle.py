"""Rectangle factor: the wheel layer is a rectangle.

With ``(lf, rf, lb, rb)`` the four hubs, the residual is the parallelogram
condition ``((lf - rf) - (lb - rb)) / sigma`` (3 rows, metres): the left-right
axle vectors of the front and back axles are equal. Together with the mirror
symmetry of the layer (:mod:`vfactor.factors.symmetry`) this makes the layer a
rectangle: a parallelogram symmetric about a plane through its centre that
contains neither pair of sides' direction is an isosceles trapezoid with
parallel legs, i.e. a rectangle. Linear, so native (see
:mod:`vfactor.factors.linear`).
"""

from __future__ import annotations

import numpy as np

from vfactor.factors.linear import linear_vector_factor

__all__ = ["rectangle_factor", "RECTANGLE_MATRIX"]

#: (3, 12) residual matrix on a layer ``[lf, rf, lb, rb]``.
RECTANGLE_MATRIX = np.hstack([np.eye(3), -np.eye(3), -np.eye(3), np.eye(3)])
RECTANGLE_MATRIX.setflags(write=False)


def rectangle_factor(wheel_key: int, sigma: float = 0.02):
    """Parallelogram condition of the wheel layer (rectangle with the symmetry factor).

    Args:
        wheel_key: key of the wheel layer 12-vector.
        sigma: standard deviation of each coordinate of the axle-vector difference, metres.
    """
    return linear_vector_factor([wheel_key], [RECTANGLE_MATRIX], np.zeros(3), sigma)
