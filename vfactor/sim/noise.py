"""Keypoint detector noise: what a keypoint CNN makes of the true projections.

:class:`NoiseModel` defaults to a paper-like setting: Gaussian pixel noise whose
standard deviation is a fraction of the vehicle's size in the image (the
diagonal of the box around its 12 projected keypoints), larger for
self-occluded keypoints; heatmap-like confidences; and a few gross errors:
outliers, left/right label swaps and missed keypoints.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from vfactor.keypoints import LEFT_RIGHT_PAIRS, NUM_KEYPOINTS

__all__ = ["NoiseModel", "NoisyKeypoints", "corrupt_keypoints", "box_diagonal"]


@dataclass(frozen=True)
class NoiseModel:
    """Noise of simulated keypoint detections (defaults: the paper-like setting).

    Attributes:
        relative_sigma: pixel noise standard deviation (per axis) as a fraction of
            the diagonal of the box around the vehicle's 12 projected keypoints.
        occluded_factor: the standard deviation is multiplied by this for
            occluded keypoints.
        confidence_visible: ``(low, high)`` of the uniform confidence of a visible keypoint.
        confidence_occluded: ``(low, high)`` of the uniform confidence of an occluded keypoint.
        outlier_rate: probability that a keypoint is replaced by a uniform random
            pixel in the keypoint box grown by ``outlier_box_growth`` (with a
            visible keypoint's confidence).
        outlier_box_growth: relative growth of the box's width and height for outliers
            (0.5: the box is 1.5 times as wide and as tall, same centre).
        swap_rate: probability, per left/right pair per camera, that the two
            keypoints swap labels.
        missing_rate: probability that a keypoint is not detected (confidence 0,
            pixel NaN).
    """

    relative_sigma: float = 0.03
    occluded_factor: float = 2.0
    confidence_visible: tuple[float, float] = (0.7, 1.0)
    confidence_occluded: tuple[float, float] = (0.3, 0.6)
    outlier_rate: float = 0.05
    outlier_box_growth: float = 0.5
    swap_rate: float = 0.03
    missing_rate: float = 0.05

    @classmethod
    def noiseless(cls) -> "NoiseModel":
        """Exact projections with random confidences: no pixel noise, outliers, swaps or misses."""
        return cls(relative_sigma=0.0, outlier_rate=0.0, swap_rate=0.0, missing_rate=0.0)

    @classmethod
    def gaussian_only(cls, relative_sigma: float = 0.03) -> "NoiseModel":
        """Pixel noise only: no outliers, swaps or misses."""
        return cls(relative_sigma=relative_sigma, outlier_rate=0.0, swap_rate=0.0, missing_rate=0.0)

    def to_dict(self) -> dict:
        """The model as a scenario file's ``noise`` entry."""
        out = {}
        for f in fields(self):
            value = getattr(self, f.name)
            out[f.name] = list(value) if isinstance(value, tuple) else value
        return out


@dataclass
class NoisyKeypoints:
    """Detected keypoints of one vehicle in one camera, and what the noise did.

    Every array is indexed by keypoint label (the fixed order).

    Attributes:
        keypoints: (12, 2) detected pixels ``(u, v)``; NaN where missing.
        confidence: (12,) in [0, 1]; 0 where missing.
        sigma_px: (12,) standard deviation of the Gaussian noise of the
            measurement now under each label, pixels.
        outlier: (12,) the measurement under this label is a uniform outlier.
        swapped: (12,) the label was swapped with its left/right partner.
        missing: (12,) not detected (missed at random, outside the image or behind the camera).
    """

    keypoints: np.ndarray
    confidence: np.ndarray
    sigma_px: np.ndarray
    outlier: np.ndarray
    swapped: np.ndarray
    missing: np.ndarray


def box_diagonal(uv: np.ndarray) -> float:
    """Diagonal of the axis-aligned box around pixels (N, 2), ignoring NaN rows."""
    uv = np.asarray(uv, dtype=float)
    uv = uv[np.all(np.isfinite(uv), axis=1)]
    if len(uv) < 2:
        return 0.0
    return float(np.linalg.norm(uv.max(0) - uv.min(0)))


def _inside(uv: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """(N,) whether pixels lie inside the image (pixel centres at integers, edges at -0.5)."""
    w, h = image_size
    return (uv[:, 0] >= -0.5) & (uv[:, 0] <= w - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= h - 0.5)


def corrupt_keypoints(
    uv_true: np.ndarray,
    occluded: np.ndarray,
    noise: NoiseModel,
    rng: np.random.Generator,
    image_size: tuple[int, int] | None = None,
    in_front: np.ndarray | None = None,
) -> NoisyKeypoints:
    """Turns true projections into detections.

    In order: Gaussian pixel noise (``relative_sigma`` times the keypoint box
    diagonal, times ``occluded_factor`` where occluded) and confidences; outliers;
    left/right swaps; random misses; then every keypoint whose true projection
    is outside the image or behind the camera (the detector cannot see it, even
    as an outlier or under a swapped label), or whose noisy pixel falls outside
    the image, is missing too. So a vehicle that partly leaves the image keeps
    only its keypoints inside, and one entirely outside gives nothing. The same number of random draws is made
    whatever the rates, so that changing a rate leaves the other draws alone.

    Args:
        uv_true: (12, 2) true projections, pixels.
        occluded: (12,) which keypoints are hidden from this camera.
        noise: the noise model.
        rng: random generator (the only source of randomness).
        image_size: ``(width, height)``; keypoints outside (truly or after noise) are missing. None: no limit.
        in_front: (12,) whether each true point is in front of the camera; False means missing.

    Returns:
        :class:`NoisyKeypoints`.
    """
    uv_true = np.asarray(uv_true, dtype=float)
    occluded = np.asarray(occluded, dtype=bool)
    if uv_true.shape != (NUM_KEYPOINTS, 2):
        raise ValueError(f"uv_true: expected shape (12, 2), got {uv_true.shape}")
    if occluded.shape != (NUM_KEYPOINTS,):
        raise ValueError(f"occluded: expected shape (12,), got {occluded.shape}")
    in_front = np.ones(NUM_KEYPOINTS, bool) if in_front is None else np.asarray(in_front, dtype=bool)

    # Fixed draws, whatever the rates.
    gauss = rng.standard_normal((NUM_KEYPOINTS, 2))
    u_conf = rng.random(NUM_KEYPOINTS)
    u_outlier = rng.random(NUM_KEYPOINTS)
    u_outlier_px = rng.random((NUM_KEYPOINTS, 2))
    u_swap = rng.random(len(LEFT_RIGHT_PAIRS))
    u_missing = rng.random(NUM_KEYPOINTS)

    finite = in_front & np.all(np.isfinite(uv_true), axis=1)
    box_lo = uv_true[finite].min(0) if finite.any() else np.zeros(2)
    box_hi = uv_true[finite].max(0) if finite.any() else np.zeros(2)
    diagonal = float(np.linalg.norm(box_hi - box_lo))

    sigma = noise.relative_sigma * diagonal * np.where(occluded, noise.occluded_factor, 1.0)
    uv = uv_true + gauss * sigma[:, None]
    lo = np.where(occluded, noise.confidence_occluded[0], noise.confidence_visible[0])
    hi = np.where(occluded, noise.confidence_occluded[1], noise.confidence_visible[1])
    confidence = lo + u_conf * (hi - lo)

    outlier = u_outlier < noise.outlier_rate
    centre, half = 0.5 * (box_lo + box_hi), 0.5 * (box_hi - box_lo) * (1.0 + noise.outlier_box_growth)
    uv[outlier] = (centre - half) + u_outlier_px[outlier] * (2.0 * half)
    lo_v, hi_v = noise.confidence_visible
    confidence[outlier] = lo_v + u_conf[outlier] * (hi_v - lo_v)
    sigma = np.where(outlier, np.nan, sigma)

    # Whether the camera can see where each measurement comes from: in front and inside the image.
    seeable = finite.copy()
    if image_size is not None:
        seeable &= _inside(np.where(finite[:, None], uv_true, 0.0), image_size)

    swapped = np.zeros(NUM_KEYPOINTS, bool)
    for (left, right), u in zip(LEFT_RIGHT_PAIRS, u_swap):
        if u < noise.swap_rate:
            order = [right, left]
            for array in (uv, confidence, sigma, outlier, seeable):
                array[[left, right]] = array[order]
            swapped[[left, right]] = True

    missing = (u_missing < noise.missing_rate) | ~seeable
    if image_size is not None:
        missing |= ~_inside(uv, image_size)
    uv[missing] = np.nan
    confidence[missing] = 0.0
    return NoisyKeypoints(uv, confidence, sigma, outlier, swapped, missing)
