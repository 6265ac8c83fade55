"""Nonlinear shape factors on the three layer keys, with complex-step Jacobians.

Each HWC constraint module (planarity, rectangle, trapezoid, distance bounds,
layer offsets) defines a :class:`ShapeTerm`: a whitened residual of the
wireframe ``points`` (..., 12, 3). :func:`shape_terms_factor` turns one or
several terms into a single ``gtsam.CustomFactor`` on ``[wheel, light, roof]``;
the graph builder fuses all HWC terms of a vehicle into one factor, one Python
call per linearisation.

Jacobians come from the complex step: ``J = Im(r(x + i h e_k)) / h`` for all 36
directions at once (one batched evaluation, exact to machine precision, no
cancellation), so residuals must be written with complex-safe operations:
``sqrt(sum(v * v))`` for norms, branches on ``.real`` (see docs/factors.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Callable

import gtsam
import numpy as np

__all__ = ["ShapeTerm", "shape_terms_factor", "evaluate_terms", "cnorm", "hinge"]

_STEP = 1e-30


@dataclass(frozen=True)
class ShapeTerm:
    """A whitened residual of the wireframe.

    Attributes:
        name: what it constrains (reported by diagnostics).
        residual: maps points (..., 12, 3) (real or complex) to (..., size).
        size: number of residual rows.
    """

    name: str
    residual: Callable[[np.ndarray], np.ndarray]
    size: int


def cnorm(v: np.ndarray, axis: int = -1) -> np.ndarray:
    """Euclidean norm that is complex-step safe (no conjugation)."""
    return np.sqrt(np.sum(v * v, axis=axis))


def hinge(q: np.ndarray, lo, hi) -> np.ndarray:
    """``q - clip(q, lo, hi)``: zero inside ``[lo, hi]``, the excess outside (complex-step safe)."""
    qr = q.real
    return np.where(qr < lo, q - lo, np.where(qr > hi, q - hi, 0.0 * q))


def evaluate_terms(terms, points: np.ndarray) -> np.ndarray:
    """Stacked residuals of ``terms`` at ``points`` (..., 12, 3)."""
    return np.concatenate([t.residual(points) for t in terms], axis=-1)


def _error(terms, this: gtsam.CustomFactor, values: gtsam.Values, H):
    keys = this.keys()
    x = np.concatenate([values.atVector(k) for k in keys])
    if H is None:
        return evaluate_terms(terms, x.reshape(12, 3))
    probes = x + 1j * _STEP * np.eye(36)  # (36, 36): one complex direction per row
    r = evaluate_terms(terms, probes.reshape(36, 12, 3))
    J = r.imag.T / _STEP  # (m, 36)
    for j in range(3):
        H[j] = np.ascontiguousarray(J[:, 12 * j : 12 * j + 12])
    return r[0].real


def shape_terms_factor(layer_keys, terms) -> gtsam.CustomFactor:
    """One factor on the (wheel, light, roof) layer keys for the given terms."""
    terms = tuple(terms)
    size = sum(t.size for t in terms)
    if size == 0:
        raise ValueError("shape_terms_factor: no residual rows")
    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(size), list(layer_keys), partial(_error, terms))
