"""Accuracy: tracks from boxes clipped by the image border, as a 2D detector gives them, with and without the amodal
pass (``vfactor track --amodal-pass``, :mod:`vfactor.net.amodal`), next to the whole vehicles' boxes.

Each scene is simulated and rendered once (``render_simulation``; its images kept in a temporary folder), the
shipped network finds the keypoints from the whole (amodal) boxes and from the same boxes clipped to the image
(the detector grows those by a quarter, its default), each scene is tracked (``track_scene``, final estimates, the
shape model held out: :func:`vfactor.evaluation.held_out_scene_model`), and the clipped scene again after
:func:`vfactor.net.amodal.redetect_clipped` from its first tracks. Prints per rig (two cameras without a road plane,
three with it) and body type the mean rotation (deg), translation (cm) and pose NEES (ratio to 6) of every solved
pose, and the mean keypoint error of each track's final shape (cm); docs/network.md, "Found again from the solved
vehicle". Needs the ``net`` and ``render`` extras.

Run: ``python benchmarks/amodal_pass.py [--seed 270] [--scenarios tracks_3veh library_tracks_2cam tracks_3cam
library_tracks]`` (about 1.5 min a scene on two cores).
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import pathlib
import sys
import tempfile

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from vfactor.evaluation import (class_rows, final_shape_errors, held_out_scene_model, pose_rows,  # noqa: E402
                                track_body_types)
from vfactor.heatmaps import clip_roi_to_image, clipped_by_border  # noqa: E402
from vfactor.net.amodal import redetect_clipped  # noqa: E402
from vfactor.net.infer import KeypointDetector  # noqa: E402
from vfactor.net.pipeline import detect_scene  # noqa: E402
from vfactor.render.scenes import render_simulation  # noqa: E402
from vfactor.sim import load_scenario, simulate  # noqa: E402
from vfactor.track import TrackOptions, track_scene  # noqa: E402

BOXES = ("whole", "clipped", "amodal pass")


def clipped_boxes(scene):
    """The scene with every box clipped to its camera's image, as a 2D detector gives it."""
    def clip(d):
        return dataclasses.replace(d, roi=tuple(float(v) for v in
                                                clip_roi_to_image(d.roi, *scene.cameras[d.camera].image_size)))

    return dataclasses.replace(scene, frames=[dataclasses.replace(frame, detections=[clip(d) for d in frame.detections])
                                              for frame in scene.frames])


def scene_rows(scenario: str, seed: int, detector, poses: dict, shapes: dict) -> str:
    """Tracks one scene three ways, adding its poses' rows and final shapes to ``poses`` and ``shapes`` (keyed by
    rig, boxes, body type); returns a line on the boxes the pass replaced."""
    sim = simulate(load_scenario(scenario), seed=seed)
    model = held_out_scene_model(sim)
    with tempfile.TemporaryDirectory(prefix="vfactor_amodal_") as folder:
        rendered = render_simulation(sim, folder, seed=seed)
        whole = detect_scene(rendered.scene, detector)
        given = clipped_boxes(rendered.scene)
        clipped = detect_scene(given, detector)
        first = track_scene(clipped, TrackOptions(), prior=model).frames
        again, replaced = redetect_clipped(clipped, first, detector)
        runs = {"whole": (whole, track_scene(whole, TrackOptions(), prior=model).frames), "clipped": (clipped, first),
                "amodal pass": (again, track_scene(again, TrackOptions(), prior=model).frames)}
    rig = "three cameras, road plane" if sim.scene.ground_plane is not None else "two cameras, no plane"
    body_types = track_body_types(sim)
    for boxes, (scene, frames) in runs.items():
        truth = dataclasses.replace(sim, scene=scene)
        for row in class_rows(sim, pose_rows(truth, frames), scene):
            for kind in (row[0], "all"):
                poses[(rig, boxes, kind)].append(row)
        for vid, error in final_shape_errors(truth, frames).items():
            for key in (body_types[vid], "all"):
                shapes[(rig, boxes, key)].append(100 * float(np.linalg.norm(error, axis=1).mean()))
    at_border = sum(clipped_by_border(d.roi, given.cameras[d.camera].image_size)
                    for frame in given.frames for d in frame.detections)
    return f"{scenario} seed {seed}: {replaced} of {at_border} clipped boxes found again"


def table(poses: dict, shapes: dict) -> str:
    lines = ["| rig | body type | boxes | poses | rotation (deg) | translation (cm) | pose NEES | final shapes (cm) |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for key in sorted(poses, key=lambda k: (k[0], k[2] != "all", k[2], BOXES.index(k[1]))):
        rows = np.array([row[2:5] for row in poses[key]], dtype=float)
        nees = rows[np.isfinite(rows[:, 2]), 2]
        lines.append(f"| {key[0]} | {key[2]} | {key[1]} | {len(rows)} | {rows[:, 0].mean():.2f} | "
                     f"{rows[:, 1].mean():.1f} | {nees.mean() / 6 if len(nees) else float('nan'):.2f}x | "
                     f"{np.mean(shapes.get(key, [np.nan])):.1f} |")
    return "\n".join(lines)


def main(argv=None) -> str:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=270)
    parser.add_argument("--scenarios", nargs="+",
                        default=["tracks_3veh", "library_tracks_2cam", "tracks_3cam", "library_tracks"])
    args = parser.parse_args(argv)
    detector = KeypointDetector()
    poses, shapes = collections.defaultdict(list), collections.defaultdict(list)
    for scenario in args.scenarios:
        print(scene_rows(scenario, args.seed, detector, poses, shapes), flush=True)
    out = table(poses, shapes)
    print(out)
    return out


if __name__ == "__main__":
    main()
