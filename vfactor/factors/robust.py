"""Robust losses applied per observation inside vfactor's batched factors.

GTSAM's ``noiseModel.Robust`` weighs a whole factor with one weight; the
projection factor holds many observations, so it applies the loss to each
2-vector itself. For a whitened residual ``e`` with norm ``n`` it returns
``r = s(n) e`` with ``s(n) = sqrt(2 rho(n)) / n``, so that ``0.5 |r|^2 = rho(n)``
exactly: Gauss-Newton on ``r`` minimises the robust cost itself, and the
Jacobian ``dr/de = s I + (s'(n) / n) e e^T`` is exact (see docs/factors.md).

Losses (``k`` is the threshold in whitened units, i.e. in sigmas):

* ``none``: ``rho = n^2 / 2``
* ``huber``: ``n^2 / 2`` for ``n <= k``, else ``k n - k^2 / 2``
* ``cauchy``: ``k^2 / 2 * log(1 + n^2 / k^2)``
* ``geman_mcclure``: ``k^2 / 2 * n^2 / (k^2 + n^2)``
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vfactor._kernels import robust_scale

__all__ = ["RobustLoss", "LOSSES", "robust_scale"]

LOSSES = ("none", "huber", "cauchy", "geman_mcclure")


@dataclass(frozen=True)
class RobustLoss:
    """A robust loss ``rho`` on whitened residual norms.

    Attributes:
        name: one of :data:`LOSSES`.
        threshold: ``k``, in whitened units (sigmas); ignored by ``none``.
    """

    name: str = "cauchy"
    threshold: float = 2.5

    def __post_init__(self):
        if self.name not in LOSSES:
            raise ValueError(f"robust loss name: expected one of {LOSSES}, got {self.name!r}")
        if not np.isfinite(self.threshold) or self.threshold <= 0:
            raise ValueError(f"robust loss threshold: expected a positive number, got {self.threshold!r}")

    @property
    def id(self) -> int:
        """The loss's index in :data:`LOSSES`, as the compiled :func:`robust_scale` takes it."""
        return LOSSES.index(self.name)

    def rho(self, n: np.ndarray) -> np.ndarray:
        """The loss of residual norms ``n`` (>= 0)."""
        k = self.threshold
        if self.name == "none":
            return 0.5 * n * n
        if self.name == "huber":
            return np.where(n <= k, 0.5 * n * n, k * n - 0.5 * k * k)
        if self.name == "cauchy":
            return 0.5 * k * k * np.log1p((n / k) ** 2)
        return 0.5 * k * k * n * n / (k * k + n * n)

    def weight(self, n: np.ndarray) -> np.ndarray:
        """IRLS weight ``rho'(n) / n`` in [0, 1] (1 for a perfect inlier)."""
        k = self.threshold
        if self.name == "none":
            return np.ones_like(n)
        if self.name == "huber":
            return np.where(n <= k, 1.0, k / np.maximum(n, 1e-300))
        if self.name == "cauchy":
            return 1.0 / (1.0 + (n / k) ** 2)
        return (k * k / (k * k + n * n)) ** 2

    def scale(self, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Returns ``s(n) = sqrt(2 rho(n)) / n`` and ``s'(n) / n`` (stable at ``n -> 0``)."""
        k = self.threshold
        if self.name == "none":
            return np.ones_like(n), np.zeros_like(n)
        if self.name == "huber":
            out = n > k
            safe = np.where(out, n, 2 * k)
            root = np.sqrt(2 * k * safe - k * k)
            s = np.where(out, root / safe, 1.0)
            ds = np.where(out, (k * k - k * safe) / (safe**3 * root), 0.0)
            return s, ds
        if self.name == "cauchy":
            u = (n / k) ** 2
            if u.min() > 1e-6:  # the common case, without masks
                log_term = np.log1p(u)
                ratio = log_term / u  # s^2
                dratio_du = (u / (1 + u) - log_term) / (u * u)
            else:
                small = u < 1e-6
                safe_u = np.where(small, 1.0, u)
                log_term = np.log1p(safe_u)
                ratio = np.where(small, 1.0 - 0.5 * u, log_term / safe_u)
                dratio_du = np.where(small, -0.5 + 2.0 * u / 3.0, (safe_u / (1 + safe_u) - log_term) / safe_u**2)
            s = np.sqrt(ratio)
            # ds/dn = d(s^2)/du * du/dn / (2 s) with du/dn = 2 n / k^2; we return ds/dn / n.
            return s, dratio_du / (k * k * s)
        # geman_mcclure: s = k / sqrt(k^2 + n^2)
        denom = k * k + n * n
        s = k / np.sqrt(denom)
        return s, -k / denom**1.5
