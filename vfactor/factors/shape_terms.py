"""Nonlinear shape factors on the three layer keys, with complex-step Jacobians.

Each HWC constraint module (planarity, rectangle, trapezoid, distance bounds,
layer offsets) defines a :class:`ShapeTerm`: a whitened residual of the
wireframe ``points`` (..., 12, 3). :func:`shape_terms_factor` turns one or
several terms into a single ``gtsam.CustomFactor`` on ``[wheel, light, roof]``;
the graph builder fuses all HWC terms of a vehicle into one factor, one Python
call per linearisation.

The four HWC terms of vfactor are compiled (:mod:`kernels.hwc`, in
:mod:`vfactor._kernels`): each fills its rows of the residual and of the
Jacobian in one call (:func:`compiled_term`; ``ShapeTerm.fill``), and the fused
factor fills all of them into one array. A term of your own is a residual
function: its Jacobian is analytic where it gives one, else it comes from the
complex step: ``J = Im(r(x + i h e_k)) / h``, exact to machine
precision with no cancellation, for all directions in one batched evaluation.
A term whose every row depends on a single layer (``row_layers``) needs only 12
probes, each moving the same coordinate of all three layers at once. Residuals
differentiated this way must be written with complex-safe operations:
``sqrt(sum(v * v))`` for norms, branches on ``.real`` (see docs/factors.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Callable

import gtsam
import numpy as np

__all__ = ["ShapeTerm", "compiled_term", "shape_terms_factor", "evaluate_terms", "cnorm", "cross", "hinge"]

_STEP = 1e-30
_SHARED_PROBES = np.tile(np.eye(12), (1, 3))  # probe k moves coordinate k of every layer


@dataclass(frozen=True)
class ShapeTerm:
    """A whitened residual of the wireframe.

    Attributes:
        name: what it constrains (reported by diagnostics).
        residual: maps points (..., 12, 3) (real or complex) to (..., size).
        size: number of residual rows.
        row_layers: optional (size,) layer index (0 wheel, 1 light, 2 roof) of
            each row, when each row depends on that layer's points only.
        jacobian: optional analytic Jacobian, points (12, 3) -> (size, 36).
        fill: optional compiled form (:func:`compiled_term`): ``fill(points (12, 3), want_jacobian, r (size,),
            J (size, 36))`` writes the residual and, where asked, the Jacobian (``J`` zero on entry).
    """

    name: str
    residual: Callable[[np.ndarray], np.ndarray]
    size: int
    row_layers: np.ndarray | None = None
    jacobian: Callable[[np.ndarray], np.ndarray] | None = None
    fill: Callable[[np.ndarray, bool, np.ndarray, np.ndarray], None] | None = None

    def jacobian_at(self, x: np.ndarray) -> np.ndarray:
        """(size, 36) Jacobian of the residual at the flattened points ``x`` (36,)."""
        if self.jacobian is not None:
            return self.jacobian(x.reshape(12, 3))
        if self.row_layers is None:
            r = self.residual((x + 1j * _STEP * np.eye(36)).reshape(36, 12, 3))
            return r.imag.T / _STEP
        r = self.residual((x + 1j * _STEP * _SHARED_PROBES).reshape(12, 12, 3))
        local = r.imag.T / _STEP  # (size, 12): d row / d (its own layer's coordinates)
        J = np.zeros((self.size, 36))
        for layer in range(3):
            rows = self.row_layers == layer
            J[rows, 12 * layer : 12 * layer + 12] = local[rows]
        return J


_NO_JACOBIAN = np.zeros((0, 36))


def compiled_term(name: str, size: int, kernel: Callable, *params) -> ShapeTerm:
    """A term whose residual and Jacobian one compiled call fills: ``kernel(points (12, 3), *params, want_jacobian,
    r (size,), J (size, 36))`` (:mod:`kernels.hwc`), its ``ShapeTerm.fill``. Its ``residual`` takes real points
    (..., 12, 3) (no complex step: the Jacobian is its own) and its ``jacobian`` points (12, 3)."""
    fill = partial(_kernel_fill, kernel, params)
    parts = ((fill, size),)
    return ShapeTerm(name, partial(_filled_residual, parts), size, jacobian=partial(_filled_jacobian, parts),
                     fill=fill)


def _kernel_fill(kernel, params, points, want_jacobian, r, J):
    kernel(points, *params, want_jacobian, r, J)


def _filled_residual(parts, points: np.ndarray) -> np.ndarray:
    points = np.asarray(points)
    if np.iscomplexobj(points):
        raise TypeError("a compiled shape term takes real points (its Jacobian is analytic, not by the complex step)")
    flat = np.ascontiguousarray(points, dtype=float).reshape(-1, 12, 3)
    out = np.stack([_filled(parts, p, False)[0] for p in flat]) if len(flat) else np.zeros((0, parts[0][1]))
    return out.reshape(*points.shape[:-2], -1)


def _filled_jacobian(parts, points: np.ndarray) -> np.ndarray:
    return _filled(parts, np.ascontiguousarray(points, dtype=float).reshape(12, 3), True)[1]


def cnorm(v: np.ndarray, axis: int = -1) -> np.ndarray:
    """Euclidean norm that is complex-step safe (no conjugation)."""
    return np.sqrt(np.sum(v * v, axis=axis))


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (a few times faster than ``np.cross`` on small arrays)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def hinge(q: np.ndarray, lo, hi) -> np.ndarray:
    """``q - clip(q, lo, hi)``: zero inside ``[lo, hi]``, the excess outside (complex-step safe)."""
    qr = q.real
    return np.where(qr < lo, q - lo, np.where(qr > hi, q - hi, 0.0 * q))


def evaluate_terms(terms, points: np.ndarray) -> np.ndarray:
    """Stacked residuals of ``terms`` at ``points`` (..., 12, 3)."""
    if np.ndim(points) == 2 and all(t.fill is not None for t in terms):
        return _filled(_parts(terms), np.ascontiguousarray(points, dtype=float), False)[0]
    return np.concatenate([t.residual(points) for t in terms], axis=-1)


def _parts(terms) -> tuple:
    """The (fill, size) of each compiled term, in order."""
    return tuple((t.fill, t.size) for t in terms)


def _filled(parts, points: np.ndarray, want_jacobian: bool) -> tuple[np.ndarray, np.ndarray]:
    """(r, J) at ``points`` (12, 3) of the compiled terms ``parts`` ((fill, size) each), each filling its rows (J: 0
    rows unless asked)."""
    size = sum(rows for _, rows in parts)
    r, J = np.zeros(size), np.zeros((size, 36)) if want_jacobian else _NO_JACOBIAN
    row = 0
    for fill, rows in parts:
        fill(points, want_jacobian, r[row : row + rows], J[row : row + rows] if want_jacobian else J)
        row += rows
    return r, J


def _error(terms, compiled: tuple | None, this: gtsam.CustomFactor, values: gtsam.Values, H):
    keys = this.keys()
    x = np.concatenate([values.atVector(k) for k in keys])
    if compiled is not None:  # every term compiled: their (fill, size), taken once when the factor was made
        r, J = _filled(compiled, x.reshape(12, 3), H is not None)
    else:
        r = evaluate_terms(terms, x.reshape(12, 3))
        J = np.concatenate([t.jacobian_at(x) for t in terms], axis=0) if H is not None else None  # (m, 36)
    if H is not None:
        for j in range(3):
            H[j] = np.ascontiguousarray(J[:, 12 * j : 12 * j + 12])
    return r


def shape_terms_factor(layer_keys, terms) -> gtsam.CustomFactor:
    """One factor on the (wheel, light, roof) layer keys for the given terms."""
    terms = tuple(terms)
    size = sum(t.size for t in terms)
    if size == 0:
        raise ValueError("shape_terms_factor: no residual rows")
    compiled = _parts(terms) if all(t.fill is not None for t in terms) else None
    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(size), list(layer_keys), partial(_error, terms, compiled))
