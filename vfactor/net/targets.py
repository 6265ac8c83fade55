"""Training targets: one Gaussian heatmap per keypoint and a per-keypoint loss weight (numpy only).

Every annotated keypoint gets a target, the self-occluded ones too (the paper
annotates and predicts them): an isotropic Gaussian of standard deviation
``sigma`` *heatmap* pixels, peak 1, rendered with
:func:`vfactor.heatmaps.render_gaussian_heatmap` at the keypoint mapped from
crop pixels to heatmap pixels (:func:`vfactor.heatmaps.image_to_heatmap` with
the whole crop as the ROI).

Weights (:func:`keypoint_weights`): 0 for a keypoint that is missing (NaN) or
outside the crop (its centre beyond the crop's edges by more than ``margin``
crop pixels), where the network cannot see it and its heatmap target is all
zeros or a clipped blob; otherwise 1, or ``self_occluded_weight`` for a
self-occluded keypoint.
"""

from __future__ import annotations

import numpy as np

from vfactor.heatmaps import image_to_heatmap, render_gaussian_heatmap

__all__ = ["heatmap_targets", "keypoint_weights", "in_crop"]


def in_crop(keypoints, crop_size: int, margin: float = 0.0) -> np.ndarray:
    """(K,) True where a keypoint (crop pixels) is finite and inside the crop.

    Inside means within the crop's pixel edges ``[-0.5, crop_size - 0.5]``
    grown by ``margin`` pixels on each side.
    """
    kp = np.asarray(keypoints, dtype=float)
    if kp.ndim != 2 or kp.shape[1] != 2:
        raise ValueError(f"keypoints: expected shape (K, 2), got {kp.shape}")
    lo, hi = -0.5 - margin, crop_size - 0.5 + margin
    finite = np.all(np.isfinite(kp), axis=1)
    with np.errstate(invalid="ignore"):
        inside = np.all((kp >= lo) & (kp <= hi), axis=1)
    return finite & inside


def heatmap_targets(keypoints, crop_size: int, heatmap_size: int, sigma: float = 1.0) -> np.ndarray:
    """Gaussian heatmap targets for all keypoints of one crop.

    Args:
        keypoints: (K, 2) keypoints ``(u, v)`` in crop pixels (OpenCV centre
            convention); NaN rows (missing annotations) give all-zero heatmaps.
        crop_size: side of the square crop, pixels.
        heatmap_size: side of the square heatmaps (``crop_size / 4`` for
            :class:`vfactor.net.model.StackedHourglass`).
        sigma: standard deviation of the Gaussians, heatmap pixels (> 0).

    Returns:
        (K, heatmap_size, heatmap_size) float32 targets with peak 1 at each
        keypoint (lower when the keypoint falls between pixel centres).

    Example:
        >>> t = heatmap_targets([[64.0, 32.0]], 128, 32)
        >>> [int(i) for i in np.unravel_index(t[0].argmax(), t[0].shape)]  # (row, col): y = (32 + 0.5) / 4 - 0.5
        [8, 16]
    """
    kp = np.asarray(keypoints, dtype=float)
    if kp.ndim != 2 or kp.shape[1] != 2:
        raise ValueError(f"keypoints: expected shape (K, 2), got {kp.shape}")
    if not np.isfinite(sigma) or sigma <= 0:
        raise ValueError(f"sigma: expected a number > 0 (heatmap pixels), got {sigma!r}")
    shape = (int(heatmap_size), int(heatmap_size))
    xy = image_to_heatmap(kp, (0.0, 0.0, float(crop_size), float(crop_size)), shape)
    cov = np.eye(2) * float(sigma) ** 2
    out = np.zeros((len(kp),) + shape, dtype=np.float32)
    # Beyond 4 sigma outside the heatmap the Gaussian is < 3e-4 everywhere on it: skip.
    reach = 4.0 * sigma
    for k, mu in enumerate(xy):
        if not np.all(np.isfinite(mu)):
            continue
        if mu[0] < -reach or mu[1] < -reach or mu[0] > shape[1] - 1 + reach or mu[1] > shape[0] - 1 + reach:
            continue
        out[k] = render_gaussian_heatmap(mu, cov, shape)
    return out


def keypoint_weights(
    keypoints,
    crop_size: int,
    self_occluded=None,
    self_occluded_weight: float = 1.0,
    margin: float = 0.0,
) -> np.ndarray:
    """(K,) float32 loss weights: 0 outside the crop or missing, else 1 (``self_occluded_weight`` if self-occluded).

    Args:
        keypoints: (K, 2) crop pixels.
        crop_size: side of the crop, pixels.
        self_occluded: (K,) bools, or None (none self-occluded).
        self_occluded_weight: weight of a self-occluded keypoint inside the crop
            (1: trained like the visible ones, as in the paper).
        margin: see :func:`in_crop`.
    """
    w = in_crop(keypoints, crop_size, margin).astype(np.float32)
    if self_occluded is not None:
        so = np.asarray(self_occluded, dtype=bool)
        if so.shape != w.shape:
            raise ValueError(f"self_occluded: expected shape {w.shape}, got {so.shape}")
        w[so] *= np.float32(self_occluded_weight)
    return w
