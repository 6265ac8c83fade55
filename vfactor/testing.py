"""Test helpers users can reuse: numerical Jacobian checks for any GTSAM factor.

GTSAM's C++ ``EXPECT_CORRECT_FACTOR_JACOBIANS`` is not wrapped for Python;
:func:`check_factor_jacobians` does the same: it linearises the factor, then
differentiates the whitened error numerically through ``Values.retract``
(central differences), key by key, and compares.
"""

from __future__ import annotations

import gtsam
import numpy as np

__all__ = ["whitened_error", "numerical_jacobians", "check_factor_jacobians"]


def whitened_error(factor: gtsam.NonlinearFactor, values: gtsam.Values) -> np.ndarray:
    """The factor's whitened error vector at ``values`` (``-b`` of its linearisation)."""
    _, b = factor.linearize(values).jacobian()
    return -np.asarray(b).ravel()


def _dim(values: gtsam.Values, key: int) -> int:
    return values.atPose3(key).localCoordinates(values.atPose3(key)).size if _is_pose3(values, key) else values.atVector(key).size


def _is_pose3(values, key) -> bool:
    try:
        values.atPose3(key)
        return True
    except RuntimeError:
        return False


def numerical_jacobians(factor: gtsam.NonlinearFactor, values: gtsam.Values, delta: float = 1e-6) -> list[np.ndarray]:
    """Central-difference Jacobians of the whitened error, one matrix per key of ``factor``.

    Variables may be ``Pose3`` (6-dof tangent, GTSAM's retract) or vectors.
    """
    jacobians = []
    for key in factor.keys():
        dim = _dim(values, key)
        cols = []
        for i in range(dim):
            step = np.zeros(dim)
            step[i] = delta
            plus, minus = gtsam.VectorValues(), gtsam.VectorValues()
            plus.insert(key, step)
            minus.insert(key, -step)
            e_plus = whitened_error(factor, values.retract(plus))
            e_minus = whitened_error(factor, values.retract(minus))
            cols.append((e_plus - e_minus) / (2 * delta))
        jacobians.append(np.column_stack(cols))
    return jacobians


def check_factor_jacobians(
    factor: gtsam.NonlinearFactor,
    values: gtsam.Values,
    delta: float = 1e-6,
    rtol: float = 1e-5,
    atol: float = 1e-6,
) -> float:
    """Asserts that the factor's analytic Jacobians match numerical ones.

    Args:
        factor: any factor whose variables are ``Pose3`` or vectors.
        values: the linearisation point.
        delta: finite-difference step in each tangent coordinate.
        rtol, atol: tolerances, relative to the largest Jacobian entry and absolute.

    Returns:
        The largest absolute difference found.

    Raises:
        AssertionError: naming the key and the worst entry when a Jacobian is off.
    """
    linear = factor.linearize(values)
    A, _ = linear.jacobian()
    numeric = numerical_jacobians(factor, values, delta)
    col, worst = 0, 0.0
    lin_keys = list(linear.keys())
    offsets = {}
    for key in lin_keys:
        d = _dim(values, key)
        offsets[key] = (col, col + d)
        col += d
    scale = max(1.0, float(np.abs(A).max()) if A.size else 1.0)
    for key, J_num in zip(factor.keys(), numeric):
        a, b = offsets[key]
        J = A[:, a:b]
        diff = np.abs(J - J_num)
        err = float(diff.max()) if diff.size else 0.0
        worst = max(worst, err)
        if err > atol + rtol * scale:
            r, c = np.unravel_index(np.argmax(diff), diff.shape)
            raise AssertionError(
                f"Jacobian of key {gtsam.DefaultKeyFormatter(key)} is off by {err:.3g} at row {r}, column {c}: "
                f"analytic {J[r, c]:.9g}, numerical {J_num[r, c]:.9g}"
            )
    return worst
