"""Accuracy: tracks with the road plane fitted to other traffic of the same rig (``vfactor fit-ground``).

The two-camera rig of ``tracks_3veh`` and ``library_tracks_2cam`` (no road
plane given). The plane is fitted (:func:`vfactor.ground_fit.fit_ground_plane`)
to the tracks of *calibration* scenes (other seeds: other vehicles, other
noise), then the held-out scenes are tracked three ways: without a plane (what
such a rig gets today), with the fitted plane, and with the true one (the
simulator's road, z = 0). Every vehicle is solved with a shape model learnt
without it. Prints per scene, per body type and per camera count (the cameras
that saw the vehicle in that frame): rotation (deg) / translation (cm) / pose
NEES (as a ratio to 6) of the one-frame solves (``frame_by_frame``, as
``vfactor solve``) and of the smoothed (isam2), online, fixed-lag (0.5 s) and
batch estimates.

Run: ``python benchmarks/ground_fit_accuracy.py [--images] [--detector-offsets] [--scenes S ...]``
(``--images``: the scenes rendered and their keypoints found by the shipped
network, as ``vfactor eval images``; needs the ``net`` and ``render`` extras,
about 40 s a scene; ``--detector-offsets``: a fourth way, the fitted plane with
``TrackOptions(detector_offsets=True)``, which acts on the network's detections only;
``--scenes``: other held-out scenes of the rig, each ``scenario:seed``, instead of :data:`HELD_OUT`).
"""

from __future__ import annotations

import argparse
import dataclasses
from collections import defaultdict

from vfactor.evaluation import class_cell, class_rows, class_tables, held_out_scene_model, pose_rows
from vfactor.factors.ground_plane import GroundPlane
from vfactor.ground_fit import fit_ground_plane
from vfactor.sim import load_scenario, simulate
from vfactor.solve import SolveOptions, solve_scene
from vfactor.track import TrackOptions, smooth_scene, track_scene

CALIBRATION = ("library_tracks_2cam:20", "tracks_3veh:20")
HELD_OUT = ("library_tracks_2cam:10", "library_tracks_2cam:11", "library_tracks_2cam:12",
            "tracks_3veh:0", "tracks_3veh:1", "tracks_3veh:2")
TRUE_PLANE = GroundPlane((0.0, 0.0, 1.0), 0.0)  # the simulator's road


def _scene(spec: str, images: bool):
    scenario, seed = spec.split(":")
    if images:
        from vfactor.net.end_to_end import render_and_detect

        sim, _, detected, _ = render_and_detect(scenario, int(seed))
        return dataclasses.replace(sim, scene=detected)
    return simulate(load_scenario(scenario), seed=int(seed))


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", action="store_true", help="the network's keypoints on rendered images")
    parser.add_argument("--lag", type=float, default=0.5)
    parser.add_argument("--detector-offsets", action="store_true",
                        help="also track with the fitted plane and each camera's detector pose offsets")
    parser.add_argument("--scenes", nargs="+", default=list(HELD_OUT), metavar="SCENARIO:SEED",
                        help="held-out scenes of the two-camera rig (default: %(default)s)")
    args = parser.parse_args(argv)

    fitted = []
    for spec in CALIBRATION:
        sim = _scene(spec, args.images)
        fitted += track_scene(sim.scene, TrackOptions(covariance=False), prior=held_out_scene_model(sim)).frames
    fit = fit_ground_plane(fitted)
    print(f"plane fitted to {', '.join(CALIBRATION)} ({fit.points} tracked poses): {fit.tilt_deg:.2f} deg from "
          f"the true road's, offset {100 * fit.plane.offset:.1f} cm (the road at 0, hubs at 0.34 m above the plane)")
    planes = {"no plane": None, "fitted plane": fit.plane, "true plane": TRUE_PLANE}
    if args.detector_offsets:
        planes["fitted plane, offsets"] = fit.plane
    methods = ("frame_by_frame", "isam2", "isam2_online", "isam2_lag", "batch")
    pooled = defaultdict(list)
    print(f"\n| scene | plane | {' | '.join(methods)} | not solved (frame by frame) |\n| --- | --- | "
          f"{' | '.join('---' for _ in methods)} | --- |")
    for spec in args.scenes:
        if spec in CALIBRATION:
            parser.error(f"--scenes: {spec} is a calibration scene (the plane is fitted to it)")
        sim = _scene(spec, args.images)
        model = held_out_scene_model(sim)
        for name, plane in planes.items():
            scene = dataclasses.replace(sim.scene, ground_plane=plane)
            options = TrackOptions(detector_offsets=name.endswith("offsets"))
            run = track_scene(scene, options, prior=model)
            runs = {"frame_by_frame": solve_scene(scene, SolveOptions(), prior=model),
                    "isam2": run.frames, "isam2_online": run.online,
                    "isam2_lag": track_scene(scene, dataclasses.replace(options, lag=args.lag), prior=model).frames,
                    "batch": smooth_scene(scene, options, prior=model)}
            rows = {m: class_rows(sim, pose_rows(sim, frames), scene) for m, frames in runs.items()}
            failed = sum(not v.ok for frame in runs["frame_by_frame"] for v in frame.vehicles)
            for m in methods:
                pooled[(name, m)] += rows[m]
            cells = " | ".join(class_cell(rows[m]) for m in methods)
            print(f"| {spec.replace(':', ' ')} | {name} | {cells} | {failed} |", flush=True)
    print("\n" + class_tables(pooled, methods, list(planes), "plane"))
    return {"fit": fit, "pooled": pooled}


if __name__ == "__main__":
    main()
