"""Validation of the keypoint network: PCK@alpha for visible and for self-occluded keypoints.

PCK@alpha ("percentage of correct keypoints"): the fraction of the keypoints of
a category whose prediction lies within ``alpha * box_size`` pixels of the
truth. Here the box is the network's square crop, so ``box_size`` is its side
(``alpha = 0.1`` with 128-pixel crops: 12.8 pixels). Predictions are decoded
from the last stack's heatmaps with :func:`vfactor.heatmaps.decode_heatmaps`; a
keypoint not found (peak below ``min_confidence``) counts as wrong. Only
keypoints inside the crop are scored; "visible" and "self-occluded" are the
annotations' flags (a keypoint occluded by another object is in neither).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from vfactor.heatmaps import decode_heatmaps
from vfactor.net.targets import in_crop

__all__ = ["PCKResult", "pck", "decode_batch", "score_predictions"]


@dataclass(frozen=True)
class PCKResult:
    """PCK scores (NaN where a category has no keypoint) and the counts behind them."""

    pck_visible: float
    pck_self_occluded: float
    pck_all: float
    n_visible: int
    n_self_occluded: int
    n_all: int
    alpha: float

    def to_dict(self) -> dict:
        return asdict(self)


def pck(pred, truth, mask, box_size, alpha: float = 0.1) -> tuple[float, int]:
    """Fraction of masked keypoints predicted within ``alpha * box_size`` pixels.

    Args:
        pred: (N, K, 2) predicted pixels (NaN: not found, counts as wrong).
        truth: (N, K, 2) true pixels.
        mask: (N, K) bools, the keypoints to score.
        box_size: scalar or (N,) box sides, pixels.
        alpha: threshold as a fraction of the box size.

    Returns:
        ``(pck, count)``; ``pck`` is NaN when ``count`` is 0.
    """
    pred, truth = np.asarray(pred, float), np.asarray(truth, float)
    mask = np.asarray(mask, bool)
    if pred.shape != truth.shape or pred.shape[:-1] != mask.shape or pred.shape[-1] != 2:
        raise ValueError(f"pck: shapes pred {pred.shape}, truth {truth.shape}, mask {mask.shape} do not match (N, K, 2)")
    box = np.broadcast_to(np.asarray(box_size, float).reshape(-1, 1) if np.ndim(box_size) else float(box_size),
                          mask.shape)
    dist = np.linalg.norm(pred - truth, axis=-1)
    correct = np.where(np.isfinite(dist), dist <= alpha * box, False)
    n = int(mask.sum())
    return (float(correct[mask].mean()) if n else float("nan")), n


def decode_batch(heatmaps: np.ndarray, crop_size: int, min_confidence: float = 0.05) -> np.ndarray:
    """(N, K, h, w) heatmaps of ``crop_size`` crops -> (N, K, 2) keypoints in crop pixels (NaN if not found)."""
    hm = np.asarray(heatmaps)
    roi = (0.0, 0.0, float(crop_size), float(crop_size))
    return np.stack([decode_heatmaps(h, roi=roi, min_confidence=min_confidence).uv for h in hm])


def score_predictions(pred, keypoints, visible, self_occluded, crop_size: int, alpha: float = 0.1) -> PCKResult:
    """PCK of predictions (crop pixels) against annotations, split into visible and self-occluded.

    Args:
        pred, keypoints: (N, K, 2) crop pixels.
        visible, self_occluded: (N, K) flags.
        crop_size: side of the crops (the box size of PCK).
        alpha: threshold fraction.
    """
    kp = np.asarray(keypoints, float)
    inside = np.stack([in_crop(k, crop_size) for k in kp]) if len(kp) else np.zeros(kp.shape[:2], bool)
    vis = np.asarray(visible, bool) & inside
    occ = np.asarray(self_occluded, bool) & inside & ~vis
    p_vis, n_vis = pck(pred, kp, vis, crop_size, alpha)
    p_occ, n_occ = pck(pred, kp, occ, crop_size, alpha)
    p_all, n_all = pck(pred, kp, inside, crop_size, alpha)
    return PCKResult(p_vis, p_occ, p_all, n_vis, n_occ, n_all, float(alpha))
