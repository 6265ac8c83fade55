"""Synthetic keypoint crops for the network tests: one coloured blob per keypoint at a known pixel."""

from __future__ import annotations

import numpy as np

#: One colour per keypoint (RGB), far enough apart to be told apart after augmentation.
COLOURS = np.array(
    [
        [255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 0], [255, 0, 255], [0, 255, 255],
        [128, 0, 0], [0, 128, 0], [0, 0, 128], [128, 128, 0], [128, 0, 128], [0, 128, 128],
    ],
    dtype=np.uint8,
)


def blob_image(keypoints, size: int, radius: float = 2.5, background: int = 40) -> np.ndarray:
    """(size, size, 3) uint8 grey image with a disc of ``COLOURS[k]`` at each finite keypoint k."""
    img = np.full((size, size, 3), background, np.uint8)
    rows, cols = np.mgrid[0:size, 0:size]
    for k, (u, v) in enumerate(np.asarray(keypoints, float)):
        if np.isfinite(u) and np.isfinite(v):
            img[(cols - u) ** 2 + (rows - v) ** 2 <= radius**2] = COLOURS[k]
    return img


def spread_keypoints(rng: np.random.Generator, size: int, lo: float = 0.1, hi: float = 0.9) -> np.ndarray:
    """(12, 2) random keypoints in ``[lo, hi] * size``, one per cell of a 4x4 grid (so blobs never overlap)."""
    cells = rng.permutation(16)[:12]
    step = (hi - lo) * size / 4
    corner = lo * size + np.stack([cells % 4, cells // 4], axis=1) * step
    return corner + rng.uniform(0.25, 0.75, size=(12, 2)) * step


def blob_dataset(n: int, size: int = 64, seed: int = 0, outside: float = 0.05):
    """Arrays ``images, keypoints, visible, self_occluded`` of ``n`` blob crops.

    Keypoints are uniform in the crop (a fraction ``outside`` of them pushed out
    of it); a third are flagged self-occluded, the rest visible.
    """
    rng = np.random.default_rng(seed)
    kp = np.stack([spread_keypoints(rng, size) for _ in range(n)])
    out = rng.random((n, 12)) < outside
    kp[out] += size  # beyond the right/bottom edge
    occ = rng.random((n, 12)) < 1 / 3
    vis = ~occ & ~out
    images = np.stack([blob_image(k, size) for k in kp])
    return images, kp.astype(np.float32), vis, occ & ~out
