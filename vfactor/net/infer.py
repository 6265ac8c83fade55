"""Inference: image + vehicle boxes -> 12 keypoints per box in image pixels, confidences, covariances, heatmaps.

:class:`KeypointDetector` crops each box (:func:`vfactor.net.crop.crop_roi`,
grown and squared as the weights' training crops were, see
:class:`vfactor.net.train.TrainConfig`'s ``roi_margin`` / ``roi_square``), runs
the network on the crops in batches, and decodes the last stack's heatmaps with
:func:`vfactor.heatmaps.decode_heatmaps` over the box actually cropped, so
``uv`` and the covariances come out in image pixels (OpenCV convention).
The decoded covariances (the heatmap blobs' spread) are then calibrated to the
network's measured errors with a :class:`vfactor.net.calibrate.CovarianceCalibration`
(by default the one stored in the weights' metadata, see
:mod:`vfactor.net.calibrate`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch

from vfactor.heatmaps import CLIPPED_EXTENSION, DecodedKeypoints, decode_heatmaps, extend_clipped_roi
from vfactor.keypoints import MIRROR_PERMUTATION
from vfactor.net.calibrate import CovarianceCalibration
from vfactor.net.crop import check_roi_in_image, crop_roi, expand_roi
from vfactor.net.model import StackedHourglass, default_weights_path, load_weights, torch_device

#: Left/right swap of the heatmap channels, as a tensor index.
_MIRROR = torch.tensor(MIRROR_PERMUTATION.tolist())

__all__ = ["KeypointDetector", "Detection", "default_weights_path", "benchmark_inference"]


@dataclass(frozen=True)
class Detection:
    """Keypoints of one box, with what they were decoded from.

    Attributes:
        keypoints: :class:`vfactor.heatmaps.DecodedKeypoints` in image pixels
            (covariances calibrated, see :attr:`KeypointDetector.calibration`).
        heatmaps: (12, h, w) float32 heatmaps of the last stack.
        roi: ``(x0, y0, x1, y1)`` box the heatmaps cover (the given box, grown,
            squared and rounded as the detector crops).
    """

    keypoints: DecodedKeypoints
    heatmaps: np.ndarray
    roi: tuple


class KeypointDetector:
    """Runs the keypoint network on boxes of images.

    Args:
        weights: a weights file (:func:`vfactor.net.model.save_weights`), a
            :class:`StackedHourglass`, or None for the shipped weights; a file is
            read by :func:`vfactor.net.model.load_weights` (a bad file raises
            :class:`vfactor.net.model.WeightsError`).
        device: "cpu", "cuda", ...; None: CUDA when available, else the CPU.
        roi_margin, roi_square: how a given box is grown (fraction per side) and
            squared before cropping; None: from the weights' metadata (the
            training crops' framing), else 0 and False.
        min_confidence: heatmap peaks below it count as "not found".
        batch_size: crops per forward pass.
        calibration: maps every decoded covariance to a calibrated one
            (:class:`vfactor.net.calibrate.CovarianceCalibration`, or its dict);
            None: the calibration in the weights' metadata when there is one,
            else the identity (the heatmaps' raw spread). Pass
            ``CovarianceCalibration()`` for the raw covariances.
        flip_test: also run every crop mirrored left-right and average its
            heatmaps, flipped back with left and right keypoints swapped
            (:data:`vfactor.keypoints.MIRROR_PERMUTATION`), with the crop's own:
            twice the network time for less noisy keypoints (on rendered
            two-camera scenes the pose error falls by about 8 %, see
            docs/results.md). The shipped calibration was fitted with it on.
        clipped_extension: a box that stops at the image border (a 2D detector's box clipped by the image) is
            first grown beyond it by this share of its side (:func:`vfactor.heatmaps.extend_clipped_roi`; 0: never),
            as the network was trained on whole vehicles' boxes, which reach beyond the image where it cuts them.

    Attributes:
        calibration: the :class:`vfactor.net.calibrate.CovarianceCalibration` applied.

    Example:
        >>> net = StackedHourglass(num_stacks=1, channels=16, input_size=64)
        >>> det = KeypointDetector(net)
        >>> image = np.zeros((120, 160, 3), np.uint8)
        >>> [d.uv.shape for d in det.detect(image, [(10, 20, 90, 100)])]
        [(12, 2)]
    """

    def __init__(self, weights=None, device=None, roi_margin: float | None = None, roi_square: bool | None = None,
                 min_confidence: float | None = None, batch_size: int = 16,
                 calibration: CovarianceCalibration | dict | None = None, flip_test: bool = True,
                 clipped_extension: float = CLIPPED_EXTENSION):
        device = torch_device(device)
        meta: dict = {}
        if isinstance(weights, StackedHourglass):
            model, self.weights_path = weights, None
        else:
            self.weights_path = weights if weights is not None else default_weights_path()
            model, meta = load_weights(self.weights_path, with_config=True)
        self.model = model.to(device).eval()
        self.device = device
        crop = meta.get("crop", {}) if isinstance(meta.get("crop"), dict) else {}
        self.roi_margin = float(roi_margin if roi_margin is not None else crop.get("margin", 0.0))
        self.roi_square = bool(roi_square if roi_square is not None else crop.get("square", False))
        self.min_confidence = float(min_confidence if min_confidence is not None else meta.get("min_confidence", 0.05))
        if isinstance(batch_size, bool) or not isinstance(batch_size, int) or batch_size < 1:
            raise ValueError(f"batch_size: expected a positive integer, got {batch_size!r}")
        self.batch_size = batch_size
        self.flip_test = bool(flip_test)
        if isinstance(clipped_extension, bool) or not isinstance(clipped_extension, (int, float)) or \
                not np.isfinite(clipped_extension) or clipped_extension < 0:
            raise ValueError(f"clipped_extension: expected a number >= 0, got {clipped_extension!r}")
        self.clipped_extension = float(clipped_extension)
        self.metadata = meta
        if calibration is None:
            calibration = CovarianceCalibration.from_metadata(meta) or CovarianceCalibration()
        elif isinstance(calibration, dict):
            calibration = CovarianceCalibration.from_dict(calibration)
        elif not isinstance(calibration, CovarianceCalibration):
            raise TypeError(f"calibration: expected a CovarianceCalibration, a dict or None, got "
                            f"{type(calibration).__name__}")
        self.calibration = calibration

    @property
    def input_size(self) -> int:
        return self.model.config.input_size

    def crop_box(self, roi) -> tuple:
        """The box cropped for a given ROI (grown, squared and rounded outwards to whole pixels)."""
        box = expand_roi(roi, self.roi_margin, self.roi_square)
        return (float(np.floor(box[0])), float(np.floor(box[1])), float(np.ceil(box[2])), float(np.ceil(box[3])))

    def detect(self, image: np.ndarray, rois: Sequence, return_heatmaps: bool = False):
        """Keypoints of every box of one image.

        Args:
            image: (H, W, 3) uint8 RGB image.
            rois: boxes ``(x0, y0, x1, y1)`` in image pixel edges (a 2D
                detector's boxes); may reach outside the image.
            return_heatmaps: also return the heatmaps.

        Returns:
            A list of :class:`vfactor.heatmaps.DecodedKeypoints` (``uv`` (12, 2)
            image pixels, ``confidence`` (12,), ``covariance`` (12, 2, 2) px^2,
            calibrated),
            one per box; with ``return_heatmaps``, ``(keypoints, heatmaps)``
            with heatmaps (N, 12, h, w) float32.
        """
        dets = self.detect_batch([image], [rois])[0]
        kps = [d.keypoints for d in dets]
        if return_heatmaps:
            size = self.input_size // 4  # the heatmaps' resolution, as detect_batch's empty batch has it
            hm = np.stack([d.heatmaps for d in dets]) if dets else np.zeros((0, 12, size, size), np.float32)
            return kps, hm
        return kps

    def detect_batch(self, images: Sequence[np.ndarray], rois: Sequence[Sequence]) -> list[list[Detection]]:
        """Keypoints of the boxes of several images, all crops batched together.

        Args:
            images: list of (H, W, 3) uint8 RGB images.
            rois: per image, a list of boxes ``(x0, y0, x1, y1)``.

        Returns:
            Per image, a list of :class:`Detection` (keypoints, heatmaps, box), one per box.
        """
        if len(images) != len(rois):
            raise ValueError(f"rois: expected one list of boxes per image ({len(images)}), got {len(rois)}")
        S = self.input_size
        crops, boxes, owner = [], [], []
        for i, (img, boxes_i) in enumerate(zip(images, rois)):
            img = np.asarray(img)
            if img.ndim != 3 or img.shape[2] != 3:
                raise ValueError(f"images[{i}]: expected an (H, W, 3) RGB image, got shape {img.shape}")
            if img.dtype != np.uint8:
                raise ValueError(f"images[{i}]: expected dtype uint8, got {img.dtype}")
            for j, roi in enumerate(boxes_i):
                try:
                    check_roi_in_image(roi, img.shape[1], img.shape[0])
                    box = self.crop_box(extend_clipped_roi(roi, img.shape[1], img.shape[0], self.clipped_extension))
                except ValueError as exc:
                    raise ValueError(f"rois[{i}][{j}]: {exc}") from None
                crop, used = crop_roi(img, box, S)
                crops.append(crop)
                boxes.append(used)
                owner.append(i)
        heatmaps = self.heatmaps(np.stack(crops)) if crops else np.zeros((0, 12, S // 4, S // 4), np.float32)
        out: list[list[Detection]] = [[] for _ in images]
        for hm, box, i in zip(heatmaps, boxes, owner):
            kp = decode_heatmaps(hm, roi=box, min_confidence=self.min_confidence)
            if not self.calibration.is_identity:
                size = (box[2] - box[0], box[3] - box[1])
                kp = DecodedKeypoints(kp.uv, kp.confidence, self.calibration.apply(kp.covariance, kp.confidence, size))
            out[i].append(Detection(kp, hm, box))
        return out

    def heatmaps(self, crops: np.ndarray) -> np.ndarray:
        """(N, S, S, 3) uint8 crops -> (N, 12, S/4, S/4) float32 heatmaps of the last stack.

        With ``flip_test``, the mean of the crop's heatmaps and its mirror image's
        (flipped back, left and right keypoints swapped).
        """
        crops = np.asarray(crops)
        S = self.input_size
        if crops.ndim != 4 or crops.shape[1:] != (S, S, 3):
            raise ValueError(f"crops: expected shape (N, {S}, {S}, 3), got {crops.shape}")
        out = []
        with torch.inference_mode():
            for i in range(0, len(crops), self.batch_size):
                x = torch.from_numpy(np.ascontiguousarray(crops[i : i + self.batch_size])).permute(0, 3, 1, 2)
                x = x.float().div(255.0).to(self.device)
                if not self.flip_test:
                    out.append(self.model(x)[-1].float().cpu().numpy())
                    continue
                # Heatmap column c of the mirrored crop is column w - 1 - c of the crop (pixel centres).
                both = self.model(torch.cat([x, x.flip(3)]))[-1].float()
                direct, mirrored = both[: len(x)], both[len(x):].flip(3)[:, _MIRROR]
                out.append((0.5 * (direct + mirrored)).cpu().numpy())
        return np.concatenate(out) if out else np.zeros((0, self.model.config.num_keypoints, S // 4, S // 4),
                                                          np.float32)


def benchmark_inference(model: StackedHourglass, batch_sizes=(1, 16), repeats: int = 20, warmup: int = 3,
                        device="cpu", decode: bool = False) -> dict[int, float]:
    """Milliseconds per crop of the forward pass (best of ``repeats``) at each batch size.

    With ``decode``, the heatmap decoding (:func:`vfactor.heatmaps.decode_heatmaps`) is timed too.
    The minimum over repeats is reported: on a shared machine it is the least disturbed figure.
    """
    model = model.to(device).eval()
    S = model.config.input_size
    gen = torch.Generator().manual_seed(0)
    result = {}
    with torch.inference_mode():
        for b in batch_sizes:
            x = torch.rand(b, 3, S, S, generator=gen).to(device)
            best = float("inf")
            for r in range(warmup + repeats):
                t = time.perf_counter()
                hm = model(x)[-1]
                if device != "cpu" and torch.cuda.is_available():
                    torch.cuda.synchronize()
                if decode:
                    for h in hm.cpu().numpy():
                        decode_heatmaps(h)
                dt = time.perf_counter() - t
                if r >= warmup:
                    best = min(best, dt)
            result[int(b)] = 1000.0 * best / b
    return result
