"""Boxes the image border clipped, replaced by the box of the vehicle the solve found: the keypoints found again.

A 2D detector's box of a vehicle the image border cuts stops at the border,
and the keypoint network, trained on whole-vehicle boxes, then puts the
keypoints it cannot see inside it (docs/network.md, "Boxes clipped by the
image border"). Once the scene is solved, each such vehicle's 3D box
(:class:`vfactor.box.Box`, from its wireframe and body type) is known roughly;
projected into the camera, it gives the whole vehicle's box, beyond the image
where the vehicle is. :func:`amodal_boxes` replaces the clipped boxes by those
and makes their detections box-only again, so that
:func:`vfactor.net.pipeline.detect_scene` finds their keypoints from the whole
box; the scene is then solved again (:func:`redetect_clipped` does the first
two steps).

A box is replaced only where the projected box agrees with the detector's
where both can be seen: the part of it inside the image overlaps the clipped
box by :data:`MIN_AGREEMENT` (intersection over union) or more, and at least
:data:`MIN_INSIDE` of it lies inside the image. A vehicle the solve did not
find, or found elsewhere, keeps its box.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from vfactor.box import Box
from vfactor.camera import Camera
from vfactor.formats.common import box_corners
from vfactor.heatmaps import clip_roi_to_image, clipped_by_border
from vfactor.observations import Scene
from vfactor.result import FrameResult

__all__ = ["BODY_SHARE", "MIN_AGREEMENT", "MIN_INSIDE", "projected_box", "amodal_boxes", "redetect_clipped"]

#: Share of the width and height of a 3D box's image box that the vehicle's body covers: the box's corners reach
#: beyond the rounded body (roof, bumpers, wheel arches). Median over the 242 whole (unclipped) detections of two
#: rendered track scenes (`tracks_3veh` 251, `tracks_3cam` 252), their 3D boxes tracked from the network's keypoints:
#: the projected box was 1.18x the rendered vehicle's box wide and 1.22x high, centred on it to 1 % of its side.
BODY_SHARE = (1.0 / 1.18, 1.0 / 1.22)
#: A clipped box is replaced only where the projected box's part inside the image overlaps it at least this much
#: (intersection over union).
MIN_AGREEMENT = 0.5
#: ... and where at least this share of the projected box lies inside the image (the network needs a quarter,
#: :func:`vfactor.net.crop.check_roi_in_image`).
MIN_INSIDE = 0.3


def projected_box(camera: Camera, box: Box) -> tuple[float, float, float, float] | None:
    """The image box ``(x0, y0, x1, y1)`` (pixel edges; it may reach beyond the image) of the vehicle whose 3D box
    is ``box`` (world frame): the box of its eight corners' pixels shrunk about its centre to :data:`BODY_SHARE`;
    None where a corner is not in front of the camera."""
    uv, depth = camera.project(box_corners(box))
    if not (np.all(depth > 0) and np.all(np.isfinite(uv))):
        return None
    x0, y0 = uv.min(axis=0) - 0.5
    x1, y1 = uv.max(axis=0) + 0.5
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    half_w, half_h = (x1 - x0) / 2 * BODY_SHARE[0], (y1 - y0) / 2 * BODY_SHARE[1]
    return (float(cx - half_w), float(cy - half_h), float(cx + half_w), float(cy + half_h))


def _area(roi) -> float:
    return max(0.0, roi[2] - roi[0]) * max(0.0, roi[3] - roi[1])


def _iou(a, b) -> float:
    inter = _area((max(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), min(a[3], b[3])))
    union = _area(a) + _area(b) - inter
    return inter / union if union > 0 else 0.0


def amodal_boxes(scene: Scene, results: list[FrameResult]) -> tuple[Scene, int]:
    """The scene with each box the image border clipped replaced by its vehicle's projected 3D box, the detection
    box-only again (its keypoints to be found anew by :func:`vfactor.net.pipeline.detect_scene`).

    Args:
        scene: the scene whose keypoints were found from its boxes (its frames' images as given).
        results: the scene's solved frames (one per frame, :func:`vfactor.solve.solve_scene` or a track's): each
            solved vehicle's ``box``.

    Returns:
        The new scene (other detections as they were) and how many boxes were replaced.

    Raises:
        ValueError: ``results`` is not one per frame of ``scene``.
    """
    if len(results) != len(scene.frames):
        raise ValueError(f"results: expected one per frame of the scene ({len(scene.frames)}), got {len(results)}")
    frames, replaced = [], 0
    for frame, solved in zip(scene.frames, results):
        boxes = {v.id: v.box for v in solved.vehicles if v.ok and v.box is not None}
        detections = list(frame.detections)
        for j, det in enumerate(detections):
            camera = scene.cameras[det.camera]
            if det.roi is None or camera.image_size is None or det.vehicle not in boxes or \
                    not clipped_by_border(det.roi, camera.image_size):
                continue
            whole = projected_box(camera, boxes[det.vehicle])
            if whole is None:
                continue
            inside = tuple(clip_roi_to_image(whole, *camera.image_size))
            if _iou(inside, det.roi) < MIN_AGREEMENT or _area(inside) < MIN_INSIDE * _area(whole):
                continue
            detections[j] = dataclasses.replace(det, roi=whole, keypoints=np.full((12, 2), np.nan),
                                                confidence=np.zeros(12), covariance=None, heatmaps=None,
                                                from_image=True, covariance_calibrated=False, shape_sigma=None,
                                                bias_sigma=None)
            replaced += 1
        frames.append(dataclasses.replace(frame, detections=detections))
    return dataclasses.replace(scene, frames=frames), replaced


def redetect_clipped(scene: Scene, results: list[FrameResult], detector=None, **detect_options) -> tuple[Scene, int]:
    """:func:`amodal_boxes` then :func:`vfactor.net.pipeline.detect_scene` (``detector``: None for the shipped
    weights; ``detect_options`` go to it): the scene with the clipped vehicles' keypoints found from their whole
    boxes, and how many boxes were replaced. Solve it again for the estimates."""
    from vfactor.net.pipeline import detect_scene  # noqa: PLC0415

    amodal, replaced = amodal_boxes(scene, results)
    return (detect_scene(amodal, detector, **detect_options) if replaced else scene), replaced
