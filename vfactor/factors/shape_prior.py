"""Shape prior: a Gaussian on the 36 body-frame coordinates toward the mean shape.

Residual ``R (x - mean)`` with ``R^T R = Sigma^-1 * weight`` (``Sigma`` learnt from
the PASCAL3D+ cars, :func:`vfactor.shape_model.default_shape_prior`) over the
three layer keys. Linear, so native.
"""

from __future__ import annotations

from functools import partial

import gtsam
import numpy as np

from vfactor.factors.linear import linear_vector_factor
from vfactor.factors.robust import RobustLoss, robust_scale
from vfactor.shape_model import ShapePrior

__all__ = ["shape_prior_factor"]


def shape_prior_factor(layer_keys, prior: ShapePrior, weight: float = 1.0, loss: RobustLoss = RobustLoss("none")):
    """Gaussian (or, with a robust ``loss``, heavy-tailed) prior of the (wheel, light, roof) layers.

    Args:
        layer_keys: the three layer keys in (wheel, light, roof) order.
        prior: mean (12, 3) and covariance (36, 36), metres.
        weight: multiplies the information (``1 / weight`` scales the covariance).
        loss: robust loss on the whole 36-vector's Mahalanobis norm; ``"none"``
            gives the Gaussian, a native linear factor.
    """
    if weight <= 0:
        raise ValueError(f"shape prior weight: expected > 0, got {weight}")
    cache = prior.__dict__.setdefault("_factors", {})  # a prior's factor is made once per keys, weight and loss
    key = (tuple(layer_keys), float(weight), loss)
    if key not in cache:
        if len(cache) >= 64:
            cache.clear()
        cache[key] = _shape_prior_factor(tuple(layer_keys), prior, float(weight), loss)
    return cache[key]


def _shape_prior_factor(layer_keys, prior: ShapePrior, weight: float, loss: RobustLoss):
    R = prior.sqrt_information() * np.sqrt(weight)
    b = R @ np.asarray(prior.mean).ravel()
    if loss.name == "none":
        blocks = [R[:, 12 * j : 12 * j + 12] for j in range(3)]
        return linear_vector_factor(layer_keys, blocks, b, 1.0)
    error = partial(_robust_error, np.ascontiguousarray(R), b, loss.id, float(loss.threshold))
    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(36), list(layer_keys), error)


def _robust_error(R, b, loss_id, k, this: gtsam.CustomFactor, values: gtsam.Values, H):
    keys = this.keys()
    x = np.concatenate((values.atVector(keys[0]), values.atVector(keys[1]), values.atVector(keys[2])))
    e = R @ x - b
    s, ds = robust_scale(loss_id, k, float(np.sqrt(e @ e)))
    if H is not None:
        J = s * R + np.outer(ds * e, e @ R)  # (s I + (s'/n) e e^T) R
        H[0], H[1], H[2] = J[:, :12], J[:, 12:24], J[:, 24:]
    return s * e
