"""Small dense linear algebra for the per-vehicle matrices (42 x 42: pose and shape), single-threaded by construction.

NumPy's LAPACK runs these sizes through a multi-threaded BLAS; on a machine whose cores are busy (a shared server,
several solves in parallel) its threads wait for one another, and a 42 x 42 ``numpy.linalg.eigh`` took 1.2 ms on
average (tails of several ms) where it takes 0.19 ms alone: a third of a whole one-frame solve
(docs/performance.md, "Small matrices off the threaded BLAS").

:func:`symmetric_eigen_kernel`: the eigen-decomposition of a symmetric matrix by Householder reduction to a
tridiagonal matrix, then the implicit QL iteration with Wilkinson-type shifts (Golub and Van Loan, *Matrix
Computations*, 4th ed., sections 8.3.1 and 8.3.4; Wilkinson and Reinsch, *Handbook for Automatic Computation II*),
accumulating the orthogonal transformations into the eigenvectors.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["symmetric_eigen_kernel"]

#: QL iterations allowed per eigenvalue (it converges cubically: 2-3 are usual).
_MAX_SWEEPS = 60


@njit
def symmetric_eigen_kernel(A, w_out, V_out):
    """Eigenvalues and eigenvectors of the symmetric (n, n) ``A`` (only its lower triangle is read).

    Args:
        A: (n, n) float64, symmetric; not modified.
        w_out: (n,) the eigenvalues, ascending.
        V_out: (n, n) the orthonormal eigenvectors, as columns in the order of ``w_out``: ``A = V diag(w) V^T``.

    Returns:
        0 on success; 1 when an eigenvalue did not converge in :data:`_MAX_SWEEPS` iterations (the outputs are then
        not an eigen-decomposition).
    """
    n = A.shape[0]
    T = np.empty((n, n))  # working copy, made symmetric from the lower triangle
    for i in range(n):
        for j in range(i + 1):
            T[i, j] = A[i, j]
            T[j, i] = A[i, j]
    Q = V_out
    for i in range(n):
        for j in range(n):
            Q[i, j] = 1.0 if i == j else 0.0
    v = np.empty(n)
    p = np.empty(n)
    # Householder reduction: T <- H_k T H_k zeroes column k below the subdiagonal; Q <- Q H_k.
    for k in range(n - 2):
        norm = 0.0
        for i in range(k + 1, n):
            norm += T[i, k] * T[i, k]
        norm = math.sqrt(norm)
        if norm == 0.0:
            continue
        alpha = -norm if T[k + 1, k] > 0.0 else norm
        vnorm2 = 0.0
        for i in range(k + 1, n):
            v[i] = T[i, k]
        v[k + 1] -= alpha
        for i in range(k + 1, n):
            vnorm2 += v[i] * v[i]
        if vnorm2 == 0.0:
            continue
        scale = 1.0 / math.sqrt(vnorm2)
        for i in range(k + 1, n):
            v[i] *= scale
        # H T H = T - 2 (v q^T + q v^T) on the trailing block, with p = T v, K = v^T p, q = p - K v
        K = 0.0
        for i in range(k + 1, n):
            s = 0.0
            for j in range(k + 1, n):
                s += T[i, j] * v[j]
            p[i] = s
            K += v[i] * s
        for i in range(k + 1, n):
            p[i] -= K * v[i]
        for i in range(k + 1, n):
            for j in range(k + 1, n):
                T[i, j] -= 2.0 * (v[i] * p[j] + p[i] * v[j])
        T[k + 1, k] = alpha
        T[k, k + 1] = alpha
        for i in range(k + 2, n):
            T[i, k] = 0.0
            T[k, i] = 0.0
        for i in range(n):  # Q <- Q H: Q[:, k+1:] -= 2 (Q[:, k+1:] v) v^T
            s = 0.0
            for j in range(k + 1, n):
                s += Q[i, j] * v[j]
            s *= 2.0
            for j in range(k + 1, n):
                Q[i, j] -= s * v[j]
    d = w_out
    e = np.zeros(n)  # e[i] couples d[i] and d[i + 1]; e[n - 1] = 0
    for i in range(n):
        d[i] = T[i, i]
    for i in range(n - 1):
        e[i] = T[i + 1, i]
    # Implicit QL: for each l, chase the shifted QL step over the unreduced block l..m until e[l] vanishes.
    eps = 2.220446049250313e-16
    for l in range(n):
        sweeps = 0
        while True:
            m = l
            while m < n - 1:
                if abs(e[m]) <= eps * (abs(d[m]) + abs(d[m + 1])):
                    break
                m += 1
            if m == l:
                break
            sweeps += 1
            if sweeps > _MAX_SWEEPS:
                return 1
            g = (d[l + 1] - d[l]) / (2.0 * e[l])
            r = math.hypot(g, 1.0)
            g = d[m] - d[l] + e[l] / (g + (r if g >= 0.0 else -r))  # d[m] - shift
            s = 1.0
            c = 1.0
            shift_sum = 0.0
            underflow = False
            i = m - 1
            while i >= l:
                f = s * e[i]
                b = c * e[i]
                r = math.hypot(f, g)
                e[i + 1] = r
                if r == 0.0:  # the block splits: restart on the smaller one
                    d[i + 1] -= shift_sum
                    e[m] = 0.0
                    underflow = True
                    break
                s = f / r
                c = g / r
                g = d[i + 1] - shift_sum
                r = (d[i] - g) * s + 2.0 * c * b
                shift_sum = s * r
                d[i + 1] = g + shift_sum
                g = c * r - b
                for k in range(n):  # the rotation of coordinates i, i + 1 into the eigenvectors
                    f = Q[k, i + 1]
                    Q[k, i + 1] = s * Q[k, i] + c * f
                    Q[k, i] = c * Q[k, i] - s * f
                i -= 1
            if underflow:
                continue
            d[l] -= shift_sum
            e[l] = g
            e[m] = 0.0
    # ascending order (selection sort of the columns: n is small)
    for i in range(n - 1):
        k = i
        for j in range(i + 1, n):
            if d[j] < d[k]:
                k = j
        if k != i:
            t = d[i]
            d[i] = d[k]
            d[k] = t
            for row in range(n):
                t = Q[row, i]
                Q[row, i] = Q[row, k]
                Q[row, k] = t
    return 0
