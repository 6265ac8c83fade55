"""The noise scale's fixed point and the body types' evidence (:mod:`vfactor.shape_evidence`) as kernels (numba
source, compiled ahead of time into :mod:`vfactor._kernels`).

:func:`vfactor.shape_evidence.noise_scale` and
:func:`~vfactor.shape_evidence.inlier_noise_scale` ask, several times per
vehicle, what the fit would be with every pixel sigma times ``s``: the
effective number of parameters, the residuals one Gauss-Newton step ahead
and each observation's 2 x 2 leverage block, each a 42 x 42 system. In NumPy
that was three ``np.linalg.solve`` calls and a dozen small array operations
per step (about 1500 LAPACK calls per 30 vehicles, and multi-threaded BLAS
on 42 x 42 matrices that a shared machine slows down many times over); this
kernel does one step in one compiled, single-threaded loop: the Cholesky
factor of ``H(s)``, its inverse, and the products (docs/performance.md).

The maths is that of :class:`vfactor.shape_evidence._ScaledFit` (docs/factors.md);
the tests check it against ``np.linalg.solve``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["fit_at_scale_kernel", "log_evidence_kernel"]


@njit
def fit_at_scale_kernel(total, projection, total_eta, projection_eta, jacobian, rhs, w, max_leverage, q_out,
                        freedom_out):
    """The fit with the projection factor's information times ``w = 1 / s^2``, and its studentised residuals.

    ``H(s) = H + (w - 1) H_proj``, ``eta(s) = eta + (w - 1) eta_proj``;
    ``p = w tr(H_proj H(s)^-1)``; the residuals one Gauss-Newton step ahead,
    ``e = A H(s)^-1 eta(s) - b``; the leverage blocks
    ``M_i = w A_i H(s)^-1 A_i^T`` (``A_i``: observation i's two rows of the
    whitened Jacobian); the studentised squared residuals
    ``q_i = e_i^T (I - M_i)^-1 e_i`` and ``tr(I - M_i)`` (2 x 2 algebra in closed form).

    Args:
        total, projection: (m, m) Gauss-Newton Hessians of the whole graph and of
            the projection factor (variables ``[pose (6), shape (36)]``, m = 42).
        total_eta, projection_eta: (m,) their information vectors.
        jacobian: (2n, m) the projection factor's whitened Jacobian ``A`` (0 rows:
            no residuals or leverages are computed).
        rhs: (2n,) its right-hand side ``b`` (minus the residuals).
        w: ``1 / s^2``.
        max_leverage: an observation whose leverage (the larger eigenvalue of ``M_i``) is at
            least this says nothing about the noise: its ``q_i`` is NaN.
        q_out: (n,) studentised squared residuals, written.
        freedom_out: (n,) ``tr(I - M_i)``, the observation's share of the residual degrees
            of freedom, written.

    Returns:
        ``p``, or NaN when ``H(s)`` is not positive definite.
    """
    m = total.shape[0]
    # Cholesky factor of H(s) (lower; the mean of the two triangles, so that rounding cannot break symmetry)
    L = np.zeros((m, m))
    for i in range(m):
        for j in range(i + 1):
            s = 0.5 * (total[i, j] + total[j, i]) + (w - 1.0) * 0.5 * (projection[i, j] + projection[j, i])
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                if not s > 0.0:
                    return math.nan
                L[i, i] = math.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    # its inverse (lower triangular)
    Li = np.zeros((m, m))
    for j in range(m):
        Li[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, m):
            s = 0.0
            for k in range(j, i):
                s -= L[i, k] * Li[k, j]
            Li[i, j] = s / L[i, i]
    # H(s)^-1 = Li^T Li = U U^T with U = Li^T (rows contiguous): p and the step
    U = np.ascontiguousarray(Li.T)
    g = np.empty(m)
    for a in range(m):
        g[a] = total_eta[a] + (w - 1.0) * projection_eta[a]
    step = np.zeros(m)
    trace = 0.0
    for a in range(m):
        for b in range(a, m):
            h = 0.0
            for k in range(b, m):
                h += U[a, k] * U[b, k]
            if a == b:
                trace += projection[a, a] * h
                step[a] += h * g[a]
            else:
                trace += (projection[a, b] + projection[b, a]) * h
                step[a] += h * g[b]
                step[b] += h * g[a]
    rows = jacobian.shape[0]
    if rows == 0:
        return w * trace
    # residuals one step ahead, and X = A Li^T (so that A H(s)^-1 A^T = X X^T)
    X = np.zeros((rows, m))
    e = np.empty(rows)
    for r in range(rows):
        s = -rhs[r]
        for a in range(m):
            s += jacobian[r, a] * step[a]
        e[r] = s
        for k in range(m):
            x = 0.0
            for j in range(k + 1):
                x += jacobian[r, j] * Li[k, j]
            X[r, k] = x
    for i in range(rows // 2):
        m00, m01, m11 = 0.0, 0.0, 0.0
        for k in range(m):
            m00 += X[2 * i, k] * X[2 * i, k]
            m01 += X[2 * i, k] * X[2 * i + 1, k]
            m11 += X[2 * i + 1, k] * X[2 * i + 1, k]
        m00, m01, m11 = w * m00, w * m01, w * m11
        freedom_out[i] = 2.0 - m00 - m11
        leverage = 0.5 * (m00 + m11) + math.sqrt((0.5 * (m00 - m11)) ** 2 + m01 * m01)
        if not leverage < max_leverage:
            q_out[i] = math.nan
            continue
        r00, r01, r11 = 1.0 - m00, -m01, 1.0 - m11  # I - M_i
        e0, e1 = e[2 * i], e[2 * i + 1]
        q_out[i] = (r11 * e0 * e0 - 2.0 * r01 * e0 * e1 + r00 * e1 * e1) / (r00 * r11 - r01 * r01)
    return w * trace


@njit
def log_evidence_kernel(information, eta, precisions, precision_means, quadratic_out, logdet_out):
    """Per prior k: ``b^T (Lambda + P_k)^-1 b`` with ``b = eta + P_k mu_k``, and ``log|Lambda + P_k|``.

    The terms of :meth:`vfactor.shape_model.ShapeModel.type_log_evidence` (the
    Laplace evidence of each body type's prior): one Cholesky factorisation and
    one forward substitution per prior, in one compiled loop.

    Args:
        information: (m, m) the observations' information on the shape, ``Lambda`` (1/m^2).
        eta: (m,) their information vector (1/m).
        precisions: (K, m, m) each prior's ``P_k = Sigma_k^-1``.
        precision_means: (K, m) each prior's ``P_k mu_k``.
        quadratic_out: (K,) ``b^T (Lambda + P_k)^-1 b``, written (NaN where ``Lambda + P_k`` is not
            positive definite).
        logdet_out: (K,) ``log|Lambda + P_k|``, written (NaN likewise).
    """
    K, m = precisions.shape[0], precisions.shape[1]
    L = np.empty((m, m))
    y = np.empty(m)
    for c in range(K):
        definite = True
        logdet = 0.0
        for i in range(m):
            for j in range(i + 1):
                s = 0.5 * (information[i, j] + information[j, i]) + 0.5 * (precisions[c, i, j] + precisions[c, j, i])
                for k in range(j):
                    s -= L[i, k] * L[j, k]
                if i == j:
                    if not s > 0.0:
                        definite = False
                        break
                    L[i, i] = math.sqrt(s)
                    logdet += 2.0 * math.log(L[i, i])
                else:
                    L[i, j] = s / L[j, j]
            if not definite:
                break
        if not definite:
            quadratic_out[c] = math.nan
            logdet_out[c] = math.nan
            continue
        quadratic = 0.0
        for i in range(m):
            s = eta[i] + precision_means[c, i]
            for k in range(i):
                s -= L[i, k] * y[k]
            y[i] = s / L[i, i]
            quadratic += y[i] * y[i]
        quadratic_out[c] = quadratic
        logdet_out[c] = logdet
