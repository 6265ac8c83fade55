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

import numpy as np

from vfactor._kernels import truncated_means_kernel

__all__ = ["truncated_means"]


def truncated_means(mu, sigma, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Mean ``m`` of ``N(mu, sigma^2)`` truncated to ``[lo, hi]`` and ``dm/dmu``, elementwise over arrays of one
    shape (broadcast; pixels).

    The compiled :func:`kernels.truncation.truncated_mean` that the projection kernel
    inlines, for NumPy callers. Stable for ``mu`` deep inside the window (``m = mu``,
    slope 1) and many sigmas outside (``m`` at the nearer edge, slope 0). Requires
    ``lo < hi`` and ``sigma > 0``.

    Returns:
        (m, dm/dmu), each of the broadcast shape.
    """
    mu, sigma, lo, hi = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (mu, sigma, lo, hi)))
    m, slope = np.empty(mu.size), np.empty(mu.size)
    truncated_means_kernel(mu.ravel().copy(), sigma.ravel().copy(), lo.ravel().copy(), hi.ravel().copy(), m, slope)
    return m.reshape(mu.shape), slope.reshape(mu.shape)
