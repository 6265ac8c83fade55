"""Rectangle factor: the wheel layer is a rectangle.

With ``(lf, rf, lb, rb)`` the four hubs: the parallelogram condition
``(lf - rf) - (lb - rb) = 0`` (3 rows) and equal diagonals
``|lf - rb| - |rf - lb| = 0`` (1 row), metres, over ``sigma``. A parallelogram
with equal diagonals is a rectangle.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from vfactor.factors.shape_terms import ShapeTerm, cnorm
from vfactor.keypoints import LAYER_NAMES, LAYERS

__all__ = ["rectangle_term"]


def _residual(layer, sigma, points):
    lf, rf, lb, rb = (points[..., i, :] for i in LAYERS[layer])
    parallelogram = (lf - rf) - (lb - rb)
    diagonals = cnorm(lf - rb) - cnorm(rf - lb)
    return np.concatenate([parallelogram, diagonals[..., None]], axis=-1) / sigma


def rectangle_term(layer: str = "wheel", sigma: float = 0.02) -> ShapeTerm:
    """The rectangle residual of one layer (4 rows)."""
    return ShapeTerm("rectangle", partial(_residual, layer, sigma), 4, np.full(4, LAYER_NAMES.index(layer)))
