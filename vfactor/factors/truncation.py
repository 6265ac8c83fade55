"""Keypoints measured near the image border: the mean of a Gaussian truncated to the image.

A detector that reports keypoints only inside the image loses the noisy pixels
pushed across the border, so the keypoints it keeps near the border lie, on
average, inside their true projections, and least squares on them shrinks a
vehicle that leaves a view (docs/factors.md, "Truncation at the image
border"). The projection factor therefore compares a measurement that comes
with a window (:attr:`KeypointObservations.window`) with the mean of a kept
measurement, per image axis::

    a_lo = (lo - mu) / sigma,  a_hi = (hi - mu) / sigma,  P = Phi(a_hi) - Phi(a_lo)
    m(mu)   = mu + sigma (phi(a_lo) - phi(a_hi)) / P
    dm/dmu  = 1 + (a_lo phi(a_lo) - a_hi phi(a_hi)) / P - ((phi(a_lo) - phi(a_hi)) / P)^2

(``dm/dmu`` is the truncated variance over ``sigma^2``, in ``[0, 1]``). A few
sigmas inside the window ``m = mu`` and ``dm/dmu = 1``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["truncated_mean", "truncated_means"]

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)
_SQRT_HALF = math.sqrt(0.5)
_INSIDE_SIGMAS = 8.0  # sigmas from both edges beyond which m = mu and dm/dmu = 1 to double precision


@njit(cache=True, inline="always")
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


@njit(cache=True)
def _truncated_means(mu, sigma, lo, hi, m, slope):
    for i in range(mu.shape[0]):
        m[i], slope[i] = truncated_mean(mu[i], sigma[i], lo[i], hi[i])


def truncated_means(mu, sigma, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """:func:`truncated_mean` elementwise over arrays of one shape (broadcast), for NumPy callers."""
    mu, sigma, lo, hi = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (mu, sigma, lo, hi)))
    m, slope = np.empty(mu.size), np.empty(mu.size)
    _truncated_means(mu.ravel().copy(), sigma.ravel().copy(), lo.ravel().copy(), hi.ravel().copy(), m, slope)
    return m.reshape(mu.shape), slope.reshape(mu.shape)
