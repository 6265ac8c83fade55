"""The robust losses' scale ``s(n)`` of one residual norm (numba source, compiled ahead of time into
:mod:`vfactor._kernels`).

The losses, and ``r = s(n) e`` with ``0.5 |r|^2 = rho(n)``: :mod:`vfactor.factors.robust`.
"""

from __future__ import annotations

import math

from numba import njit

__all__ = ["robust_scale"]


@njit
def robust_scale(loss_id, k, n):
    """``s(n)`` and ``s'(n) / n`` of one residual norm ``n``; ``loss_id`` is :attr:`vfactor.factors.robust.RobustLoss.id`.

    For the factors' kernels (and :mod:`vfactor.factors.shape_prior`, through
    :mod:`vfactor._kernels`); :meth:`vfactor.factors.robust.RobustLoss.scale` is
    the same in NumPy, the tests' reference. The losses: :mod:`vfactor.factors.robust`.
    """
    if loss_id == 0:
        return 1.0, 0.0
    if loss_id == 1:
        if n <= k:
            return 1.0, 0.0
        root = math.sqrt(2.0 * k * n - k * k)
        return root / n, (k * k - k * n) / (n * n * n * root)
    if loss_id == 2:
        u = (n / k) ** 2
        if u < 1e-6:
            ratio = 1.0 - 0.5 * u
            dratio = -0.5 + 2.0 * u / 3.0
        else:
            log_term = math.log1p(u)
            ratio = log_term / u
            dratio = (u / (1.0 + u) - log_term) / (u * u)
        s = math.sqrt(ratio)
        return s, dratio / (k * k * s)
    denom = k * k + n * n
    return k / math.sqrt(denom), -k / denom**1.5
