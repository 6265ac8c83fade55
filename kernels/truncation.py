"""The mean of a Gaussian truncated to the image and its slope (numba source, compiled ahead of time into
:mod:`vfactor._kernels`).

Why and the formulas: :mod:`vfactor.factors.truncation`. :func:`truncated_mean`
is inlined into the projection kernel (:mod:`kernels.projection`).
"""

from __future__ import annotations

import math

from numba import njit

__all__ = ["truncated_mean", "truncated_means_kernel"]

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)
_SQRT_HALF = math.sqrt(0.5)
_INSIDE_SIGMAS = 8.0  # sigmas from both edges beyond which m = mu and dm/dmu = 1 to double precision


@njit(inline="always")
def truncated_mean(mu, sigma, lo, hi):
    """Mean ``m`` of ``N(mu, sigma^2)`` truncated to ``[lo, hi]`` and ``dm/dmu``.

    Stable for ``mu`` deep inside the window (``m = mu``, slope 1) and many
    sigmas outside (``m`` at the nearer edge, slope 0). Requires ``lo < hi``
    and ``sigma > 0``.

    Returns:
        (m, dm/dmu).
    """
    a_lo = (lo - mu) / sigma
    a_hi = (hi - mu) / sigma
    if a_lo < -_INSIDE_SIGMAS and a_hi > _INSIDE_SIGMAS:  # the shift is below 1e-14 sigma: skip the special functions
        return mu, 1.0
    # Mirror the window so that mu is nearer its upper edge: the mass then
    # comes from the lower tail, which erfc keeps accurate down to 1e-300.
    flip = a_hi + a_lo > 0.0
    if flip:
        a_lo, a_hi = -a_hi, -a_lo
    p = 0.5 * math.erfc(-a_hi * _SQRT_HALF) - 0.5 * math.erfc(-a_lo * _SQRT_HALF)
    if p < 1e-300:  # mu beyond ~37 sigma outside: the kept measurement sits on the edge
        shift, slope = a_hi, 0.0
    else:
        log_p = math.log(p)
        g_lo = math.exp(-0.5 * a_lo * a_lo - _LOG_SQRT_2PI - log_p)  # phi(a_lo) / P
        g_hi = math.exp(-0.5 * a_hi * a_hi - _LOG_SQRT_2PI - log_p)
        shift = g_lo - g_hi
        slope = min(max(1.0 + a_lo * g_lo - a_hi * g_hi - shift * shift, 0.0), 1.0)
    return (mu - sigma * shift if flip else mu + sigma * shift), slope


@njit
def truncated_means_kernel(mu, sigma, lo, hi, m, slope):
    """Fills ``m[i], slope[i] = truncated_mean(mu[i], sigma[i], lo[i], hi[i])`` over (n,) arrays."""
    for i in range(mu.shape[0]):
        m[i], slope[i] = truncated_mean(mu[i], sigma[i], lo[i], hi[i])
