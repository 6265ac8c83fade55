"""Images and boxes to keypoints for a whole scene: the network stage of the image-to-pose pipeline.

A scene file may give, per frame, an image per camera (``"images"``) and per
vehicle only its box in that image (a detection with ``"roi"`` and no
keypoints; see :mod:`vfactor.scene`). :func:`detect_scene` runs the keypoint
network (:class:`~vfactor.net.infer.KeypointDetector`) on every such box and
returns the scene with the detections' keypoints, confidences and
(calibrated) 2x2 pixel covariances filled in, ready for
:func:`vfactor.solve.solve_scene` or :func:`vfactor.track.track_scene`.
``vfactor solve`` and ``vfactor track`` call it themselves.

Example::

    from vfactor.scene import load_scene
    from vfactor.net.pipeline import detect_scene
    from vfactor.solve import solve_scene

    scene = detect_scene(load_scene("scene_with_images.json"), heatmaps_dir="heatmaps")
    results = solve_scene(scene)
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable

import numpy as np

from vfactor.errors import SceneError
from vfactor.images import read_rgb
from vfactor.net.crop import check_roi_in_image
from vfactor.observations import Scene, resolve_path

__all__ = ["detect_scene", "read_image"]


def read_image(path: str | Path, field: str, image_size: tuple[int, int] | None = None) -> np.ndarray:
    """Reads an image file as (H, W, 3) uint8 RGB (:func:`vfactor.images.read_rgb`: 16-bit files scaled by their bit
    depth, grey as three channels).

    Args:
        path: image file (any format OpenCV reads: PNG, JPEG, TIFF, ...).
        field: the scene field that names it (for error messages).
        image_size: the camera's ``(width, height)``, checked when given.

    Raises:
        SceneError: unreadable file, or a size other than the camera's.
    """
    try:
        image = read_rgb(path)
    except (OSError, ValueError) as exc:
        raise SceneError(field, f"cannot read an image from {path}: {getattr(exc, 'strerror', None) or exc}") from None
    if image is None:
        raise SceneError(field, f"cannot read an image from {path}")
    height, width = image.shape[:2]
    if image_size is not None and (width, height) != tuple(image_size):
        raise SceneError(field, f"the image is {width}x{height} pixels but the camera's image_size is "
                                f"{image_size[0]}x{image_size[1]}")
    return image


def detect_scene(
    scene: Scene,
    detector=None,
    heatmaps_dir: str | Path | None = None,
    progress: Callable[[int, int], None] | None = None,
    engine=None,
) -> Scene:
    """Finds the keypoints of every box-only detection of a scene with the keypoint network.

    Per frame, the images of the cameras with box-only detections
    (``Detection.from_image``) are read and all their boxes go through the
    network in batches. Each such detection gets the decoded ``keypoints``
    (image pixels), ``confidence`` (0 where the network found nothing) and
    ``covariance`` (px^2, the detector's calibrated heatmap covariances) and
    ``covariance_calibrated`` (True unless the detector's calibration is the
    identity); ``from_image`` is cleared. Other detections are kept as they are.

    Args:
        scene: the scene (from :func:`vfactor.scene.load_scene`, or made in code).
        detector: a :class:`~vfactor.net.infer.KeypointDetector`; None: the shipped weights.
        heatmaps_dir: when given, each detection's heatmaps are saved there as
            ``f<frame>_d<detection index>_<camera>_<vehicle>.npy`` and the detection names the file,
            with ``heatmaps_roi`` the box they cover (the given box grown and squared as the detector crops
            it), so that :func:`vfactor.scene.save_scene` writes a scene that reloads to the same keypoints
            and overlays can show the heatmaps. ``roi`` stays the given box either way: saving the heatmaps
            changes no estimate (it made views whose crop reaches past the image count as cut by the border).
        progress: called with ``(frames done, frames total)``.
        engine: where the frames' boxes go through the network (:mod:`vfactor.parallel`; default: in this
            process). On a cluster every worker loads the detector's weights once (its images and
            ``heatmaps_dir`` must be on a file system the workers share); the keypoints do not depend on it.

    Returns:
        A new :class:`Scene` (the input is not changed).

    Raises:
        SceneError: a frame's image cannot be read or is not its camera's
            ``image_size`` (the field names the image, e.g. ``frames[3].images.cam0``).
    """
    from vfactor.parallel import InProcess

    engine = engine or InProcess()
    if detector is None and isinstance(engine, InProcess):
        from vfactor.net.infer import KeypointDetector

        detector = KeypointDetector()
    out_dir = Path(heatmaps_dir) if heatmaps_dir is not None else None
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
    # a cluster's workers each build the detector from its settings (a torch model is not sent per task)
    sent = detector if isinstance(engine, InProcess) else _detector_settings(detector)
    units = ((f, frame, scene.cameras, scene.base_dir, sent, out_dir) for f, frame in enumerate(scene.frames))
    frames = list(engine.map(_detect_frame, units, progress=progress, total=len(scene.frames)))
    return dataclasses.replace(scene, frames=frames)


def _detector_settings(detector):
    """What a worker needs to build the same detector: its weights file and settings ({}: the shipped weights);
    a detector of in-memory weights is sent whole."""
    if detector is None:
        return {}
    if detector.weights_path is None:
        return detector
    return {"weights": str(detector.weights_path), "roi_margin": detector.roi_margin, "roi_square": detector.roi_square,
            "min_confidence": detector.min_confidence, "batch_size": detector.batch_size,
            "flip_test": detector.flip_test, "calibration": detector.calibration.to_dict()}


_DETECTORS: dict = {}


def _worker_detector(settings: dict):
    """The detector of ``settings`` on this worker, built once per process."""
    key = tuple(sorted((k, str(v)) for k, v in settings.items()))
    if key not in _DETECTORS:
        from vfactor.net.infer import KeypointDetector

        _DETECTORS[key] = KeypointDetector(**settings)
    return _DETECTORS[key]


def _detect_frame(unit: tuple):
    """One frame of :func:`detect_scene`: the frame with its box-only detections detected."""
    f, frame, cameras, base_dir, detector, out_dir = unit
    if isinstance(detector, dict):
        detector = _worker_detector(detector)
    pending = [j for j, det in enumerate(frame.detections) if det.from_image]
    detections = list(frame.detections)
    if not pending:
        return frame
    cams = list(dict.fromkeys(frame.detections[j].camera for j in pending))
    images = []
    for name in cams:
        image = (frame.images or {}).get(name)
        if image is None:
            raise SceneError(f"frames[{f}].images.{name}", "missing: detections of this camera give only a box")
        images.append(read_image(resolve_path(image, base_dir), f"frames[{f}].images.{name}", cameras[name].image_size))
    for j in pending:  # a box mostly outside its image is bad input, named here
        det, image = frame.detections[j], images[cams.index(frame.detections[j].camera)]
        try:
            check_roi_in_image(det.roi, image.shape[1], image.shape[0])
        except ValueError as exc:
            raise SceneError(f"frames[{f}].detections[{j}].roi", str(exc)) from None
    rois = [[frame.detections[j].roi for j in pending if frame.detections[j].camera == name] for name in cams]
    found = detector.detect_batch(images, rois)
    queue = {name: list(dets) for name, dets in zip(cams, found)}
    for j in pending:
        det = frame.detections[j]
        result = queue[det.camera].pop(0)
        kp = result.keypoints
        changes = dict(keypoints=np.asarray(kp.uv, float), confidence=np.asarray(kp.confidence, float),
                       covariance=np.asarray(kp.covariance, float), from_image=False,
                       **detector.calibration.detection_fields())
        if out_dir is not None:
            path = out_dir / f"f{f:04d}_d{j:02d}_{_safe(det.camera)}_{_safe(det.vehicle)}.npy"
            np.save(path, np.asarray(result.heatmaps, np.float32))
            changes.update(heatmaps=str(path.resolve()), heatmaps_roi=tuple(float(b) for b in result.roi))
        detections[j] = dataclasses.replace(det, **changes)
    return dataclasses.replace(frame, detections=detections)


def _safe(name: str) -> str:
    """A name as a file-name part (letters, digits, '-', '_'; others become '_')."""
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name) or "_"
