"""Native (C++) factors for residuals that are linear in the layer 12-vectors.

A residual ``r = sum_j A_j x_j - b`` over vector-valued keys is exact as a
``gtsam.JacobianFactor`` wrapped in a ``gtsam.LinearContainerFactor`` linearised
at zero: GTSAM evaluates and relinearises it in C++ with no Python call, which
keeps the symmetry, body-frame and shape-prior factors off the Python path.
"""

from __future__ import annotations

import gtsam
import numpy as np

__all__ = ["linear_vector_factor"]


def linear_vector_factor(keys, blocks, b, sigmas) -> gtsam.LinearContainerFactor:
    """A native factor with whitened residual ``(sum_j blocks[j] x_j - b) / sigmas``.

    Args:
        keys: one to three keys of vector-valued variables.
        blocks: the matrices ``A_j`` (m x dim_j), one per key.
        b: (m,) right-hand side.
        sigmas: (m,) standard deviations (same units as the residual).
    """
    keys, blocks = list(keys), [np.asarray(a, float) for a in blocks]
    if not 1 <= len(keys) <= 3 or len(keys) != len(blocks):
        raise ValueError("linear_vector_factor: expected one to three keys, one block each")
    b = np.asarray(b, float)
    sigmas = np.broadcast_to(np.asarray(sigmas, float), b.shape).copy()
    model = gtsam.noiseModel.Diagonal.Sigmas(sigmas)
    args = []
    for key, a in zip(keys, blocks):
        args += [key, a]
    jacobian = gtsam.JacobianFactor(*args, b, model)
    zero = gtsam.Values()
    for key, a in zip(keys, blocks):
        zero.insert(key, np.zeros(a.shape[1]))
    return gtsam.LinearContainerFactor(jacobian, zero)
