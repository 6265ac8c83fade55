"""One-frame pose and keypoint NEES from the keypoint network's keypoints, per body type and camera count, for models
of the detector's error of the shape (``GraphConfig.shape_error_through_fit``) on the same solutions.

Renders each scene (``scenario:seed``), finds the keypoints with the shipped network, solves every vehicle with the
shape model learnt without it (:func:`vfactor.net.shape_error.vehicle_errors`) and prints, per body type, camera
count and in all, the mean pose NEES (x 6) and keypoint NEES (x 3) with the shares under their chi-square 95 %
bounds, for each ``--through-fit`` factor, every detection given ``--shape-sigma`` (default: the shipped
calibration's; 0: no error of the shape).

Run: ``python benchmarks/network_frame_nees.py [--cache DIR] [--shape-sigma S] [--through-fit 0 1] SCENARIO:SEED
...`` (about 80 s a scene to render and detect on two CPU cores, 5-10 s a scene and factor to solve; ``--cache``
keeps the detected scenes, :func:`vfactor.net.end_to_end.detected_scene`). Needs torch and moderngl.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from vfactor.graph import GraphConfig
from vfactor.metrics import nees_summary
from vfactor.net.end_to_end import detected_scene
from vfactor.net.shape_error import keypoint_nees_at, pose_nees_at, vehicle_errors
from vfactor.solve import SolveOptions
from vfactor.vehicle_library import BODY_TYPES


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+", metavar="SCENARIO:SEED")
    parser.add_argument("--cache", type=Path, help="folder that keeps the detected scenes")
    parser.add_argument("--shape-sigma", type=float,
                        help="shape_sigma (m at 9 m^3; default: the shipped calibration's)")
    parser.add_argument("--through-fit", type=float, nargs="+", default=[GraphConfig().shape_error_through_fit],
                        help="GraphConfig.shape_error_through_fit factors to compare (default: the default)")
    args = parser.parse_args(argv)
    if args.shape_sigma is None:
        from vfactor.net.infer import KeypointDetector, default_weights_path

        args.shape_sigma = KeypointDetector(default_weights_path()).calibration.shape_sigma
    scenes = [detected_scene(spec, args.cache) for spec in args.scenes]
    print(f"shape_sigma {args.shape_sigma:.4f} m at 9 m^3; {', '.join(args.scenes)}\n")
    print("| shape_error_through_fit | class | vehicles | pose NEES | under | keypoint NEES | under |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for factor in args.through_fit:
        graph = dataclasses.replace(GraphConfig(), shape_error_through_fit=factor)
        vehicles = [v for sim, detected in scenes for v in vehicle_errors(sim, detected, SolveOptions(graph=graph))]
        pose = pose_nees_at(vehicles, args.shape_sigma, graph.shape_sigma_size_exponent)
        keypoints = keypoint_nees_at(vehicles, args.shape_sigma, graph.shape_sigma_size_exponent)
        groups = {c: [v.body_type == c for v in vehicles] for c in (*BODY_TYPES, "pascal3d")}
        counts = sorted({v.cameras for v in vehicles})
        groups.update({f"{n} cameras": [v.cameras == n for v in vehicles] for n in counts})
        groups["all"] = [True] * len(vehicles)
        for name, mask in groups.items():
            mask = np.asarray(mask, dtype=bool)
            if not mask.any():
                continue
            p, k = nees_summary(pose[mask], 6), nees_summary(keypoints[mask], 3)
            print(f"| {factor:g} | {name} | {mask.sum()} | {p['ratio']:.2f}x | {100 * p['under_95']:.1f} % "
                  f"| {k['ratio']:.2f}x | {100 * k['under_95']:.1f} % |")


if __name__ == "__main__":
    main()
