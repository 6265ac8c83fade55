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

import contextlib
import dataclasses
import tempfile
from pathlib import Path

import numpy as np

from vfactor.evaluation import (accuracy_table, body_type_of, body_type_table, compare_methods, compare_tracking,
                                consistency_table, held_out_scene_model, summarise_methods, tracking_table)
from vfactor.graph import roi_cut_by_border
from vfactor.net.evaluate import pck
from vfactor.net.pipeline import detect_scene
from vfactor.sim import load_scenario, simulate
from vfactor.vehicle_library import BODY_TYPES
from vfactor.solve import SolveOptions, solve_scene

__all__ = ["evaluate_images", "render_and_detect", "detected_scene", "keypoint_accuracy", "calibration_table",
           "images_report", "network_class_tables", "network_saw"]


def network_saw(model: str) -> bool:
    """Whether the training split of the keypoint network (:data:`vfactor.render.dataset.TRAIN`, which the shipped
    weights were trained on) draws the vehicle model ``model`` (a row's ``"preset"``: a preset name, a library id or
    ``"pascal3d_<index>"``)."""
    from vfactor.render.dataset import TRAIN

    if model.startswith("pascal3d_"):
        return int(model.split("_", 1)[1]) in TRAIN.pascal_models
    return model in TRAIN.presets or model in TRAIN.library_models


def _unseen(rows: dict[str, list[dict]]) -> dict[str, list[dict]]:
    """``rows`` of the vehicles whose model the network never saw in training (:func:`network_saw`)."""
    return {m: [r for r in v if not network_saw(r["preset"])] for m, v in rows.items()}


def keypoint_accuracy(detected, rendered, crop_box, body_types=None) -> dict:
    """Pixel accuracy of the network's keypoints on full camera images, and how well their covariances cover it.

    Args:
        detected: the scene after :func:`detect_scene`.
        rendered: the :class:`~vfactor.render.scenes.RenderedScene` (true keypoints and visibility).
        crop_box: callable ROI -> the box the detector crops (``KeypointDetector.crop_box``).
        body_types: optional ``{(frame index, vehicle id): class}`` (e.g. the truth's body type): the same
            figures per class under ``"by_body_type"``.

    Returns:
        ``pck_visible``, ``pck_self_occluded`` (PCK@0.1 of the crop's side, as in
        training), ``median_px_visible`` (pixels), ``median_rel_visible`` (fraction of
        the crop's side), counts ``visible``, ``self_occluded``, and ``missed``
        (in-image keypoints the network found nothing for); ``d2_mean`` and ``d2_count``: the mean squared
        Mahalanobis distance ``e^T S^-1 e`` of the PCK-correct in-image keypoints under the detections' pixel
        covariances ``S`` (image px^2; chi-square(2), mean 2, if they are calibrated; NaN without covariances).
        With ``body_types``, ``by_body_type``: class -> those figures for its detections. ``by_view``: ``"whole"``
        and ``"cut"`` -> those figures for the detections whose vehicle lies wholly in the image and those whose
        true box the image border cuts (:func:`vfactor.graph.roi_cut_by_border`; a vehicle entering or leaving a
        view), where there are any.
    """
    pred, truth, vis, occ, sides, cov, classes, cut = [], [], [], [], [], [], [], []
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
            cov.append(det.covariance if det.covariance is not None else np.full((len(uv), 2, 2), np.nan))
            classes.append(None if body_types is None else body_types.get((f, det.vehicle)))
            cut.append(roi_cut_by_border(rendered.boxes_true[f][key], detected.cameras[det.camera].image_size))
    arrays = tuple(map(np.asarray, (pred, truth, vis, occ, sides, cov)))
    out = _accuracy(*arrays)
    cut = np.array(cut, dtype=bool)
    out["by_view"] = {view: _accuracy(*(a[rows] for a in arrays)) for view, rows in (("whole", ~cut), ("cut", cut))
                      if rows.any()}
    if body_types is not None:
        classes = np.array(classes, dtype=object)
        out["by_body_type"] = {c: _accuracy(*(a[classes == c] for a in arrays))
                               for c in dict.fromkeys(c for c in classes if c is not None)}
    return out


def _accuracy(pred, truth, vis, occ, sides, cov) -> dict:
    """The figures of :func:`keypoint_accuracy` for stacked detections: (N, 12, 2) pixels, (N, 12) masks, (N,) crop
    sides, (N, 12, 2, 2) covariances."""
    p_vis, n_vis = pck(pred, truth, vis, sides)
    p_occ, n_occ = pck(pred, truth, occ, sides)
    error = pred - truth
    dist = np.linalg.norm(error, axis=-1)
    found = np.isfinite(dist)
    correct = (vis | occ) & found & (np.where(found, dist, np.inf) <= 0.1 * sides[:, None])
    correct &= np.all(np.isfinite(cov), axis=(-2, -1))
    d2 = np.einsum("ni,nij,nj->n", error[correct], np.linalg.inv(cov[correct]), error[correct]) if correct.any() \
        else np.zeros(0)
    return {
        "pck_visible": p_vis,
        "pck_self_occluded": p_occ,
        "median_px_visible": float(np.median(dist[vis & found])) if (vis & found).any() else float("nan"),
        "median_rel_visible": float(np.median((dist / sides[:, None])[vis & found])) if (vis & found).any()
        else float("nan"),
        "visible": n_vis,
        "self_occluded": n_occ,
        "missed": int(((vis | occ) & ~found).sum()),
        "d2_mean": float(d2.mean()) if len(d2) else float("nan"),
        "d2_count": int(len(d2)),
    }


def calibration_table(keypoints: dict) -> str:
    """Markdown, per body type, of :func:`keypoint_accuracy`'s ``by_body_type``: PCK, median error and the mean d2 of
    the PCK-correct keypoints under their covariances (calibrated: 2); then all detections, and those of vehicles
    whole in the image and cut by its border (``by_view``)."""
    lines = ["| body type | PCK@0.1 visible | PCK@0.1 self-occluded | median error of visible keypoints (% of crop) "
             "| mean d2 of PCK-correct keypoints (calibrated: 2) | keypoints |", "| --- " * 6 + "|"]
    groups = keypoints.get("by_body_type", {})
    for c in [t for t in (*BODY_TYPES, "pascal3d") if t in groups] + [t for t in groups if t not in (*BODY_TYPES,
                                                                                                    "pascal3d")]:
        k = groups[c]
        lines.append(f"| {c} | {k['pck_visible']:.3f} | {k['pck_self_occluded']:.3f} | "
                     f"{100 * k['median_rel_visible']:.2f} | {k['d2_mean']:.2f} | {k['d2_count']} |")
    views = keypoints.get("by_view", {})
    for label, k in [("all", keypoints)] + [(name, views[view]) for view, name in
                                           (("whole", "whole in the image"), ("cut", "cut by the image border"))
                                           if view in views]:
        lines.append(f"| {label} | {k['pck_visible']:.3f} | {k['pck_self_occluded']:.3f} | "
                     f"{100 * k['median_rel_visible']:.2f} | {k['d2_mean']:.2f} | {k['d2_count']} |")
    return "\n".join(lines)


def render_and_detect(scenario: str, seed: int, frames: int | None = None, detector=None,
                      work_dir: str | Path | None = None, progress=None, clip_boxes: bool = False,
                      real_roofs: bool = True):
    """Simulates a scenario, renders its camera images and finds the keypoints in the vehicles' boxes.

    Args:
        scenario: packaged scenario name or file (cameras need ``image_size``).
        seed: the simulation's and the rendering's seed.
        frames: number of frames (default: the scenario's).
        detector: a :class:`~vfactor.net.infer.KeypointDetector`; None: the shipped weights.
        work_dir: folder for the images, the scene file and the heatmaps; None: a temporary folder, removed
            afterwards.
        progress: called with ``(images rendered, images total)``.
        clip_boxes: give the network the boxes clipped to the image, as a 2D detector gives them (default: the
            whole vehicles' boxes; :func:`vfactor.render.scenes.render_simulation`).
        real_roofs: draw each vehicle's roof at its real height (a library vehicle's published one; the default);
            False: at its window tops (:func:`vfactor.render.scenes.render_simulation`).

    Returns:
        ``(simulation, rendered scene, detected scene, detector)``: the detected scene holds the network's
        keypoints in place of the boxes.
    """
    from vfactor.net.infer import KeypointDetector
    from vfactor.render.scenes import render_simulation

    detector = detector or KeypointDetector()
    sim = simulate(load_scenario(scenario), seed=seed, num_frames=frames)
    with tempfile.TemporaryDirectory(prefix="vfactor_eval_images_") as tmp:
        folder = Path(work_dir) if work_dir is not None else Path(tmp)
        rendered = render_simulation(sim, folder, seed=seed, progress=progress, clip_boxes=clip_boxes,
                                     real_roofs=real_roofs)
        detected = detect_scene(rendered.scene, detector, heatmaps_dir=folder / "heatmaps" if work_dir else None)
    return sim, rendered, detected, detector


def detected_scene(spec: str, cache: str | Path | None = None):
    """``(simulation, detected scene)`` of ``"scenario:seed"`` (:func:`render_and_detect` with the shipped network,
    the scenario's frames), read from the folder ``cache`` where it was kept there (``scenario_seed.pkl``) and kept
    there when rendered; None: rendered every time. For benchmarks that run on the same detections again: a kept
    scene keeps the calibration it was detected with (``shape_sigma``, ``bias_sigma``)."""
    import pickle

    scenario, seed = spec.rsplit(":", 1)
    path = Path(cache) / f"{scenario}_{seed}.pkl" if cache is not None else None
    if path is not None and path.exists():
        with open(path, "rb") as f:
            return pickle.load(f)
    sim, _, detected, _ = render_and_detect(scenario, int(seed))
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "wb") as f:
            pickle.dump((sim, detected), f)
    return sim, detected


def evaluate_images(scenario: str = "accuracy_2cam", frames: int | None = None, seed: int = 0, detector=None,
                    work_dir: str | Path | None = None, options: SolveOptions = SolveOptions(),
                    progress=None, track_options=None, clip_boxes: bool = False, amodal_pass: bool = False,
                    real_roofs: bool = True) -> dict:
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
        track_options: the tracking comparison's :class:`~vfactor.track.TrackOptions` (default: the defaults).
        clip_boxes: the network gets the boxes clipped to the image (:func:`render_and_detect`).
        real_roofs: each vehicle's roof drawn at its real height (:func:`render_and_detect`).
        amodal_pass: the keypoints of the vehicles whose boxes stop at the image border are found again in the
            boxes of the vehicles a first solve found (tracked where the scenario moves, else one frame at a time;
            each vehicle with the shape model learnt without it), and everything is evaluated on those
            (:func:`vfactor.net.amodal.redetect_clipped`).

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
    replaced = None
    # the amodal pass reads the images again: they stay in a temporary folder until it is done (without it, or with
    # a work_dir, render_and_detect keeps or removes them itself)
    images = tempfile.TemporaryDirectory(prefix="vfactor_eval_images_") if amodal_pass and work_dir is None else \
        contextlib.nullcontext(work_dir)
    with images as folder:
        sim, rendered, detected, detector = render_and_detect(scenario, seed, frames, detector, folder, progress,
                                                              clip_boxes, real_roofs)
        tracked = sim.scenario.motion is not None
        if amodal_pass:
            from vfactor.net.amodal import redetect_clipped
            from vfactor.track import TrackOptions, track_scene

            model = held_out_scene_model(sim)
            first = (track_scene(detected, track_options or TrackOptions(), prior=model).frames if tracked else
                     solve_scene(detected, dataclasses.replace(options, covariance=False), prior=model))
            given = dataclasses.replace(detected, frames=[  # the given boxes (a work_dir's scene holds the crops')
                dataclasses.replace(frame, detections=[dataclasses.replace(d, roi=g.roi) for d, g in
                                                       zip(frame.detections, raw.detections)])
                for frame, raw in zip(detected.frames, rendered.scene.frames)])
            detected, replaced = redetect_clipped(given, first, detector)
    body_types = {(f, vid): body_type_of(sim.truth[f][vid].preset) for f in range(len(sim.scene.frames))
                  for vid in sim.truth[f]}
    keypoints = keypoint_accuracy(detected, rendered, detector.crop_box, body_types)
    rows = compare_methods(dataclasses.replace(sim, scene=detected), options)
    rows["factor_graph_simulated_noise"] = compare_methods(sim, options, methods=("factor_graph",))["factor_graph"]
    tracking = compare_tracking(dataclasses.replace(sim, scene=detected), track_options) if tracked else None
    return {"scenario": sim.scenario.name, "seed": seed, "frames": len(sim.scene.frames), "clip_boxes": clip_boxes,
            "real_roofs": real_roofs,
            "amodal_pass_boxes": replaced,
            "keypoints": keypoints,
            "summary": summarise_methods(rows), "rows": rows, "tracking": tracking}


def network_class_tables(rows: dict[str, list[dict]]) -> str:
    """Markdown: the factor graph's errors per body type from the network's keypoints, its covariances'
    consistency, and the same from the simulator's keypoints (``rows``: :func:`evaluate_images`'s, or several
    seeds' pooled)."""
    return (f"Per body type, from the network's keypoints (each vehicle solved with a shape model learnt without "
            f"it):\n\n{body_type_table(rows)}\n\nConsistency of the factor graph's covariances from the network's "
            f"keypoints and their heatmap covariances (NEES; consistent: 1.00x and 95 %):\n\n"
            f"{consistency_table(rows)}\n\nThe same from the simulator's keypoints:\n\n"
            f"{consistency_table(rows, 'factor_graph_simulated_noise')}\n")


def images_report(evaluation: dict) -> str:
    """Markdown of :func:`evaluate_images`: keypoint accuracy and the methods' pose and shape errors."""
    k = evaluation["keypoints"]
    return (
        f"### {evaluation['scenario']}: rendered images -> keypoint network -> factor graph, "
        f"{evaluation['frames']} frames, seed {evaluation['seed']}"
        + (", boxes clipped to the image" if evaluation.get("clip_boxes") else "")
        + ("" if evaluation.get("real_roofs", True) else ", roofs at the window tops") + "\n\n"
        + (f"Amodal pass: {evaluation['amodal_pass_boxes']} boxes clipped by the image border replaced by the "
           f"boxes of the vehicles a first solve found, their keypoints found again.\n\n"
           if evaluation.get("amodal_pass_boxes") is not None else "")
        + f"Network keypoints on the full images: PCK@0.1 {k['pck_visible']:.3f} visible ({k['visible']}), "
        f"{k['pck_self_occluded']:.3f} self-occluded or hidden ({k['self_occluded']}); median error of visible "
        f"keypoints {k['median_px_visible']:.1f} px ({100 * k['median_rel_visible']:.1f} % of the crop side); "
        f"{k['missed']} not found.\n\n"
        + (f"The network's keypoints per body type, and how their calibrated covariances cover their errors:\n\n"
           f"{calibration_table(k)}\n\n" if k.get("by_body_type") else "")
        + f"{accuracy_table(evaluation['summary'])}\n\n"
        "factor_graph_simulated_noise: the factor graph on the simulator's keypoints (paper-like noise) of the "
        "same vehicles, for comparison with the network's keypoints.\n"
        + (f"\n{network_class_tables(evaluation['rows'])}" if evaluation.get("rows") else "")
        + (f"\nThe vehicles whose model the network never saw in training (`vfactor.net.end_to_end.network_saw`: "
           f"the held-out half of the vehicle library, the hatchback and SUV presets, PASCAL3D+ models 7-8), per "
           f"body type:\n\n{body_type_table(_unseen(evaluation['rows']))}\n\nTheir covariances' consistency:\n\n"
           f"{consistency_table(_unseen(evaluation['rows']))}\n"
           if evaluation.get("rows") and any(not network_saw(r["preset"]) for r in evaluation["rows"]["factor_graph"])
           else "")
        + (f"\nTracking from the network's keypoints:\n\n{tracking_table(evaluation['tracking'])}\n"
           if evaluation.get("tracking") else "")
    )
