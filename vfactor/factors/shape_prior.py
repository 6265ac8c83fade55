"""Shape prior: a Gaussian on the 36 body-frame coordinates toward the mean shape.

Residual ``R (x - mean)`` with ``R^T R = Sigma^-1 * weight`` (``Sigma`` learnt from
the PASCAL3D+ cars, :func:`vfactor.shape_model.default_shape_prior`) over the
three layer keys. Linear, so native.
"""

from __future__ import annotations

import numpy as np

from vfactor.factors.linear import linear_vector_factor
from vfactor.shape_model import ShapePrior

__all__ = ["shape_prior_factor"]


def shape_prior_factor(layer_keys, prior: ShapePrior, weight: float = 1.0):
    """Gaussian prior of the (wheel, light, roof) layers.

    Args:
        layer_keys: the three layer keys in (wheel, light, roof) order.
        prior: mean (12, 3) and covariance (36, 36), metres.
        weight: multiplies the information (``1 / weight`` scales the covariance).
    """
    if weight <= 0:
        raise ValueError(f"shape prior weight: expected > 0, got {weight}")
    R = prior.sqrt_information() * np.sqrt(weight)
    blocks = [R[:, 12 * j : 12 * j + 12] for j in range(3)]
    return linear_vector_factor(layer_keys, blocks, R @ np.asarray(prior.mean).ravel(), 1.0)
