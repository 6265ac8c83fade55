"""End-to-end accuracy: rendered camera images -> keypoint network -> factor graph, against ground truth.

:func:`evaluate_images` simulates a scenario (poses, shapes, which camera
reports which vehicle), renders every camera image
(:func:`vfactor.render.scenes.render_simulation`: the vehicles' true shapes as
meshes, held-out paint colours, a detector's noisy boxes), finds the keypoints
with the network (:func:`vfactor.net.pipeline.detect_scene`) and runs the
methods of :mod:`vfactor.evaluation` (factor graph, triangulation, PnP, the
known-shape reference) on the network's keypoints. Beside them, the factor
graph on the simulator's own keypoints (paper-like noise on the true
projections) shows how the network's errors compare with that noise model.
A scenario with motion (each id one vehicle over its frames) is also tracked
from the network's keypoints (:func:`vfactor.evaluation.compare_tracking`:
iSAM2, fixed lag and batch smoothing beside frame-by-frame solving).
``vfactor eval images`` is the command; it needs torch and moderngl.
"""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path

import numpy as np

from vfactor.evaluation import (accuracy_table, body_type_table, compare_methods, compare_tracking, consistency_table,
                                summarise_methods, tracking_table)
from vfactor.net.evaluate import pck
from vfactor.net.pipeline import detect_scene
from vfactor.sim import load_scenario, simulate
from vfactor.solve import SolveOptions

__all__ = ["evaluate_images", "keypoint_accuracy", "images_report"]


def keypoint_accuracy(detected, rendered, crop_box) -> dict:
    """Pixel accuracy of the network's keypoints on full camera images.

    Args:
        detected: the scene after :func:`detect_scene`.
        rendered: the :class:`~vfactor.render.scenes.RenderedScene` (true keypoints and visibility).
        crop_box: callable ROI -> the box the detector crops (``KeypointDetector.crop_box``).

    Returns:
        ``pck_visible``, ``pck_self_occluded`` (PCK@0.1 of the crop's side, as in
        training), ``median_px_visible`` (pixels), ``median_rel_visible`` (fraction of
        the crop's side), counts ``visible``, ``self_occluded``, and ``missed``
        (in-image keypoints the network found nothing for).
    """
    pred, truth, vis, occ, sides = [], [], [], [], []
    for f, frame in enumerate(detected.frames):
        for det in frame.detections:
            key = (det.camera, det.vehicle)
            if key not in rendered.keypoints_true[f]:
                continue
            uv = rendered.keypoints_true[f][key]
            inside = detected.cameras[det.camera].in_image(uv)
            visible = rendered.visible[f][key] & inside
            x0, y0, x1, y1 = crop_box(rendered.boxes_true[f][key])
            pred.append(np.where(det.confidence[:, None] > 0, det.keypoints, np.nan))
            truth.append(uv)
            vis.append(visible)
            occ.append(inside & ~visible)
            sides.append(max(x1 - x0, y1 - y0))
    pred, truth, vis, occ, sides = map(np.asarray, (pred, truth, vis, occ, sides))
    p_vis, n_vis = pck(pred, truth, vis, sides)
    p_occ, n_occ = pck(pred, truth, occ, sides)
    dist = np.linalg.norm(pred - truth, axis=-1)
    found = np.isfinite(dist)
    return {
        "pck_visible": p_vis,
        "pck_self_occluded": p_occ,
        "median_px_visible": float(np.median(dist[vis & found])),
        "median_rel_visible": float(np.median((dist / sides[:, None])[vis & found])),
        "visible": n_vis,
        "self_occluded": n_occ,
        "missed": int(((vis | occ) & ~found).sum()),
    }


def evaluate_images(scenario: str = "accuracy_2cam", frames: int | None = None, seed: int = 0, detector=None,
                    work_dir: str | Path | None = None, options: SolveOptions = SolveOptions(),
                    progress=None) -> dict:
    """Runs the image-to-pose pipeline on rendered scenes of a scenario and scores it.

    Args:
        scenario: packaged scenario name or file (cameras need ``image_size``).
        frames: number of frames (default: the scenario's).
        seed: the simulation's and the rendering's seed.
        detector: a :class:`~vfactor.net.infer.KeypointDetector`; None: the shipped weights.
        work_dir: folder for the images, the scene file and the heatmaps; None: a
            temporary folder, removed afterwards.
        options: solver options of the factor graph.
        progress: called with ``(images rendered, images total)``.

    Returns:
        ``{"scenario", "seed", "frames", "keypoints": keypoint_accuracy(...),
        "summary": method -> summarise_methods row, "rows": method -> compare_methods rows,
        "tracking": compare_tracking(...) or None}``;
        the methods are ``factor_graph``, ``triangulation``, ``pnp``, ``known_shape`` on the
        network's keypoints and ``factor_graph_simulated_noise`` on the simulator's keypoints;
        ``tracking`` is given for a scenario with motion (each id one vehicle over
        its frames); without motion every frame holds new vehicles and there is
        nothing to track.
    """
    from vfactor.net.infer import KeypointDetector
    from vfactor.render.scenes import render_simulation

    detector = detector or KeypointDetector()
    sim = simulate(load_scenario(scenario), seed=seed, num_frames=frames)
    with tempfile.TemporaryDirectory(prefix="vfactor_eval_images_") as tmp:
        folder = Path(work_dir) if work_dir is not None else Path(tmp)
        rendered = render_simulation(sim, folder, seed=seed, progress=progress)
        detected = detect_scene(rendered.scene, detector, heatmaps_dir=folder / "heatmaps" if work_dir else None)
    keypoints = keypoint_accuracy(detected, rendered, detector.crop_box)
    rows = compare_methods(dataclasses.replace(sim, scene=detected), options)
    rows["factor_graph_simulated_noise"] = compare_methods(sim, options, methods=("factor_graph",))["factor_graph"]
    tracked = sim.scenario.motion is not None
    tracking = compare_tracking(dataclasses.replace(sim, scene=detected)) if tracked else None
    return {"scenario": sim.scenario.name, "seed": seed, "frames": len(sim.scene.frames), "keypoints": keypoints,
            "summary": summarise_methods(rows), "rows": rows, "tracking": tracking}


def images_report(evaluation: dict) -> str:
    """Markdown of :func:`evaluate_images`: keypoint accuracy and the methods' pose and shape errors."""
    k = evaluation["keypoints"]
    return (
        f"### {evaluation['scenario']}: rendered images -> keypoint network -> factor graph, "
        f"{evaluation['frames']} frames, seed {evaluation['seed']}\n\n"
        f"Network keypoints on the full images: PCK@0.1 {k['pck_visible']:.3f} visible ({k['visible']}), "
        f"{k['pck_self_occluded']:.3f} self-occluded or hidden ({k['self_occluded']}); median error of visible "
        f"keypoints {k['median_px_visible']:.1f} px ({100 * k['median_rel_visible']:.1f} % of the crop side); "
        f"{k['missed']} not found.\n\n"
        f"{accuracy_table(evaluation['summary'])}\n\n"
        "factor_graph_simulated_noise: the factor graph on the simulator's keypoints (paper-like noise) of the "
        "same vehicles, for comparison with the network's keypoints.\n"
        + (f"\nPer body type, from the network's keypoints (each vehicle solved with a shape model learnt without "
           f"it):\n\n{body_type_table(evaluation['rows'])}\n\nConsistency of the factor graph's covariances from "
           f"the network's keypoints and their heatmap covariances (NEES; consistent: 1.00x and 95 %):\n\n"
           f"{consistency_table(evaluation['rows'])}\n\nThe same from the simulator's keypoints:\n\n"
           f"{consistency_table(evaluation['rows'], 'factor_graph_simulated_noise')}\n" if evaluation.get("rows") else "")
        + (f"\nTracking from the network's keypoints:\n\n{tracking_table(evaluation['tracking'])}\n"
           if evaluation.get("tracking") else "")
    )
