"""The hierarchical wireframe constraint's (HWC) terms: residuals and Jacobians (numba source, compiled ahead of
time into :mod:`vfactor._kernels`).

The HWC factor (:func:`vfactor.graph.hwc_factor`) fuses four kinds of terms on a vehicle's 12 body-frame keypoints;
the maths of each is in its module of :mod:`vfactor.factors` (planarity, trapezoid, distance_bounds,
layer_offset) and in docs/factors.md. Written with NumPy, one linearisation cost about 300 us (the layer and
trapezoid terms' Jacobians by a batched complex step, 12 probes) and the lazy HWC check on a solution about 200 us,
12 % of the association of a frame of 30 vehicles (docs/performance.md). Each kernel here fills its rows of the
factor's residual and Jacobian in one compiled call.

Every kernel takes ``points`` (12, 3), the wireframe in keypoint order (metres, body frame), and writes ``r``
(its rows, whitened) and, where ``want_jacobian``, ``J`` (its rows, 36 columns: ``3 k + axis`` for keypoint ``k``;
zero on entry). The Jacobians of the layer and trapezoid terms are taken by the complex step, ``Im(r(x + i h e)) /
h`` with ``h = 1e-30``, exact to rounding as the NumPy terms' were; those of the hinge terms are analytic (a hinge
at its kink takes the inner side: zero, as the NumPy terms did). A degenerate wireframe (a layer or an edge of no
extent, coincident points, NaN) gives NaN rows, as NumPy's ``0 / 0`` did, never a division error.
"""

from __future__ import annotations

import cmath
import math

import numpy as np
from numba import njit

__all__ = ["layer_plane_kernel", "trapezoid_kernel", "distance_bounds_kernel", "layer_offset_kernel"]

_STEP = 1e-30


@njit
def _hinge(q, lo, hi):
    """``q - clip(q, lo, hi)`` on the real part's side (complex-step safe)."""
    if q.real < lo:
        return q - lo
    if q.real > hi:
        return q - hi
    return 0.0 * q


@njit
def _plane_rows(quad, sigma_m, sigma_rad):
    """(planarity, perpendicularity) of one layer's corners ``quad`` (4, 3) complex (lf, rf, lb, rb)."""
    d1 = quad[3] - quad[0]  # rb - lf
    d2 = quad[2] - quad[1]  # lb - rf
    n0 = d1[1] * d2[2] - d1[2] * d2[1]
    n1 = d1[2] * d2[0] - d1[0] * d2[2]
    n2 = d1[0] * d2[1] - d1[1] * d2[0]
    squared = n0 * n0 + n1 * n1 + n2 * n2
    if squared == 0.0:  # a layer collapsed to a line or a point: no plane (NaN, as NumPy's 0 / 0)
        return complex(math.nan, 0.0), complex(math.nan, 0.0)
    norm = cmath.sqrt(squared)
    e = quad[1] - quad[0]  # rf - lf
    planar = (n0 * e[0] + n1 * e[1] + n2 * e[2]) / norm / sigma_m
    return planar, n1 / norm / sigma_rad


@njit
def layer_plane_kernel(points, indices, sigma_m, sigma_rad, want_jacobian, r, J):
    """Planarity and perpendicularity of each layer (:mod:`vfactor.factors.planarity`): two rows per layer.

    Args:
        points: (12, 3) keypoints (m).
        indices: (L, 4) each layer's keypoints (lf, rf, lb, rb).
        sigma_m: planarity sigma (m); sigma_rad: perpendicularity sigma (rad).
        want_jacobian: whether to fill ``J``.
        r: (2 L,) written; J: (2 L, 36) written where asked (zero on entry).
    """
    quad = np.empty((4, 3), dtype=np.complex128)
    for layer in range(indices.shape[0]):
        for a in range(4):
            for c in range(3):
                quad[a, c] = points[indices[layer, a], c]
        planar, perpendicular = _plane_rows(quad, sigma_m, sigma_rad)
        r[2 * layer] = planar.real
        r[2 * layer + 1] = perpendicular.real
        if want_jacobian:
            for a in range(4):
                for c in range(3):
                    quad[a, c] += 1j * _STEP
                    planar, perpendicular = _plane_rows(quad, sigma_m, sigma_rad)
                    quad[a, c] = points[indices[layer, a], c]
                    column = 3 * indices[layer, a] + c
                    J[2 * layer, column] = planar.imag / _STEP
                    J[2 * layer + 1, column] = perpendicular.imag / _STEP


@njit
def _trapezoid_rows(quad, lo, hi, sigma_rad, sigma_ratio, out):
    """The parallel sides (3 rows) and the width ratio (1 row) of one layer ``quad`` (4, 3) complex, into ``out``."""
    f = quad[0] - quad[1]
    b = quad[2] - quad[3]
    nf = cmath.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
    nb = cmath.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2])
    if nf == 0.0 or nb == 0.0:  # an edge of no length: no direction (NaN, as NumPy's 0 / 0)
        for k in range(4):
            out[k] = complex(math.nan, 0.0)
        return
    f0, f1, f2 = f[0] / nf, f[1] / nf, f[2] / nf
    b0, b1, b2 = b[0] / nb, b[1] / nb, b[2] / nb
    out[0] = (f1 * b2 - f2 * b1) / sigma_rad
    out[1] = (f2 * b0 - f0 * b2) / sigma_rad
    out[2] = (f0 * b1 - f1 * b0) / sigma_rad
    out[3] = _hinge(nf / nb, lo, hi) / sigma_ratio


@njit
def trapezoid_kernel(points, indices, lo, hi, sigma_rad, sigma_ratio, want_jacobian, r, J):
    """Parallel front and back edges and their width ratio within bounds (:mod:`vfactor.factors.trapezoid`): four
    rows per layer.

    Args:
        points: (12, 3) keypoints (m).
        indices: (L, 4) each layer's keypoints (lf, rf, lb, rb).
        lo, hi: (L,) bounds of the front / back width ratio.
        sigma_rad: the parallel rows' sigma (rad); sigma_ratio: the ratio row's.
        want_jacobian: whether to fill ``J``.
        r: (4 L,) written; J: (4 L, 36) written where asked (zero on entry).
    """
    quad = np.empty((4, 3), dtype=np.complex128)
    rows = np.empty(4, dtype=np.complex128)
    for layer in range(indices.shape[0]):
        for a in range(4):
            for c in range(3):
                quad[a, c] = points[indices[layer, a], c]
        _trapezoid_rows(quad, lo[layer], hi[layer], sigma_rad, sigma_ratio, rows)
        for k in range(4):
            r[4 * layer + k] = rows[k].real
        if want_jacobian:
            for a in range(4):
                for c in range(3):
                    quad[a, c] += 1j * _STEP
                    _trapezoid_rows(quad, lo[layer], hi[layer], sigma_rad, sigma_ratio, rows)
                    quad[a, c] = points[indices[layer, a], c]
                    column = 3 * indices[layer, a] + c
                    for k in range(4):
                        J[4 * layer + k, column] = rows[k].imag / _STEP


@njit
def distance_bounds_kernel(points, pairs, lo, hi, sigma, want_jacobian, r, J):
    """Each pair's distance within bounds (:mod:`vfactor.factors.distance_bounds`): one row per pair.

    Args:
        points: (12, 3) keypoints (m).
        pairs: (P, 2) keypoint indices.
        lo, hi: (P,) bounds (m).
        sigma: the rows' sigma (m).
        want_jacobian: whether to fill ``J``.
        r: (P,) written; J: (P, 36) written where asked (zero on entry).
    """
    for p in range(pairs.shape[0]):
        i, j = pairs[p, 0], pairs[p, 1]
        d0 = points[i, 0] - points[j, 0]
        d1 = points[i, 1] - points[j, 1]
        d2 = points[i, 2] - points[j, 2]
        d = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if d < lo[p]:
            r[p] = (d - lo[p]) / sigma
        elif d > hi[p]:
            r[p] = (d - hi[p]) / sigma
        else:
            r[p] = 0.0 * d  # NaN for a NaN distance, as NumPy's hinge
            continue
        if want_jacobian:
            scale = 1.0 / (d * sigma) if d > 0.0 else math.nan  # no direction between coincident points
            J[p, 3 * i] = d0 * scale
            J[p, 3 * i + 1] = d1 * scale
            J[p, 3 * i + 2] = d2 * scale
            J[p, 3 * j] = -d0 * scale
            J[p, 3 * j + 1] = -d1 * scale
            J[p, 3 * j + 2] = -d2 * scale


@njit
def layer_offset_kernel(points, indices, lo, hi, sigma, want_jacobian, r, J):
    """Each layer's centroid within bounds of the wheel layer's along x and z (:mod:`vfactor.factors.layer_offset`):
    two rows per layer.

    Args:
        points: (12, 3) keypoints (m).
        indices: (1 + L, 4) the wheel layer's keypoints, then each bounded layer's.
        lo, hi: (L, 2) bounds of the x and z offsets (m).
        sigma: the rows' sigma (m).
        want_jacobian: whether to fill ``J``.
        r: (2 L,) written; J: (2 L, 36) written where asked (zero on entry).
    """
    for layer in range(indices.shape[0] - 1):
        for a in range(2):
            axis = 2 * a  # x, then z
            wheels, mine = 0.0, 0.0
            for k in range(4):
                wheels += points[indices[0, k], axis]
                mine += points[indices[layer + 1, k], axis]
            offset = mine / 4.0 - wheels / 4.0
            row = 2 * layer + a
            if offset < lo[layer, a]:
                r[row] = (offset - lo[layer, a]) / sigma
            elif offset > hi[layer, a]:
                r[row] = (offset - hi[layer, a]) / sigma
            else:
                r[row] = 0.0 * offset  # NaN for a NaN offset, as NumPy's hinge
                continue
            if want_jacobian:
                for k in range(4):
                    J[row, 3 * indices[layer + 1, k] + axis] = 0.25 / sigma
                    J[row, 3 * indices[0, k] + axis] = -0.25 / sigma
