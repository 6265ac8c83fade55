"""Camera images of a simulated scene, and the scene file that gives them with vehicle boxes.

:func:`render_simulation` draws every camera of every frame of a
:class:`vfactor.sim.Simulation` (each vehicle at its true pose with its true
shape and hub height, on a textured road under a sun), writes the images as
PNG files, and returns a :class:`~vfactor.observations.Scene` whose detections
carry only a box (``roi``) per vehicle and camera, as a 2D vehicle detector
would give them, and ``from_image`` set: the keypoint network
(:func:`vfactor.net.pipeline.detect_scene`) then finds the keypoints. The
simulation's own keypoints (with their simulated noise) are not used.

A box is the vehicle mesh's amodal box (the whole vehicle, also where it is
hidden or leaves the image) with each edge moved by Gaussian noise of
``box_noise`` times the box's larger side, the imprecision of a detector.
Which vehicle each camera reports is the simulation's decision (its
visibility rules), so the rendered scene and the simulated one hold the same
(frame, camera, vehicle) detections.

Appearances (paint, details), the light and the road are drawn from ``seed``;
by default paints come from the held-out colour bins of
:data:`vfactor.render.dataset.HELD_OUT`, which the shipped weights never saw
in training.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from vfactor.heatmaps import clip_roi_to_image
from vfactor.observations import Detection, Frame, Scene
from vfactor.render.dataset import HELD_OUT, SplitSpec, random_appearance, random_ground, random_light, roof_height
from vfactor.render.renderer import Renderer
from vfactor.scene import save_scene
from vfactor.sim import Simulation

__all__ = ["RenderedScene", "render_simulation"]


@dataclasses.dataclass
class RenderedScene:
    """What :func:`render_simulation` made.

    Attributes:
        scene: cameras and frames with ``images`` and box-only detections.
        path: the scene file written (``<out_dir>/scene.json``).
        boxes_true: per frame, ``(camera, vehicle)`` -> the noise-free amodal box ``(x0, y0, x1, y1)``.
        keypoints_true: per frame, ``(camera, vehicle)`` -> (12, 2) true keypoint pixels
            (projected with the camera's distortion).
        visible: per frame, ``(camera, vehicle)`` -> (12,) keypoints in the image and hidden by nothing.
    """

    scene: Scene
    path: Path
    boxes_true: list[dict]
    keypoints_true: list[dict]
    visible: list[dict]


def _share_inside(box, size) -> float:
    """Share of a box's area ``(x0, y0, x1, y1)`` inside an image of ``size = (width, height)``."""
    w = min(box[2], size[0]) - max(box[0], 0.0)
    h = min(box[3], size[1]) - max(box[1], 0.0)
    if w < 1 or h < 1:
        return 0.0
    return float(w * h / ((box[2] - box[0]) * (box[3] - box[1])))


def render_simulation(
    sim: Simulation,
    out_dir: str | Path,
    seed: int = 0,
    split: SplitSpec = HELD_OUT,
    box_noise: float = 0.02,
    pixel_noise: float = 2.0,
    supersample: float = 2.0,
    progress: Callable[[int, int], None] | None = None,
    min_inside: float = 0.25,
    clip_boxes: bool = False,
    real_roofs: bool = True,
) -> RenderedScene:
    """Renders every camera image of a simulation and writes a scene file of images and boxes.

    Args:
        sim: the simulation (cameras with ``image_size``; per frame the vehicles'
            true poses and shapes; the detections say which camera reports which vehicle).
        out_dir: folder for ``images/f<frame>_<camera>.png`` and ``scene.json`` (created).
        seed: draws the vehicles' appearances, the light, the road and the noise.
        split: whose colour bins the paints come from (default: the held-out split's).
        box_noise: standard deviation of each box edge, fraction of the box's larger side.
        pixel_noise: standard deviation of the Gaussian sensor noise, grey levels.
        supersample: the renderer's anti-aliasing factor.
        progress: called with ``(images done, images total)``.
        min_inside: a box is reported only when at least this share of its area
            lies in the image (a 2D detector does not report a vehicle almost
            wholly out of view, and the keypoint network refuses such a box:
            ``vfactor.net.crop.MIN_ROI_INSIDE``, the same 25 %).
        clip_boxes: report each box clipped to the image, as a 2D detector gives the box of a vehicle the image
            border cuts (default: the whole vehicle's box, which reaches beyond the image there; docs/network.md,
            "Boxes clipped by the image border"). The images and the true boxes are the same either way.
        real_roofs: draw each vehicle's roof at its real height (:func:`vfactor.render.dataset.roof_height`: a
            library vehicle's published one; the default) instead of at its window tops (False: the renderer's
            earlier default; docs/rendering.md, "Roofs").

    Returns:
        :class:`RenderedScene`.

    Raises:
        ValueError: a camera without ``image_size``, or a negative noise level.
        vfactor.render.RenderingUnavailable: no OpenGL context (moderngl or EGL missing).
    """
    if not (box_noise >= 0 and pixel_noise >= 0):
        raise ValueError(f"box_noise, pixel_noise: expected numbers >= 0, got {box_noise}, {pixel_noise}")
    for name, camera in sim.scene.cameras.items():
        if camera.image_size is None:
            raise ValueError(f"cameras.{name}.image_size: needed to render the camera's images")
    out_dir = Path(out_dir)
    (out_dir / "images").mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    light, ground = random_light(rng), random_ground(rng)
    ids = list(dict.fromkeys(vid for truth in sim.truth for vid in truth))
    appearance = {vid: random_appearance(rng, split) for vid in ids}
    renderers: dict[tuple[int, int], Renderer] = {}
    frames, boxes_true, keypoints_true, visible = [], [], [], []
    total, done = len(sim.scene.frames) * len(sim.scene.cameras), 0
    try:
        for f, frame in enumerate(sim.scene.frames):
            truth = sim.truth[f]
            order = list(truth)
            vehicles = [(truth[v].wireframe, truth[v].world_T_vehicle, appearance[v], truth[v].wheel_radius,
                         roof_height(truth[v].wireframe, truth[v].preset, truth[v].wheel_radius)
                         if real_roofs else None)
                        for v in order]
            images, boxes_f, uv_f, vis_f, detections = {}, {}, {}, {}, []
            reported = {(d.camera, d.vehicle) for d in frame.detections}
            for name, camera in sim.scene.cameras.items():
                size = tuple(camera.image_size)
                if size not in renderers:
                    renderers[size] = Renderer(*size, supersample=supersample)
                rendered = renderers[size].render(camera, vehicles, light=light, ground=ground)
                image = rendered.image.astype(np.float32)
                if pixel_noise > 0:
                    image += rng.normal(0.0, pixel_noise, image.shape)
                image = np.clip(image + 0.5, 0, 255).astype(np.uint8)
                path = out_dir / "images" / f"f{f:04d}_{name}.png"
                if not cv2.imwrite(str(path), image[..., ::-1]):
                    raise OSError(f"could not write {path}")
                images[name] = str(path.resolve())
                for vid, ann in zip(order, rendered.annotations):
                    if (name, vid) not in reported or not np.all(np.isfinite(ann.box)):
                        continue
                    box = np.asarray(ann.box, float)
                    side = max(box[2] - box[0], box[3] - box[1])
                    noisy = box + rng.normal(0.0, box_noise * side, 4)
                    if not (noisy[2] > noisy[0] + 1 and noisy[3] > noisy[1] + 1):
                        noisy = box
                    if _share_inside(noisy, size) < min_inside:
                        continue
                    if clip_boxes:
                        noisy = clip_roi_to_image(noisy, *size)
                    detections.append(Detection(camera=name, vehicle=vid, keypoints=np.full((12, 2), np.nan),
                                                confidence=np.zeros(12), roi=tuple(float(b) for b in noisy),
                                                from_image=True))
                    boxes_f[(name, vid)] = tuple(float(b) for b in box)
                    uv_f[(name, vid)] = np.asarray(ann.uv, float)
                    vis_f[(name, vid)] = np.asarray(ann.visible, bool)
                done += 1
                if progress is not None:
                    progress(done, total)
            frames.append(Frame(t=frame.t, detections=detections, images=images))
            boxes_true.append(boxes_f)
            keypoints_true.append(uv_f)
            visible.append(vis_f)
    finally:
        for r in renderers.values():
            r.release()
    scene = Scene(cameras=dict(sim.scene.cameras), frames=frames, base_dir=out_dir.resolve(),
                  ground_plane=sim.scene.ground_plane)
    path = out_dir / "scene.json"
    save_scene(scene, path)
    return RenderedScene(scene, path, boxes_true, keypoints_true, visible)
