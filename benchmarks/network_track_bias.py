"""Tracks from the keypoint network's keypoints, with and without the detector's bias (``Detection.bias_sigma``).

Renders each scene (``scenario:seed``), finds the keypoints with the shipped network (its calibration sets each
detection's ``shape_sigma`` and ``bias_sigma``), tracks the vehicles (iSAM2 final and online, iSAM2 with a 1 s
fixed lag, batch smoothing; each with the shape model learnt without the scene's vehicle models) once with the
detections as they are and once with their ``bias_sigma`` removed, and prints per method and per rig (three cameras
with the road plane, two without) the mean rotation and translation errors, the pose NEES (x 6) and the share of poses
under the chi-square 95 % bound, and per body type the pose NEES.

Run: ``python benchmarks/network_track_bias.py [--cache DIR] [--bias R P Y X Y Z] [--runs with] SCENARIO:SEED
...`` (about two minutes a scene to render and detect on two CPU cores; ``--cache`` keeps the detected
scenes, which are given the shipped calibration's ``shape_sigma`` when read back; ``--bias`` replaces the shipped
calibration's bias_sigma, radians and metres; ``--runs with`` tracks with the bias only). Needs torch and
moderngl.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from vfactor.evaluation import class_rows, held_out_scene_model, pose_rows
from vfactor.metrics import CHI2_95
from vfactor.net.end_to_end import detected_scene
from vfactor.track import TrackOptions, smooth_scene, track_scene


def with_bias(scene, bias, shape_sigma=None):
    """``scene`` with every detection that carries a ``shape_sigma`` (the network's) given ``bias`` (None: none)
    and, where given, ``shape_sigma`` (the calibration's: a cached scene keeps the one it was detected with)."""
    def calibrated(d):
        if not d.shape_sigma:
            return dataclasses.replace(d, bias_sigma=None)
        return dataclasses.replace(d, bias_sigma=bias, shape_sigma=shape_sigma or d.shape_sigma)

    frames = [dataclasses.replace(f, detections=[calibrated(d) for d in f.detections]) for f in scene.frames]
    return dataclasses.replace(scene, frames=frames)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+", metavar="SCENARIO:SEED")
    parser.add_argument("--cache", type=Path, help="folder that keeps the detected scenes")
    parser.add_argument("--bias", type=float, nargs=6, metavar="S", help="bias_sigma to use (default: the shipped)")
    parser.add_argument("--runs", choices=("without", "with", "both"), default="both",
                        help="track without the bias, with it, or both (default)")
    args = parser.parse_args(argv)
    from vfactor.net.infer import KeypointDetector, default_weights_path

    calibration = KeypointDetector(default_weights_path()).calibration
    bias = calibration.bias_sigma if args.bias is None else tuple(args.bias)
    shape_sigma = calibration.shape_sigma  # the shipped calibration's, also for scenes detected before it
    print(f"bias_sigma {bias}, shape_sigma {shape_sigma}")
    rows: dict[tuple[str, str, str], list] = {}
    for spec in args.scenes:
        sim, detected = detected_scene(spec, args.cache)
        model = held_out_scene_model(sim)
        rig = "3 cameras, plane" if detected.ground_plane is not None else "2 cameras, no plane"
        for label, b in (("without", None), ("with", bias)):
            if args.runs not in (label, "both"):
                continue
            scene = with_bias(detected, b, shape_sigma)
            run = track_scene(scene, TrackOptions(), prior=model)
            runs = {"isam2": run.frames, "isam2, online": run.online,
                    "isam2, 1 s lag": track_scene(scene, TrackOptions(lag=1.0), prior=model).frames,
                    "batch": smooth_scene(scene, TrackOptions(), prior=model)}
            for method, frames in runs.items():
                truth = dataclasses.replace(sim, scene=scene)
                rows.setdefault((method, rig, label), []).extend(class_rows(sim, pose_rows(truth, frames), scene))
    print("\n| method | rig | bias | poses | rotation (deg) | translation (cm) | pose NEES | under the bound | "
          "NEES per body type |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for (method, rig, label), rs in sorted(rows.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][2] != "without")):
        r = np.array([x[2:] for x in rs], dtype=float)
        types = np.array([x[0] for x in rs])
        per_type = ", ".join(f"{t} {np.nanmean(r[types == t, 2]) / 6:.2f}x" for t in sorted(set(types)))
        print(f"| {method} | {rig} | {label} | {len(r)} | {r[:, 0].mean():.2f} | {r[:, 1].mean():.2f} | "
              f"{np.nanmean(r[:, 2]) / 6:.2f}x | {100 * np.nanmean(r[:, 2] < CHI2_95[6]):.0f} % | {per_type} |")


if __name__ == "__main__":
    main()
