"""Diagnosis: what keeps two-camera tracks' final shapes from issue 10's 5 cm: the shape's own pixels, or its poses?

Each scene of the two-camera rig (``tracks_3veh``, ``library_tracks_2cam``: no road plane) is smoothed in batch
(:func:`vfactor.track.smooth_scene`, the shape model held out) several ways, and each track's final shape compared
with the truth (mean body-frame keypoint error, cm), per body type:

* ``free``: as vfactor smooths it;
* ``true poses``: the same graph with every pose held at the truth by a prior of 0.1 mm / 1e-4 rad (what the shape
  would be if the track's poses were known: the shape's information from its pixels alone);
* ``true rotations`` / ``true translations`` / ``true height, roll, pitch`` (what a road plane could give): only
  those components held (body-frame tangent of the pose; the others free);
* ``tighter acceleration``: no truth; the motion model's acceleration sigmas at a quarter
  (:class:`~vfactor.factors.motion.MotionModel` ``sigma_acceleration`` 0.5 m/s^2, ``sigma_yaw_acceleration``
  0.25 rad/s^2), to see whether a smoother motion model would carry the poses' information across frames.

The priors are added by wrapping ``vfactor.track._add_pose_factors`` for the run (a diagnosis, not an API).

Run: ``python benchmarks/track_shape_known_poses.py [--seeds FIRST END] [--ways free true_poses ...]``
(defaults: seeds 280-289 of both scenarios, every way; about 2 min a way on 2 cores).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import pathlib
import sys

import gtsam
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
import vfactor.track as track  # noqa: E402
from vfactor.evaluation import (final_shape_errors, final_shape_table, held_out_scene_model,  # noqa: E402
                                track_body_types)
from vfactor.factors.motion import MotionModel  # noqa: E402
from vfactor.keys import KeyScheme  # noqa: E402
from vfactor.sim import load_scenario, simulate  # noqa: E402

HELD, FREE = 1e-4, 1e3  # sigmas (rad, m) of a held and a free component of the truth prior
#: way -> the sigmas of the prior at the true pose (rotation about body x, y, z, then body-frame translation), or
#: None (no prior).
WAYS = {
    "free": None,
    "true_poses": [HELD] * 6,
    "true_rotations": [HELD] * 3 + [FREE] * 3,
    "true_translations": [FREE] * 3 + [HELD] * 3,
    "true_height_roll_pitch": [HELD, HELD, FREE, FREE, FREE, HELD],
    "tighter_acceleration": None,
}
SCENARIOS = ("tracks_3veh", "library_tracks_2cam")


@contextlib.contextmanager
def poses_held(truth: dict, sigmas):
    """While open, every pose factor the batch smoother adds for a key of ``truth`` (pose key -> true
    ``world_T_vehicle``) comes with a prior at the truth of ``sigmas``."""
    original = track._add_pose_factors
    noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, dtype=float))

    def with_truth(graph, poses, key, t, options, hub):
        original(graph, poses, key, t, options, hub)
        if key in truth:
            graph.add(gtsam.PriorFactorPose3(key, truth[key], noise))

    track._add_pose_factors = with_truth
    try:
        yield
    finally:
        track._add_pose_factors = original


def true_poses(sim) -> dict:
    """Pose key of the batch smoother (track index, frame index) -> the true ``world_T_vehicle``."""
    keys, scene = KeyScheme(), sim.scene
    units = track._track_units(scene, track.frame_order(scene), (scene.cameras, None, None, None))
    return {keys.pose_key(index, i): sim.truth[i][vid].world_T_vehicle for vid, index, (_, frames) in units
            for i, _ in frames}


def final_shapes(sim, way: str) -> dict[str, float]:
    """Track id -> final shape error (cm) of ``sim`` smoothed the way ``way``."""
    motion = MotionModel(sigma_acceleration=0.5, sigma_yaw_acceleration=0.25) if way == "tighter_acceleration" \
        else MotionModel()
    options = track.TrackOptions(covariance=False, motion=motion)
    held = poses_held(true_poses(sim), WAYS[way]) if WAYS[way] is not None else contextlib.nullcontext()
    with held:
        frames = track.smooth_scene(sim.scene, options, prior=held_out_scene_model(sim))
    return {vid: 100 * float(np.linalg.norm(e, axis=1).mean()) for vid, e in final_shape_errors(sim, frames).items()}


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs=2, default=(280, 290), metavar=("FIRST", "END"))
    parser.add_argument("--ways", nargs="+", default=list(WAYS), choices=list(WAYS))
    args = parser.parse_args(argv)
    errors = {way: {} for way in args.ways}  # way -> body type -> final shape errors (cm)
    for scenario in SCENARIOS:
        for seed in range(*args.seeds):
            sim = simulate(load_scenario(scenario), seed=seed)
            types = track_body_types(sim)
            line = []
            for way in args.ways:
                shapes = final_shapes(sim, way)
                for vid, error in shapes.items():
                    errors[way].setdefault(types[vid], []).append(error)
                line.append(f"{way} " + ", ".join(f"{types[v]} {e:.1f}" for v, e in sorted(shapes.items())))
            print(f"{scenario} {seed}: " + "; ".join(line), flush=True)
    print("\n" + final_shape_table(errors, "poses"))
    return errors


if __name__ == "__main__":
    main()
